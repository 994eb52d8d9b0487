//! SPEC §6 `learned`: a probabilistic neural network (a small MLP) that maps a
//! measurement's predictable features to its noise covariance R.
//!
//! The network sees [`learned_input`]: the image position (u, v), the normalised
//! distance s, the glare c, the viewing elevation ε and the bearing relative to the
//! rover's heading α = β − θ as (cos α, sin α). Two `tanh` hidden layers of equal width
//! (at most [`MAX_HIDDEN`]) feed three outputs (a, b, d), read as the Cholesky factor
//! of R in the *line-of-sight frame* (first axis along the horizontal bearing β from
//! the sensor to the rover):
//!
//! ```text
//! L = [[exp a, 0], [b, exp d]]      (a, d clamped to [−12, 4]: std 6 µm … 55 m)
//! R = Rot(β) · L·Lᵀ · Rot(β)ᵀ
//! ```
//!
//! so R is symmetric positive definite for any weights, and a camera that does not
//! know where the map's x axis points gives the same noise for the same view in any
//! direction (interpretation: SPEC leaves the output frame open; predicting in the
//! line-of-sight frame builds that invariance in instead of learning it). Training
//! minimises paper eq. 5's negative log-likelihood, `½·Σ(ln det R + eᵀR⁻¹e)` (the
//! printed equation carries a stray minus sign: it is the log-likelihood).
//!
//! The forward pass (`mlp`) runs in `f32` on stack arrays: no allocation per
//! candidate. Its `tanh` is a rational approximation within 1e-6 of the exact one
//! (the training framework's), which lets each layer vectorize; the numbers are the
//! same bit for bit on every x86-64, whatever vector width it has.
//! Weights come from bytes ([`Learned::from_bytes`]); the file is read by the
//! binaries. A file that is truncated, corrupt, of another format or of the wrong
//! shape is a [`LearnedModelError`] at load, never a failure later.
//!
//! ```
//! use dyfos_shared::sdsmm::{Features, Learned, LearnedWeights, Sdsmm, LEARNED_INPUTS};
//! use dyfos_shared::math::Vector3;
//!
//! // A one-unit network whose output ignores its input: std 0.1 m along the line of
//! // sight and 0.2 m across it.
//! let weights = LearnedWeights {
//!     hidden: 1,
//!     input_mean: [0.0; LEARNED_INPUTS],
//!     input_std: [1.0; LEARNED_INPUTS],
//!     w1: vec![0.0; LEARNED_INPUTS], b1: vec![0.0],
//!     w2: vec![0.0], b2: vec![0.0],
//!     w3: vec![0.0; 3], b3: vec![0.1f32.ln(), 0.0, 0.2f32.ln()],
//!     note: "hand-made".into(),
//! };
//! let bytes = Learned::new(weights).unwrap().to_bytes();
//! let model = Learned::from_bytes(&bytes).unwrap();
//! assert!(Learned::from_bytes(&bytes[..bytes.len() - 1]).is_err());
//!
//! // Looking along +y (β = π/2): the along-sight variance lands on y.
//! let f = Features { u: 0.0, v: 0.0, e: 0.0, s: 0.5, c: 0.0, w: -Vector3::y(), elevation: 0.0,
//!                    bearing: std::f64::consts::FRAC_PI_2, rho: 3.5, rover_heading: 0.0 };
//! let r = model.noise(&f);
//! assert!((r.matrix()[(1, 1)] - 0.01).abs() < 1e-8 && (r.matrix()[(0, 0)] - 0.04).abs() < 1e-8);
//! ```

use super::mlp::{Layers, MAX_WIDTH, pad_rows};
use super::{Features, Sdsmm};
use crate::math::{Cov2, Matrix2};

