//! A stopping rule for differential evolution: stop once the best energy has
//! stalled.
//!
//! SciPy's rule (`std(E) ≤ atol + tol·|mean E|`) waits until the whole population
//! has gathered, and with `tol` relative to |mean E| ≈ 15 it is both late (most of
//! a query's evaluations go to members far from the best) and loose (it stops
//! ≈ 0.04 above the grid optimum). When a local polish follows, the evolution only
//! has to find the right basin; once its best has not moved by more than an
//! absolute ε for a few generations, more generations rarely change the basin and
//! the polish does the rest at a fraction of the cost.

/// Stop when the best energy has improved by at most `epsilon` (absolute) over the
/// last `generations` generations. Only a feasible best counts: while every member
/// is infeasible the evolution goes on (until its other limits).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Stall {
    /// Smallest drop of the best energy that counts as progress.
    pub epsilon: f64,
    /// Generations without progress after which the evolution stops (≥ 1).
    pub generations: u32,
}

/// Follows one evolution's best energy, generation by generation, for a [`Stall`].
#[derive(Debug, Clone, Copy)]
pub struct StallWatch {
    rule: Stall,
    /// The best energy when progress was last counted.
    reference: f64,
    /// Generations since then.
    since: u32,
}

impl StallWatch {
    /// A watch whose reference is the starting population's best energy.
    pub fn new(rule: Stall, best: f64) -> Self {
        StallWatch { rule, reference: best, since: 0 }
    }

    /// Records the best energy at the end of a generation; true when the evolution
    /// should stop.
    pub fn stalled(&mut self, best: f64) -> bool {
        if !best.is_finite() {
            return false;
        }
        // Small drops add up: progress is measured from the last counted one, so a
        // slow steady descent is not mistaken for a stall.
        if !self.reference.is_finite() || self.reference - best > self.rule.epsilon {
            self.reference = best;
            self.since = 0;
            return false;
        }
        self.since += 1;
        self.since >= self.rule.generations
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const RULE: Stall = Stall { epsilon: 1e-3, generations: 3 };

    #[test]
    fn stops_after_the_given_generations_without_progress_and_not_before() {
        let mut w = StallWatch::new(RULE, -10.0);
        assert!(!w.stalled(-10.0));
        assert!(!w.stalled(-10.0005));
        assert!(w.stalled(-10.0009));
    }

    #[test]
    fn progress_restarts_the_count() {
        let mut w = StallWatch::new(RULE, -10.0);
        assert!(!w.stalled(-10.0));
        assert!(!w.stalled(-10.0));
        assert!(!w.stalled(-10.01));
        assert!(!w.stalled(-10.01));
        assert!(!w.stalled(-10.01));
        assert!(w.stalled(-10.01));
    }

    #[test]
    fn small_drops_that_add_up_count_as_progress() {
        let mut w = StallWatch::new(RULE, -10.0);
        // 0.0006 a generation: below ε each, 0.0012 over two from the reference.
        for g in 1..=20 {
            assert!(!w.stalled(-10.0 - 0.0006 * f64::from(g)), "generation {g}");
        }
    }

    #[test]
    fn an_infeasible_best_never_stalls() {
        let mut w = StallWatch::new(RULE, f64::INFINITY);
        for _ in 0..10 {
            assert!(!w.stalled(f64::INFINITY));
        }
        // The first feasible best is progress, then the count starts.
        assert!(!w.stalled(-5.0));
        assert!(!w.stalled(-5.0));
        assert!(!w.stalled(-5.0));
        assert!(w.stalled(-5.0));
    }
}
