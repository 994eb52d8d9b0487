//! `brute`: the exhaustive grid of SPEC §8, the "best possible" answer.
//!
//! Points are numbered with ρ slowest and ψ_v fastest. Each thread scores a
//! contiguous range of indices into its own slice of one cost array; the minimum
//! is then found in index order, and among points within 1e-9 of it the lowest
//! index wins. So the answer is the same whatever the thread count.

use super::{Evaluator, Found, Search, SearchControl, SearchOutcome};
use crate::lupp::Lupp;
use dyfos_shared::answer::{EvalStats, StopReason};
use dyfos_shared::sensor::{SearchSpace, SensorState};
use std::f64::consts::PI;

/// Grid sizes over (ρ, ψ, φ, ψ_v).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Brute {
    /// Points per axis; SPEC's default is 25 × 17 × 13 × 72.
    pub grid: [usize; 4],
}

impl Default for Brute {
    fn default() -> Self {
        Brute { grid: [25, 17, 13, 72] }
    }
}

/// `lo + i·(hi − lo)/(n − 1)`, the last exactly `hi`; one point sits mid-range.
fn axis(lo: f64, hi: f64, i: usize, n: usize) -> f64 {
    match n {
        1 => 0.5 * (lo + hi),
        _ if i == n - 1 => hi,
        _ => lo + i as f64 * (hi - lo) / (n - 1) as f64,
    }
}

impl Brute {
    /// Number of grid points.
    pub fn len(&self) -> usize {
        self.grid.iter().product()
    }

    /// Whether the grid has no points.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The candidate numbered `index`.
    pub fn point(&self, space: &SearchSpace, index: usize) -> SensorState {
        let [nr, np, nf, ny] = self.grid;
        let iy = index % ny;
        let i_phi = index / ny % nf;
        let i_psi = index / (ny * nf) % np;
        let i_rho = index / (ny * nf * np);
        SensorState::new(
            axis(space.lo[0], space.hi[0], i_rho, nr),
            axis(space.lo[1], space.hi[1], i_psi, np),
            axis(space.lo[2], space.hi[2], i_phi, nf),
            -PI + 2.0 * PI * iy as f64 / ny as f64,
        )
    }
}

impl Search for Brute {
    fn search(&self, lupp: &Lupp, control: &SearchControl) -> SearchOutcome {
        let space = *lupp.space();
        let n = self.len().min(usize::try_from(control.budget.unwrap_or(u64::MAX)).unwrap_or(usize::MAX));
        let mut costs = vec![f64::INFINITY; n];
        let threads = control.threads.clamp(1, 256);
        let chunk = n.div_ceil(threads).max(1);
        // Each worker evaluates its range with its own evaluator (no budget: the
        // range is already cut to it) and reports counts and early stops.
        let unbudgeted = SearchControl { budget: None, ..*control };
        let parts: Vec<(EvalStats, Option<StopReason>)> = std::thread::scope(|scope| {
            let handles: Vec<_> = costs
                .chunks_mut(chunk)
                .enumerate()
                .map(|(t, slice)| {
                    let control = &unbudgeted;
                    scope.spawn(move || {
                        let mut eval = Evaluator::new(lupp, control);
                        for (k, cost) in slice.iter_mut().enumerate() {
                            match eval.evaluate(&self.point(&space, t * chunk + k)) {
                                Some(e) => *cost = e.cost().filter(|c| !c.is_nan()).unwrap_or(f64::INFINITY),
                                None => break,
                            }
                        }
                        (eval.stats, eval.stopped())
                    })
                })
                .collect();
            handles.into_iter().map(|h| h.join().expect("brute worker panicked")).collect()
        });
        let mut stats = EvalStats::default();
        let mut stop = if n < self.len() { StopReason::Budget } else { StopReason::Finished };
        for (s, stopped) in parts {
            stats += s;
            // One abandoning thread abandons the whole search.
            if let Some(reason) = stopped
                && stop != StopReason::Abandoned
            {
                stop = reason;
            }
        }
        let min = costs.iter().copied().fold(f64::INFINITY, f64::min);
        let best = (min.is_finite())
            .then(|| costs.iter().position(|c| *c <= min + 1e-9).expect("the minimum is in the array"))
            .map(|i| Found { x: self.point(&space, i), cost: costs[i] });
        SearchOutcome { best, stats, stop }
    }
}
