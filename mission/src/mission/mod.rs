//! Missions: the world, the rover's start and waypoints, and the simulation's
//! noise — what the rover and viewer processes play (SPEC §9, §10 "Simulated").
//!
//! [`Mission::builtin`] is SPEC §10's simulated evaluation: 25 cylinders 10 m tall
//! and 1 m across in a 20 m × 20 m map, and 10 fixed waypoints over 24.6 m.
//! [`Mission::from_json`] reads the same from a file:
//!
//! ```json
//! {
//!   "scenario": { "bounds": [...], "sun": {...}, "obstacles": [...],
//!                 "rover": {"mean": [x, y, θ], "cov": [[...], [...], [...]]},
//!                 "params": {...} },
//!   "waypoints": [[x1, y1], [x2, y2], ...],
//!   "true_start": [x, y, θ],
//!   "viewer_start": [x, y, z, yaw],
//!   "odometry": {"trans_per_m": 0.002, "trans_per_rad": 0.0001,
//!                "rot_per_m": 0.0005, "rot_per_rad": 0.002},
//!   "sun_azimuth_rate": 0.0
//! }
//! ```
//!
//! - `scenario` is a SPEC §11 document, validated the same way; its `rover` is the
//!   rover's *initial belief* at the start (mean and covariance), and its `params`
//!   are the viewer's, the camera's and the daemon's.
//! - `waypoints` (required, 1 to 10 000, inside the bounds) are visited in order;
//!   the last is the goal. Each is a rendezvous.
//! - `true_start` (optional) is the rover's true start pose; by default it is drawn
//!   from the initial belief with the run's seed, so the filter starts consistent.
//! - `viewer_start` (optional) is where the viewer takes off; by default 3 m above
//!   the rover's start, facing the same way.
//! - `odometry` (optional, each field optional) overrides the odometry noise
//!   ([`OdometryNoise`]).
//! - `sun_azimuth_rate` (optional, rad per simulated second, |rate| ≤ 1, default 0)
//!   moves the sun during the mission; the viewer, which owns the map, sends the
//!   daemon the new sun as a map delta with its next query.
//!
//! Unknown fields are errors, like everywhere else.
//!
//! ```
//! use dyfos_mission::mission::Mission;
//!
//! let m = Mission::builtin();
//! assert_eq!(m.world.obstacles().len(), 25);
//! assert_eq!(m.waypoints.len(), 10);
//! assert!(m.path_length() > 20.0);
//! let again = Mission::from_json(&m.to_json()).unwrap();
//! assert_eq!(again, m);
//! assert!(Mission::from_json(r#"{"waypoints": []}"#).is_err());
//! ```

pub mod failure;
pub mod log;
pub mod output;
pub mod presence;
pub mod topics;

use crate::sim::OdometryNoise;
use dyfos_shared::math::{Point2, wrap_angle};
use dyfos_shared::params::Params;
use dyfos_shared::posterior::Belief;
use dyfos_shared::scenario::{Object, Scenario, ScenarioError};
use dyfos_shared::world::{Bounds, Obstacle, Sun, VerticalCylinder, World};
use serde::{Deserialize, Serialize};

/// Most waypoints in one mission.
pub const MAX_WAYPOINTS: usize = 10_000;

/// A mission: everything the rover and the viewer need to play it.
#[derive(Debug, Clone, PartialEq)]
pub struct Mission {
    /// The map (the viewer's, uploaded to the daemon), at version 0.
    pub world: World,
    /// Rover, viewer, camera and SDSMM parameters.
    pub params: Params,
    /// The rover's initial belief at the start.
    pub initial_belief: Belief,
    /// Waypoints to visit in order; the last is the goal.
    pub waypoints: Vec<[f64; 2]>,
    /// The true start pose; `None` draws it from the initial belief.
    pub true_start: Option<[f64; 3]>,
    /// The viewer's take-off position and yaw.
    pub viewer_start: ([f64; 3], f64),
    /// The odometry noise of the simulated rover (and the filter's model of it).
    pub odometry: OdometryNoise,
    /// How fast the sun's azimuth turns, rad per simulated second.
    pub sun_azimuth_rate: f64,
}

/// A mission file that cannot be used.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MissionParseError {
    /// Not JSON or not of the mission's shape.
    #[error("{path}{message}")]
    Malformed {
        /// Field path with a trailing `: `, or empty.
        path: String,
        /// What is wrong.
        message: String,
    },
    /// The embedded scenario is invalid.
    #[error("scenario.{0}")]
    Scenario(ScenarioError),
    /// A value is out of range.
    #[error("{path} {message}")]
    Invalid {
        /// The field.
        path: String,
        /// What is wrong and what would be right.
        message: String,
    },
}

