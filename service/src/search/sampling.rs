//! `random` and `center` (SPEC §8): uniform samples until the first feasible one.

use super::{Evaluator, Search, SearchControl, SearchOutcome};
use crate::lupp::Lupp;
use dyfos_shared::answer::StopReason;
use dyfos_shared::limits::MAX_SAMPLING_TRIES;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Uniform samples over the whole search space.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct RandomSampling;

/// ψ = φ = 0 (the rover in the image centre, PAMPC's heuristic), uniform ρ and yaw.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct CenterView;

fn first_feasible(
    lupp: &Lupp,
    control: &SearchControl,
    mut draw: impl FnMut(&mut ChaCha8Rng) -> [f64; 4],
) -> SearchOutcome {
    let mut rng = ChaCha8Rng::seed_from_u64(control.seed);
    let mut eval = Evaluator::new(lupp, control);
    for _ in 0..MAX_SAMPLING_TRIES {
        let x = lupp.space().from_unit(&draw(&mut rng));
        match eval.evaluate(&x) {
            None => break,
            Some(e) if e.cost().is_some() => break,
            Some(_) => {}
        }
    }
    eval.finish(StopReason::Finished)
}

impl Search for RandomSampling {
    fn search(&self, lupp: &Lupp, control: &SearchControl) -> SearchOutcome {
        first_feasible(lupp, control, |rng| std::array::from_fn(|_| rng.random::<f64>()))
    }
}

impl Search for CenterView {
    fn search(&self, lupp: &Lupp, control: &SearchControl) -> SearchOutcome {
        first_feasible(lupp, control, |rng| {
            let (rho, yaw) = (rng.random::<f64>(), rng.random::<f64>());
            [rho, 0.5, 0.5, yaw]
        })
    }
}
