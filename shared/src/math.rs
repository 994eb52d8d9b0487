//! Math types with names that say what a number is.
//!
//! All geometry is `f64`, 3D, in the `map` frame of ROS REP 103 (x forward, y left,
//! z up). Covariances are SPD-checked newtypes: a [`Cov3`] in a signature is a
//! valid rover belief covariance, not just any 3×3 matrix.
//!
//! ```
//! use dyfos_shared::math::{Cov2, wrap_angle};
//! use nalgebra::Matrix2;
//! use std::f64::consts::PI;
//!
//! assert!(Cov2::new(Matrix2::new(1.0, 0.0, 0.0, -1.0)).is_err());
//! assert_eq!(wrap_angle(PI), -PI);
//! ```

pub use nalgebra::{Isometry3, Matrix2, Matrix3, Point2, Point3, Rotation3, UnitQuaternion, Vector2, Vector3};
use std::f64::consts::PI;

/// Wraps an angle into `[−π, π)`; π itself reads as −π (SPEC §4).
#[inline]
pub fn wrap_angle(a: f64) -> f64 {
    let w = rem_euclid(a + PI, 2.0 * PI) - PI;
    // rem_euclid can round up to exactly 2π for tiny negative inputs.
    if w >= PI { w - 2.0 * PI } else { w }
}

/// Rotation about +z by `yaw`.
#[inline]
pub fn rot_z(yaw: f64) -> Matrix3<f64> {
    let (s, c) = yaw.sin_cos();
    Matrix3::new(c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0)
}

/// Rotation about +y by `pitch`, right-handed: positive pitch turns +x towards −z.
#[inline]
pub fn rot_y(pitch: f64) -> Matrix3<f64> {
    let (s, c) = pitch.sin_cos();
    Matrix3::new(c, 0.0, s, 0.0, 1.0, 0.0, -s, 0.0, c)
}

/// A quaternion written `[x, y, z, w]` in SPEC §3's canonical sign: w ≥ 0, and where
/// w = 0 the first non-zero of x, y, z positive.
pub fn canonical_xyzw(q: &UnitQuaternion<f64>) -> [f64; 4] {
    let c = q.coords; // nalgebra stores (i, j, k, w)
    let mut v = [c.x, c.y, c.z, c.w];
    let flip = if v[3] != 0.0 { v[3] < 0.0 } else { v[..3].iter().find(|x| **x != 0.0).is_some_and(|x| *x < 0.0) };
    if flip {
        v.iter_mut().for_each(|x| *x = -*x);
    }
    v.iter_mut().for_each(|x| *x += 0.0); // -0.0 → 0.0
    v
}

/// Why a matrix is not a valid covariance.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum CovarianceError {
    /// An entry is NaN or infinite.
    #[error("entry ({row}, {col}) is not finite ({value})")]
    NotFinite {
        /// Row of the entry.
        row: usize,
        /// Column of the entry.
        col: usize,
        /// The value found.
        value: f64,
    },
    /// `|Σ_ij − Σ_ji|` exceeds `1e-9·max(1, max|Σ|)` (SPEC §11).
    #[error("not symmetric: entries ({row}, {col}) and ({col}, {row}) differ by {diff:e}")]
    NotSymmetric {
        /// Row of the first entry.
        row: usize,
        /// Column of the first entry.
        col: usize,
        /// The absolute difference.
        diff: f64,
    },
    /// The matrix has a non-positive eigenvalue (Cholesky fails).
    #[error("not positive definite")]
    NotPositiveDefinite,
}

