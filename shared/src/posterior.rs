//! The rover's belief and the predicted Kalman posterior (SPEC §7, paper eqs. 6–7).
//!
//! With `H = [I₂ 0]`: `S = HΣ⁻Hᵀ + R`, `K = Σ⁻HᵀS⁻¹`, `Σ⁺ = (I₃ − KH)Σ⁻` and the
//! cost `E = ln det Σ⁺`. By the matrix determinant lemma
//! `E = ln det Σ⁻ + ln det R − ln det S`, which is what the search evaluates.
//!
//! ```
//! use dyfos_shared::math::{Cov2, Cov3};
//! use dyfos_shared::posterior::{Prior, predicted_posterior};
//!
//! let prior = Cov3::from_rows(&[[0.2, 0.05, 0.0], [0.05, 0.1, 0.0], [0.0, 0.0, 0.05]]).unwrap();
//! let r = Cov2::from_rows(&[[0.01, 0.0], [0.0, 0.01]]).unwrap();
//! let full = predicted_posterior(&prior, &r).determinant().ln();
//! assert!((Prior::new(&prior).cost(&r) - full).abs() < 1e-12);
//! ```

use crate::limits::MAX_COORDINATE;
use crate::math::{Cov2, Cov3, Matrix2, Matrix3, Point3, Vector3, det2};

/// The rover's belief (x, y, θ) with covariance Σ; in a rendezvous request, the a
/// priori belief propagated to the rendezvous time (SPEC §2).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Belief {
    /// Mean (x, y, θ): position in m, heading in rad.
    pub mean: Vector3<f64>,
    /// Covariance Σ⁻.
    pub cov: Cov3,
}

/// Why a belief is invalid.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum BeliefError {
    /// A mean component is NaN, infinite or beyond ±1e6.
    #[error("mean[{index}] = {value} must be a finite number within ±1e6")]
    Mean {
        /// 0, 1 or 2 for x, y, θ.
        index: usize,
        /// The value.
        value: f64,
    },
    /// The covariance is not SPD.
    #[error("covariance {0}")]
    Covariance(#[from] crate::math::CovarianceError),
}

impl Belief {
    /// Checks a finite mean and an SPD covariance.
    pub fn new(mean: [f64; 3], cov: [[f64; 3]; 3]) -> Result<Self, BeliefError> {
        for (index, value) in mean.iter().enumerate() {
            if !(value.is_finite() && value.abs() <= MAX_COORDINATE) {
                return Err(BeliefError::Mean { index, value: *value });
            }
        }
        Ok(Belief { mean: Vector3::from(mean), cov: Cov3::from_rows(&cov)? })
    }

    /// The marker centre `p_t = (x, y, marker_height)` (SPEC §2).
    pub fn marker(&self, marker_height: f64) -> Point3<f64> {
        Point3::new(self.mean.x, self.mean.y, marker_height)
    }
}

/// Σ⁺ by the full Kalman form (SPEC §7), unsymmetrised.
pub fn predicted_posterior(prior: &Cov3, r: &Cov2) -> Matrix3<f64> {
    let p = prior.matrix();
    let s = p.fixed_view::<2, 2>(0, 0) + r.matrix();
    let s_inv = s.try_inverse().unwrap_or_else(|| Matrix2::repeat(f64::NAN));
    let k = p.fixed_view::<3, 2>(0, 0) * s_inv;
    let mut kh = Matrix3::zeros();
    kh.fixed_view_mut::<3, 2>(0, 0).copy_from(&k);
    (Matrix3::identity() - kh) * p
}

/// The prior with what the cost needs precomputed once per request.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Prior {
    cov: Cov3,
    xy: Matrix2<f64>,
    ln_det: f64,
}

impl Prior {
    /// Precomputes `ln det Σ⁻` and the position block.
    pub fn new(cov: &Cov3) -> Self {
        let m = cov.matrix();
        Prior { cov: *cov, xy: m.fixed_view::<2, 2>(0, 0).into_owned(), ln_det: m.determinant().ln() }
    }

    /// The prior covariance.
    pub fn cov(&self) -> &Cov3 {
        &self.cov
    }

    /// `E = ln det Σ⁺ = ln det Σ⁻ + ln det R − ln det S` (closed-form 2×2 determinants).
    #[inline]
    pub fn cost(&self, r: &Cov2) -> f64 {
        let r = r.matrix();
        self.ln_det + det2(r).ln() - det2(&(self.xy + r)).ln()
    }

    /// Σ⁺ by the full Kalman form.
    pub fn posterior(&self, r: &Cov2) -> Matrix3<f64> {
        predicted_posterior(&self.cov, r)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn determinant_lemma_matches_the_full_form() {
        let priors = [
            [[0.2, 0.05, 0.0], [0.05, 0.1, 0.0], [0.0, 0.0, 0.05]],
            [[1.3, -0.9, 0.1], [-0.9, 0.8, -0.05], [0.1, -0.05, 0.3]],
            [[1e-3, 0.0, 0.0], [0.0, 4.0, 0.0], [0.0, 0.0, 1e-4]],
        ];
        let noises = [[[0.0018, 0.0], [0.0, 0.0018]], [[0.05, 0.02], [0.02, 0.09]], [[3.0, -1.0], [-1.0, 1.0]]];
        for p in priors {
            let prior = Cov3::from_rows(&p).unwrap();
            for n in noises {
                let r = Cov2::from_rows(&n).unwrap();
                let full = predicted_posterior(&prior, &r);
                let lemma = Prior::new(&prior).cost(&r);
                assert!((full.determinant().ln() - lemma).abs() < 1e-10 * lemma.abs().max(1.0));
                // Σ⁺ ≼ Σ⁻: a measurement never adds uncertainty.
                assert!((prior.matrix() - full).symmetric_eigenvalues().iter().all(|e| *e > -1e-12));
            }
        }
    }

    #[test]
    fn position_only_measurement_leaves_uncorrelated_heading_alone() {
        let prior = Cov3::from_rows(&[[0.2, 0.05, 0.0], [0.05, 0.1, 0.0], [0.0, 0.0, 0.05]]).unwrap();
        let r = Cov2::from_rows(&[[0.01, 0.0], [0.0, 0.01]]).unwrap();
        let post = predicted_posterior(&prior, &r);
        assert_eq!(post[(2, 2)], 0.05);
        assert!(post[(0, 0)] < 0.01);
    }

    #[test]
    fn belief_validation() {
        let cov = [[0.2, 0.05, 0.0], [0.05, 0.1, 0.0], [0.0, 0.0, 0.05]];
        assert!(matches!(Belief::new([0.0, f64::INFINITY, 0.0], cov), Err(BeliefError::Mean { index: 1, .. })));
        assert!(matches!(Belief::new([0.0; 3], [[0.0; 3]; 3]), Err(BeliefError::Covariance(_))));
    }
}
