//! The `learned` model's forward pass: two `tanh` layers and a linear one, in `f32`,
//! on stack arrays, over the widest vector registers the CPU has.
//!
//! Every output is `bias + w₀x₀ + w₁x₁ + …`, each product rounded and then added in
//! input order, and `tanh` is the same rational function lane by lane, with no fused
//! multiply-add anywhere. So the numbers are the same bit for bit whatever the
//! vector width: 4 lanes (SSE2, every x86-64), 8 (AVX2) or 16 (AVX-512), chosen
//! once per process from what the CPU offers (`pulp` detects it and compiles the
//! loop once per width; the choice changes the speed, never the answer).

use pulp::{Arch, Simd, WithSimd};
use std::sync::LazyLock;

/// Widest hidden layer the forward pass's stack arrays hold.
pub(super) const MAX_WIDTH: usize = 64;

/// Lanes of the widest vector (AVX-512: 16 `f32`). Every weight row and bias is
/// zero-padded to a multiple of it ([`pad_rows`]), so a layer is whole vectors at any
/// width the CPU has: no scalar tail (the 3 outputs are lanes of one vector).
pub(super) const PAD: usize = 16;

/// Most output vectors a layer sums together, each in its own register: their
/// chains of dependent adds overlap instead of running one after another.
const REGISTERS: usize = 8;

/// `n` rounded up to a multiple of [`PAD`]: a padded row's length.
pub(super) const fn padded(n: usize) -> usize {
    n.next_multiple_of(PAD)
}

/// A `rows × n` row-major matrix with each row zero-padded to [`padded`]`(n)`.
pub(super) fn pad_rows(m: &[f32], n: usize) -> Vec<f32> {
    let stride = padded(n);
    let mut out = vec![0f32; m.len() / n.max(1) * stride];
    for (dst, src) in out.chunks_exact_mut(stride).zip(m.chunks_exact(n.max(1))) {
        dst[..n].copy_from_slice(src);
    }
    out
}

/// The instruction set the forward pass runs with, detected once.
static ARCH: LazyLock<Arch> = LazyLock::new(Arch::new);

/// A network's weights, each matrix input-major with rows padded by [`pad_rows`]
/// (row i holds the weights of input i to every output, so a layer sums scaled
/// contiguous rows: no horizontal sums), each bias padded the same way.
#[derive(Debug, Clone, Copy)]
pub(super) struct Layers<'a, const I: usize, const O: usize> {
    /// Hidden width (≤ [`MAX_WIDTH`]).
    pub hidden: usize,
    pub t1: &'a [f32],
    pub b1: &'a [f32],
    pub t2: &'a [f32],
    pub b2: &'a [f32],
    pub t3: &'a [f32],
    pub b3: &'a [f32],
}

impl<const I: usize, const O: usize> Layers<'_, I, O> {
    /// The network's outputs for the normalised input `x`.
    #[inline]
    pub fn forward(&self, x: &[f32; I]) -> [f32; O] {
        ARCH.dispatch(Forward { layers: self, x })
    }
}

struct Forward<'a, 'b, const I: usize, const O: usize> {
    layers: &'a Layers<'b, I, O>,
    x: &'a [f32; I],
}

impl<const I: usize, const O: usize> WithSimd for Forward<'_, '_, I, O> {
    type Output = [f32; O];

    #[inline(always)]
    fn with_simd<S: Simd>(self, simd: S) -> [f32; O] {
        const { assert!(O <= PAD) };
        let l = self.layers;
        let h = l.hidden;
        let mut h1 = [0f32; MAX_WIDTH];
        layer(simd, self.x, l.t1, l.b1, &mut h1, h);
        tanh_all(simd, &mut h1[..padded(h)]);
        let mut h2 = [0f32; MAX_WIDTH];
        layer(simd, &h1[..h], l.t2, l.b2, &mut h2, h);
        tanh_all(simd, &mut h2[..padded(h)]);
        let mut out = [0f32; PAD];
        layer(simd, &h2[..h], l.t3, l.b3, &mut out, O);
        std::array::from_fn(|k| out[k])
    }
}