/// Inputs the network takes: u, v, s, c, ε, cos α, sin α (see [`learned_input`]).
pub const LEARNED_INPUTS: usize = 7;
/// Outputs: the Cholesky parameters (a, b, d).
pub const LEARNED_OUTPUTS: usize = 3;
/// Widest hidden layer a model file may have (the forward pass's stack arrays).
pub const MAX_HIDDEN: usize = MAX_WIDTH;
/// Range the log-diagonal outputs a and d are clamped to.
pub const LOG_STD_RANGE: (f64, f64) = (-12.0, 4.0);

/// File format version written by [`Learned::to_bytes`].
const FORMAT_VERSION: u32 = 1;
/// Which input encoding the file was trained on ([`learned_input`], version 1).
const FEATURE_SET: u32 = 1;
const MAGIC: &[u8; 8] = b"DYFOSMLP";
/// Longest provenance note accepted, bytes.
const MAX_NOTE: usize = 64 * 1024;

/// The network's input for `f`, before normalisation: `[u, v, s, c, ε, cos α, sin α]`
/// with α = β − θ (SPEC §6 features; θ from [`Features::with_rover_heading`]).
#[inline]
pub fn learned_input(f: &Features) -> [f64; LEARNED_INPUTS] {
    let (sa, ca) = f.relative_bearing().sin_cos();
    [f.u, f.v, f.s, f.c, f.elevation, ca, sa]
}

/// R from the network's raw outputs (a, b, d) and the bearing β (see the module doc).
#[inline]
pub fn noise_from_outputs(out: &[f64; LEARNED_OUTPUTS], bearing: f64) -> Cov2 {
    rotated_noise(out, bearing.sin_cos())
}

/// [`noise_from_outputs`] with `(sin β, cos β)` given.
#[inline]
fn rotated_noise(out: &[f64; LEARNED_OUTPUTS], (s, c): (f64, f64)) -> Cov2 {
    let (lo, hi) = LOG_STD_RANGE;
    let l11 = out[0].clamp(lo, hi).exp();
    let l21 = out[1];
    let l22 = out[2].clamp(lo, hi).exp();
    // L·Lᵀ in the line-of-sight frame, then rotated by β.
    let (p, q, r) = (l11 * l11, l11 * l21, l21 * l21 + l22 * l22);
    let xx = c * c * p - 2.0 * s * c * q + s * s * r;
    let yy = s * s * p + 2.0 * s * c * q + c * c * r;
    let xy = s * c * (p - r) + (c * c - s * s) * q;
    Cov2::new_unchecked(Matrix2::new(xx, xy, xy, yy))
}

/// The weights of a two-hidden-layer MLP, row-major `[out][in]` like a linear
/// layer's weight matrix: `h1 = tanh(W1·x̂ + b1)`, `h2 = tanh(W2·h1 + b2)`,
/// `out = W3·h2 + b3`, with `x̂ = (x − input_mean) / input_std`.
#[derive(Debug, Clone, PartialEq)]
pub struct LearnedWeights {
    /// Width of both hidden layers, 1..=[`MAX_HIDDEN`].
    pub hidden: usize,
    /// Per-input mean subtracted before the first layer.
    pub input_mean: [f32; LEARNED_INPUTS],
    /// Per-input scale (> 0) divided by before the first layer.
    pub input_std: [f32; LEARNED_INPUTS],
    /// `hidden × LEARNED_INPUTS`.
    pub w1: Vec<f32>,
    /// `hidden`.
    pub b1: Vec<f32>,
    /// `hidden × hidden`.
    pub w2: Vec<f32>,
    /// `hidden`.
    pub b2: Vec<f32>,
    /// `LEARNED_OUTPUTS × hidden`.
    pub w3: Vec<f32>,
    /// `LEARNED_OUTPUTS`.
    pub b3: Vec<f32>,
    /// Free-text provenance (how the model was trained), kept in the file.
    pub note: String,
}