#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawMission {
    scenario: serde_json::Value,
    waypoints: Vec<[f64; 2]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    true_start: Option<[f64; 3]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    viewer_start: Option<[f64; 4]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    odometry: Option<Object<OdometryNoise>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    sun_azimuth_rate: Option<f64>,
}

/// The built-in world's cylinders (x, y): placed once by a fixed pseudo-random draw
/// over the map, each at least 1.7 m from the rover's path (rover radius 0.75 m +
/// cylinder radius 0.5 m + 0.45 m) and 2 m from the others; 16 within 3.5 m of the
/// path, where they hem in the viewer and block its lines of sight.
const BUILTIN_CYLINDERS: [[f64; 2]; 25] = [
    [9.3, 9.2],
    [3.1, -2.4],
    [-3.9, -0.9],
    [-0.3, -5.4],
    [-6.0, -8.2],
    [0.3, 4.3],
    [-2.9, -9.3],
    [0.2, 1.4],
    [0.2, 6.4],
    [9.1, 3.6],
    [-8.9, -9.0],
    [5.5, 2.5],
    [-2.5, 0.6],
    [-1.7, -7.2],
    [5.6, 0.1],
    [5.4, 8.3],
    [-7.7, 1.7],
    [8.8, -4.4],
    [-5.2, 7.8],
    [-3.7, 9.2],
    [1.3, -3.3],
    [0.7, 8.6],
    [2.8, -5.7],
    [0.4, -9.5],
    [5.1, -5.9],
];

/// The built-in start (x, y) and waypoints: a winding 24.6 m path through the trees.
const BUILTIN_START: [f64; 2] = [-8.0, -7.0];
const BUILTIN_WAYPOINTS: [[f64; 2]; 10] = [
    [-6.0, -5.5],
    [-4.0, -6.5],
    [-2.0, -4.5],
    [-1.0, -2.0],
    [1.0, -1.0],
    [2.5, 1.0],
    [2.0, 3.5],
    [4.0, 5.0],
    [6.0, 4.5],
    [7.5, 6.5],
];

impl Mission {
    /// SPEC §10's simulated mission: bounds [−10, −10, 10, 10], the sun at 34°
    /// elevation from azimuth 2.4 rad, 25 cylinders (radius 0.5 m, height 10 m),
    /// the rover starting at (−8, −7) facing its first waypoint with a belief of 5 cm
    /// and 0.05 rad standard deviation, 10 waypoints, SPEC's default parameters,
    /// default odometry noise, the viewer taking off 3 m above the start.
    pub fn builtin() -> Self {
        let bounds = Bounds::new([-10.0, -10.0, 10.0, 10.0]).expect("valid bounds");
        let sun = Sun::new(0.6, 2.4).expect("valid sun");
        let obstacles = BUILTIN_CYLINDERS.iter().enumerate().map(|(i, c)| {
            (
                i as u32 + 1,
                Obstacle::Cylinder(VerticalCylinder { center: Point2::new(c[0], c[1]), radius: 0.5, height: 10.0 }),
            )
        });
        let world = World::new(0, bounds, sun, obstacles, None).expect("valid built-in world");
        let [x, y] = BUILTIN_START;
        let heading = (BUILTIN_WAYPOINTS[0][1] - y).atan2(BUILTIN_WAYPOINTS[0][0] - x);
        let initial_belief = Belief::new([x, y, heading], [[0.0025, 0.0, 0.0], [0.0, 0.0025, 0.0], [0.0, 0.0, 0.0025]])
            .expect("valid belief");
        Mission {
            world,
            params: Params::default(),
            initial_belief,
            waypoints: BUILTIN_WAYPOINTS.to_vec(),
            true_start: None,
            viewer_start: ([x, y, 3.0], heading),
            odometry: OdometryNoise::default(),
            sun_azimuth_rate: 0.0,
        }
    }

