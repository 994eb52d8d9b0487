//! Training data for the `learned` SDSMM: simulated camera measurements of the rover.
//!
//! [`generate`] draws many (sensor, rover, sun) states — a candidate x uniform over
//! the search space box (SPEC §4), the rover's heading uniform over [−π, π), the sun's
//! elevation uniform over [0°, 80°] and its azimuth over [−π, π) — computes the SPEC §6
//! features from these true states, and draws the measurement error e ~ N(0, R) from
//! the reference camera ([`Synthetic`], which the learner never sees). Obstacles play
//! no part: they decide feasibility, not noise.
//!
//! A [`DataSet`] is stored as little-endian bytes: `DYFOSDAT`, version (u32), columns
//! (u32, = [`COLUMNS`]), rows (u64), the rows as `f64`
//! `[e_x, e_y, u, v, e, s, c, w_x, w_y, w_z, ε, β, ρ, θ]`, then an FNV-1a checksum.
//! Raw features, not the network's inputs, so a new input encoding needs no new data.
//!
//! ```
//! use dyfos_service::learned::{DataSet, DataSpec, generate};
//!
//! let data = generate(&DataSpec { samples: 100, seed: 7, ..DataSpec::default() });
//! let again = DataSet::from_bytes(&data.to_bytes()).unwrap();
//! assert_eq!(again, data);
//! ```

use dyfos_shared::math::{Point3, Vector3};
use dyfos_shared::params::Params;
use dyfos_shared::sdsmm::{Features, Sdsmm, Synthetic};
use dyfos_shared::sensor::{SearchSpace, SensorRig};
use dyfos_shared::world::Sun;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::f64::consts::{PI, TAU};

/// Columns per row: the error (2) and the raw features (12).
pub const COLUMNS: usize = 14;
const MAGIC: &[u8; 8] = b"DYFOSDAT";
const VERSION: u32 = 1;
const HEADER: usize = 8 + 4 + 4 + 8;

/// One simulated measurement: its error `measured − true` (m) and its features.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample {
    /// Measurement error on (x, y), m.
    pub error: [f64; 2],
    /// The features of the true states.
    pub features: Features,
}

/// A set of samples.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct DataSet {
    /// The samples, in drawing order.
    pub samples: Vec<Sample>,
}

/// What to simulate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DataSpec {
    /// Number of samples.
    pub samples: usize,
    /// Seed of the ChaCha8 stream: the same spec gives the same bytes.
    pub seed: u64,
    /// Camera and search-space parameters (SPEC defaults).
    pub params: Params,
    /// The reference camera the errors are drawn from.
    pub truth: Synthetic,
    /// Sun elevation range, rad.
    pub sun_elevation: (f64, f64),
}

impl Default for DataSpec {
    fn default() -> Self {
        DataSpec {
            samples: 400_000,
            seed: 0,
            params: Params::default(),
            truth: Synthetic::default(),
            sun_elevation: (0.0, 80f64.to_radians()),
        }
    }
}

/// Why data-set bytes cannot be read.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DataSetError {
    /// Not a data-set file.
    #[error("is not a dyfos data set (it does not start with `DYFOSDAT`); write one with `dyfos train-data`")]
    NotADataSet,
    /// Another format version or column count.
    #[error(
        "has format version {version} with {columns} columns; this build reads version {VERSION} with {COLUMNS}: regenerate it with `dyfos train-data`"
    )]
    Format {
        /// Version in the file.
        version: u32,
        /// Columns in the file.
        columns: u32,
    },
    /// Shorter or longer than its header says.
    #[error("has {len} bytes but its header promises {expected}; it is truncated or corrupt, regenerate it")]
    Length {
        /// Bytes present.
        len: usize,
        /// Bytes the header implies.
        expected: u128,
    },
    /// Checksum mismatch.
    #[error("is corrupt (checksum mismatch); regenerate it with `dyfos train-data`")]
    Checksum,
    /// A value is NaN or infinite.
    #[error("has a non-finite value in row {row}, column {column}; regenerate it")]
    NonFinite {
        /// Row.
        row: usize,
        /// Column.
        column: usize,
    },
}

/// A standard normal pair by Box–Muller (rand 0.10 has no normal distribution
/// without `rand_distr`, which is not among the project's crates).
fn normal_pair(rng: &mut ChaCha8Rng) -> (f64, f64) {
    let u1: f64 = 1.0 - rng.random::<f64>(); // (0, 1]
    let u2: f64 = rng.random::<f64>();
    let r = (-2.0 * u1.ln()).sqrt();
    let (s, c) = (TAU * u2).sin_cos();
    (r * c, r * s)
}