fn check_spd<const N: usize>(m: &nalgebra::SMatrix<f64, N, N>) -> Result<(), CovarianceError>
where
    nalgebra::Const<N>: nalgebra::DimMin<nalgebra::Const<N>, Output = nalgebra::Const<N>>,
{
    let mut max_abs: f64 = 0.0;
    for row in 0..N {
        for col in 0..N {
            let value = m[(row, col)];
            if !value.is_finite() {
                return Err(CovarianceError::NotFinite { row, col, value });
            }
            max_abs = max_abs.max(value.abs());
        }
    }
    let tol = 1e-9 * max_abs.max(1.0);
    for row in 0..N {
        for col in row + 1..N {
            let diff = (m[(row, col)] - m[(col, row)]).abs();
            if diff > tol {
                return Err(CovarianceError::NotSymmetric { row, col, diff });
            }
        }
    }
    // Cholesky reads the lower triangle only; symmetric up to `tol` makes that fair.
    match nalgebra::Cholesky::new(*m) {
        Some(ch) if ch.l_dirty().diagonal().iter().all(|d| *d > 0.0 && d.is_finite()) => Ok(()),
        _ => Err(CovarianceError::NotPositiveDefinite),
    }
}

macro_rules! covariance {
    ($name:ident, $n:literal, $mat:ident, $doc:literal) => {
        #[doc = $doc]
        #[derive(Debug, Clone, Copy, PartialEq)]
        pub struct $name($mat<f64>);

        impl $name {
            /// Checks that `m` is finite, symmetric (SPEC §11's tolerance) and positive definite.
            pub fn new(m: $mat<f64>) -> Result<Self, CovarianceError> {
                check_spd::<$n>(&m)?;
                Ok(Self(m))
            }

            /// Wraps `m` without checking. Use only where `m` is SPD by construction
            /// (a sum of SPD matrices, a model's output).
            #[inline]
            pub fn new_unchecked(m: $mat<f64>) -> Self {
                Self(m)
            }

            /// The matrix.
            #[inline]
            pub fn matrix(&self) -> &$mat<f64> {
                &self.0
            }

            /// The rows, for JSON and wire output.
            pub fn to_rows(&self) -> [[f64; $n]; $n] {
                std::array::from_fn(|r| std::array::from_fn(|c| self.0[(r, c)]))
            }

            /// Builds from rows (checked).
            pub fn from_rows(rows: &[[f64; $n]; $n]) -> Result<Self, CovarianceError> {
                Self::new($mat::from_fn(|r, c| rows[r][c]))
            }
        }
    };
}

covariance!(Cov2, 2, Matrix2, "A 2×2 covariance (measurement noise R), symmetric positive definite.");
covariance!(Cov3, 3, Matrix3, "A 3×3 covariance over (x, y, θ), symmetric positive definite.");

/// Determinant of a 2×2 matrix, closed form.
#[inline]
pub fn det2(m: &Matrix2<f64>) -> f64 {
    m[(0, 0)] * m[(1, 1)] - m[(0, 1)] * m[(1, 0)]
}

/// `v.floor()`, the same value for every input (NaN and infinities included), inline:
/// without SSE4.1, which baseline x86-64 builds do not assume, `f64::floor` is a
/// library call, and the voxel walk floors a few coordinates per step.
#[inline(always)]
pub fn floor(v: f64) -> f64 {
    // From 2^52 on every f64 is an integer; NaN fails the comparison and is returned.
    if v.abs() < 4_503_599_627_370_496.0 {
        let t = v as i64 as f64;
        let f = if t > v { t - 1.0 } else { t };
        // The cast loses the sign of -0.0, which `f64::floor` keeps.
        if f == 0.0 { f.copysign(v) } else { f }
    } else {
        v
    }
}

/// `v.rem_euclid(m)` for a positive finite `m`, the same value for every input,
/// without `fmod` (a library routine of a hundred instructions) when `v` lies
/// within one turn of `[0, m)`, as a wrapped yaw after a step does:
/// `v % m` is `v` for `|v| < m`, and `v − m`, exact (Sterbenz), for `m ≤ v < 2m`.
#[inline(always)]
pub fn rem_euclid(v: f64, m: f64) -> f64 {
    if (0.0..m).contains(&v) {
        v
    } else if (m..2.0 * m).contains(&v) {
        v - m
    } else if v > -m && v < 0.0 {
        v + m
    } else {
        v.rem_euclid(m)
    }
}

/// Rows of a 3×3 matrix, for JSON output.
pub fn rows3(m: &Matrix3<f64>) -> [[f64; 3]; 3] {
    std::array::from_fn(|r| std::array::from_fn(|c| m[(r, c)]))
}