    /// Reads and validates a mission document (format in the module docs).
    pub fn from_json(json: &str) -> Result<Self, MissionParseError> {
        let de = &mut serde_json::Deserializer::from_str(json);
        let malformed = |path: String, message: String| {
            let path = if path.is_empty() || path == "." { String::new() } else { format!("{path}: ") };
            MissionParseError::Malformed { path, message }
        };
        // Records as JSON objects only, and nothing after the document, as for scenarios.
        let raw: Object<RawMission> = serde_path_to_error::deserialize(&mut *de)
            .map_err(|e| malformed(e.path().to_string(), e.into_inner().to_string()))?;
        de.end().map_err(|e| malformed(String::new(), e.to_string()))?;
        let raw = raw.0;
        let scenario = Scenario::from_json(&raw.scenario.to_string()).map_err(MissionParseError::Scenario)?;
        let invalid = |path: String, message: String| MissionParseError::Invalid { path, message };
        if raw.waypoints.is_empty() || raw.waypoints.len() > MAX_WAYPOINTS {
            return Err(invalid(
                "waypoints".into(),
                format!("has {} entries; give 1 to {MAX_WAYPOINTS} waypoints [x, y]", raw.waypoints.len()),
            ));
        }
        let bounds = scenario.world.bounds();
        for (i, w) in raw.waypoints.iter().enumerate() {
            if !(w[0].is_finite() && w[1].is_finite() && bounds.contains(w[0], w[1])) {
                return Err(invalid(
                    format!("waypoints[{i}]"),
                    format!("= {w:?} must be finite and inside the bounds {:?}", bounds.to_array()),
                ));
            }
        }
        if let Some(s) = raw.true_start
            && !(s.iter().all(|v| v.is_finite()) && bounds.contains(s[0], s[1]))
        {
            return Err(invalid("true_start".into(), format!("= {s:?} must be finite and inside the bounds")));
        }
        if let Some(v) = raw.viewer_start
            && !(v.iter().all(|x| x.is_finite()) && bounds.contains(v[0], v[1]) && v[2].abs() <= 1e4)
        {
            return Err(invalid("viewer_start".into(), format!("= {v:?} must be finite and inside the bounds")));
        }
        let odometry = raw.odometry.map(|o| o.0).unwrap_or_default();
        odometry.validate().map_err(|m| invalid("odometry".into(), m.trim_start_matches("odometry.").to_string()))?;
        let sun_azimuth_rate = raw.sun_azimuth_rate.unwrap_or(0.0);
        if !(sun_azimuth_rate.is_finite() && sun_azimuth_rate.abs() <= 1.0) {
            return Err(invalid("sun_azimuth_rate".into(), format!("= {sun_azimuth_rate} must be within ±1 rad/s")));
        }
        let mean = scenario.belief.mean;
        let viewer_start = match raw.viewer_start {
            Some(v) => ([v[0], v[1], v[2]], wrapped(v[3])),
            None => ([mean.x, mean.y, 3.0], wrapped(mean.z)),
        };
        Ok(Mission {
            world: scenario.world,
            params: scenario.params,
            initial_belief: scenario.belief,
            waypoints: raw.waypoints,
            true_start: raw.true_start,
            viewer_start,
            odometry,
            sun_azimuth_rate,
        })
    }

    /// The mission as a document [`Mission::from_json`] reads back to an equal one.
    pub fn to_json(&self) -> String {
        let scenario = Scenario { world: self.world.clone(), belief: self.initial_belief, params: self.params };
        let raw = RawMission {
            scenario: serde_json::from_str(&scenario.to_json()).expect("scenario JSON parses"),
            waypoints: self.waypoints.clone(),
            true_start: self.true_start,
            viewer_start: Some([
                self.viewer_start.0[0],
                self.viewer_start.0[1],
                self.viewer_start.0[2],
                self.viewer_start.1,
            ]),
            odometry: Some(Object(self.odometry)),
            sun_azimuth_rate: (self.sun_azimuth_rate != 0.0).then_some(self.sun_azimuth_rate),
        };
        serde_json::to_string_pretty(&raw).expect("mission serializes")
    }

    /// Reads a mission file, or the built-in mission for `None`.
    pub fn load(path: Option<&std::path::Path>) -> Result<Self, MissionLoadError> {
        let Some(path) = path else { return Ok(Mission::builtin()) };
        let text = std::fs::read_to_string(path)
            .map_err(|e| MissionLoadError::Read { path: path.display().to_string(), message: e.to_string() })?;
        Mission::from_json(&text)
            .map_err(|source| MissionLoadError::Invalid { path: path.display().to_string(), source })
    }

