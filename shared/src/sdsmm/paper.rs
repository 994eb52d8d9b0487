//! The paper's fixed linear model (§V of the paper, SPEC §6 `paper`).

use super::{Features, Sdsmm};
use crate::math::{Cov2, Matrix2};

/// σ* = σ1² + σ2² + (c·σ3)² with σ1 = 0.03, σ2 = 0.03 + 0.27·e, σ3 = 0.03 + 0.47·s.
#[inline]
pub fn paper_variance(f: &Features) -> f64 {
    let s1 = 0.03;
    let s2 = 0.03 + 0.27 * f.e;
    let s3 = 0.03 + 0.47 * f.s;
    s1 * s1 + s2 * s2 + (f.c * s3) * (f.c * s3)
}

/// The paper's isotropic model: `R = σ*·I₂`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Paper;

impl Sdsmm for Paper {
    #[inline]
    fn noise(&self, f: &Features) -> Cov2 {
        Cov2::new_unchecked(Matrix2::identity() * paper_variance(f))
    }
}
