//! `dyfos`: differential evolution with SciPy's `differential_evolution` semantics
//! (SPEC §8), optionally followed by a local polish.
//!
//! SciPy-faithful parts: parameters live in the unit cube and are scaled to the
//! search space; population `max(5, popsize·dims)`; Latin-hypercube start; the
//! dither scale `U(0.5, 1)` drawn once per generation; best1bin (`best + F·(r0 −
//! r1)`, r0 ≠ r1 drawn from the population without the current member); binomial
//! crossover at 0.7 with one forced parameter; components outside [0, 1] redrawn
//! uniformly; immediate updating (a trial that is no worse replaces its parent and,
//! if no worse than the best, is promoted to index 0); stop when
//! `std(E) ≤ atol + tol·|mean(E)|` (population std).
//!
//! Interpretations (SPEC leaves them open): an infeasible candidate has energy +∞,
//! so it loses to every feasible one and two infeasible ones compare equal (the
//! trial wins, as `inf <= inf` does in SciPy); the population is converged only when
//! every member is feasible.
//!
//! The `dyfos` default adds a polish: a compass search from the best member in the
//! unit cube (yaw wraps around), halving its step until 1e-5 or 300 evaluations.
//! SciPy's tolerance is relative to |mean E| ≈ 15, so it stops ≈0.05 above the grid
//! optimum; the polish closes that gap for a few hundred cheap evaluations
//! (`bench/RESULTS.md`).

use super::{Evaluator, Search, SearchControl, SearchOutcome};
use crate::lupp::Lupp;
use dyfos_shared::answer::StopReason;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

const DIMS: usize = 4;
type Member = [f64; DIMS];

/// Differential evolution settings. [`DifferentialEvolution::scipy`] is SciPy's
/// defaults; [`DifferentialEvolution::dyfos`] adds the polish.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DifferentialEvolution {
    /// Population = max(5, popsize·4).
    pub popsize: usize,
    /// Dither range of the mutation scale F.
    pub mutation: (f64, f64),
    /// Crossover probability.
    pub recombination: f64,
    /// Relative convergence tolerance.
    pub tol: f64,
    /// Absolute convergence tolerance.
    pub atol: f64,
    /// Most generations.
    pub max_generations: u32,
    /// Most evaluations of the polish; 0 turns it off.
    pub polish_evaluations: u64,
}

impl DifferentialEvolution {
    /// SciPy's defaults, no polish: the paper's optimizer.
    pub fn scipy() -> Self {
        DifferentialEvolution {
            popsize: 15,
            mutation: (0.5, 1.0),
            recombination: 0.7,
            tol: 0.01,
            atol: 0.0,
            max_generations: 1000,
            polish_evaluations: 0,
        }
    }

    /// The `dyfos` default: SciPy's search, then a compass-search polish.
    pub fn dyfos() -> Self {
        DifferentialEvolution { polish_evaluations: 300, ..Self::scipy() }
    }
}

impl Default for DifferentialEvolution {
    fn default() -> Self {
        Self::dyfos()
    }
}

/// Energy of a candidate: its cost if feasible, +∞ otherwise.
#[inline]
fn energy(e: Option<crate::lupp::Evaluation>) -> f64 {
    e.and_then(|e| e.cost()).filter(|c| !c.is_nan()).unwrap_or(f64::INFINITY)
}

fn converged(energies: &[f64], tol: f64, atol: f64) -> bool {
    if !energies.iter().all(|e| e.is_finite()) {
        return false;
    }
    let n = energies.len() as f64;
    let mean = energies.iter().sum::<f64>() / n;
    let var = energies.iter().map(|e| (e - mean) * (e - mean)).sum::<f64>() / n;
    var.sqrt() <= atol + tol * mean.abs()
}

/// Fisher–Yates on column `j` (written out: the stream must not depend on a
/// library's shuffle, which may change between versions).
fn shuffle_column(pop: &mut [Member], j: usize, rng: &mut ChaCha8Rng) {
    for i in (1..pop.len()).rev() {
        let k = rng.random_range(0..=i);
        let (a, b) = (pop[i][j], pop[k][j]);
        (pop[i][j], pop[k][j]) = (b, a);
    }
}