/// Why model bytes (or weights) cannot be used. Every message says what to do.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LearnedModelError {
    /// The data end early.
    #[error(
        "is truncated: {len} bytes, but its header needs at least {needed}; copy it again or retrain it with `dyfos train`"
    )]
    Truncated {
        /// Bytes needed to read on.
        needed: usize,
        /// Bytes present.
        len: usize,
    },
    /// The data do not start with the model magic.
    #[error("is not a dyfos model file (it does not start with `DYFOSMLP`); pass a file written by `dyfos train`")]
    NotAModel,
    /// A format version this build cannot read.
    #[error(
        "has format version {found}, this build reads version {supported}; retrain it with this build's `dyfos train`"
    )]
    Version {
        /// Version in the file.
        found: u32,
        /// Version this build reads.
        supported: u32,
    },
    /// Trained on another input encoding.
    #[error(
        "was trained on feature set {found}, this build computes feature set {supported}; retrain it with this build's `dyfos train`"
    )]
    FeatureSet {
        /// Feature set in the file.
        found: u32,
        /// Feature set this build computes.
        supported: u32,
    },
    /// A layer has a size this build cannot run.
    #[error(
        "has the wrong shape: {what} = {found}, this build needs {expected}; retrain it with this build's `dyfos train`"
    )]
    Shape {
        /// Which size: "inputs", "hidden", "outputs" or a weight tensor's length.
        what: &'static str,
        /// The size found.
        found: u64,
        /// What is accepted.
        expected: String,
    },
    /// A weight is NaN or infinite.
    #[error(
        "has a non-finite value in {tensor}[{index}]; the training diverged, retrain it (e.g. with a smaller learning rate)"
    )]
    NonFinite {
        /// The tensor's name.
        tensor: &'static str,
        /// Index of the first bad value.
        index: usize,
    },
    /// An input scale is not positive.
    #[error("has input_std[{index}] = {value}, which must be > 0; retrain it")]
    InputScale {
        /// The input.
        index: usize,
        /// Its scale.
        value: f32,
    },
    /// The provenance note is not UTF-8 or too long.
    #[error("has an unreadable note ({reason}); the file is corrupt, copy it again or retrain it")]
    Note {
        /// What is wrong.
        reason: &'static str,
    },
    /// The stored checksum does not match the content.
    #[error("is corrupt (checksum {computed:016x} ≠ stored {stored:016x}); copy it again or retrain it")]
    Checksum {
        /// Checksum in the file.
        stored: u64,
        /// Checksum of the content.
        computed: u64,
    },
    /// Bytes follow the checksum.
    #[error("has {extra} bytes after its end; it is corrupt or not a single model file")]
    TrailingBytes {
        /// How many.
        extra: usize,
    },
}

/// The `learned` SDSMM: validated weights, ready for the allocation-free forward pass.
#[derive(Clone, PartialEq)]
pub struct Learned {
    weights: LearnedWeights,
    /// `w1`, `w2`, `w3` transposed (input-major), so each layer is a sum of scaled
    /// contiguous rows: no horizontal sums, and it vectorizes; every row and bias
    /// zero-padded to whole vectors (`mlp::pad_rows`).
    t1: Vec<f32>,
    t2: Vec<f32>,
    t3: Vec<f32>,
    b1: Vec<f32>,
    b2: Vec<f32>,
    b3: Vec<f32>,
}

impl std::fmt::Debug for Learned {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Learned")
            .field("inputs", &LEARNED_INPUTS)
            .field("hidden", &self.weights.hidden)
            .field("note", &self.weights.note)
            .finish_non_exhaustive()
    }
}

fn fnv1a(bytes: &[u8]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in bytes {
        h ^= u64::from(*b);
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    h
}

fn check_finite(tensor: &'static str, values: &[f32]) -> Result<(), LearnedModelError> {
    match values.iter().position(|v| !v.is_finite()) {
        Some(index) => Err(LearnedModelError::NonFinite { tensor, index }),
        None => Ok(()),
    }
}

fn check_len(what: &'static str, values: &[f32], expected: usize) -> Result<(), LearnedModelError> {
    if values.len() == expected {
        Ok(())
    } else {
        Err(LearnedModelError::Shape { what, found: values.len() as u64, expected: expected.to_string() })
    }
}

/// Reads little-endian values off the front of a byte slice.
struct Reader<'b> {
    bytes: &'b [u8],
    at: usize,
}