/// Draws `spec.samples` measurements (see the module doc).
pub fn generate(spec: &DataSpec) -> DataSet {
    let mut rng = ChaCha8Rng::seed_from_u64(spec.seed);
    let params = &spec.params;
    let space = SearchSpace::new(params);
    let rig = SensorRig::new(params);
    let target = Point3::new(0.0, 0.0, params.marker_height);
    let (el_lo, el_hi) = spec.sun_elevation;
    let samples = (0..spec.samples)
        .map(|_| {
            let unit: [f64; 4] = std::array::from_fn(|_| rng.random::<f64>());
            let x = space.from_unit(&unit);
            let heading = rng.random::<f64>() * TAU - PI;
            let elevation = el_lo + rng.random::<f64>() * (el_hi - el_lo);
            let azimuth = rng.random::<f64>() * TAU - PI;
            let sun = Sun::new(elevation, azimuth).map(|s| s.direction()).unwrap_or_else(|_| Vector3::z());
            let pose = rig.pose(&target, &x);
            let features = Features::new(params, &sun, &pose, &target).with_rover_heading(heading);
            let r = spec.truth.noise(&features);
            let l = r.matrix().cholesky().map(|c| c.l()).unwrap_or_default();
            let (z1, z2) = normal_pair(&mut rng);
            let e = l * nalgebra::Vector2::new(z1, z2);
            Sample { error: [e.x, e.y], features }
        })
        .collect();
    DataSet { samples }
}

fn fnv1a(bytes: &[u8]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in bytes {
        h ^= u64::from(*b);
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    h
}

impl Sample {
    fn to_row(self) -> [f64; COLUMNS] {
        let f = &self.features;
        [
            self.error[0],
            self.error[1],
            f.u,
            f.v,
            f.e,
            f.s,
            f.c,
            f.w.x,
            f.w.y,
            f.w.z,
            f.elevation,
            f.bearing,
            f.rho,
            f.rover_heading,
        ]
    }

    fn from_row(r: &[f64; COLUMNS]) -> Self {
        Sample {
            error: [r[0], r[1]],
            features: Features {
                u: r[2],
                v: r[3],
                e: r[4],
                s: r[5],
                c: r[6],
                w: Vector3::new(r[7], r[8], r[9]),
                elevation: r[10],
                bearing: r[11],
                rho: r[12],
                rover_heading: r[13],
            },
        }
    }
}

impl DataSet {
    /// The file's bytes (see the module doc).
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(HEADER + self.samples.len() * COLUMNS * 8 + 8);
        out.extend_from_slice(MAGIC);
        out.extend_from_slice(&VERSION.to_le_bytes());
        out.extend_from_slice(&(COLUMNS as u32).to_le_bytes());
        out.extend_from_slice(&(self.samples.len() as u64).to_le_bytes());
        for s in &self.samples {
            for v in s.to_row() {
                out.extend_from_slice(&v.to_le_bytes());
            }
        }
        let sum = fnv1a(&out);
        out.extend_from_slice(&sum.to_le_bytes());
        out
    }

    /// Parses a data-set file's bytes.
    pub fn from_bytes(bytes: &[u8]) -> Result<Self, DataSetError> {
        if bytes.len() < HEADER || &bytes[..8] != MAGIC {
            return Err(DataSetError::NotADataSet);
        }
        let u32_at = |i: usize| u32::from_le_bytes([bytes[i], bytes[i + 1], bytes[i + 2], bytes[i + 3]]);
        let (version, columns) = (u32_at(8), u32_at(12));
        if version != VERSION || columns as usize != COLUMNS {
            return Err(DataSetError::Format { version, columns });
        }
        let rows = u64::from_le_bytes(std::array::from_fn(|i| bytes[16 + i]));
        let expected = HEADER as u128 + u128::from(rows) * (COLUMNS as u128 * 8) + 8;
        if bytes.len() as u128 != expected {
            return Err(DataSetError::Length { len: bytes.len(), expected });
        }
        let body_end = bytes.len() - 8;
        let stored = u64::from_le_bytes(std::array::from_fn(|i| bytes[body_end + i]));
        if stored != fnv1a(&bytes[..body_end]) {
            return Err(DataSetError::Checksum);
        }
        let mut samples = Vec::with_capacity(rows as usize);
        for (row, chunk) in bytes[HEADER..body_end].chunks_exact(COLUMNS * 8).enumerate() {
            let values: [f64; COLUMNS] =
                std::array::from_fn(|i| f64::from_le_bytes(std::array::from_fn(|k| chunk[8 * i + k])));
            if let Some(column) = values.iter().position(|v| !v.is_finite()) {
                return Err(DataSetError::NonFinite { row, column });
            }
            samples.push(Sample::from_row(&values));
        }
        Ok(DataSet { samples })
    }

    /// Splits off the last `fraction` of the samples (at least one of each, when
    /// there are two or more) as a validation set: `(train, validation)`.
    pub fn split(&self, fraction: f64) -> (&[Sample], &[Sample]) {
        let n = self.samples.len();
        let k = ((n as f64 * fraction).round() as usize).clamp(usize::from(n >= 2), n.saturating_sub(1));
        self.samples.split_at(n - k)
    }
}

