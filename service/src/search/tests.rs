//! One suite for every algorithm: never infeasible, same seed ⇒ same bits, counts
//! add up, and thread counts do not change `brute`.

use super::*;
use dyfos_shared::prelude::*;
use std::sync::atomic::{AtomicBool, Ordering};

pub(super) fn example() -> Scenario {
    Scenario::from_json(include_str!("../../../tests/data/example.json")).unwrap()
}

/// Runs `f` on the LUPP of `s` with its own noise model.
pub(super) fn with_lupp<T>(s: &Scenario, f: impl FnOnce(&Lupp) -> T) -> T {
    let model = NoiseModel::from_params(&s.params).unwrap();
    f(&Lupp::new(&s.world, &s.belief, &s.params, &model))
}

/// [`with_lupp`] on `tests/data/example.json`.
fn on_example<T>(f: impl FnOnce(&Lupp) -> T) -> T {
    with_lupp(&example(), f)
}

fn algorithms() -> Vec<AnySearch> {
    let mut all: Vec<AnySearch> = Algorithm::ALL.into_iter().map(AnySearch::from).collect();
    // A coarse grid keeps the debug-build suite fast; the default grid is checked
    // against the golden vectors in tests/golden.rs.
    all[2] = AnySearch::Brute(Brute { grid: [6, 5, 5, 24] });
    all
}

#[test]
fn every_algorithm_returns_a_feasible_pose_deterministically() {
    on_example(|lupp| {
        for algo in algorithms() {
            for seed in [0, 1, 42] {
                let control = SearchControl::seeded(seed);
                let out = algo.search(lupp, &control);
                let best = out.best.unwrap_or_else(|| panic!("{algo:?} found nothing"));
                assert_eq!(lupp.evaluate(&best.x).cost(), Some(best.cost), "{algo:?} returned an infeasible pose");
                let again = algo.search(lupp, &control);
                assert_eq!(
                    again.best.map(|b| (b.x.to_array().map(f64::to_bits), b.cost.to_bits())),
                    out.best.map(|b| (b.x.to_array().map(f64::to_bits), b.cost.to_bits()))
                );
                assert_eq!(again.stats, out.stats);
                let st = out.stats;
                assert!(st.workspace + st.collision + st.occlusion < st.total);
            }
        }
    });
}

#[test]
fn brute_is_the_same_on_any_thread_count() {
    on_example(|lupp| {
        let brute = Brute { grid: [7, 5, 5, 36] };
        let one = brute.search(lupp, &SearchControl { threads: 1, ..SearchControl::seeded(0) });
        for threads in [2, 3, 8] {
            let many = brute.search(lupp, &SearchControl { threads, ..SearchControl::seeded(0) });
            assert_eq!(many, one, "{threads} threads");
        }
        assert_eq!(one.stats.total, brute.len() as u64);
    });
}

#[test]
fn budget_caps_evaluations_and_keeps_answers_feasible() {
    on_example(|lupp| {
        for algo in algorithms() {
            let out = algo.search(lupp, &SearchControl { budget: Some(100), ..SearchControl::seeded(3) });
            assert!(out.stats.total <= 100, "{algo:?}: {}", out.stats.total);
            if let Some(best) = out.best {
                assert_eq!(lupp.evaluate(&best.x).cost(), Some(best.cost));
            }
        }
        let out = DifferentialEvolution::dyfos()
            .search(lupp, &SearchControl { budget: Some(100), ..SearchControl::seeded(3) });
        assert_eq!(out.stop, StopReason::Budget);
    });
}

#[test]
fn a_past_deadline_stops_at_once() {
    on_example(|lupp| {
        let past = std::time::Instant::now();
        for algo in algorithms() {
            let out = algo.search(lupp, &SearchControl { deadline: Some(past), ..SearchControl::seeded(3) });
            assert_eq!(out.stop, StopReason::Deadline, "{algo:?}");
            assert!(out.best.is_none());
        }
    });
}

