//! The rover's extended Kalman filter over (x, y, θ).
//!
//! **Predict** with one odometry increment `u = (δd, δθ)` through the mid-point
//! unicycle `f(s, u)` ([`crate::sim::unicycle`]):
//!
//! ```text
//! θm = θ + δθ/2
//! F  = ∂f/∂s = [[1, 0, −δd·sin θm], [0, 1, δd·cos θm], [0, 0, 1]]
//! L  = ∂f/∂u = [[cos θm, −δd/2·sin θm], [sin θm, δd/2·cos θm], [0, 1]]
//! Σ ← F Σ Fᵀ + L M Lᵀ,   M = diag(var δd, var δθ)  (OdometryNoise::covariance)
//! ```
//!
//! **Update** with the viewer's position measurement z = (x, y) and its R, with
//! `H = [I₂ 0]`: `y = z − Hs`, `S = HΣHᵀ + R`, `K = ΣHᵀS⁻¹`, `s ← s + Ky` (θ
//! wrapped into [−π, π)), and the Joseph form `Σ ← (I − KH) Σ (I − KH)ᵀ + K R Kᵀ`,
//! symmetrized, which stays SPD under rounding.
//!
//! ```
//! use dyfos_mission::rover::ekf::Ekf;
//! use dyfos_mission::sim::{Motion, OdometryNoise};
//! use dyfos_shared::math::Cov2;
//! use dyfos_shared::posterior::Belief;
//!
//! let start = Belief::new([0.0, 0.0, 0.0], [[0.01, 0.0, 0.0], [0.0, 0.01, 0.0], [0.0, 0.0, 0.01]])?;
//! let mut ekf = Ekf::new(&start);
//! for _ in 0..20 {
//!     ekf.predict(&Motion { distance: 0.1, turn: 0.0 }, &OdometryNoise::default());
//! }
//! let before = ekf.cov()[(1, 1)]; // grown by the heading uncertainty over 2 m
//! ekf.update([2.05, 0.02], &Cov2::from_rows(&[[0.0018, 0.0], [0.0, 0.0018]])?)?;
//! assert!(ekf.cov()[(1, 1)] < 0.0018 && before > 0.01);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use crate::sim::{Motion, OdometryNoise, unicycle};
use dyfos_shared::math::{Cov2, Cov3, Matrix2, Matrix3, Vector2, Vector3, wrap_angle};
use dyfos_shared::posterior::Belief;
use nalgebra::{Matrix2x3, Matrix3x2};

/// The filter state: mean and covariance over (x, y, θ).
#[derive(Debug, Clone, PartialEq)]
pub struct Ekf {
    mean: Vector3<f64>,
    cov: Matrix3<f64>,
}

/// Why a measurement was not used.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum EkfUpdateError {
    /// The innovation covariance S is singular or not finite.
    #[error("innovation covariance is singular; measurement ignored")]
    Singular,
    /// The measurement is not finite.
    #[error("measurement ({0}, {1}) is not finite; ignored")]
    NotFinite(f64, f64),
}

/// What one update did, for logs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Innovation {
    /// z − Hs, m.
    pub residual: [f64; 2],
    /// Squared Mahalanobis distance yᵀS⁻¹y (χ² with 2 degrees of freedom when the
    /// filter is consistent).
    pub mahalanobis2: f64,
}

impl Ekf {
    /// A filter starting from `belief`.
    pub fn new(belief: &Belief) -> Self {
        Ekf { mean: belief.mean, cov: *belief.cov.matrix() }
    }

    /// The mean (x, y, θ).
    pub fn mean(&self) -> [f64; 3] {
        self.mean.into()
    }

    /// The covariance.
    pub fn cov(&self) -> &Matrix3<f64> {
        &self.cov
    }

    /// The current belief. The covariance is symmetric and SPD by construction; if
    /// rounding ever broke that, the diagonal is floored so the belief stays valid.
    pub fn belief(&self) -> Belief {
        let sym = (self.cov + self.cov.transpose()) * 0.5;
        let cov = Cov3::new(sym).unwrap_or_else(|_| {
            Cov3::new_unchecked(Matrix3::from_diagonal(&sym.diagonal().map(|d| d.abs().max(1e-12))))
        });
        Belief { mean: self.mean, cov }
    }

    /// Propagates through one odometry increment with the noise model `noise`.
    pub fn predict(&mut self, m: &Motion, noise: &OdometryNoise) {
        let theta_m = self.mean.z + m.turn / 2.0;
        let (s, c) = theta_m.sin_cos();
        let f = Matrix3::new(1.0, 0.0, -m.distance * s, 0.0, 1.0, m.distance * c, 0.0, 0.0, 1.0);
        let l = Matrix3x2::new(c, -m.distance / 2.0 * s, s, m.distance / 2.0 * c, 0.0, 1.0);
        let [vd, vt] = noise.covariance(m);
        let q = Matrix2::new(vd, 0.0, 0.0, vt);
        self.mean = Vector3::from(unicycle(self.mean.into(), m));
        let p = f * self.cov * f.transpose() + l * q * l.transpose();
        self.cov = (p + p.transpose()) * 0.5;
    }

