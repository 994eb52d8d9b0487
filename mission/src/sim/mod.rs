//! The simulated world of the mission: rover kinematics and odometry noise, the
//! rover's ground truth, the viewer's flight, the simulated camera and time.
//!
//! Nothing here is seen by the rover's filter: the filter gets only the odometry
//! increments ([`Motion`]) it commanded. The true pose ([`TrueRover`]) moves by the
//! same increments plus noise drawn from [`OdometryNoise`], whose *statistics* the
//! filter knows (a consistent filter) but whose *draws* it never sees.
//!
//! ```
//! use dyfos_mission::sim::{Motion, OdometryNoise, TrueRover, unicycle};
//!
//! let noise = OdometryNoise::default();
//! // Driving 1 m straight adds a variance of 0.002 m² along the track.
//! let q = noise.covariance(&Motion { distance: 1.0, turn: 0.0 });
//! assert_eq!(q, [0.002, 0.0005]);
//! let ideal = unicycle([0.0, 0.0, 0.0], &Motion { distance: 1.0, turn: 0.0 });
//! assert_eq!(ideal, [1.0, 0.0, 0.0]);
//! let mut truth = TrueRover::new([0.0, 0.0, 0.0], noise, 7);
//! truth.drive(&Motion { distance: 1.0, turn: 0.0 });
//! assert!((truth.pose()[0] - 1.0).abs() < 0.3 && truth.pose() != ideal);
//! ```

mod camera;
mod clock;
mod flight;

pub use camera::{CameraView, SimCamera};
pub use clock::SimClock;
pub use flight::{Flight, FlightLimits};

use dyfos_shared::math::wrap_angle;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// One odometry increment: distance driven along the heading and heading change,
/// over one control tick.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Motion {
    /// Signed distance, m.
    pub distance: f64,
    /// Heading change, rad.
    pub turn: f64,
}

/// The unicycle step with the mid-point heading (exact for arcs to second order):
/// `x += δd·cos(θ + δθ/2)`, `y += δd·sin(θ + δθ/2)`, `θ = wrap(θ + δθ)`.
#[inline]
pub fn unicycle(pose: [f64; 3], m: &Motion) -> [f64; 3] {
    let mid = pose[2] + m.turn / 2.0;
    [pose[0] + m.distance * mid.cos(), pose[1] + m.distance * mid.sin(), wrap_angle(pose[2] + m.turn)]
}

/// Odometry noise that grows with distance and turning: for an increment
/// (δd, δθ) the slip added to the true motion is zero-mean Gaussian with
///
/// ```text
/// var(δd) = trans_per_m · |δd| + trans_per_rad · |δθ|      (m²)
/// var(δθ) = rot_per_m   · |δd| + rot_per_rad   · |δθ|      (rad²)
/// ```
///
/// independent between the two and between ticks, so the variance of a leg does
/// not depend on the tick length. The defaults give, over the built-in mission's
/// 2.5 m legs, about 7 cm of along-track and 2° of heading error per leg, and 3°
/// per 90° turn: a rover that loses a metre or more over 25 m without help.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct OdometryNoise {
    /// Along-track variance per metre driven, m²/m (default 0.002).
    pub trans_per_m: f64,
    /// Along-track variance per radian turned, m²/rad (default 0.0001).
    pub trans_per_rad: f64,
    /// Heading variance per metre driven, rad²/m (default 0.0005).
    pub rot_per_m: f64,
    /// Heading variance per radian turned, rad²/rad (default 0.002).
    pub rot_per_rad: f64,
}

impl Default for OdometryNoise {
    fn default() -> Self {
        OdometryNoise { trans_per_m: 0.002, trans_per_rad: 0.0001, rot_per_m: 0.0005, rot_per_rad: 0.002 }
    }
}

impl OdometryNoise {
    /// `[var(δd), var(δθ)]` for one increment.
    #[inline]
    pub fn covariance(&self, m: &Motion) -> [f64; 2] {
        let (d, t) = (m.distance.abs(), m.turn.abs());
        [self.trans_per_m * d + self.trans_per_rad * t, self.rot_per_m * d + self.rot_per_rad * t]
    }

    /// Checks that every coefficient is finite and ≥ 0 (at most 10).
    pub fn validate(&self) -> Result<(), String> {
        for (name, v) in [
            ("trans_per_m", self.trans_per_m),
            ("trans_per_rad", self.trans_per_rad),
            ("rot_per_m", self.rot_per_m),
            ("rot_per_rad", self.rot_per_rad),
        ] {
            if !(v.is_finite() && (0.0..=10.0).contains(&v)) {
                return Err(format!("odometry.{name} = {v} must be a number in [0, 10]"));
            }
        }
        Ok(())
    }
}

