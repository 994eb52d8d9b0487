//! How a `dyfos` query's time grows with the map: numerical maps with more
//! cylinders at the paper's density, and the same maps as 0.1 m occupancy grids.
//!
//! ```
//! use dyfos_bench::scaling::{MapKind, obstacle_scaling};
//! use dyfos_service::search::{AnySearch, Brute};
//!
//! let coarse = AnySearch::Brute(Brute { grid: [3, 3, 3, 8] });
//! let rows = obstacle_scaling(&[25, 100], 1, 1, &coarse, Some(0.5));
//! assert_eq!(rows.len(), 4);
//! assert_eq!((rows[0].kind, rows[0].obstacles, rows[0].half_width), (MapKind::Cylinders, 25, 10.0));
//! assert_eq!((rows[3].kind, rows[3].half_width), (MapKind::Voxels { resolution: 0.5 }, 20.0));
//! assert!(rows[3].occupied_cells.unwrap() > 10_000);
//! ```

use crate::evaluation::{Contender, Timing, duration, evaluate};
use crate::numerical::{NumericalConfig, numerical_map, voxelized};
use crate::stats::Summary;
use dyfos_service::search::AnySearch;
use std::fmt::Write;

/// How the obstacles of a scaling row are represented.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum MapKind {
    /// Exact cylinders in the BVH.
    Cylinders,
    /// The cylinders rasterized into an occupancy grid.
    Voxels {
        /// Cell side, m.
        resolution: f64,
    },
}

/// Query times for one map size and representation.
#[derive(Debug, Clone, PartialEq)]
pub struct ScalingRow {
    /// Cylinders drawn.
    pub obstacles: usize,
    /// Half the map's side, m.
    pub half_width: f64,
    /// Representation.
    pub kind: MapKind,
    /// Occupied cells of the grid, for voxel rows.
    pub occupied_cells: Option<usize>,
    /// Per-query wall time over the maps, s; `None` when the map could not be built.
    pub seconds: Option<Summary>,
    /// Per-query CPU time, s, median over the maps.
    pub cpu_seconds: Option<f64>,
    /// Per-query CPU-µs per evaluated candidate, median over the maps.
    pub micros_per_evaluation: Option<f64>,
    /// Candidates per query, median.
    pub evaluations: Option<f64>,
    /// Maps on which the search found a feasible pose.
    pub feasible: usize,
    /// Why the row is empty, if it is.
    pub skipped: Option<String>,
}

/// Times `search` (one thread) on `maps` maps for each cylinder count, and, with
/// `voxel_resolution`, on the same maps rasterized. A grid beyond the map limits
/// gives a row with `skipped` set instead of failing the run.
pub fn obstacle_scaling(
    counts: &[usize],
    maps: usize,
    seed: u64,
    search: &AnySearch,
    voxel_resolution: Option<f64>,
) -> Vec<ScalingRow> {
    let contender = [Contender { name: "search".into(), search: *search, threads: 1 }];
    let mut rows = Vec::new();
    for &n in counts {
        let config = NumericalConfig::with_cylinders(n);
        let scenarios: Vec<_> = (0..maps as u64).map(|i| numerical_map(seed, i, &config)).collect();
        rows.push(row(n, &config, MapKind::Cylinders, None, &scenarios, &contender, seed));
        if let Some(resolution) = voxel_resolution {
            let kind = MapKind::Voxels { resolution };
            let grids: Result<Vec<_>, _> = scenarios.iter().map(|s| voxelized(s, resolution)).collect();
            match grids {
                Ok(grids) => {
                    let cells = grids.iter().map(|g| g.world.voxels().map_or(0, |v| v.len() as usize)).max();
                    rows.push(row(n, &config, kind, cells, &grids, &contender, seed));
                }
                Err(e) => rows.push(ScalingRow {
                    obstacles: n,
                    half_width: config.half_width,
                    kind,
                    occupied_cells: None,
                    seconds: None,
                    cpu_seconds: None,
                    micros_per_evaluation: None,
                    evaluations: None,
                    feasible: 0,
                    skipped: Some(e.to_string()),
                }),
            }
        }
    }
    rows
}

fn row(
    n: usize,
    config: &NumericalConfig,
    kind: MapKind,
    occupied_cells: Option<usize>,
    scenarios: &[dyfos_shared::scenario::Scenario],
    contender: &[Contender],
    seed: u64,
) -> ScalingRow {
    let run = evaluate(scenarios, contender, seed, 3);
    let q = &run.queries[0];
    let timing = Timing::of(q);
    ScalingRow {
        obstacles: n,
        half_width: config.half_width,
        kind,
        occupied_cells,
        seconds: timing.seconds,
        cpu_seconds: timing.cpu_seconds.map(|s| s.median),
        micros_per_evaluation: timing.micros_per_evaluation.map(|s| s.median),
        evaluations: timing.evaluations.map(|s| s.median),
        feasible: q.iter().filter(|q| q.feasible()).count(),
        skipped: None,
    }
}

/// The rows as a markdown table.
pub fn scaling_table(rows: &[ScalingRow]) -> String {
    let mut out = String::from(
        "| cylinders | map | obstacles as | occupied cells | time median | ± std | max | CPU time median | evaluations median | CPU-µs per evaluation | feasible |\n|---:|---|---|---:|---:|---:|---:|---:|---:|---:|---:|\n",
    );
    for r in rows {
        let side = format!("{0:.0} × {0:.0} m", 2.0 * r.half_width);
        let kind = match r.kind {
            MapKind::Cylinders => "cylinders".to_string(),
            MapKind::Voxels { resolution } => format!("voxels {resolution} m"),
        };
        let cells = r.occupied_cells.map_or("–".into(), |c| c.to_string());
        match (&r.seconds, &r.skipped) {
            (Some(s), _) => {
                let _ = writeln!(
                    out,
                    "| {} | {side} | {kind} | {cells} | {} | {} | {} | {} | {:.0} | {:.3} | {}/{} |",
                    r.obstacles,
                    duration(s.median),
                    duration(s.std),
                    duration(s.max),
                    r.cpu_seconds.map_or("–".into(), duration),
                    r.evaluations.unwrap_or(f64::NAN),
                    r.micros_per_evaluation.unwrap_or(f64::NAN),
                    r.feasible,
                    s.count
                );
            }
            (None, why) => {
                let why = why.as_deref().unwrap_or("no maps");
                let _ = writeln!(out, "| {} | {side} | {kind} | {cells} | skipped: {why} | | | | | | |", r.obstacles);
            }
        }
    }
    out
}
