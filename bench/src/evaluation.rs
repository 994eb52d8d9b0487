//! Runs search algorithms over a set of scenarios and tabulates cost and run time:
//! the paper's numerical evaluation (SPEC §10, paper §V-A and Fig. 4).
//!
//! ```
//! use dyfos_bench::evaluation::{Contender, evaluate};
//! use dyfos_bench::numerical::{NumericalConfig, numerical_maps};
//! use dyfos_shared::answer::Algorithm;
//!
//! let maps = numerical_maps(1, 2, &NumericalConfig::paper());
//! let contenders = [Contender::algorithm(Algorithm::Center, 1), Contender::algorithm(Algorithm::Random, 1)];
//! let run = evaluate(&maps, &contenders, 1, 1);
//! assert_eq!(run.queries.len(), 2);
//! assert!(run.queries[0].iter().all(|q| q.feasible()));
//! println!("{}", run.cost_table());
//! ```
//!
//! A query's time covers preparing the pipeline for the request
//! ([`Lupp::new`]) and the search, as the daemon would spend it; it is the median
//! over `repeats` identical runs (which must give identical answers). Each
//! answer is re-evaluated: a pose the constraints reject, or whose cost differs
//! from the one reported, counts as infeasible.

use crate::stats::Summary;
use cpu_time::ProcessTime;
use dyfos_service::lupp::Lupp;
use dyfos_service::search::{AnySearch, Search, SearchControl, SearchOutcome};
use dyfos_shared::answer::{Algorithm, EvalStats, StopReason};
use dyfos_shared::scenario::Scenario;
use dyfos_shared::sdsmm::NoiseModel;
use dyfos_shared::sensor::SensorState;
use std::fmt::Write;
use std::time::Instant;

/// A search configuration under test, with a name for tables.
#[derive(Debug, Clone, PartialEq)]
pub struct Contender {
    /// Column name, e.g. `dyfos`.
    pub name: String,
    /// The search and its settings.
    pub search: AnySearch,
    /// Worker threads (only `brute` uses more than one).
    pub threads: usize,
}

impl Contender {
    /// `algorithm` with its default settings; `threads` applies to `brute`, the
    /// others run on one thread.
    pub fn algorithm(algorithm: Algorithm, threads: usize) -> Self {
        let threads = if algorithm == Algorithm::Brute { threads.max(1) } else { 1 };
        Contender { name: algorithm.name().to_string(), search: AnySearch::from(algorithm), threads }
    }
}

/// One contender's answer on one map.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Query {
    /// The answer's candidate x, `None` for `no_feasible_pose`.
    pub x: Option<SensorState>,
    /// Cost E of the answer, `None` for `no_feasible_pose`.
    pub cost: Option<f64>,
    /// Whether the answer re-evaluates as feasible with the same cost.
    pub verified: bool,
    /// Whether every repeat gave the same answer, bit for bit.
    pub repeatable: bool,
    /// Median wall time of the repeats, s.
    pub seconds: f64,
    /// Median CPU time of the repeats, s, summed over the search's threads (`NaN`
    /// where the platform does not report it). On a shared, busy machine this is
    /// the steadier figure: wall time on idle cores ≈ CPU time / threads.
    pub cpu_seconds: f64,
    /// Candidates evaluated.
    pub evaluations: EvalStats,
    /// Why the search stopped.
    pub stop: StopReason,
}

impl Query {
    /// Feasible, verified answer.
    pub fn feasible(&self) -> bool {
        self.cost.is_some() && self.verified
    }
}

/// The results of [`evaluate`]: one row of queries per contender, one per map.
#[derive(Debug, Clone, PartialEq)]
pub struct Evaluation {
    /// Contender names, in the order of `queries`.
    pub names: Vec<String>,
    /// Threads each contender ran on.
    pub threads: Vec<usize>,
    /// `queries[c][m]`: contender c on map m.
    pub queries: Vec<Vec<Query>>,
}

