//! # dyfos-mission
//!
//! The paper's simulated missions (SPEC §9, §10), played by real processes over
//! iceoryx2: the rover ([`rover`]: EKF, controller, the rendezvous loop) and the
//! viewer ([`viewer`]: the map's owner, asking `dyfosd` through `dyfos-client`
//! where to put its camera), the simulation they run in ([`sim`]: true motion,
//! camera, flight, clock), the mission files and the topics between the two
//! ([`mission`]), and the evaluation of a run ([`eval`]: APE, SVG, MCAP files for
//! Foxglove and ROS 2). The `dyfos-rover` and `dyfos-viewer` binaries are thin
//! layers over [`rover::run_rover`] and [`viewer::run_viewer`].
//!
//! A robot that only asks the daemon links `dyfos-client`, not this crate.
//!
//! ```
//! use dyfos_mission::mission::Mission;
//!
//! let m = Mission::builtin();
//! assert_eq!(m.waypoints.len(), 10);
//! ```
#![warn(missing_docs)]

pub mod cli;
pub mod eval;
pub mod mission;
pub mod rover;
pub mod sim;
pub mod viewer;