/// The mean negative log-likelihood per sample of `model` on `samples` (paper eq. 5
/// divided by K, with the Gaussian's constant): `½(ln det R + eᵀR⁻¹e) + ln 2π`, nats.
pub fn mean_nll(model: &impl Sdsmm, samples: &[Sample]) -> f64 {
    let total: f64 = samples.iter().map(|s| sample_nll(model, s)).sum();
    total / samples.len().max(1) as f64
}

/// One sample's negative log-likelihood under `model`, nats.
pub fn sample_nll(model: &impl Sdsmm, s: &Sample) -> f64 {
    let r = model.noise(&s.features);
    let m = r.matrix();
    let det = m[(0, 0)] * m[(1, 1)] - m[(0, 1)] * m[(1, 0)];
    let (ex, ey) = (s.error[0], s.error[1]);
    // eᵀR⁻¹e with the closed-form inverse.
    let quad = (m[(1, 1)] * ex * ex - 2.0 * m[(0, 1)] * ex * ey + m[(0, 0)] * ey * ey) / det;
    0.5 * (det.ln() + quad) + TAU.ln()
}

#[cfg(test)]
mod tests {
    use super::*;
    use dyfos_shared::sdsmm::Paper;

    #[test]
    fn same_seed_same_bytes_other_seed_other_bytes() {
        let spec = DataSpec { samples: 200, seed: 3, ..DataSpec::default() };
        assert_eq!(generate(&spec).to_bytes(), generate(&spec).to_bytes());
        assert_ne!(generate(&spec).to_bytes(), generate(&DataSpec { seed: 4, ..spec }).to_bytes());
    }

    #[test]
    fn features_cover_the_search_space() {
        let data = generate(&DataSpec { samples: 5000, seed: 1, ..DataSpec::default() });
        let max = |f: fn(&Sample) -> f64| data.samples.iter().map(f).fold(f64::MIN, f64::max);
        let min = |f: fn(&Sample) -> f64| data.samples.iter().map(f).fold(f64::MAX, f64::min);
        assert!(max(|s| s.features.u) > 0.95 && min(|s| s.features.u) < -0.95);
        assert!(max(|s| s.features.v) > 0.95 && min(|s| s.features.v) < -0.95);
        assert!(max(|s| s.features.s) > 0.99 && min(|s| s.features.s) < 0.01);
        assert!(max(|s| s.features.c) > 1.5 && min(|s| s.features.c) == 0.0);
        assert!(max(|s| s.features.relative_bearing()) > 3.0 && min(|s| s.features.relative_bearing()) < -3.0);
    }

    #[test]
    fn errors_follow_the_reference_camera() {
        // Whitened by the true R, the errors have unit covariance; whitened by the
        // paper's R they do not. And the truth scores a lower NLL than `paper`.
        let data = generate(&DataSpec { samples: 20_000, seed: 2, ..DataSpec::default() });
        let truth = Synthetic::default();
        let mut m = nalgebra::Matrix2::<f64>::zeros();
        for s in &data.samples {
            let l = truth.noise(&s.features).matrix().cholesky().unwrap();
            let z = l.l().solve_lower_triangular(&nalgebra::Vector2::from(s.error)).unwrap();
            m += z * z.transpose();
        }
        m /= data.samples.len() as f64;
        assert!((m - nalgebra::Matrix2::identity()).abs().max() < 0.05, "{m}");
        let (true_nll, paper_nll) = (mean_nll(&truth, &data.samples), mean_nll(&Paper, &data.samples));
        assert!(true_nll + 0.2 < paper_nll, "{true_nll} vs {paper_nll}");
    }

    #[test]
    fn damaged_files_are_refused() {
        let bytes = generate(&DataSpec { samples: 10, seed: 5, ..DataSpec::default() }).to_bytes();
        assert_eq!(DataSet::from_bytes(b"DYFOSMLP........................").unwrap_err(), DataSetError::NotADataSet);
        assert!(matches!(DataSet::from_bytes(&bytes[..bytes.len() - 3]), Err(DataSetError::Length { .. })));
        let mut bad = bytes.clone();
        bad[100] ^= 1;
        assert_eq!(DataSet::from_bytes(&bad).unwrap_err(), DataSetError::Checksum);
        let mut other = bytes.clone();
        other[12] = 9;
        assert!(matches!(DataSet::from_bytes(&other), Err(DataSetError::Format { columns: 9, .. })));
    }

    #[test]
    fn split_keeps_both_sides() {
        let data = generate(&DataSpec { samples: 10, seed: 5, ..DataSpec::default() });
        let (train, val) = data.split(0.2);
        assert_eq!((train.len(), val.len()), (8, 2));
        let (train, val) = data.split(0.0);
        assert_eq!((train.len(), val.len()), (9, 1));
    }
}
