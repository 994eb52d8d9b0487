//! # dyfos-service
//!
//! The optimizer side of DyFOS: the localization uncertainty prediction pipeline
//! ([`lupp`]), the search algorithms ([`search`]), and the daemon `dyfosd`.
//!
//! ```
//! use dyfos_service::{solve, search::SearchControl};
//! use dyfos_shared::prelude::*;
//!
//! let scenario = Scenario::from_json(include_str!("../../tests/data/example.json")).unwrap();
//! let model = NoiseModel::from_params(&scenario.params).unwrap();
//! let answer = solve(&scenario.world, &scenario.belief, &scenario.params, &model,
//!                    Algorithm::Dyfos, &SearchControl::seeded(1)).unwrap();
//! println!("fly the viewer to {} (E = {:.3})", answer.viewer_position, answer.cost);
//! ```

pub mod daemon;
pub mod launch;
pub mod learned;
pub mod lupp;
pub mod search;
pub mod store;

use dyfos_shared::answer::{Algorithm, Answer, EvalStats, StopReason};
use dyfos_shared::params::Params;
use dyfos_shared::posterior::Belief;
use dyfos_shared::sdsmm::NoiseModel;
use dyfos_shared::world::World;
use lupp::Lupp;
use search::{AnySearch, Search, SearchControl};
use std::time::Instant;

/// Why a search has no answer.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum SearchError {
    /// No candidate passed the constraints (SPEC §8 `no_feasible_pose`).
    #[error("no_feasible_pose: none of {} candidates was feasible ({} workspace, {} collision, {} occlusion){}",
        stats.total, stats.workspace, stats.collision, stats.occlusion,
        match stop { StopReason::Deadline => "; the deadline passed first", StopReason::Budget => "; the evaluation budget ran out", StopReason::Abandoned => "; the search was abandoned", _ => "" })]
    NoFeasiblePose {
        /// What was tried.
        stats: EvalStats,
        /// Why the search stopped.
        stop: StopReason,
    },
}

/// Searches for the optimal sensor state: the one call from a request to an answer.
///
/// `params` must be valid. The answer's `micros` is the wall time of the search and
/// the final prediction.
pub fn solve(
    world: &World,
    belief: &Belief,
    params: &Params,
    model: &NoiseModel,
    algorithm: Algorithm,
    control: &SearchControl,
) -> Result<Answer, SearchError> {
    let started = Instant::now();
    let lupp = Lupp::new(world, belief, params, model);
    let outcome = AnySearch::from(algorithm).search(&lupp, control);
    let Some(best) = outcome.best else {
        return Err(SearchError::NoFeasiblePose { stats: outcome.stats, stop: outcome.stop });
    };
    let p = lupp.predict(&best.x);
    debug_assert!(p.evaluation.cost() == Some(best.cost), "an answer must be feasible");
    Ok(Answer {
        algorithm,
        x: best.x,
        cost: best.cost,
        sensor_position: p.pose.position,
        sensor_orientation: p.pose.quaternion(),
        viewer_position: p.pose.viewer_position,
        viewer_yaw: p.pose.viewer_yaw,
        r: p.r.to_rows(),
        posterior: p.posterior,
        evaluations: outcome.stats,
        micros: u64::try_from(started.elapsed().as_micros()).unwrap_or(u64::MAX),
        map_version: world.version(),
        stop: outcome.stop,
    })
}
