//! The rover's waypoint controller: the commands that take its *estimate* to the
//! next waypoint.
//!
//! The rover has no exteroception, so between measurements its estimate moves only
//! by the commands it gives. The whole leg can therefore be planned from the
//! estimate at its start ([`plan_leg`]); applying the plan to the filter yields
//! exactly the belief the rover will hold on arrival — the rendezvous belief it
//! sends the viewer before setting off (the paper's belief propagation).
//!
//! ```
//! use dyfos_mission::rover::controller::{DriveConfig, plan_leg};
//! use dyfos_mission::sim::unicycle;
//!
//! let plan = plan_leg([0.0, 0.0, 0.0], [2.0, 1.0], &DriveConfig::default());
//! let end = plan.iter().fold([0.0, 0.0, 0.0], unicycle);
//! assert!((end[0] - 2.0).hypot(end[1] - 1.0) <= 0.05);
//! ```

use crate::sim::{Motion, unicycle};
use dyfos_shared::math::wrap_angle;

/// Drive limits and gains.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DriveConfig {
    /// Control tick, s (default 0.05).
    pub dt: f64,
    /// Top speed, m/s (default 0.5).
    pub speed: f64,
    /// Top turn rate, rad/s (default 1.0).
    pub turn_rate: f64,
    /// Turn in place while the bearing error exceeds this, rad (default 0.5).
    pub turn_in_place: f64,
    /// Arrival radius around the waypoint, m (default 0.05).
    pub tolerance: f64,
}

impl Default for DriveConfig {
    fn default() -> Self {
        DriveConfig { dt: 0.05, speed: 0.5, turn_rate: 1.0, turn_in_place: 0.5, tolerance: 0.05 }
    }
}

/// Most ticks of one leg: a guard against a controller that cannot converge.
const MAX_TICKS: usize = 100_000;

/// The commands from `start` (the estimate) to within `tolerance` of `goal`:
/// turn in place towards the goal while the bearing error is large, else drive at
/// `min(speed, max(0.1, dist))` m/s while steering with gain 2/s, both limited.
pub fn plan_leg(start: [f64; 3], goal: [f64; 2], cfg: &DriveConfig) -> Vec<Motion> {
    let mut pose = start;
    let mut plan = Vec::new();
    for _ in 0..MAX_TICKS {
        let (dx, dy) = (goal[0] - pose[0], goal[1] - pose[1]);
        let dist = dx.hypot(dy);
        if dist <= cfg.tolerance {
            break;
        }
        let bearing = wrap_angle(dy.atan2(dx) - pose[2]);
        let max_turn = cfg.turn_rate * cfg.dt;
        let m = if bearing.abs() > cfg.turn_in_place {
            Motion { distance: 0.0, turn: bearing.clamp(-max_turn, max_turn) }
        } else {
            let v = cfg.speed.min(dist.max(0.1));
            Motion { distance: (v * cfg.dt).min(dist), turn: (2.0 * bearing * cfg.dt).clamp(-max_turn, max_turn) }
        };
        pose = unicycle(pose, &m);
        plan.push(m);
    }
    plan
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plans_reach_the_goal_from_any_heading() {
        let cfg = DriveConfig::default();
        for heading in [-3.0, -1.5, 0.0, 0.7, 2.0, 3.1] {
            for goal in [[2.0, 0.5], [-1.0, -2.5], [0.0, 3.0]] {
                let plan = plan_leg([0.0, 0.0, heading], goal, &cfg);
                let end = plan.iter().fold([0.0, 0.0, heading], unicycle);
                let miss = (end[0] - goal[0]).hypot(end[1] - goal[1]);
                assert!(miss <= cfg.tolerance, "heading {heading}, goal {goal:?}: missed by {miss}");
                let len: f64 = plan.iter().map(|m| m.distance).sum();
                let direct = goal[0].hypot(goal[1]);
                assert!(len < direct * 1.2 + 0.1, "detour: {len} m for {direct} m");
            }
        }
        assert!(plan_leg([1.0, 1.0, 0.0], [1.0, 1.01], &cfg).is_empty());
    }
}
