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
        let (det_r, det_s) = self.determinants(r);
        self.cost_of(det_r, det_s)
    }

    /// `det R` and `det S = det(Σ⁻_xy + R)`.
    #[inline(always)]
    fn determinants(&self, r: &Cov2) -> (f64, f64) {
        let r = r.matrix();
        (det2(r), det2(&(self.xy + r)))
    }

    #[inline(always)]
    fn cost_of(&self, det_r: f64, det_s: f64) -> f64 {
        self.ln_det + det_r.ln() - det_s.ln()
    }

    /// What [`Prior::cost_below`] compares with to prove a cost at least `bound`
    /// without its logarithms. A bound it cannot use safely (not finite, or beyond
    /// the range the proof covers) proves nothing.
    pub fn cost_bound(&self, bound: f64) -> CostBound {
        self.cost_bound_with_slack(bound, CostBound::SLACK)
    }

    fn cost_bound_with_slack(&self, bound: f64, slack: f64) -> CostBound {
        let usable = bound.abs() <= CostBound::LOG_LIMIT && self.ln_det.abs() <= CostBound::LOG_LIMIT;
        CostBound { ratio: if usable { (bound - self.ln_det + slack).exp() } else { f64::INFINITY } }
    }

    /// [`Prior::cost`], bit for bit, or `None` when that cost is sure to be at
    /// least `bound`'s (then the two logarithms are not taken): for a search that
    /// only wants costs below the best it has.
    #[inline]
    pub fn cost_below(&self, r: &Cov2, bound: &CostBound) -> Option<f64> {
        let (det_r, det_s) = self.determinants(r);
        let range = CostBound::DET_MIN..=CostBound::DET_MAX;
        if range.contains(&det_r) && range.contains(&det_s) && det_r / det_s > bound.ratio {
            return None;
        }
        Some(self.cost_of(det_r, det_s))
    }

    /// Σ⁺ by the full Kalman form.
    pub fn posterior(&self, r: &Cov2) -> Matrix3<f64> {
        predicted_posterior(&self.cov, r)
    }
}

/// A cost bound for [`Prior::cost_below`], as the ratio `det R / det S` above which
/// the cost `ln det Σ⁻ + ln det R − ln det S` is at least the bound.
///
/// Why the comparison is safe: with both determinants in `[DET_MIN, DET_MAX]` their
/// ratio is a normal number, off by half an ulp; the ratio here is
/// `exp(bound − ln det Σ⁻ + SLACK)` to an ulp or two (or below the smallest normal
/// number, which every such ratio exceeds), its argument off by a few ulps of
/// `LOG_LIMIT`. A computed ratio above it thus proves
/// `ln det R − ln det S > bound − ln det Σ⁻ + SLACK − 1e-11`, and the cost as
/// computed (three roundings of numbers below `2·LOG_LIMIT` in size, a few ulps
/// each, well under 1e-10 in all) is at least `bound`: `SLACK` is many times what
/// the roundings can take.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CostBound {
    ratio: f64,
}

impl CostBound {
    /// Determinants outside this range are always costed exactly.
    const DET_MIN: f64 = 1e-150;
    const DET_MAX: f64 = 1e150;
    /// Bounds and priors with a larger `|ln|` are never used to skip.
    const LOG_LIMIT: f64 = 1e4;
    /// How far above the bound a cost must be proved to be skipped.
    const SLACK: f64 = 1e-9;

    /// A bound that skips nothing.
    pub const NONE: CostBound = CostBound { ratio: f64::INFINITY };
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

    /// Costs and bounds over priors and noises from tight to loose, each bound at
    /// a cost, a hair either side of it, or anywhere; `slack` as [`CostBound::SLACK`]
    /// or not. Returns (costs skipped though below their bound, costs skipped,
    /// exact costs that differ from [`Prior::cost`]'s bits).
    fn skips(slack: f64) -> (usize, usize, usize) {
        let mut k = 7u64;
        let mut next = || {
            k = k.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1_442_695_040_888_963_407);
            (k >> 11) as f64 / (1u64 << 53) as f64
        };
        let (mut wrong, mut skipped, mut changed) = (0, 0, 0);
        for _ in 0..300 {
            let scale = 10f64.powf(next() * 8.0 - 5.0);
            let (a, b, c) = (0.1 + next(), 0.1 + next(), next() - 0.5);
            let prior = Cov3::from_rows(&[
                [a * scale, c * scale * 0.3, 0.0],
                [c * scale * 0.3, b * scale, 0.0],
                [0.0, 0.0, 0.05],
            ]);
            let Ok(prior) = prior else { continue };
            let prior = Prior::new(&prior);
            let mut bound = 0.0;
            for i in 0..200 {
                let s = 10f64.powf(next() * 8.0 - 6.0);
                let (x, y, z) = (0.1 + next(), 0.1 + next(), next() - 0.5);
                let Ok(r) = Cov2::from_rows(&[[x * s, z * s * 0.3], [z * s * 0.3, y * s]]) else { continue };
                let cost = prior.cost(&r);
                if i % 3 == 0 {
                    bound = cost;
                }
                let at = match i % 4 {
                    0 => bound,
                    1 => bound + (next() - 0.5) * 4e-9,
                    2 => bound + (next() - 0.5) * 1e-12,
                    _ => cost + (next() - 0.5) * 10.0,
                };
                match prior.cost_below(&r, &prior.cost_bound_with_slack(at, slack)) {
                    None => {
                        skipped += 1;
                        wrong += usize::from(cost < at);
                    }
                    Some(c) => changed += usize::from(c.to_bits() != cost.to_bits()),
                }
            }
        }
        (wrong, skipped, changed)
    }

    /// A cost is skipped only when it is at least the bound; others are exact.
    #[test]
    fn a_skipped_cost_is_at_least_the_bound() {
        let (wrong, skipped, changed) = skips(CostBound::SLACK);
        assert_eq!((wrong, changed), (0, 0));
        assert!(skipped > 10_000, "{skipped} skipped: the test tests little");
        let r = Cov2::from_rows(&[[0.01, 0.0], [0.0, 0.01]]).unwrap();
        let prior = Prior::new(&Cov3::from_rows(&[[0.2, 0.05, 0.0], [0.05, 0.1, 0.0], [0.0, 0.0, 0.05]]).unwrap());
        for bound in [f64::INFINITY, f64::NAN, 2e4, -2e4] {
            assert_eq!(prior.cost_below(&r, &prior.cost_bound(bound)), Some(prior.cost(&r)), "{bound}");
        }
        assert_eq!(prior.cost_below(&r, &CostBound::NONE), Some(prior.cost(&r)));
    }

    /// The test above can fail: with the slack turned the other way, costs just
    /// below their bound are skipped.
    #[test]
    fn a_negative_slack_skips_costs_below_the_bound() {
        assert!(skips(-CostBound::SLACK).0 > 0);
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