    /// Fuses a position measurement `z` with covariance `r` (Joseph form).
    pub fn update(&mut self, z: [f64; 2], r: &Cov2) -> Result<Innovation, EkfUpdateError> {
        if !(z[0].is_finite() && z[1].is_finite()) {
            return Err(EkfUpdateError::NotFinite(z[0], z[1]));
        }
        let h = Matrix2x3::new(1.0, 0.0, 0.0, 0.0, 1.0, 0.0);
        let y = Vector2::new(z[0] - self.mean.x, z[1] - self.mean.y);
        let s = h * self.cov * h.transpose() + r.matrix();
        let s_inv = s.try_inverse().filter(|m| m.iter().all(|v| v.is_finite())).ok_or(EkfUpdateError::Singular)?;
        let k = self.cov * h.transpose() * s_inv;
        let mut mean = self.mean + k * y;
        mean.z = wrap_angle(mean.z);
        let i_kh = Matrix3::identity() - k * h;
        let p = i_kh * self.cov * i_kh.transpose() + k * r.matrix() * k.transpose();
        self.mean = mean;
        self.cov = (p + p.transpose()) * 0.5;
        Ok(Innovation { residual: [y.x, y.y], mahalanobis2: (y.transpose() * s_inv * y)[(0, 0)] })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::{TrueRover, standard_normal, stream_seed};
    use dyfos_shared::posterior::predicted_posterior;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    fn belief() -> Belief {
        Belief::new([1.0, 2.0, 0.3], [[0.2, 0.05, 0.01], [0.05, 0.1, 0.0], [0.01, 0.0, 0.05]]).unwrap()
    }

    #[test]
    fn update_covariance_matches_the_posterior_of_spec_7() {
        let r = Cov2::from_rows(&[[0.01, 0.002], [0.002, 0.02]]).unwrap();
        let mut ekf = Ekf::new(&belief());
        ekf.update([1.1, 1.9], &r).unwrap();
        let expected = predicted_posterior(&belief().cov, &r);
        assert!((ekf.cov() - expected).abs().max() < 1e-12, "{} vs {}", ekf.cov(), expected);
    }

    #[test]
    fn heading_is_wrapped_after_an_update() {
        let b = Belief::new([0.0, 0.0, 3.1], [[1.0, 0.0, 0.9], [0.0, 1.0, 0.0], [0.9, 0.0, 1.0]]).unwrap();
        let mut ekf = Ekf::new(&b);
        ekf.update([1.0, 0.0], &Cov2::from_rows(&[[0.01, 0.0], [0.0, 0.01]]).unwrap()).unwrap();
        let theta = ekf.mean()[2];
        assert!((-std::f64::consts::PI..std::f64::consts::PI).contains(&theta), "θ = {theta}");
        assert!(theta < 0.0, "3.1 + ~0.9 wraps to the negative side: {theta}");
    }

    #[test]
    fn predict_grows_uncertainty_with_distance_and_turning() {
        let noise = OdometryNoise::default();
        let mut straight = Ekf::new(&belief());
        let mut turning = Ekf::new(&belief());
        for _ in 0..20 {
            straight.predict(&Motion { distance: 0.05, turn: 0.0 }, &noise);
            turning.predict(&Motion { distance: 0.05, turn: 0.05 }, &noise);
        }
        let det0 = belief().cov.matrix().determinant();
        assert!(straight.cov().determinant() > det0);
        assert!(turning.cov()[(2, 2)] > straight.cov()[(2, 2)]);
        assert!((straight.mean()[0] - (1.0 + 0.3f64.cos())).abs() < 1e-12);
    }

    /// The filter is consistent: over many simulated runs with measurements, the
    /// normalized estimation error squared averages the state dimension (3).
    #[test]
    fn filter_is_consistent_with_the_simulated_truth() {
        let noise = OdometryNoise::default();
        let r = Cov2::from_rows(&[[0.02, 0.0], [0.0, 0.02]]).unwrap();
        let runs = 400;
        let mut nees = 0.0;
        for run in 0..runs {
            let b = Belief::new([0.0, 0.0, 0.0], [[0.01, 0.0, 0.0], [0.0, 0.01, 0.0], [0.0, 0.0, 0.01]]).unwrap();
            let mut rng = ChaCha8Rng::seed_from_u64(stream_seed(run, 9, 0));
            let start =
                [0.1 * standard_normal(&mut rng), 0.1 * standard_normal(&mut rng), 0.1 * standard_normal(&mut rng)];
            let mut truth = TrueRover::new(start, noise, stream_seed(run, 9, 1));
            let mut ekf = Ekf::new(&b);
            for leg in 0..6 {
                for _ in 0..40 {
                    let m = Motion { distance: 0.05, turn: if leg % 2 == 0 { 0.02 } else { -0.03 } };
                    truth.drive(&m);
                    ekf.predict(&m, &noise);
                }
                let t = truth.pose();
                let z = [
                    t[0] + 0.02f64.sqrt() * standard_normal(&mut rng),
                    t[1] + 0.02f64.sqrt() * standard_normal(&mut rng),
                ];
                ekf.update(z, &r).unwrap();
            }
            let t = truth.pose();
            let m = ekf.mean();
            let e = Vector3::new(t[0] - m[0], t[1] - m[1], wrap_angle(t[2] - m[2]));
            nees += (e.transpose() * ekf.cov().try_inverse().unwrap() * e)[(0, 0)];
        }
        let avg = nees / runs as f64;
        assert!((2.5..3.5).contains(&avg), "average NEES {avg}, expected ≈ 3");
    }
}
