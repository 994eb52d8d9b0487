//! SPEC §6 `anisotropic`: monocular depth error grows along the line of sight when
//! the camera looks at the ground at a grazing angle.

use super::{Features, Sdsmm, paper_variance};
use crate::math::{Cov2, Matrix2, Vector2};

/// `R = σ*·(I₂ + λ·w_xy·w_xyᵀ)`, i.e. `Rot(β)·diag(σ*(1 + λcos²ε), σ*)·Rot(β)ᵀ`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Anisotropic {
    /// Stretch λ ≥ 0 along the horizontal line of sight.
    pub lambda: f64,
}

impl Sdsmm for Anisotropic {
    #[inline]
    fn noise(&self, f: &Features) -> Cov2 {
        let w = Vector2::new(f.w.x, f.w.y);
        Cov2::new_unchecked((Matrix2::identity() + w * w.transpose() * self.lambda) * paper_variance(f))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::Vector3;

    #[test]
    fn equals_the_rotated_diagonal_form() {
        let w = Vector3::new(0.3, -0.5, 0.7).normalize();
        let f = Features {
            u: 0.1,
            v: 0.2,
            e: 0.2,
            s: 0.4,
            c: 0.5,
            w,
            elevation: 0.0,
            bearing: 0.0,
            rho: 3.0,
            rover_heading: 0.0,
        };
        let elevation = w.z.atan2(w.x.hypot(w.y));
        let beta = (-w.y).atan2(-w.x); // sensor → rover is −w
        let (sb, cb) = beta.sin_cos();
        let rot = Matrix2::new(cb, -sb, sb, cb);
        let sigma = paper_variance(&f);
        let diag = Matrix2::new(sigma * (1.0 + 3.0 * elevation.cos().powi(2)), 0.0, 0.0, sigma);
        let expected = rot * diag * rot.transpose();
        let r = Anisotropic { lambda: 3.0 }.noise(&f);
        assert!((r.matrix() - expected).norm() < 1e-15, "{r:?} vs {expected}");
    }
}