/// The search seed used on map `index` of a run seeded `seed`.
pub fn query_seed(seed: u64, index: usize) -> u64 {
    seed.wrapping_mul(0x9E37_79B9_7F4A_7C15).wrapping_add(index as u64)
}

/// One search: outcome, wall time and CPU time (s).
fn run_once(
    search: &AnySearch,
    scenario: &Scenario,
    model: &NoiseModel,
    control: &SearchControl,
) -> (SearchOutcome, f64, f64) {
    // The process clock sums every thread, `brute`'s workers included (the
    // benchmark runs nothing else meanwhile).
    let cpu = ProcessTime::try_now().ok();
    let started = Instant::now();
    let lupp = Lupp::new(&scenario.world, &scenario.belief, &scenario.params, model);
    let outcome = search.search(&lupp, control);
    let wall = started.elapsed().as_secs_f64();
    let cpu_time = cpu.and_then(|c| c.try_elapsed().ok()).map_or(f64::NAN, |d| d.as_secs_f64());
    (outcome, wall, cpu_time)
}

fn bits(o: &SearchOutcome) -> Option<([u64; 4], u64)> {
    o.best.map(|b| (b.x.to_array().map(f64::to_bits), b.cost.to_bits()))
}

/// Runs every contender on every scenario, `repeats` times each (at least once),
/// with the model each scenario's parameters name (`paper` or `anisotropic`).
/// Maps are the outer loop, so slow drifts of the machine hit all contenders alike.
pub fn evaluate(scenarios: &[Scenario], contenders: &[Contender], seed: u64, repeats: usize) -> Evaluation {
    evaluate_with(
        scenarios,
        |s| NoiseModel::from_params(&s.params).expect("a built-in model; use `evaluate_with` for others"),
        contenders,
        seed,
        repeats,
    )
}

/// [`evaluate`] with the noise model of each scenario given by `model` (e.g. a
/// learned model loaded from a file).
pub fn evaluate_with(
    scenarios: &[Scenario],
    model: impl Fn(&Scenario) -> NoiseModel,
    contenders: &[Contender],
    seed: u64,
    repeats: usize,
) -> Evaluation {
    let mut queries: Vec<Vec<Query>> = vec![Vec::with_capacity(scenarios.len()); contenders.len()];
    for (m, scenario) in scenarios.iter().enumerate() {
        let model = model(scenario);
        for (c, contender) in contenders.iter().enumerate() {
            let control = SearchControl { threads: contender.threads, ..SearchControl::seeded(query_seed(seed, m)) };
            let mut times = Vec::with_capacity(repeats.max(1));
            let mut cpu_times = Vec::with_capacity(repeats.max(1));
            let (first, t, cpu) = run_once(&contender.search, scenario, &model, &control);
            times.push(t);
            cpu_times.push(cpu);
            let mut repeatable = true;
            for _ in 1..repeats.max(1) {
                let (again, t, cpu) = run_once(&contender.search, scenario, &model, &control);
                repeatable &= bits(&again) == bits(&first) && again.stats == first.stats;
                times.push(t);
                cpu_times.push(cpu);
            }
            let verified = first.best.is_some_and(|b| {
                let lupp = Lupp::new(&scenario.world, &scenario.belief, &scenario.params, &model);
                lupp.evaluate(&b.x).cost().map(f64::to_bits) == Some(b.cost.to_bits())
            });
            queries[c].push(Query {
                x: first.best.map(|b| b.x),
                cost: first.best.map(|b| b.cost),
                verified,
                repeatable,
                seconds: Summary::of(&times).expect("at least one run").median,
                cpu_seconds: if cpu_times.iter().all(|c| c.is_finite()) {
                    Summary::of(&cpu_times).expect("at least one run").median
                } else {
                    f64::NAN
                },
                evaluations: first.stats,
                stop: first.stop,
            });
        }
    }
    Evaluation {
        names: contenders.iter().map(|c| c.name.clone()).collect(),
        threads: contenders.iter().map(|c| c.threads).collect(),
        queries,
    }
}

