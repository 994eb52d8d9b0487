//! The search algorithms of SPEC §8.
//!
//! A [`Search`] proposes candidates, the [`Lupp`] scores each one, and an
//! [`Evaluator`] counts them against the request's budget and deadline — the split
//! ripgrep makes between its searcher, matcher and sink. A new algorithm only adds
//! a file here. Whoever asked can abandon a search midway through
//! [`SearchControl::abandon`] (the daemon does when the client goes away).
//!
//! ```
//! use dyfos_service::lupp::Lupp;
//! use dyfos_service::search::{DifferentialEvolution, Search, SearchControl};
//! use dyfos_shared::prelude::*;
//!
//! let scenario = Scenario::from_json(include_str!("../../../tests/data/example.json")).unwrap();
//! let model = NoiseModel::from_params(&scenario.params).unwrap();
//! let lupp = Lupp::new(&scenario.world, &scenario.belief, &scenario.params, &model);
//! let outcome = DifferentialEvolution::dyfos().search(&lupp, &SearchControl::seeded(7));
//! let best = outcome.best.expect("a feasible pose");
//! assert_eq!(outcome, DifferentialEvolution::dyfos().search(&lupp, &SearchControl::seeded(7)));
//! assert!(best.cost < -10.0);
//! ```

mod brute;
mod de;
mod margin;
mod sampling;
mod stall;

pub use brute::Brute;
pub use de::{DifferentialEvolution, Polish};
pub use margin::{TieBreak, margin};
pub use sampling::{CenterView, RandomSampling};
pub use stall::Stall;

use crate::lupp::{Evaluation, Lupp};
use dyfos_shared::answer::{Algorithm, EvalStats, StopReason};
use dyfos_shared::sensor::SensorState;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

/// How far a search may go, and its random stream.
#[derive(Debug, Clone, Copy)]
pub struct SearchControl<'c> {
    /// Seed of the ChaCha stream: the same seed gives the same answer, bit for bit.
    pub seed: u64,
    /// Most candidates to evaluate; `None` for the algorithm's own limits.
    pub budget: Option<u64>,
    /// Stop with the best so far when this instant passes.
    pub deadline: Option<Instant>,
    /// Worker threads for parallel algorithms (`brute`); the answer does not depend on it.
    pub threads: usize,
    /// Raised (by another thread) when nobody wants the answer any more: the search
    /// then stops as soon as it looks, with [`StopReason::Abandoned`]. Every search
    /// thread looks with the deadline, every [`Evaluator::CLOCK_EVERY`] evaluations.
    /// A flag never raised changes nothing, bit for bit.
    pub abandon: Option<&'c AtomicBool>,
    /// Called at the same looks as `abandon`, by every search thread: the caller
    /// may hold the search there (the daemon does, to hand its core to another
    /// client's query). Holding it changes nothing but the time, bit for bit.
    pub checkpoint: Option<&'c dyn Checkpoint>,
}

/// Where a running search can be held: [`Checkpoint::checkpoint`] is called every
/// [`Evaluator::CLOCK_EVERY`] evaluations and returns when the search may go on.
pub trait Checkpoint: Sync + std::fmt::Debug {
    /// Returns at once, or when the search may go on.
    fn checkpoint(&self);
}

impl SearchControl<'static> {
    /// Seed `seed`, no budget, no deadline, all cores, nobody to abandon it.
    pub fn seeded(seed: u64) -> Self {
        let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
        SearchControl { seed, budget: None, deadline: None, threads, abandon: None, checkpoint: None }
    }
}

/// The best feasible candidate of a search.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Found {
    /// The candidate.
    pub x: SensorState,
    /// Its cost E.
    pub cost: f64,
}

/// What a search returns: its best feasible candidate, if any, and its counts.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SearchOutcome {
    /// The best feasible candidate, `None` if none was found.
    pub best: Option<Found>,
    /// Candidates evaluated, by rejection.
    pub stats: EvalStats,
    /// Why it stopped.
    pub stop: StopReason,
}

/// A search algorithm: proposes candidates to a [`Lupp`] and keeps the best.
pub trait Search {
    /// Runs the search. Must never return an infeasible `best`.
    fn search(&self, lupp: &Lupp, control: &SearchControl) -> SearchOutcome;
}

/// The algorithm a request chose, dispatched statically.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum AnySearch {
    /// `dyfos` or `dyfos-scipy`.
    DifferentialEvolution(DifferentialEvolution),
    /// `brute`.
    Brute(Brute),
    /// `random`.
    Random(RandomSampling),
    /// `center`.
    Center(CenterView),
}