impl<'b> Reader<'b> {
    fn take(&mut self, n: usize) -> Result<&'b [u8], LearnedModelError> {
        let end = self.at.checked_add(n).filter(|e| *e <= self.bytes.len());
        let end =
            end.ok_or(LearnedModelError::Truncated { needed: self.at.saturating_add(n), len: self.bytes.len() })?;
        let s = &self.bytes[self.at..end];
        self.at = end;
        Ok(s)
    }

    fn u32(&mut self) -> Result<u32, LearnedModelError> {
        let b = self.take(4)?;
        Ok(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    }

    fn u64(&mut self) -> Result<u64, LearnedModelError> {
        let b = self.take(8)?;
        Ok(u64::from_le_bytes(std::array::from_fn(|i| b[i])))
    }

    fn f32s(&mut self, n: usize) -> Result<Vec<f32>, LearnedModelError> {
        let b = self.take(n.checked_mul(4).ok_or(LearnedModelError::Truncated { needed: usize::MAX, len: 0 })?)?;
        Ok(b.chunks_exact(4).map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect())
    }
}

/// `rows × cols` row-major → `cols × rows` row-major.
fn transpose(m: &[f32], rows: usize, cols: usize) -> Vec<f32> {
    (0..cols).flat_map(|c| (0..rows).map(move |r| m[r * cols + c])).collect()
}

impl Learned {
    /// Validates `weights`: sizes, finite values, positive input scales.
    pub fn new(weights: LearnedWeights) -> Result<Self, LearnedModelError> {
        let h = weights.hidden;
        if !(1..=MAX_HIDDEN).contains(&h) {
            return Err(LearnedModelError::Shape {
                what: "hidden",
                found: h as u64,
                expected: format!("1..={MAX_HIDDEN}"),
            });
        }
        check_len("w1", &weights.w1, h * LEARNED_INPUTS)?;
        check_len("b1", &weights.b1, h)?;
        check_len("w2", &weights.w2, h * h)?;
        check_len("b2", &weights.b2, h)?;
        check_len("w3", &weights.w3, LEARNED_OUTPUTS * h)?;
        check_len("b3", &weights.b3, LEARNED_OUTPUTS)?;
        check_finite("input_mean", &weights.input_mean)?;
        check_finite("input_std", &weights.input_std)?;
        if let Some((index, value)) = weights.input_std.iter().enumerate().find(|(_, v)| **v <= 0.0) {
            return Err(LearnedModelError::InputScale { index, value: *value });
        }
        for (name, t) in [
            ("w1", &weights.w1),
            ("b1", &weights.b1),
            ("w2", &weights.w2),
            ("b2", &weights.b2),
            ("w3", &weights.w3),
            ("b3", &weights.b3),
        ] {
            check_finite(name, t)?;
        }
        if weights.note.len() > MAX_NOTE {
            return Err(LearnedModelError::Note { reason: "longer than 64 KiB" });
        }
        let t1 = pad_rows(&transpose(&weights.w1, h, LEARNED_INPUTS), h);
        let t2 = pad_rows(&transpose(&weights.w2, h, h), h);
        let t3 = pad_rows(&transpose(&weights.w3, LEARNED_OUTPUTS, h), LEARNED_OUTPUTS);
        let b1 = pad_rows(&weights.b1, h);
        let b2 = pad_rows(&weights.b2, h);
        let b3 = pad_rows(&weights.b3, LEARNED_OUTPUTS);
        Ok(Learned { weights, t1, t2, t3, b1, b2, b3 })
    }

    /// The weights.
    pub fn weights(&self) -> &LearnedWeights {
        &self.weights
    }

    /// The hidden layers' width.
    pub fn hidden(&self) -> usize {
        self.weights.hidden
    }

    /// The provenance note stored with the weights.
    pub fn note(&self) -> &str {
        &self.weights.note
    }

