//! The viewer's flight: a level, kinematic move with speed and yaw-rate limits.

use dyfos_shared::math::wrap_angle;

/// The viewer's motion limits.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FlightLimits {
    /// Top speed, m/s (default 2).
    pub speed: f64,
    /// Top yaw rate, rad/s (default 1).
    pub yaw_rate: f64,
}

impl Default for FlightLimits {
    fn default() -> Self {
        FlightLimits { speed: 2.0, yaw_rate: 1.0 }
    }
}

/// A straight flight from one pose to another at the limits: translation and yaw
/// change together, and the slower of the two sets the duration. The path is not
/// planned around obstacles (the simulation checks only the end pose, which the
/// daemon already checked against the collision constraint).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Flight {
    /// Start position p_v and yaw.
    pub from: ([f64; 3], f64),
    /// End position and yaw.
    pub to: ([f64; 3], f64),
    /// Simulated duration, s.
    pub duration: f64,
}

impl Flight {
    /// The flight between two poses under `limits`.
    pub fn new(from: ([f64; 3], f64), to: ([f64; 3], f64), limits: &FlightLimits) -> Self {
        let d = (0..3).map(|i| (to.0[i] - from.0[i]).powi(2)).sum::<f64>().sqrt();
        let turn = wrap_angle(to.1 - from.1).abs();
        let duration = (d / limits.speed).max(turn / limits.yaw_rate);
        Flight { from, to, duration }
    }

    /// The pose `t` seconds after take-off (clamped to the flight).
    pub fn at(&self, t: f64) -> ([f64; 3], f64) {
        if self.duration <= 0.0 || t >= self.duration {
            return self.to;
        }
        let a = (t / self.duration).max(0.0);
        let p = std::array::from_fn(|i| self.from.0[i] + a * (self.to.0[i] - self.from.0[i]));
        (p, wrap_angle(self.from.1 + a * wrap_angle(self.to.1 - self.from.1)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_slower_axis_sets_the_duration() {
        let l = FlightLimits::default();
        let f = Flight::new(([0.0, 0.0, 1.0], 0.0), ([4.0, 0.0, 1.0], 0.5), &l);
        assert_eq!(f.duration, 2.0);
        let g = Flight::new(([0.0, 0.0, 1.0], 3.0), ([0.0, 0.0, 1.0], -3.0), &l);
        assert!((g.duration - (2.0 * std::f64::consts::PI - 6.0)).abs() < 1e-12, "turns the short way");
        assert_eq!(f.at(1.0).0, [2.0, 0.0, 1.0]);
        assert_eq!(f.at(9.0), f.to);
    }
}
