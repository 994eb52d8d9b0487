//! # dyfos-bench
//!
//! Benchmarks and reproductions of the paper's evaluations, as a library the
//! `dyfos-bench` binary (and the test suite) drive.
//!
//! - [`numerical`]: the seeded random maps of SPEC §10, with voxel variants;
//! - [`compare`]: two builds' `dyfos solve` interleaved on the same scenarios (`dyfos-bench compare`);
//! - [`evaluation`]: runs search algorithms over maps, tabulates cost E and run time;
//! - [`latency`]: the request mix, drivers, in-process baseline and iceoryx2 floor of
//!   `dyfos-bench latency`;
//! - [`learned`]: the learned SDSMM against the synthetic camera it was trained on;
//! - [`octomap`]: a synthetic OctoMap building of any size, for load/update/query figures;
//! - [`scaling`]: `dyfos` query time as the map grows;
//! - [`stats`], [`svg`]: summaries and plots for the reports.
//!
//! ```
//! use dyfos_bench::evaluation::{Contender, evaluate};
//! use dyfos_bench::numerical::{NumericalConfig, numerical_maps};
//! use dyfos_shared::answer::Algorithm;
//!
//! let maps = numerical_maps(42, 1, &NumericalConfig::paper());
//! let run = evaluate(&maps, &[Contender::algorithm(Algorithm::Dyfos, 1)], 42, 1);
//! assert!(run.queries[0][0].feasible());
//! ```

pub mod compare;
pub mod evaluation;
pub mod latency;
pub mod learned;
pub mod numerical;
pub mod octomap;
pub mod scaling;
pub mod stats;
pub mod svg;
pub mod table;