/// Run-time statistics over one contender's queries: wall time, CPU time, CPU time
/// per evaluation and evaluations (CPU figures only where the clock was readable).
pub struct Timing {
    /// Wall time, s.
    pub seconds: Option<Summary>,
    /// CPU time, s.
    pub cpu_seconds: Option<Summary>,
    /// CPU time per evaluation, µs.
    pub micros_per_evaluation: Option<Summary>,
    /// Candidates evaluated.
    pub evaluations: Option<Summary>,
}

impl Timing {
    /// The statistics of `queries`.
    pub fn of(queries: &[Query]) -> Self {
        let secs: Vec<f64> = queries.iter().map(|q| q.seconds).collect();
        let cpu: Vec<f64> = queries.iter().map(|q| q.cpu_seconds).filter(|c| c.is_finite()).collect();
        let per: Vec<f64> = queries
            .iter()
            .filter(|q| q.evaluations.total > 0 && q.cpu_seconds.is_finite())
            .map(|q| q.cpu_seconds * 1e6 / q.evaluations.total as f64)
            .collect();
        let evals: Vec<f64> = queries.iter().map(|q| q.evaluations.total as f64).collect();
        Timing {
            seconds: Summary::of(&secs),
            cpu_seconds: Summary::of(&cpu),
            micros_per_evaluation: Summary::of(&per),
            evaluations: Summary::of(&evals),
        }
    }
}

impl Evaluation {
    /// Index of the contender named `name`.
    pub fn index(&self, name: &str) -> Option<usize> {
        self.names.iter().position(|n| n == name)
    }

    /// Costs of the feasible answers of contender `c`.
    pub fn costs(&self, c: usize) -> Vec<f64> {
        self.queries[c].iter().filter(|q| q.feasible()).filter_map(|q| q.cost).collect()
    }

    /// Per map, `cost(a) − cost(b)` (`None` where either found nothing).
    pub fn gaps(&self, a: usize, b: usize) -> Vec<Option<f64>> {
        self.queries[a]
            .iter()
            .zip(&self.queries[b])
            .map(|(qa, qb)| Some(qa.cost.filter(|_| qa.feasible())? - qb.cost.filter(|_| qb.feasible())?))
            .collect()
    }

    /// The index of the median map by contender `c`'s cost (the lower middle one for
    /// an even count), among maps where it found a pose.
    pub fn median_map(&self, c: usize) -> Option<usize> {
        let mut order: Vec<(f64, usize)> =
            self.queries[c].iter().enumerate().filter_map(|(m, q)| q.cost.map(|e| (e, m))).collect();
        order.sort_by(|a, b| a.0.total_cmp(&b.0));
        order.get(order.len().saturating_sub(1) / 2).map(|(_, m)| *m)
    }

    /// Markdown table of E per contender: median, mean, min, max, and failures.
    pub fn cost_table(&self) -> String {
        let mut out = String::from(
            "| algorithm | E median | E mean | E min | E max | no pose | infeasible | not repeatable |\n|---|---:|---:|---:|---:|---:|---:|---:|\n",
        );
        for (c, name) in self.names.iter().enumerate() {
            let q = &self.queries[c];
            let none = q.iter().filter(|q| q.cost.is_none()).count();
            let bad = q.iter().filter(|q| q.cost.is_some() && !q.verified).count();
            let unrepeatable = q.iter().filter(|q| !q.repeatable).count();
            match Summary::of(&self.costs(c)) {
                Some(s) => {
                    let _ = writeln!(
                        out,
                        "| {name} | {:.4} | {:.4} | {:.4} | {:.4} | {none} | {bad} | {unrepeatable} |",
                        s.median, s.mean, s.min, s.max
                    );
                }
                None => {
                    let _ = writeln!(out, "| {name} | – | – | – | – | {none} | {bad} | {unrepeatable} |");
                }
            }
        }
        out
    }