    /// Parses a model file's bytes (format: `DYFOSMLP`, version, feature set, sizes,
    /// the `f32` tensors in [`LearnedWeights`] order, the note, an FNV-1a checksum;
    /// all little-endian).
    pub fn from_bytes(bytes: &[u8]) -> Result<Self, LearnedModelError> {
        let mut r = Reader { bytes, at: 0 };
        if bytes.len() >= MAGIC.len() && &bytes[..MAGIC.len()] != MAGIC {
            return Err(LearnedModelError::NotAModel);
        }
        r.take(MAGIC.len())?;
        let version = r.u32()?;
        if version != FORMAT_VERSION {
            return Err(LearnedModelError::Version { found: version, supported: FORMAT_VERSION });
        }
        let feature_set = r.u32()?;
        if feature_set != FEATURE_SET {
            return Err(LearnedModelError::FeatureSet { found: feature_set, supported: FEATURE_SET });
        }
        let inputs = r.u32()?;
        let hidden = r.u32()?;
        let outputs = r.u32()?;
        if inputs as usize != LEARNED_INPUTS {
            return Err(LearnedModelError::Shape {
                what: "inputs",
                found: inputs.into(),
                expected: LEARNED_INPUTS.to_string(),
            });
        }
        if outputs as usize != LEARNED_OUTPUTS {
            return Err(LearnedModelError::Shape {
                what: "outputs",
                found: outputs.into(),
                expected: LEARNED_OUTPUTS.to_string(),
            });
        }
        let h = hidden as usize;
        if !(1..=MAX_HIDDEN).contains(&h) {
            return Err(LearnedModelError::Shape {
                what: "hidden",
                found: hidden.into(),
                expected: format!("1..={MAX_HIDDEN}"),
            });
        }
        // Sizes are known now: check the total length before reading tensors, so a
        // truncated file says so rather than failing on some tensor.
        let tensors = 2 * LEARNED_INPUTS + h * LEARNED_INPUTS + h + h * h + h + LEARNED_OUTPUTS * h + LEARNED_OUTPUTS;
        let minimum = r.at + 4 * tensors + 4 + 8;
        if bytes.len() < minimum {
            return Err(LearnedModelError::Truncated { needed: minimum, len: bytes.len() });
        }
        let input_mean = r.f32s(LEARNED_INPUTS)?;
        let input_std = r.f32s(LEARNED_INPUTS)?;
        let w1 = r.f32s(h * LEARNED_INPUTS)?;
        let b1 = r.f32s(h)?;
        let w2 = r.f32s(h * h)?;
        let b2 = r.f32s(h)?;
        let w3 = r.f32s(LEARNED_OUTPUTS * h)?;
        let b3 = r.f32s(LEARNED_OUTPUTS)?;
        let note_len = r.u32()? as usize;
        if note_len > MAX_NOTE {
            return Err(LearnedModelError::Note { reason: "longer than 64 KiB" });
        }
        let note = r.take(note_len)?;
        let content_end = r.at;
        let stored = r.u64()?;
        let computed = fnv1a(&bytes[..content_end]);
        if stored != computed {
            return Err(LearnedModelError::Checksum { stored, computed });
        }
        if r.at != bytes.len() {
            return Err(LearnedModelError::TrailingBytes { extra: bytes.len() - r.at });
        }
        let note = String::from_utf8(note.to_vec()).map_err(|_| LearnedModelError::Note { reason: "not UTF-8" })?;
        Learned::new(LearnedWeights {
            hidden: h,
            input_mean: std::array::from_fn(|i| input_mean[i]),
            input_std: std::array::from_fn(|i| input_std[i]),
            w1,
            b1,
            w2,
            b2,
            w3,
            b3,
            note,
        })
    }