#[test]
fn no_feasible_pose_when_the_rover_is_buried() {
    let mut s = example();
    // A box over the whole map from the ground up to 9 m: nothing can see or fly.
    s.world = s
        .world
        .apply(&[MapDelta::UpsertObstacle {
            id: 99,
            obstacle: Obstacle::Box(dyfos_shared::world::AxisBox {
                min: Point3::new(-10.0, -10.0, 0.0),
                max: Point3::new(10.0, 10.0, 9.0),
            }),
        }])
        .unwrap();
    with_lupp(&s, |lupp| {
        for algo in algorithms() {
            let out = algo.search(lupp, &SearchControl { budget: Some(20_000), ..SearchControl::seeded(0) });
            assert!(out.best.is_none(), "{algo:?}");
            assert_eq!(out.stats.feasible(), 0);
        }
    });
}

#[test]
fn paper_optimum_ignores_the_prior_anisotropic_does_not() {
    // SPEC §6: the isotropic model's cost is monotone in σ*, so the best candidate
    // is the same for any prior; the anisotropic one trades directions.
    let s = example();
    let priors = [
        [[0.2, 0.05, 0.0], [0.05, 0.1, 0.0], [0.0, 0.0, 0.05]],
        [[2.0, 0.0, 0.0], [0.0, 0.02, 0.0], [0.0, 0.0, 0.05]],
        [[0.02, 0.0, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, 0.05]],
    ];
    let brute = Brute { grid: [5, 5, 5, 36] };
    let best_for = |model: ModelKind, prior: [[f64; 3]; 3]| {
        let params = Params { model, ..s.params };
        let belief = Belief::new(s.belief.mean.into(), prior).unwrap();
        let m = NoiseModel::from_params(&params).unwrap();
        let lupp = Lupp::new(&s.world, &belief, &params, &m);
        brute.search(&lupp, &SearchControl::seeded(0)).best.unwrap().x
    };
    let paper: Vec<_> = priors.iter().map(|p| best_for(ModelKind::Paper, *p)).collect();
    assert!(paper.windows(2).all(|w| w[0] == w[1]), "{paper:?}");
    let aniso: Vec<_> = priors.iter().map(|p| best_for(ModelKind::Anisotropic, *p)).collect();
    assert!(aniso[1].yaw != aniso[2].yaw || aniso[1].psi != aniso[2].psi, "{aniso:?}");
}

#[test]
fn adaptive_polish_reaches_the_image_centre_and_improves_on_scipy() {
    // With the `paper` model the noise grows with e = max(|u|, |v|), so the optimum
    // on the example is in the image centre: a kink that only the polish's centre
    // move reaches exactly. SciPy's search alone stops short of it.
    on_example(|lupp| {
        for seed in [0, 1, 2] {
            let control = SearchControl::seeded(seed);
            let best = |de: DifferentialEvolution| de.search(lupp, &control).best.unwrap();
            let (dyfos, scipy) = (best(DifferentialEvolution::dyfos()), best(DifferentialEvolution::scipy()));
            assert_eq!((dyfos.x.psi, dyfos.x.phi), (0.0, 0.0), "seed {seed}: {dyfos:?}");
            assert!(dyfos.cost < scipy.cost - 0.01, "seed {seed}: {} vs SciPy's {}", dyfos.cost, scipy.cost);
        }
    });
}

#[test]
fn a_raised_abandon_flag_stops_every_algorithm_at_once() {
    on_example(|lupp| {
        let raised = AtomicBool::new(true);
        for algo in algorithms() {
            for threads in [1, 3] {
                let control = SearchControl { abandon: Some(&raised), threads, ..SearchControl::seeded(3) };
                let out = algo.search(lupp, &control);
                assert_eq!(out.stop, StopReason::Abandoned, "{algo:?}, {threads} threads");
                assert_eq!(out.stats.total, 0, "{algo:?}, {threads} threads");
                assert!(out.best.is_none());
            }
        }
        // Abandonment wins over a deadline that passed too.
        let past = std::time::Instant::now();
        let control = SearchControl { abandon: Some(&raised), deadline: Some(past), ..SearchControl::seeded(3) };
        assert_eq!(DifferentialEvolution::dyfos().search(lupp, &control).stop, StopReason::Abandoned);
    });
}