    /// Markdown table of run time per contender (median ± std, max) and evaluations.
    pub fn time_table(&self) -> String {
        let mut out = String::from(
            "| algorithm | threads | time median | ± std | max | CPU time median | evaluations median | CPU-µs per evaluation (median) |\n|---|---:|---:|---:|---:|---:|---:|---:|\n",
        );
        for (c, name) in self.names.iter().enumerate() {
            let timing = Timing::of(&self.queries[c]);
            let (Some(t), Some(e)) = (timing.seconds, timing.evaluations) else { continue };
            let per = timing.micros_per_evaluation.map_or("–".to_string(), |p| format!("{:.3}", p.median));
            let cpu = timing.cpu_seconds.map_or("–".to_string(), |c| duration(c.median));
            let _ = writeln!(
                out,
                "| {name} | {} | {} | {} | {} | {cpu} | {:.0} | {per} |",
                self.threads[c],
                duration(t.median),
                duration(t.std),
                duration(t.max),
                e.median
            );
        }
        out
    }

    /// Markdown table of `a − b` per map, with the median map of `b` marked.
    pub fn gap_table(&self, a: usize, b: usize) -> String {
        let (na, nb) = (&self.names[a], &self.names[b]);
        let median = self.median_map(b);
        let mut out = format!("| map | E {nb} | E {na} | {na} − {nb} |\n|---:|---:|---:|---:|\n");
        for (m, gap) in self.gaps(a, b).iter().enumerate() {
            let mark = if Some(m) == median { " (median)" } else { "" };
            let cost = |q: &Query| q.cost.map_or("–".into(), |e| format!("{e:.5}"));
            let _ = writeln!(
                out,
                "| {m}{mark} | {} | {} | {} |",
                cost(&self.queries[b][m]),
                cost(&self.queries[a][m]),
                gap.map_or("–".into(), |g| format!("{g:+.5}"))
            );
        }
        out
    }
}

/// A duration in s, ms or µs, whichever reads best.
pub fn duration(seconds: f64) -> String {
    if seconds >= 1.0 {
        format!("{seconds:.2} s")
    } else if seconds >= 1e-3 {
        format!("{:.2} ms", seconds * 1e3)
    } else {
        format!("{:.0} µs", seconds * 1e6)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::numerical::{NumericalConfig, numerical_maps};

    #[test]
    fn gaps_and_median_map() {
        let q = |cost: f64| Query {
            x: None,
            cost: Some(cost),
            verified: true,
            repeatable: true,
            seconds: 1e-3,
            cpu_seconds: 1e-3,
            evaluations: EvalStats::default(),
            stop: StopReason::Finished,
        };
        let run = Evaluation {
            names: vec!["a".into(), "b".into()],
            threads: vec![1, 2],
            queries: vec![vec![q(-1.0), q(-3.0), q(-2.0)], vec![q(-1.5), q(-3.0), q(-2.5)]],
        };
        assert_eq!(run.gaps(0, 1), vec![Some(0.5), Some(0.0), Some(0.5)]);
        assert_eq!(run.median_map(1), Some(2));
        assert!(run.gap_table(0, 1).contains("| 2 (median) | -2.50000 | -2.00000 | +0.50000 |"));
    }

    #[test]
    fn every_contender_answers_feasibly_and_repeatably() {
        let maps = numerical_maps(9, 2, &NumericalConfig::paper());
        let contenders = [Contender::algorithm(Algorithm::Random, 1), Contender::algorithm(Algorithm::Center, 1)];
        let run = evaluate(&maps, &contenders, 9, 2);
        for q in run.queries.iter().flatten() {
            assert!(q.feasible() && q.repeatable, "{q:?}");
        }
        assert!(run.cost_table().lines().count() == 4 && run.time_table().contains("| random | 1 |"));
    }
}