    /// The model file's bytes (see [`Learned::from_bytes`]).
    pub fn to_bytes(&self) -> Vec<u8> {
        let w = &self.weights;
        let mut out = Vec::new();
        out.extend_from_slice(MAGIC);
        for v in [FORMAT_VERSION, FEATURE_SET, LEARNED_INPUTS as u32, w.hidden as u32, LEARNED_OUTPUTS as u32] {
            out.extend_from_slice(&v.to_le_bytes());
        }
        let tensors: [&[f32]; 8] = [&w.input_mean, &w.input_std, &w.w1, &w.b1, &w.w2, &w.b2, &w.w3, &w.b3];
        for t in tensors {
            for v in t {
                out.extend_from_slice(&v.to_le_bytes());
            }
        }
        out.extend_from_slice(&(w.note.len() as u32).to_le_bytes());
        out.extend_from_slice(w.note.as_bytes());
        let sum = fnv1a(&out);
        out.extend_from_slice(&sum.to_le_bytes());
        out
    }

    /// The raw outputs (a, b, d) for an unnormalised input (see [`learned_input`]).
    /// Stack arrays only: no allocation.
    #[inline]
    pub fn forward(&self, input: &[f64; LEARNED_INPUTS]) -> [f64; LEARNED_OUTPUTS] {
        let w = &self.weights;
        let x: [f32; LEARNED_INPUTS] = std::array::from_fn(|i| (input[i] as f32 - w.input_mean[i]) / w.input_std[i]);
        let layers = Layers::<LEARNED_INPUTS, LEARNED_OUTPUTS> {
            hidden: w.hidden,
            t1: &self.t1,
            b1: &self.b1,
            t2: &self.t2,
            b2: &self.b2,
            t3: &self.t3,
            b3: &self.b3,
        };
        let out = layers.forward(&x);
        out.map(f64::from)
    }
}

