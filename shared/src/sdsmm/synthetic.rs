//! The synthetic reference camera: the "true" measurement noise of the learned-model
//! experiments, a camera whose formula is known so a trained model can be judged
//! against it (`dyfos-bench learned`). Training data are drawn from it, and planning quality is
//! judged by it; the `learned` model never sees its formula, only samples.
//!
//! It is `anisotropic` made deliberately different from the linear `paper` model in
//! ways a linear model cannot follow:
//!
//! ```text
//! σ₂  = 0.03 + 0.30·e²          image-edge error grows quadratically (paper: linearly)
//! σ_d = 0.06·s²                 far targets are worse even without glare
//! σ*ₜ = 0.03² + σ₂² + (c·(0.03 + 0.47·s))² + σ_d²
//! α   = β − θ                   bearing relative to the rover's heading
//! along = σ*ₜ·(1 + λ·cos²ε)·(1 + 0.3·cos 2α)   along the horizontal line of sight
//! cross = σ*ₜ·(1 + 0.8·u²)                     across it: lens distortion at the sides
//! R   = Rot(β)·diag(along, cross)·Rot(β)ᵀ
//! ```
//!
//! The `cos 2α` term stands for a marker whose printed pattern is coarser along the
//! rover's heading: seen from the rover's front or back (α = 0, π) the depth variance is
//! 30 % larger, from its side 30 % smaller. The measurement error is zero-mean: a Kalman filter (SPEC §7)
//! models no measurement bias, so the deviation from `paper` is in the covariance
//! (a different floor and shape), not in a mean offset.
//!
//! ```
//! use dyfos_shared::sdsmm::{Features, Sdsmm, Synthetic};
//! use dyfos_shared::math::Vector3;
//!
//! // Image centre, nearest range, no glare, looking straight down: only the floor.
//! let f = Features { u: 0.0, v: 0.0, e: 0.0, s: 0.0, c: 0.0, w: Vector3::z(),
//!                    elevation: std::f64::consts::FRAC_PI_2, bearing: 0.0, rho: 1.0,
//!                    rover_heading: 0.0 };
//! let r = Synthetic::default().noise(&f);
//! assert!((r.matrix()[(1, 1)] - 2.0 * 0.03f64.powi(2)).abs() < 1e-15);
//! ```

use super::{Features, Sdsmm};
use crate::math::{Cov2, Matrix2};

/// The reference camera's parameters; [`Synthetic::default`] is the documented model.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Synthetic {
    /// Stretch λ along the horizontal line of sight (as `anisotropic`).
    pub lambda: f64,
    /// Gain of the quadratic image-edge term, m.
    pub edge_gain: f64,
    /// Gain of the range term σ_d = gain·s², m.
    pub range_gain: f64,
    /// Widening across the line of sight at the image sides, `1 + k·u²`.
    pub lateral_gain: f64,
    /// Relative-bearing modulation of the along-sight variance, `1 + h·cos 2α` (|h| < 1).
    pub heading_gain: f64,
}

impl Default for Synthetic {
    fn default() -> Self {
        Synthetic { lambda: 3.0, edge_gain: 0.30, range_gain: 0.06, lateral_gain: 0.8, heading_gain: 0.3 }
    }
}

impl Synthetic {
    /// σ*ₜ, the isotropic part of the variance, m².
    #[inline]
    pub fn variance(&self, f: &Features) -> f64 {
        let s1 = 0.03;
        let s2 = 0.03 + self.edge_gain * f.e * f.e;
        let s3 = 0.03 + 0.47 * f.s;
        let sd = self.range_gain * f.s * f.s;
        s1 * s1 + s2 * s2 + (f.c * s3) * (f.c * s3) + sd * sd
    }

    /// The variances (along, across) the horizontal line of sight, m².
    #[inline]
    pub fn principal_variances(&self, f: &Features) -> (f64, f64) {
        let sigma = self.variance(f);
        let alpha = f.relative_bearing();
        let along =
            sigma * (1.0 + self.lambda * f.elevation.cos().powi(2)) * (1.0 + self.heading_gain * (2.0 * alpha).cos());
        let cross = sigma * (1.0 + self.lateral_gain * f.u * f.u);
        (along, cross)
    }
}

impl Sdsmm for Synthetic {
    #[inline]
    fn noise(&self, f: &Features) -> Cov2 {
        let (along, cross) = self.principal_variances(f);
        let (sb, cb) = f.bearing.sin_cos();
        let xx = along * cb * cb + cross * sb * sb;
        let yy = along * sb * sb + cross * cb * cb;
        let xy = (along - cross) * sb * cb;
        Cov2::new_unchecked(Matrix2::new(xx, xy, xy, yy))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::Vector3;

    fn features(u: f64, e: f64, s: f64, c: f64, elevation: f64, bearing: f64, heading: f64) -> Features {
        let (se, ce) = elevation.sin_cos();
        let w = Vector3::new(-ce * bearing.cos(), -ce * bearing.sin(), se);
        Features { u, v: 0.0, e, s, c, w, elevation, bearing, rho: 1.0 + 5.0 * s, rover_heading: heading }
    }

    #[test]
    fn eigenvectors_follow_the_line_of_sight() {
        let m = Synthetic::default();
        let f = features(0.5, 0.5, 0.3, 0.4, 0.6, 1.1, -0.4);
        let r = m.noise(&f);
        let (along, cross) = m.principal_variances(&f);
        let los = nalgebra::Vector2::new(f.bearing.cos(), f.bearing.sin());
        let side = nalgebra::Vector2::new(-los.y, los.x);
        assert!((r.matrix() * los - los * along).norm() < 1e-15);
        assert!((r.matrix() * side - side * cross).norm() < 1e-15);
        assert!(crate::math::Cov2::new(*r.matrix()).is_ok());
    }

    #[test]
    fn differs_from_paper_where_a_linear_model_cannot_follow() {
        let m = Synthetic::default();
        // Quadratic edge term: at e = 0.5 the edge std is 0.03 + 0.3/4, not 0.03 + 0.27/2.
        let centre = m.variance(&features(0.0, 0.0, 0.0, 0.0, 0.5, 0.0, 0.0));
        let half = m.variance(&features(0.0, 0.5, 0.0, 0.0, 0.5, 0.0, 0.0));
        assert!((half - centre - (0.105f64.powi(2) - 0.03f64.powi(2))).abs() < 1e-15);
        // The relative bearing matters: side view vs front view.
        let front = m.principal_variances(&features(0.0, 0.0, 0.5, 0.0, 0.5, 0.3, 0.3)).0;
        let side = m.principal_variances(&features(0.0, 0.0, 0.5, 0.0, 0.5, 0.3, 0.3 + std::f64::consts::FRAC_PI_2)).0;
        assert!((side / front - 0.7 / 1.3).abs() < 1e-12, "{side} / {front}");
    }
}