#[test]
fn the_abandon_flag_is_read_with_the_clock() {
    on_example(|lupp| {
        let flag = AtomicBool::new(false);
        let control = SearchControl { abandon: Some(&flag), ..SearchControl::seeded(0) };
        let mut eval = Evaluator::new(lupp, &control);
        let x = SensorState::new(8.0, 0.0, 0.0, 0.0);
        for _ in 0..100 {
            assert!(eval.evaluate(&x).is_some());
        }
        // Raised mid-search (by another thread, in the daemon): the evaluations up to
        // the next look still run, none after it.
        flag.store(true, Ordering::Relaxed);
        let mut more = 0;
        while eval.evaluate(&x).is_some() {
            more += 1;
        }
        assert_eq!(100 + more, 2 * Evaluator::CLOCK_EVERY);
        assert_eq!(eval.stopped(), Some(StopReason::Abandoned));
        assert!(eval.evaluate(&x).is_none(), "an abandoned evaluator stays stopped");
        let out = eval.finish(StopReason::Finished);
        assert_eq!((out.stop, out.stats.total), (StopReason::Abandoned, 2 * Evaluator::CLOCK_EVERY));
    });
}

#[test]
fn an_abandon_flag_never_raised_changes_nothing() {
    on_example(|lupp| {
        let lowered = AtomicBool::new(false);
        for algo in algorithms() {
            for threads in [1, 2, 3] {
                for seed in [0, 5] {
                    let plain = SearchControl { threads, ..SearchControl::seeded(seed) };
                    let watched = SearchControl { abandon: Some(&lowered), ..plain };
                    let (a, b) = (algo.search(lupp, &plain), algo.search(lupp, &watched));
                    let bits = |o: &SearchOutcome| o.best.map(|b| (b.x.to_array().map(f64::to_bits), b.cost.to_bits()));
                    assert_eq!((bits(&a), a.stats, a.stop), (bits(&b), b.stats, b.stop), "{algo:?}, {threads} threads");
                }
            }
        }
    });
}

/// A checkpoint that holds the search a while, at every look: called at every
/// look, by every thread, and the answer is the same bit for bit.
#[derive(Debug, Default)]
struct SlowCheckpoint {
    calls: std::sync::atomic::AtomicU64,
}

impl super::Checkpoint for SlowCheckpoint {
    fn checkpoint(&self) {
        self.calls.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        std::thread::sleep(std::time::Duration::from_micros(20));
    }
}

#[test]
fn a_search_held_at_its_checkpoints_gives_the_same_answer() {
    on_example(|lupp| {
        for algo in algorithms() {
            for threads in [1, 3] {
                let held = SlowCheckpoint::default();
                let plain = SearchControl { threads, budget: Some(3000), ..SearchControl::seeded(4) };
                let watched = SearchControl { checkpoint: Some(&held), ..plain };
                let (a, b) = (algo.search(lupp, &plain), algo.search(lupp, &watched));
                let bits = |o: &SearchOutcome| o.best.map(|b| (b.x.to_array().map(f64::to_bits), b.cost.to_bits()));
                assert_eq!((bits(&a), a.stats, a.stop), (bits(&b), b.stats, b.stop), "{algo:?}, {threads} threads");
                // One look every CLOCK_EVERY evaluations of each thread, from the first.
                let calls = held.calls.load(std::sync::atomic::Ordering::Relaxed);
                assert!(
                    calls >= b.stats.total / Evaluator::CLOCK_EVERY,
                    "{algo:?}: {calls} looks for {} evaluations",
                    b.stats.total
                );
            }
        }
    });
}