impl From<Algorithm> for AnySearch {
    /// The algorithm with its default settings.
    fn from(a: Algorithm) -> Self {
        match a {
            Algorithm::Dyfos => AnySearch::DifferentialEvolution(DifferentialEvolution::dyfos()),
            Algorithm::DyfosScipy => AnySearch::DifferentialEvolution(DifferentialEvolution::scipy()),
            Algorithm::Brute => AnySearch::Brute(Brute::default()),
            Algorithm::Random => AnySearch::Random(RandomSampling),
            Algorithm::Center => AnySearch::Center(CenterView),
        }
    }
}

impl Search for AnySearch {
    fn search(&self, lupp: &Lupp, control: &SearchControl) -> SearchOutcome {
        match self {
            AnySearch::DifferentialEvolution(s) => s.search(lupp, control),
            AnySearch::Brute(s) => s.search(lupp, control),
            AnySearch::Random(s) => s.search(lupp, control),
            AnySearch::Center(s) => s.search(lupp, control),
        }
    }
}

/// Evaluates candidates for one search thread, counting them and enforcing the
/// budget, deadline and abandonment. The deadline and the abandon flag are read
/// every [`Evaluator::CLOCK_EVERY`] evaluations, so checking them costs nothing
/// measurable.
pub struct Evaluator<'l, 'a> {
    lupp: &'l Lupp<'a>,
    /// Counts so far.
    pub stats: EvalStats,
    budget: u64,
    deadline: Option<Instant>,
    abandon: Option<&'l AtomicBool>,
    checkpoint: Option<&'l dyn Checkpoint>,
    stopped: Option<StopReason>,
    best: Option<Found>,
}

impl<'l, 'a> Evaluator<'l, 'a> {
    /// Evaluations between deadline (and abandon flag) checks.
    pub const CLOCK_EVERY: u64 = 64;

    /// A fresh evaluator under `control`'s budget, deadline and abandon flag.
    pub fn new(lupp: &'l Lupp<'a>, control: &SearchControl<'l>) -> Self {
        Evaluator {
            lupp,
            stats: EvalStats::default(),
            budget: control.budget.unwrap_or(u64::MAX),
            deadline: control.deadline,
            abandon: control.abandon,
            checkpoint: control.checkpoint,
            stopped: None,
            best: None,
        }
    }

    /// Evaluates `x`, or returns `None` once the budget or deadline is spent or
    /// the search is abandoned. Keeps the best feasible candidate seen (first of
    /// equal costs).
    #[inline]
    pub fn evaluate(&mut self, x: &SensorState) -> Option<Evaluation> {
        self.evaluate_with(x, |lupp| lupp.evaluate(x))
    }

    /// As [`Evaluator::evaluate`], with the verdict on `x` given by `verdict`: for a
    /// search that knows more about `x` than the pipeline does (its pose, computed
    /// from parts; checks settled for many candidates at once). `verdict` must give
    /// exactly what [`Lupp::evaluate`] gives for `x`.
    #[inline]
    pub fn evaluate_with(&mut self, x: &SensorState, verdict: impl FnOnce(&Lupp) -> Evaluation) -> Option<Evaluation> {
        if self.stopped.is_some() {
            return None;
        }
        if self.stats.total >= self.budget {
            self.stopped = Some(StopReason::Budget);
            return None;
        }
        if self.stats.total.is_multiple_of(Self::CLOCK_EVERY) {
            if let Some(c) = self.checkpoint {
                c.checkpoint();
            }
            // Relaxed: the flag orders nothing else; a raise is seen at a later look.
            if self.abandon.is_some_and(|a| a.load(Ordering::Relaxed)) {
                self.stopped = Some(StopReason::Abandoned);
                return None;
            }
            if self.deadline.is_some_and(|d| Instant::now() >= d) {
                self.stopped = Some(StopReason::Deadline);
                return None;
            }
        }
        let e = verdict(self.lupp);
        e.count(&mut self.stats);
        // A NaN cost (no valid model should give one) must not become a best that
        // nothing can beat.
        if let Some(cost) = e.cost()
            && !cost.is_nan()
            && self.best.is_none_or(|b| cost < b.cost)
        {
            self.best = Some(Found { x: *x, cost });
        }
        Some(e)
    }

    /// The lowest-cost feasible candidate evaluated so far (the first of equal costs).
    pub fn best(&self) -> Option<Found> {
        self.best
    }

    /// Why evaluation stopped early, if it did.
    pub fn stopped(&self) -> Option<StopReason> {
        self.stopped
    }

    /// The outcome, with `stop` unless the budget, deadline or abandonment cut it short.
    pub fn finish(self, stop: StopReason) -> SearchOutcome {
        SearchOutcome { best: self.best, stats: self.stats, stop: self.stopped.unwrap_or(stop) }
    }
}

#[cfg(test)]
mod tests;