    /// Length of the rover's planned path from the initial belief's mean through
    /// every waypoint, m.
    pub fn path_length(&self) -> f64 {
        let mut at = [self.initial_belief.mean.x, self.initial_belief.mean.y];
        let mut total = 0.0;
        for w in &self.waypoints {
            total += (w[0] - at[0]).hypot(w[1] - at[1]);
            at = *w;
        }
        total
    }
}

/// `a` wrapped into [−π, π), untouched if it already is (so files round-trip exactly).
fn wrapped(a: f64) -> f64 {
    if (-std::f64::consts::PI..std::f64::consts::PI).contains(&a) { a } else { wrap_angle(a) }
}

/// A mission file that cannot be loaded.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MissionLoadError {
    /// The file cannot be read.
    #[error("cannot read mission file {path}: {message}")]
    Read {
        /// The file.
        path: String,
        /// The OS's reason.
        message: String,
    },
    /// The file's content is invalid.
    #[error("{path}: {source}")]
    Invalid {
        /// The file.
        path: String,
        /// What is wrong.
        #[source]
        source: MissionParseError,
    },
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn builtin_matches_spec_10() {
        let m = Mission::builtin();
        assert_eq!(m.world.obstacles().len(), 25);
        for o in m.world.obstacles().values() {
            let Obstacle::Cylinder(c) = o else { panic!("not a cylinder") };
            assert_eq!((c.radius, c.height), (0.5, 10.0));
        }
        assert_eq!(m.waypoints.len(), 10);
        assert!(m.path_length() > 20.0, "{}", m.path_length());
        // The path keeps the rover clear of every tree.
        let mut at = BUILTIN_START;
        for w in &m.waypoints {
            for c in &BUILTIN_CYLINDERS {
                let (dx, dy) = (w[0] - at[0], w[1] - at[1]);
                let t = (((c[0] - at[0]) * dx + (c[1] - at[1]) * dy) / (dx * dx + dy * dy)).clamp(0.0, 1.0);
                let d = (c[0] - at[0] - t * dx).hypot(c[1] - at[1] - t * dy);
                assert!(d >= 1.7, "cylinder {c:?} is {d} m from the leg to {w:?}");
            }
            at = *w;
        }
    }

    #[test]
    fn file_errors_name_the_field() {
        let good = Mission::builtin().to_json();
        let cases = [
            (good.replacen("\"waypoints\"", "\"waypoint\"", 1), "unknown field `waypoint`"),
            (good.replacen("\"trans_per_m\": 0.002", "\"trans_per_m\": -1.0", 1), "odometry trans_per_m = -1"),
            (good.replacen("\"rho_min\": 1.0", "\"rho_min\": 7.0", 1), "scenario.params.rho_min = 7"),
            (good.replacen("-6.0,\n      -5.5", "-60.0,\n      -5.5", 1), "waypoints[0]"),
        ];
        for (text, expected) in cases {
            assert!(text != good, "edit for `{expected}` did not apply");
            let err = Mission::from_json(&text).unwrap_err().to_string();
            assert!(err.contains(expected), "`{err}` should mention `{expected}`");
        }
    }

    #[test]
    fn records_are_objects_and_nothing_follows_the_document() {
        let good = Mission::builtin().to_json();
        assert!(Mission::from_json(&good).is_ok());
        // serde would take the odometry's fields in order from an array.
        let mut doc: serde_json::Value = serde_json::from_str(&good).unwrap();
        let fields: Vec<serde_json::Value> = doc["odometry"].as_object().unwrap().values().cloned().collect();
        doc["odometry"] = serde_json::Value::Array(fields);
        let cases = [
            (doc.to_string(), "odometry: invalid type: sequence, expected a JSON object"),
            (format!("{good} x"), "trailing characters"),
            ("[]".to_string(), "invalid type: sequence, expected a JSON object"),
        ];
        for (text, expected) in cases {
            let err = Mission::from_json(&text).unwrap_err().to_string();
            assert!(err.contains(expected), "`{err}` should mention `{expected}`");
        }
    }

    #[test]
    fn optional_fields_have_defaults() {
        let m = Mission::builtin();
        let scenario = Scenario { world: m.world.clone(), belief: m.initial_belief, params: m.params };
        let text = format!(r#"{{"scenario": {}, "waypoints": [[0.0, 0.0]]}}"#, scenario.to_json());
        let parsed = Mission::from_json(&text).unwrap();
        assert_eq!(parsed.odometry, OdometryNoise::default());
        assert_eq!(parsed.true_start, None);
        assert_eq!(parsed.viewer_start.0[2], 3.0);
    }
}
