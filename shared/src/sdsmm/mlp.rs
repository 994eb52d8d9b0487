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

/// The instruction set the forward pass runs with, detected once.
static ARCH: LazyLock<Arch> = LazyLock::new(Arch::new);

/// A network's weights, each matrix input-major: row i holds the weights of input i
/// to every output, so a layer sums scaled contiguous rows (no horizontal sums).
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
        let l = self.layers;
        let h = l.hidden;
        let mut h1 = [0f32; MAX_WIDTH];
        layer(simd, self.x, l.t1, l.b1, &mut h1[..h]);
        tanh_all(simd, &mut h1[..h]);
        let mut h2 = [0f32; MAX_WIDTH];
        layer(simd, &h1[..h], l.t2, l.b2, &mut h2[..h]);
        tanh_all(simd, &mut h2[..h]);
        let mut out = [0f32; O];
        layer(simd, &h2[..h], l.t3, l.b3, &mut out);
        out
    }
}

/// Output vectors summed together: their sums stay in registers across the inputs.
const REGISTERS: usize = 4;

/// `out = bias + Σᵢ input[i] · wt[i·n ..][..n]`, each output summed in input order.
#[inline(always)]
pub(super) fn layer<S: Simd>(simd: S, input: &[f32], wt: &[f32], bias: &[f32], out: &mut [f32]) {
    let n = out.len();
    let lanes = S::F32_LANES;
    let mut j = 0;
    // Blocks of REGISTERS vectors, then of one vector, then single outputs.
    while j + REGISTERS * lanes <= n {
        let (b, _) = S::as_simd_f32s(&bias[j..j + REGISTERS * lanes]);
        let mut acc: [S::f32s; REGISTERS] = std::array::from_fn(|k| b[k]);
        for (x, row) in input.iter().zip(wt.chunks_exact(n)) {
            let xs = simd.splat_f32s(*x);
            let (w, _) = S::as_simd_f32s(&row[j..j + REGISTERS * lanes]);
            for k in 0..REGISTERS {
                acc[k] = simd.add_f32s(acc[k], simd.mul_f32s(w[k], xs));
            }
        }
        let (o, _) = S::as_mut_simd_f32s(&mut out[j..j + REGISTERS * lanes]);
        o.copy_from_slice(&acc);
        j += REGISTERS * lanes;
    }
    while j + lanes <= n {
        let (b, _) = S::as_simd_f32s(&bias[j..j + lanes]);
        let mut acc = b[0];
        for (x, row) in input.iter().zip(wt.chunks_exact(n)) {
            let (w, _) = S::as_simd_f32s(&row[j..j + lanes]);
            acc = simd.add_f32s(acc, simd.mul_f32s(w[0], simd.splat_f32s(*x)));
        }
        S::as_mut_simd_f32s(&mut out[j..j + lanes]).0[0] = acc;
        j += lanes;
    }
    for (k, o) in out.iter_mut().enumerate().skip(j) {
        *o = bias[k];
        for (x, row) in input.iter().zip(wt.chunks_exact(n)) {
            *o += row[k] * x;
        }
    }
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
            layer(simd, self.input, self.wt, self.bias, self.out);
            tanh_all(simd, self.out);
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
