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
//! The `dyfos` default adds a polish ([`Polish::Mirrored`]): a pattern search from
//! the best member with a step per direction, that also tries the image centre and
//! moves ψ and φ together ([`Polish::Adaptive`]), for at most 150 evaluations, then
//! the same from the member's mirror image through the rover (viewer yaw + π), for
//! at most 150 more. SciPy's tolerance is relative to |mean E| ≈ 15, so its search
//! stops ≈0.04 above the grid optimum; the polish closes that gap and lands at or
//! below `brute` on the median map. The mirror start catches the evolution settling
//! on the wrong side of the rover, where an axis-aligned noise model (`anisotropic`,
//! `learned`) has the same shape and only glare and obstacles differ. A compass
//! search (± each axis at one shared step), the first polish, stalled on the ridge
//! |u| = |v| of the image error and spent its evaluations walking flat directions.
//! Today's figures: `bench/RESULTS.md`, "Numerical"; the runs that chose between
//! the polishes: `bench/history/2026-11.md`.

use super::{Evaluator, Search, SearchControl, SearchOutcome};
use crate::lupp::Lupp;
use dyfos_shared::answer::StopReason;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

const DIMS: usize = 4;
type Member = [f64; DIMS];

/// The local search that refines the evolution's best member (SPEC §8: "a final
/// local polish of the best feasible member"). It works in the unit cube, yaw
/// wrapping around and the other coordinates clamped to the box; it only accepts
/// strict improvements, so it never makes the answer worse.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Polish {
    /// None: SciPy's answer as it is.
    Off,
    /// Adaptive pattern search: first the image centre (ψ = 0, φ = 0, both), then
    /// moves along ± each axis and the two (ψ, φ) diagonals, each pair with its own
    /// step, doubled (up to 1/4) after a success and halved after both directions
    /// fail, until every step is below 1e-9.
    Adaptive {
        /// Most evaluations.
        evaluations: u64,
    },
    /// [`Polish::Adaptive`] from the best member, then again from its mirror image
    /// through the rover (ψ_v + π, the same ρ, ψ, φ: the sensor on the opposite
    /// side). The `anisotropic` and `learned` noise depend on the line of sight's
    /// axis, not its sense, so a pose and its mirror have the same noise shape and
    /// differ only in sun glare and obstacles: two basins the evolution may settle
    /// in the worse of.
    Mirrored {
        /// Most evaluations of each of the two polishes.
        evaluations: u64,
    },
}

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
    /// The local search from the best member after the evolution.
    pub polish: Polish,
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
            polish: Polish::Off,
        }
    }

    /// The `dyfos` default: SciPy's search, then the adaptive pattern-search polish
    /// from the best member and from its mirror image (at most 150 evaluations each).
    pub fn dyfos() -> Self {
        DifferentialEvolution { polish: Polish::Mirrored { evaluations: 150 }, ..Self::scipy() }
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
        if eval.stopped().is_none() && energies[0].is_finite() {
            match self.polish {
                Polish::Off => {}
                Polish::Adaptive { evaluations } => adaptive(&mut eval, lupp, pop[0], energies[0], evaluations),
                Polish::Mirrored { evaluations } => {
                    adaptive(&mut eval, lupp, pop[0], energies[0], evaluations);
                    let [rho, psi, phi, yaw] = pop[0];
                    let mirror = [rho, psi, phi, (yaw + 0.5).rem_euclid(1.0)];
                    if let Some(e) = eval.evaluate(&space.from_unit(&mirror)) {
                        adaptive(&mut eval, lupp, mirror, energy(Some(e)), evaluations);
                    }
                }
            }
        }
        eval.finish(stop)
    }
}

/// Moves `x` by `step` along `dir` in the unit cube: yaw wraps, the rest clamps.
fn moved(x: &Member, dir: &Member, step: f64) -> Member {
    let mut y = *x;
    for j in 0..DIMS {
        if dir[j] != 0.0 {
            y[j] += dir[j] * step;
            y[j] = if j == DIMS - 1 { y[j].rem_euclid(1.0) } else { y[j].clamp(0.0, 1.0) };
        }
    }
    y
}

/// Direction pairs of [`Polish::Adaptive`]: each axis, then the (ψ, φ) diagonals.
/// The diagonals matter because the noise grows with `e = max(|u|, |v|)`: where
/// |u| = |v|, moving ψ or φ alone cannot lower e, and an axis-only search stalls
/// short of the image centre (1e-4 rad off costs ≈0.004 in E).
const PAIRS: [Member; DIMS + 2] = [
    [1.0, 0.0, 0.0, 0.0],
    [0.0, 1.0, 0.0, 0.0],
    [0.0, 0.0, 1.0, 0.0],
    [0.0, 0.0, 0.0, 1.0],
    [0.0, 1.0, 1.0, 0.0],
    [0.0, 1.0, -1.0, 0.0],
];