/// `out[j] = bias[j] + Σᵢ input[i] · wt[i·padded(n) + j]` for j < n, each output
/// summed in input order. `wt` and `bias` are padded ([`pad_rows`]); `out` has room
/// for `padded(n)` values, and the lanes past `n` get the padding's sums.
#[inline(always)]
pub(super) fn layer<S: Simd>(simd: S, input: &[f32], wt: &[f32], bias: &[f32], out: &mut [f32], n: usize) {
    let stride = padded(n);
    let lanes = S::F32_LANES;
    debug_assert!(PAD.is_multiple_of(lanes) && wt.len() >= input.len() * stride && bias.len() >= stride);
    let rows = &wt[..input.len() * stride];
    let mut vectors = n.div_ceil(lanes);
    let mut j = 0;
    while vectors >= REGISTERS {
        block::<S, REGISTERS>(simd, input, rows, stride, j, bias, out);
        j += REGISTERS * lanes;
        vectors -= REGISTERS;
    }
    match vectors {
        0 => {}
        1 => block::<S, 1>(simd, input, rows, stride, j, bias, out),
        2 => block::<S, 2>(simd, input, rows, stride, j, bias, out),
        3 => block::<S, 3>(simd, input, rows, stride, j, bias, out),
        4 => block::<S, 4>(simd, input, rows, stride, j, bias, out),
        5 => block::<S, 5>(simd, input, rows, stride, j, bias, out),
        6 => block::<S, 6>(simd, input, rows, stride, j, bias, out),
        _ => block::<S, 7>(simd, input, rows, stride, j, bias, out),
    }
}

/// The `K` output vectors from column `j` on, summed together: one register each.
#[inline(always)]
fn block<S: Simd, const K: usize>(
    simd: S,
    input: &[f32],
    rows: &[f32],
    stride: usize,
    j: usize,
    bias: &[f32],
    out: &mut [f32],
) {
    let columns = j..j + K * S::F32_LANES;
    let (b, _) = S::as_simd_f32s(&bias[columns.clone()]);
    let mut acc: [S::f32s; K] = std::array::from_fn(|k| b[k]);
    for (x, row) in input.iter().zip(rows.chunks_exact(stride)) {
        let xs = simd.splat_f32s(*x);
        let (w, _) = S::as_simd_f32s(&row[columns.clone()]);
        for k in 0..K {
            acc[k] = simd.add_f32s(acc[k], simd.mul_f32s(w[k], xs));
        }
    }
    S::as_mut_simd_f32s(&mut out[columns]).0.copy_from_slice(&acc);
}

/// [`fast_tanh`] of every value, a vector at a time.
#[inline(always)]
fn tanh_all<S: Simd>(simd: S, values: &mut [f32]) {
    let (head, tail) = S::as_mut_simd_f32s(values);
    for v in head {
        *v = fast_tanh_s(simd, *v);
    }
    for v in tail {
        *v = fast_tanh(*v);
    }
}

/// Where [`fast_tanh`] is ±1 in `f32`.
const TANH_CLAMP: f32 = 7.905_311;
const P: [f32; 7] =
    [-2.760_768_5e-16, 2.000_188e-13, -8.604_672e-11, 5.122_297e-8, 1.485_722_4e-5, 6.372_619_3e-4, 4.893_524_6e-3];
const Q: [f32; 4] = [1.198_258_4e-6, 1.185_347_1e-4, 2.268_434_6e-3, 4.893_525e-3];

/// tanh in `f32` by a rational minimax approximation (Eigen's `ptanh_float`
/// coefficients): branch-free, so a layer of them vectorizes; within 1e-6 of the
/// exact value (checked in the tests), far below the model's own error.
#[inline(always)]
pub(super) fn fast_tanh(x: f32) -> f32 {
    let x = x.clamp(-TANH_CLAMP, TANH_CLAMP);
    let x2 = x * x;
    let mut p = x2 * P[0] + P[1];
    for c in &P[2..] {
        p = p * x2 + c;
    }
    p *= x;
    let mut q = x2 * Q[0] + Q[1];
    for c in &Q[2..] {
        q = q * x2 + c;
    }
    p / q
}