#[cfg(test)]
mod tests {
    /// `count` pseudo-random words (xorshift64 from `seed`).
    fn words(seed: u64, count: usize) -> impl Iterator<Item = u64> {
        let mut x = seed;
        (0..count).map(move |_| {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            x
        })
    }

    #[test]
    fn floor_is_f64_floor() {
        let mut values = vec![0.0, -0.0, 0.3, -0.3, 1.0, -1.0, 2.5, -2.5, 1e-300, -1e-300, f64::NAN, f64::INFINITY];
        values.extend([f64::NEG_INFINITY, 4_503_599_627_370_495.5, -4_503_599_627_370_495.5, 9.3e18, -9.3e18, 1e300]);
        for x in words(0x9E37_79B9_7F4A_7C15, 100_000) {
            values.push(f64::from_bits(x));
            values.push((x as i64 >> 20) as f64 / 1024.0);
        }
        for v in values {
            assert_eq!(super::floor(v).to_bits(), v.floor().to_bits(), "floor({v:e})");
        }
    }

    #[test]
    fn rem_euclid_is_f64_rem_euclid() {
        use std::f64::consts::TAU;
        let mut values = vec![0.0, -0.0, 1e-300, -1e-300, f64::NAN, f64::INFINITY, f64::NEG_INFINITY, f64::MAX];
        for m in [1.0, TAU] {
            for edge in [m, 2.0 * m, -m, -2.0 * m, 0.0] {
                let mut v: f64 = edge;
                for _ in 0..4 {
                    v = v.next_down();
                }
                for _ in 0..9 {
                    values.push(v);
                    v = v.next_up();
                }
            }
        }
        for x in words(0x2545_F491_4F6C_DD1D, 100_000) {
            values.push(f64::from_bits(x));
            values.push((x as i64 >> 10) as f64 / (1u64 << 51) as f64);
        }
        for m in [1.0, std::f64::consts::TAU, 0.3] {
            for &v in &values {
                assert_eq!(super::rem_euclid(v, m).to_bits(), v.rem_euclid(m).to_bits(), "rem_euclid({v:e}, {m})");
            }
        }
    }

    use super::*;

    #[test]
    fn wrap_angle_range() {
        for a in [-10.0, -PI, -PI + 1e-12, 0.0, PI - 1e-12, PI, 3.0 * PI, 1e6] {
            let w = wrap_angle(a);
            assert!((-PI..PI).contains(&w), "{a} -> {w}");
            assert!(((w - a) / (2.0 * PI)).round() * 2.0 * PI - (w - a) < 1e-6);
        }
        assert_eq!(wrap_angle(PI), -PI);
        assert_eq!(wrap_angle(-PI), -PI);
    }

    #[test]
    fn canonical_quaternion_sign() {
        let q = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(-0.5, 0.5, -0.5, 0.5));
        assert_eq!(canonical_xyzw(&q), [-0.5, 0.5, -0.5, 0.5]);
        let q = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(0.0, 0.0, -1.0, 0.0));
        assert_eq!(canonical_xyzw(&q), [0.0, 1.0, 0.0, 0.0]);
    }

    #[test]
    fn covariance_checks() {
        assert!(Cov3::from_rows(&[[0.2, 0.05, 0.0], [0.05, 0.1, 0.0], [0.0, 0.0, 0.05]]).is_ok());
        assert!(matches!(
            Cov3::from_rows(&[[0.2, 0.06, 0.0], [0.05, 0.1, 0.0], [0.0, 0.0, 0.05]]),
            Err(CovarianceError::NotSymmetric { row: 0, col: 1, .. })
        ));
        assert_eq!(Cov2::from_rows(&[[1.0, 2.0], [2.0, 1.0]]), Err(CovarianceError::NotPositiveDefinite));
        assert!(matches!(
            Cov2::from_rows(&[[f64::NAN, 0.0], [0.0, 1.0]]),
            Err(CovarianceError::NotFinite { row: 0, col: 0, .. })
        ));
        assert_eq!(Cov2::from_rows(&[[0.0, 0.0], [0.0, 1.0]]), Err(CovarianceError::NotPositiveDefinite));
    }
}