/// [`Polish::Adaptive`] from `start` (energy `e0`).
fn adaptive(eval: &mut Evaluator, lupp: &Lupp, start: Member, e0: f64, max_evals: u64) {
    let space = *lupp.space();
    let (mut x, mut ex) = (start, e0);
    let limit = eval.stats.total.saturating_add(max_evals);
    // Returns Some(true) if y was better and taken, None once out of evaluations.
    let try_move = |eval: &mut Evaluator, x: &mut Member, ex: &mut f64, y: Member| -> Option<bool> {
        if y == *x {
            return Some(false);
        }
        if eval.stats.total >= limit {
            return None;
        }
        let ey = energy(Some(eval.evaluate(&space.from_unit(&y))?));
        if ey < *ex {
            (*x, *ex) = (y, ey);
            return Some(true);
        }
        Some(false)
    };
    // The image centre is where e = 0: a kink no finite step reaches exactly.
    for centre in [[x[0], 0.5, x[2], x[3]], [x[0], x[1], 0.5, x[3]], [x[0], 0.5, 0.5, x[3]]] {
        if try_move(eval, &mut x, &mut ex, centre).is_none() {
            return;
        }
    }
    let mut steps = [1.0 / 32.0; DIMS + 2];
    let mut signs = [1.0; DIMS + 2];
    loop {
        let mut active = false;
        for (p, axis) in PAIRS.iter().enumerate() {
            if steps[p] < 1e-9 {
                continue;
            }
            active = true;
            let mut success = false;
            for sign in [signs[p], -signs[p]] {
                let dir = axis.map(|a| a * sign);
                let y = moved(&x, &dir, steps[p]);
                match try_move(eval, &mut x, &mut ex, y) {
                    None => return,
                    Some(true) => {
                        signs[p] = sign;
                        success = true;
                        break;
                    }
                    Some(false) => {}
                }
            }
            steps[p] = if success { (2.0 * steps[p]).min(0.25) } else { 0.5 * steps[p] };
        }
        if !active {
            return;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use dyfos_shared::prelude::*;

    /// Map 21 of `dyfos-bench numerical --seed 2 --model anisotropic`: the evolution
    /// settles on the far side of the rover for some seeds (viewer yaw ≈ 1.72 rad
    /// against ≈ −1.89 at the optimum), 0.18 above `brute`'s −17.9735.
    fn mirror_basin() -> Scenario {
        Scenario::from_json(include_str!("../../../tests/data/anisotropic-mirror-basin.json")).unwrap()
    }

    #[test]
    fn the_mirror_polish_leaves_the_far_side_basin() {
        let s = mirror_basin();
        let model = NoiseModel::from_params(&s.params).unwrap();
        let lupp = Lupp::new(&s.world, &s.belief, &s.params, &model);
        // The grid optimum, `dyfos solve --algo brute` on this map.
        let brute = -17.973484018360878;
        let adaptive =
            DifferentialEvolution { polish: Polish::Adaptive { evaluations: 300 }, ..DifferentialEvolution::scipy() };
        let (mut near_adaptive, mut near_mirrored) = (0, 0);
        for seed in 0..12 {
            let control = SearchControl::seeded(seed);
            let a = adaptive.search(&lupp, &control);
            let m = DifferentialEvolution::dyfos().search(&lupp, &control);
            // The same number of evaluations: 300 of polish either way, plus the mirror.
            assert!(m.stats.total <= a.stats.total + 1, "seed {seed}: {} vs {}", m.stats.total, a.stats.total);
            near_adaptive += usize::from(a.best.unwrap().cost < brute + 0.01);
            near_mirrored += usize::from(m.best.unwrap().cost < brute + 0.01);
        }
        // Measured: 2 of 12 seeds reach the optimum with the adaptive polish alone, 8 with the mirror.
        assert!(near_mirrored >= near_adaptive + 4, "mirrored {near_mirrored} vs adaptive {near_adaptive} of 12 seeds");
        // Seed 1 is one that ends on the far side without the mirror.
        let control = SearchControl::seeded(1);
        let (a, m) = (
            adaptive.search(&lupp, &control).best.unwrap(),
            DifferentialEvolution::dyfos().search(&lupp, &control).best.unwrap(),
        );
        assert!(a.cost > brute + 0.1 && a.x.yaw > 0.0, "{a:?}");
        assert!(m.cost < brute + 0.01 && m.x.yaw < 0.0, "{m:?}");
    }
}
