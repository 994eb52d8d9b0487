//! What a search answers (SPEC §8): the chosen sensor and viewer poses, the
//! candidate x, the predicted noise R, the posterior Σ⁺ and its cost E, and how
//! the search got there.

use crate::codes::codes;
use crate::math::{Matrix3, Point3, UnitQuaternion, canonical_xyzw, rows3};
use crate::sensor::SensorState;

codes! {
    /// The search algorithms of SPEC §8; the code is the wire's `algorithm` tag, the
    /// name the command-line and JSON one.
    pub enum Algorithm("algorithm", serde) {
        /// Differential evolution (the DyFOS optimizer), with a final local polish.
        Dyfos = 0, "dyfos";
        /// Differential evolution exactly as SciPy's defaults, no polish (the paper's).
        DyfosScipy = 1, "dyfos-scipy";
        /// Exhaustive grid on all cores.
        Brute = 2, "brute";
        /// Uniform samples until the first feasible one.
        Random = 3, "random";
        /// Rover in the image centre, uniform ρ and yaw until the first feasible one.
        Center = 4, "center";
    }
}

/// Candidates evaluated, split by the first constraint that rejected them (SPEC §5).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
pub struct EvalStats {
    /// Every candidate evaluated.
    pub total: u64,
    /// Rejected: viewer outside the bounds or the altitude limits.
    pub workspace: u64,
    /// Rejected: viewer too close to an obstacle.
    pub collision: u64,
    /// Rejected: the line of sight to the rover is blocked.
    pub occlusion: u64,
}

impl EvalStats {
    /// Candidates that passed every constraint.
    pub fn feasible(&self) -> u64 {
        self.total - self.workspace - self.collision - self.occlusion
    }
}

impl std::ops::AddAssign for EvalStats {
    fn add_assign(&mut self, o: Self) {
        self.total += o.total;
        self.workspace += o.workspace;
        self.collision += o.collision;
        self.occlusion += o.occlusion;
    }
}

codes! {
    /// Why a search stopped; the code is the reply's `stop`.
    pub enum StopReason("stop", serde) {
        /// The search ran to its natural end (converged, grid done, feasible sample found).
        Finished = 0, "finished";
        /// Differential evolution hit its generation cap.
        MaxGenerations = 1, "max_generations";
        /// The request's evaluation budget ran out.
        Budget = 2, "budget";
        /// The request's deadline passed; the answer is the best found so far.
        Deadline = 3, "deadline";
        /// Whoever asked no longer wants the answer (the daemon saw the client go away),
        /// so the search gave up; the daemon sends no reply for it.
        Abandoned = 4, "abandoned";
    }
}

/// The optimal sensor state found, with everything SPEC §8 says an answer carries.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Answer {
    /// The algorithm that found it.
    pub algorithm: Algorithm,
    /// The candidate x.
    pub x: SensorState,
    /// E = ln det Σ⁺.
    pub cost: f64,
    /// Sensor position p_s.
    pub sensor_position: Point3<f64>,
    /// Sensor orientation R_ws.
    pub sensor_orientation: UnitQuaternion<f64>,
    /// Viewer position p_v.
    pub viewer_position: Point3<f64>,
    /// Viewer yaw ψ_v.
    pub viewer_yaw: f64,
    /// Predicted measurement noise R.
    pub r: [[f64; 2]; 2],
    /// Predicted posterior Σ⁺.
    pub posterior: Matrix3<f64>,
    /// Evaluation counts.
    pub evaluations: EvalStats,
    /// Compute time, µs.
    pub micros: u64,
    /// The map version searched.
    pub map_version: u64,
    /// Why the search stopped; `Deadline` means the best so far, not converged.
    pub stop: StopReason,
}

impl Answer {
    /// The JSON object `dyfos solve` prints.
    pub fn to_json(&self) -> serde_json::Value {
        serde_json::json!({
            "algorithm": self.algorithm.name(),
            "x": self.x.to_array(),
            "cost": self.cost,
            "sensor_position": <[f64; 3]>::from(self.sensor_position.coords),
            "sensor_quaternion": canonical_xyzw(&self.sensor_orientation),
            "viewer_position": <[f64; 3]>::from(self.viewer_position.coords),
            "viewer_yaw": self.viewer_yaw,
            "R": self.r,
            "posterior": rows3(&self.posterior),
            "evaluations": self.evaluations,
            "micros": self.micros,
            "map_version": self.map_version,
            "stop": self.stop,
        })
    }
}