/// [`fast_tanh`] lane by lane: the same operations in the same order. The layers'
/// values are finite (finite inputs and weights), where `min`/`max` clamp as
/// `f32::clamp` does.
#[inline(always)]
fn fast_tanh_s<S: Simd>(simd: S, x: S::f32s) -> S::f32s {
    let x = simd.min_f32s(simd.max_f32s(x, simd.splat_f32s(-TANH_CLAMP)), simd.splat_f32s(TANH_CLAMP));
    let x2 = simd.mul_f32s(x, x);
    let step = |acc: S::f32s, c: f32| simd.add_f32s(simd.mul_f32s(acc, x2), simd.splat_f32s(c));
    let mut p = step(simd.splat_f32s(P[0]), P[1]);
    for c in &P[2..] {
        p = step(p, *c);
    }
    p = simd.mul_f32s(p, x);
    let mut q = step(simd.splat_f32s(Q[0]), Q[1]);
    for c in &Q[2..] {
        q = step(q, *c);
    }
    simd.div_f32s(p, q)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The plain loop [`layer`] blocks: each output summed in input order.
    fn plain_layer(input: &[f32], wt: &[f32], bias: &[f32], out: &mut [f32]) {
        out.copy_from_slice(bias);
        for (x, row) in input.iter().zip(wt.chunks_exact(out.len())) {
            for (o, w) in out.iter_mut().zip(row) {
                *o += w * x;
            }
        }
    }

    struct Layer<'a> {
        input: &'a [f32],
        wt: &'a [f32],
        bias: &'a [f32],
        out: &'a mut [f32],
    }

    impl WithSimd for Layer<'_> {
        type Output = ();
        fn with_simd<S: Simd>(self, simd: S) {
            // The padded layer, as `Learned` stores it.
            let n = self.out.len();
            let wt = pad_rows(self.wt, n);
            let bias = pad_rows(self.bias, n);
            let mut out = vec![f32::NAN; padded(n)];
            layer(simd, self.input, &wt, &bias, &mut out, n);
            tanh_all(simd, &mut out);
            self.out.copy_from_slice(&out[..n]);
        }
    }

    /// Every instruction set this CPU has, scalar included, and the one detected.
    fn archs() -> Vec<(&'static str, Arch)> {
        let mut out = vec![("scalar", Arch::Scalar)];
        #[cfg(target_arch = "x86_64")]
        {
            if let Some(v3) = pulp::x86::V3::try_new() {
                out.push(("avx2", Arch::V3(v3)));
            }
            if let Some(v4) = pulp::x86::V4::try_new() {
                out.push(("avx512", Arch::V4(v4)));
            }
        }
        out.push(("detected", *ARCH));
        out
    }

    #[test]
    fn every_vector_width_gives_the_plain_loop_bit_for_bit() {
        let mut k = 1u32;
        let mut next = || {
            k = k.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (k >> 8) as f32 / (1u32 << 24) as f32 * 8.0 - 4.0
        };
        for (inputs, outputs) in [(7, 1), (7, 5), (7, 16), (7, 17), (48, 48), (64, 64), (64, 3), (33, 40), (5, 71)] {
            for _ in 0..20 {
                let input: Vec<f32> = (0..inputs).map(|_| next()).collect();
                let wt: Vec<f32> = (0..inputs * outputs).map(|_| next()).collect();
                let bias: Vec<f32> = (0..outputs).map(|_| next()).collect();
                let mut want = vec![0f32; outputs];
                plain_layer(&input, &wt, &bias, &mut want);
                want.iter_mut().for_each(|v| *v = fast_tanh(*v));
                for (name, arch) in archs() {
                    let mut got = vec![0f32; outputs];
                    arch.dispatch(Layer { input: &input, wt: &wt, bias: &bias, out: &mut got });
                    assert_eq!(
                        got.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
                        want.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
                        "{name}, {inputs} → {outputs}"
                    );
                }
            }
        }
    }

    #[test]
    fn fast_tanh_is_within_1e6_of_tanh_and_the_same_in_every_lane() {
        let mut worst = 0f64;
        let xs: Vec<f32> = (-200_000..=200_000).map(|i| i as f32 * 1e-4).collect(); // −20 … 20
        for &x in &xs {
            worst = worst.max((f64::from(fast_tanh(x)) - f64::from(x).tanh()).abs());
        }
        assert!(worst < 1e-6, "{worst}");
        assert_eq!(fast_tanh(0.0), 0.0);
        assert!((fast_tanh(f32::INFINITY) - 1.0).abs() < 1e-6 && (fast_tanh(f32::NEG_INFINITY) + 1.0).abs() < 1e-6);
        struct All<'a>(&'a mut [f32]);
        impl WithSimd for All<'_> {
            type Output = ();
            fn with_simd<S: Simd>(self, simd: S) {
                tanh_all(simd, self.0);
            }
        }
        for (name, arch) in archs() {
            let mut got = xs.clone();
            arch.dispatch(All(&mut got));
            let same = got.iter().zip(&xs).all(|(g, x)| g.to_bits() == fast_tanh(*x).to_bits());
            assert!(same, "{name}");
        }
    }
}