/// A standard normal draw (Box–Muller; one of the pair is discarded so that every
/// draw consumes the stream the same way).
#[inline]
pub fn standard_normal(rng: &mut ChaCha8Rng) -> f64 {
    let u1: f64 = 1.0 - rng.random::<f64>(); // (0, 1]
    let u2: f64 = rng.random::<f64>();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

/// The seed of one independent random stream: `stream` names its purpose and
/// `index` its instance (e.g. the step), mixed with the run's seed by splitmix64.
pub fn stream_seed(seed: u64, stream: u64, index: u64) -> u64 {
    let mut x = seed ^ stream.wrapping_mul(0x9e37_79b9_7f4a_7c15) ^ index.wrapping_mul(0xd1b5_4a32_d192_ed03);
    x = (x ^ (x >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    x = (x ^ (x >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    x ^ (x >> 31)
}

/// Named random streams, so that no two uses share draws.
pub mod streams {
    /// The rover's true start pose.
    pub const START: u64 = 1;
    /// The rover's wheel slip.
    pub const SLIP: u64 = 2;
    /// The camera's measurement noise (indexed by step).
    pub const CAMERA: u64 = 3;
    /// The daemon's search seed (indexed by step).
    pub const SEARCH: u64 = 4;
}

/// The rover's true pose, driven by odometry increments plus unseen slip.
#[derive(Debug, Clone)]
pub struct TrueRover {
    pose: [f64; 3],
    noise: OdometryNoise,
    rng: ChaCha8Rng,
}

impl TrueRover {
    /// A rover at `pose` whose slip is drawn from the stream `seed`.
    pub fn new(pose: [f64; 3], noise: OdometryNoise, seed: u64) -> Self {
        TrueRover { pose, noise, rng: ChaCha8Rng::seed_from_u64(seed) }
    }

    /// Moves by `m` plus slip `~ N(0, noise.covariance(m))`.
    pub fn drive(&mut self, m: &Motion) {
        let [vd, vt] = self.noise.covariance(m);
        let slipped = Motion {
            distance: m.distance + vd.sqrt() * standard_normal(&mut self.rng),
            turn: m.turn + vt.sqrt() * standard_normal(&mut self.rng),
        };
        self.pose = unicycle(self.pose, &slipped);
    }

    /// The true (x, y, θ).
    pub fn pose(&self) -> [f64; 3] {
        self.pose
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn slip_has_the_stated_variance() {
        // Many independent 1 m legs of 20 ticks: the along-track error's variance is
        // trans_per_m · 1 m, whatever the tick length.
        let noise = OdometryNoise::default();
        let n = 4000;
        let mut sum2 = 0.0;
        let mut head2 = 0.0;
        for i in 0..n {
            let mut t = TrueRover::new([0.0; 3], noise, stream_seed(5, streams::SLIP, i));
            for _ in 0..20 {
                t.drive(&Motion { distance: 0.05, turn: 0.0 });
            }
            sum2 += (t.pose()[0] - 1.0).powi(2);
            head2 += t.pose()[2].powi(2);
        }
        let var = sum2 / n as f64;
        let var_heading = head2 / n as f64;
        assert!((var / noise.trans_per_m - 1.0).abs() < 0.1, "along-track variance {var}");
        assert!((var_heading / noise.rot_per_m - 1.0).abs() < 0.1, "heading variance {var_heading}");
    }

    #[test]
    fn streams_differ_and_repeat() {
        assert_eq!(stream_seed(1, 2, 3), stream_seed(1, 2, 3));
        assert_ne!(stream_seed(1, 2, 3), stream_seed(1, 2, 4));
        assert_ne!(stream_seed(1, 2, 3), stream_seed(1, 3, 3));
        let mut a = ChaCha8Rng::seed_from_u64(9);
        let draws: Vec<f64> = (0..20000).map(|_| standard_normal(&mut a)).collect();
        let mean = draws.iter().sum::<f64>() / draws.len() as f64;
        let var = draws.iter().map(|d| (d - mean).powi(2)).sum::<f64>() / draws.len() as f64;
        assert!(mean.abs() < 0.03 && (var - 1.0).abs() < 0.04, "mean {mean}, var {var}");
    }

    #[test]
    fn bad_noise_is_named() {
        let bad = OdometryNoise { rot_per_m: f64::NAN, ..OdometryNoise::default() };
        assert!(bad.validate().unwrap_err().contains("odometry.rot_per_m"));
        assert!(OdometryNoise::default().validate().is_ok());
    }
}
