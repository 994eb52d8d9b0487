//! # dyfos-shared
//!
//! Everything both sides of DyFOS agree on, with no I/O: the math types, the world
//! map and its ray queries, the sensor geometry, the SDSMM noise models, the Kalman
//! posterior, scenario files, the JSON of maps and map deltas (`map_json`) and the
//! wire types of the daemon's services.
//!
//! ```
//! use dyfos_shared::prelude::*;
//!
//! let scenario = Scenario::from_json(r#"{
//!     "bounds": [-10.0, -10.0, 10.0, 10.0],
//!     "sun": {"elevation": 0.7, "azimuth": 2.1},
//!     "obstacles": [{"id": 1, "cylinder": {"x": 2.0, "y": 1.0, "radius": 0.5, "height": 10.0}}],
//!     "rover": {"mean": [0.0, 0.0, 0.3],
//!               "cov": [[0.2, 0.05, 0.0], [0.05, 0.1, 0.0], [0.0, 0.0, 0.05]]}
//! }"#).unwrap();
//! assert_eq!(scenario.world.obstacles().len(), 1);
//! assert_eq!(scenario.params, Params::default());
//! ```
#![warn(missing_docs)]

pub mod answer;
pub mod codes;
pub mod limits;
pub mod map_json;
pub mod math;
pub mod params;
pub mod posterior;
pub mod scenario;
pub mod sdsmm;
pub mod sensor;
pub mod wire;
pub mod world;

/// The types most users need, in one `use`.
pub mod prelude {
    pub use crate::answer::{Algorithm, Answer, EvalStats, StopReason};
    pub use crate::math::{Cov2, Cov3, CovarianceError, Isometry3, Point3, UnitQuaternion, Vector3};
    pub use crate::params::{ModelKind, ParamError, Params};
    pub use crate::posterior::{Belief, Prior};
    pub use crate::scenario::{Scenario, ScenarioError};
    pub use crate::sdsmm::{Features, NoiseModel, Sdsmm};
    pub use crate::sensor::{SearchSpace, SensorPose, SensorState};
    pub use crate::world::{Bounds, MapDelta, MapDeltaError, Obstacle, Sun, VoxelGrid, World};
    pub use nalgebra as na;
}