impl Sdsmm for Learned {
    #[inline]
    fn noise(&self, f: &Features) -> Cov2 {
        // The rotation's sine and cosine first: they do not wait for the network, so
        // they run while its chains of dependent adds do (the same numbers).
        let rotation = f.bearing.sin_cos();
        rotated_noise(&self.forward(&learned_input(f)), rotation)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::Vector3;

    /// A small network with varied, deterministic weights.
    fn weights(hidden: usize) -> LearnedWeights {
        let mut k = 0u32;
        let mut next = |scale: f32| {
            k += 1;
            // A fixed pseudo-random sequence in [−scale, scale].
            let x = (k.wrapping_mul(2_654_435_761) >> 8) as f32 / (1u32 << 24) as f32;
            (2.0 * x - 1.0) * scale
        };
        LearnedWeights {
            hidden,
            input_mean: std::array::from_fn(|_| next(0.5)),
            input_std: std::array::from_fn(|_| 0.5 + next(0.4).abs()),
            w1: (0..hidden * LEARNED_INPUTS).map(|_| next(0.8)).collect(),
            b1: (0..hidden).map(|_| next(0.3)).collect(),
            w2: (0..hidden * hidden).map(|_| next(0.5)).collect(),
            b2: (0..hidden).map(|_| next(0.3)).collect(),
            w3: (0..LEARNED_OUTPUTS * hidden).map(|_| next(0.5)).collect(),
            b3: vec![-3.0, 0.01, -2.5],
            note: "test".into(),
        }
    }

    fn features(seed: f64) -> Features {
        let w = Vector3::new(seed.sin(), (2.0 * seed).cos(), 0.5 + 0.4 * seed.cos()).normalize();
        Features {
            u: 0.9 * (3.0 * seed).sin(),
            v: 0.8 * (5.0 * seed).cos(),
            e: 0.5,
            s: 0.5 + 0.5 * (7.0 * seed).sin(),
            c: 1.0 + (11.0 * seed).cos(),
            w,
            elevation: w.z.atan2(w.x.hypot(w.y)),
            bearing: (-w.y).atan2(-w.x),
            rho: 3.0,
            rover_heading: seed,
        }
    }

    /// The same network in f64, straight from the definition.
    fn reference_forward(w: &LearnedWeights, input: &[f64; LEARNED_INPUTS]) -> [f64; 3] {
        let h = w.hidden;
        let x: Vec<f64> =
            (0..LEARNED_INPUTS).map(|i| (input[i] - f64::from(w.input_mean[i])) / f64::from(w.input_std[i])).collect();
        let layer = |wt: &[f32], b: &[f32], x: &[f64], n_out: usize, act: bool| -> Vec<f64> {
            (0..n_out)
                .map(|j| {
                    let z = f64::from(b[j]) + (0..x.len()).map(|i| f64::from(wt[j * x.len() + i]) * x[i]).sum::<f64>();
                    if act { z.tanh() } else { z }
                })
                .collect()
        };
        let h1 = layer(&w.w1, &w.b1, &x, h, true);
        let h2 = layer(&w.w2, &w.b2, &h1, h, true);
        let o = layer(&w.w3, &w.b3, &h2, 3, false);
        [o[0], o[1], o[2]]
    }

    #[test]
    fn forward_matches_the_definition() {
        for hidden in [1, 5, 32, MAX_HIDDEN] {
            let w = weights(hidden);
            let model = Learned::new(w.clone()).unwrap();
            for i in 0..50 {
                let input = learned_input(&features(f64::from(i) * 0.37));
                let got = model.forward(&input);
                let want = reference_forward(&w, &input);
                for k in 0..3 {
                    assert!((got[k] - want[k]).abs() < 1e-4, "hidden {hidden}, out {k}: {got:?} vs {want:?}");
                }
            }
        }
    }

    /// The committed model's raw outputs on fixed inputs, as `f32` bits: pinned from
    /// the forward pass before it was reorganised for speed, so any change of
    /// summation order or `tanh` (which would change `learned` answers) fails here.
    #[test]
    fn committed_model_outputs_are_pinned_bit_for_bit() {
        const PINNED: [[u32; LEARNED_OUTPUTS]; 6] = [
            [3_219_324_328, 3_141_803_687, 3_221_954_280],
            [3_196_796_974, 999_787_904, 3_206_193_346],
            [1_069_526_156, 983_716_112, 1_069_160_318],
            [1_040_652_244, 989_239_366, 3_180_020_950],
            [1_067_158_079, 1_007_828_347, 1_068_686_387],
            [1_063_376_614, 1_006_014_152, 1_060_188_798],
        ];
        let model = Learned::from_bytes(include_bytes!("../../../tests/data/learned/model.bin")).unwrap();
        let got: Vec<[u32; LEARNED_OUTPUTS]> = (0..PINNED.len())
            .map(|i| model.forward(&learned_input(&features(0.3 + 0.71 * i as f64))).map(|v| (v as f32).to_bits()))
            .collect();
        assert_eq!(got, PINNED, "{got:?}");
    }

    #[test]
    fn noise_is_spd_and_rotates_with_the_view() {
        let model = Learned::new(weights(16)).unwrap();
        for i in 0..100 {
            let f = features(f64::from(i) * 0.11);
            let r = model.noise(&f);
            assert!(Cov2::new(*r.matrix()).is_ok(), "{r:?}");
            // Turning the whole scene (sensor, rover heading) by γ rotates R by γ.
            let g = 0.7;
            let turned = Features { bearing: f.bearing + g, rover_heading: f.rover_heading + g, ..f };
            let rot = Matrix2::new(g.cos(), -g.sin(), g.sin(), g.cos());
            let expected = rot * r.matrix() * rot.transpose();
            assert!((model.noise(&turned).matrix() - expected).norm() < 1e-12 * r.matrix().norm().max(1e-6));
        }
    }

    #[test]
    fn outputs_map_to_the_cholesky_factor() {
        // β = 0: the line-of-sight frame is the world frame, R = L·Lᵀ.
        let r = noise_from_outputs(&[0.1f64.ln(), 0.05, 0.2f64.ln()], 0.0);
        let l = Matrix2::new(0.1, 0.0, 0.05, 0.2);
        assert!((r.matrix() - l * l.transpose()).norm() < 1e-15);
        // Clamped diagonal: never singular.
        let tiny = noise_from_outputs(&[-1e6, 0.0, -1e6], 0.3);
        assert!(Cov2::new(*tiny.matrix()).is_ok());
    }

    #[test]
    fn bytes_round_trip() {
        let model = Learned::new(weights(7)).unwrap();
        let bytes = model.to_bytes();
        assert_eq!(Learned::from_bytes(&bytes).unwrap(), model);
    }

    #[test]
    fn every_damage_is_a_clear_error() {
        let bytes = Learned::new(weights(7)).unwrap().to_bytes();
        // Every truncation fails, none panics.
        for n in 0..bytes.len() {
            let err = Learned::from_bytes(&bytes[..n]).unwrap_err();
            assert!(matches!(err, LearnedModelError::Truncated { .. } | LearnedModelError::NotAModel), "{n}: {err}");
        }
        // Every single flipped bit is caught.
        for i in 0..bytes.len() {
            let mut bad = bytes.clone();
            bad[i] ^= 0x10;
            assert!(Learned::from_bytes(&bad).is_err(), "flip at {i} went unnoticed");
        }
        let mut extra = bytes.clone();
        extra.push(0);
        assert_eq!(Learned::from_bytes(&extra).unwrap_err(), LearnedModelError::TrailingBytes { extra: 1 });
        assert_eq!(Learned::from_bytes(b"{\"not\": \"a model\"}").unwrap_err(), LearnedModelError::NotAModel);
    }

    /// Rewrites a header field and fixes the checksum, as a writer of another
    /// version or shape would.
    fn with_header(bytes: &[u8], offset: usize, value: u32) -> Vec<u8> {
        let mut b = bytes[..bytes.len() - 8].to_vec();
        b[offset..offset + 4].copy_from_slice(&value.to_le_bytes());
        let sum = fnv1a(&b);
        b.extend_from_slice(&sum.to_le_bytes());
        b
    }

    #[test]
    fn other_versions_and_shapes_are_refused() {
        let bytes = Learned::new(weights(7)).unwrap().to_bytes();
        let e = |off, v| Learned::from_bytes(&with_header(&bytes, off, v)).unwrap_err();
        assert_eq!(e(8, 2), LearnedModelError::Version { found: 2, supported: 1 });
        assert_eq!(e(12, 9), LearnedModelError::FeatureSet { found: 9, supported: 1 });
        assert!(matches!(e(16, 9), LearnedModelError::Shape { what: "inputs", found: 9, .. }));
        assert!(matches!(e(24, 4), LearnedModelError::Shape { what: "outputs", found: 4, .. }));
        assert!(matches!(e(20, 65), LearnedModelError::Shape { what: "hidden", found: 65, .. }));
        assert!(matches!(e(20, 0), LearnedModelError::Shape { what: "hidden", found: 0, .. }));
        // A hidden size that disagrees with the tensors that follow: too short or too long.
        assert!(matches!(e(20, 8), LearnedModelError::Truncated { .. }));
        assert!(Learned::from_bytes(&with_header(&bytes, 20, 6)).is_err());
        let msg = e(8, 2).to_string();
        assert!(msg.contains("dyfos train"), "{msg}");
    }

    #[test]
    fn bad_weights_are_refused() {
        let mut w = weights(3);
        w.w2[4] = f32::NAN;
        assert_eq!(Learned::new(w).unwrap_err(), LearnedModelError::NonFinite { tensor: "w2", index: 4 });
        let mut w = weights(3);
        w.input_std[2] = 0.0;
        assert!(matches!(Learned::new(w).unwrap_err(), LearnedModelError::InputScale { index: 2, .. }));
        let mut w = weights(3);
        w.b1.pop();
        assert!(matches!(Learned::new(w).unwrap_err(), LearnedModelError::Shape { what: "b1", .. }));
    }

    #[test]
    fn is_send_and_sync() {
        fn check<T: Send + Sync>() {}
        check::<Learned>();
        check::<super::super::NoiseModel>();
    }
}