/// Swaps the first member of lowest energy into index 0 (SciPy's promotion).
fn promote_lowest(pop: &mut [Member], energies: &mut [f64]) {
    let mut best = 0;
    for i in 1..energies.len() {
        if energies[i] < energies[best] {
            best = i;
        }
    }
    pop.swap(0, best);
    energies.swap(0, best);
}

impl Search for DifferentialEvolution {
    fn search(&self, lupp: &Lupp, control: &SearchControl) -> SearchOutcome {
        let mut rng = ChaCha8Rng::seed_from_u64(control.seed);
        let mut eval = Evaluator::new(lupp, control);
        let space = *lupp.space();
        let np = (self.popsize * DIMS).max(5);

        // Latin hypercube: one sample per stratum on each axis, strata shuffled per axis.
        let seg = 1.0 / np as f64;
        let mut pop: Vec<Member> =
            (0..np).map(|i| std::array::from_fn(|_| seg * rng.random::<f64>() + seg * i as f64)).collect();
        for j in 0..DIMS {
            shuffle_column(&mut pop, j, &mut rng);
        }
        let mut energies = vec![f64::INFINITY; np];
        for i in 0..np {
            let Some(e) = eval.evaluate(&space.from_unit(&pop[i])) else {
                return eval.finish(StopReason::Budget);
            };
            energies[i] = energy(Some(e));
        }
        promote_lowest(&mut pop, &mut energies);

        let mut stop = StopReason::MaxGenerations;
        'generations: for _ in 0..self.max_generations {
            let scale = self.mutation.0 + rng.random::<f64>() * (self.mutation.1 - self.mutation.0);
            for c in 0..np {
                let fill = rng.random_range(0..DIMS);
                let r0 = {
                    let r = rng.random_range(0..np - 1);
                    if r >= c { r + 1 } else { r }
                };
                let r1 = {
                    // Uniform over the members other than c and r0.
                    let (lo, hi) = if c < r0 { (c, r0) } else { (r0, c) };
                    let mut r = rng.random_range(0..np - 2);
                    if r >= lo {
                        r += 1;
                    }
                    if r >= hi {
                        r += 1;
                    }
                    r
                };
                let mut trial = pop[c];
                for j in 0..DIMS {
                    if j == fill || rng.random::<f64>() < self.recombination {
                        trial[j] = pop[0][j] + scale * (pop[r0][j] - pop[r1][j]);
                    }
                }
                for v in trial.iter_mut() {
                    if !(0.0..=1.0).contains(v) {
                        *v = rng.random::<f64>();
                    }
                }
                let Some(e) = eval.evaluate(&space.from_unit(&trial)) else {
                    break 'generations;
                };
                let en = energy(Some(e));
                if en <= energies[c] {
                    pop[c] = trial;
                    energies[c] = en;
                    if en <= energies[0] {
                        promote_lowest(&mut pop, &mut energies);
                    }
                }
            }
            if converged(&energies, self.tol, self.atol) {
                stop = StopReason::Finished;
                break;
            }
        }
        if eval.stopped().is_none() && self.polish_evaluations > 0 && energies[0].is_finite() {
            polish(&mut eval, lupp, pop[0], energies[0], self.polish_evaluations);
        }
        eval.finish(stop)
    }
}

/// Compass search in the unit cube from `start` (energy `e0`): try ±step on each
/// axis, keep strict improvements, halve the step after a sweep without one.
fn polish(eval: &mut Evaluator, lupp: &Lupp, start: Member, e0: f64, max_evals: u64) {
    let space = *lupp.space();
    let (mut x, mut ex) = (start, e0);
    let mut step = 1.0 / 32.0;
    let limit = eval.stats.total.saturating_add(max_evals);
    while step >= 1e-5 {
        let mut improved = false;
        for j in 0..DIMS {
            for dir in [1.0, -1.0] {
                if eval.stats.total >= limit {
                    return;
                }
                let mut y = x;
                y[j] += dir * step;
                y[j] = if j == DIMS - 1 { y[j].rem_euclid(1.0) } else { y[j].clamp(0.0, 1.0) };
                if y[j] == x[j] {
                    continue;
                }
                let Some(e) = eval.evaluate(&space.from_unit(&y)) else {
                    return;
                };
                let ey = energy(Some(e));
                if ey < ex {
                    (x, ex) = (y, ey);
                    improved = true;
                    break;
                }
            }
        }
        if !improved {
            step /= 2.0;
        }
    }
}
