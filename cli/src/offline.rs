//! `dyfos solve` and `dyfos eval`: scenario files searched in this process.

use crate::Failure;
use anyhow::Context;
use dyfos_service::lupp::{Evaluation, Lupp};
use dyfos_service::search::SearchControl;
use dyfos_service::{SearchError, solve as solve_scenario};
use dyfos_shared::math::{canonical_xyzw, rows3};
use dyfos_shared::prelude::*;
use dyfos_shared::world::Blocker;
use std::path::{Path, PathBuf};

/// Flags of `dyfos solve`.
#[derive(Debug, clap::Args)]
pub struct SolveArgs {
    /// Scenario file (SPEC §11 JSON).
    pub scenario: PathBuf,
    #[command(flatten)]
    pub search: SearchArgs,
    /// Worker threads for `brute` (default: all cores; the answer does not change).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Model file of the learned SDSMM (written by `dyfos train`); implies `"model": "learned"`.
    #[arg(long, value_name = "FILE")]
    pub model: Option<PathBuf>,
}

/// How to search: the same flags, and for the same values the same answer, in
/// `dyfos solve` (in this process) and `dyfos query` (through `dyfosd`).
#[derive(Debug, clap::Args)]
pub struct SearchArgs {
    /// Search algorithm.
    #[arg(long, default_value = "dyfos", value_parser = parse_algorithm)]
    pub algo: Algorithm,
    /// Seed of the random stream: the same seed gives the same answer, from `dyfos solve` or `dyfos query`.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Most candidates to evaluate (default: the algorithm's own limits).
    #[arg(long)]
    pub budget: Option<u64>,
}

/// Flags of `dyfos eval`.
#[derive(Debug, clap::Args)]
pub struct EvalArgs {
    /// Scenario file (SPEC §11 JSON).
    pub scenario: PathBuf,
    /// The candidate: ρ (m), ψ, φ, ψ_v (rad).
    #[arg(long, num_args = 4, value_names = ["RHO", "PSI", "PHI", "YAW"], allow_hyphen_values = true, required = true)]
    pub x: Vec<f64>,
    /// Model file of the learned SDSMM (written by `dyfos train`); implies `"model": "learned"`.
    #[arg(long, value_name = "FILE")]
    pub model: Option<PathBuf>,
}

pub fn parse_algorithm(s: &str) -> Result<Algorithm, String> {
    Algorithm::from_name(s).ok_or_else(|| {
        let names: Vec<_> = Algorithm::ALL.iter().map(|a| a.name()).collect();
        format!("unknown algorithm `{s}`; choose one of {}", names.join(", "))
    })
}

/// Reads and validates a scenario file; every problem is exit code 2.
pub fn load_scenario(path: &Path) -> Result<Scenario, Failure> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("cannot read scenario file {}", path.display()))
        .map_err(Failure::invalid)?;
    // An `octomap.file` is relative to the scenario's folder (SPEC §11).
    let folder = path.parent().unwrap_or(Path::new("."));
    let read = |file: &str| std::fs::read(folder.join(file)).map_err(|e| format!("cannot read `{file}`: {e}"));
    Scenario::from_json_with_files(&text, read)
        .map_err(|e| Failure::invalid(anyhow::anyhow!("{}: {e}", path.display())))
}

/// The scenario's SDSMM; a `--model` file selects `learned` with its weights. A
/// missing or unusable model file is exit code 2, before any search.
fn model_of(scenario: &mut Scenario, path: &Path, model_file: Option<&Path>) -> Result<NoiseModel, Failure> {
    let weights = match model_file {
        Some(file) => {
            scenario.params.model = ModelKind::Learned;
            Some(dyfos_service::learned::load_model(file).map_err(Failure::invalid)?)
        }
        None => None,
    };
    NoiseModel::from_params_and_weights(&scenario.params, weights.as_ref())
        .map_err(|e| Failure::invalid(anyhow::anyhow!("{}: {e}", path.display())))
}

/// `dyfos solve`.
pub fn solve(args: &SolveArgs) -> Result<(), Failure> {
    let mut scenario = load_scenario(&args.scenario)?;
    let model = model_of(&mut scenario, &args.scenario, args.model.as_deref())?;
    let mut control = SearchControl::seeded(args.search.seed);
    control.budget = args.search.budget;
    if let Some(t) = args.threads {
        control.threads = t.max(1);
    }
    let answer =
        solve_scenario(&scenario.world, &scenario.belief, &scenario.params, &model, args.search.algo, &control)
            .map_err(|e: SearchError| Failure::infeasible(e))?;
    crate::print_json(&answer.to_json());
    Ok(())
}

/// `dyfos eval`.
pub fn eval(args: &EvalArgs) -> Result<(), Failure> {
    let mut scenario = load_scenario(&args.scenario)?;
    let model = model_of(&mut scenario, &args.scenario, args.model.as_deref())?;
    let x = [args.x[0], args.x[1], args.x[2], args.x[3]];
    if let Some(bad) = x.iter().find(|v| !v.is_finite()) {
        return Err(Failure::invalid(anyhow::anyhow!("--x: {bad} is not a finite number")));
    }
    let lupp = Lupp::new(&scenario.world, &scenario.belief, &scenario.params, &model);
    let x = SensorState::from_array(x);
    let p = lupp.predict(&x);
    let (feasible, reason, cost) = match p.evaluation {
        Evaluation::Feasible { cost } => (true, None, Some(cost)),
        Evaluation::Rejected(r) => (false, Some(r.name()), None),
    };
    let blockers: Vec<serde_json::Value> = p
        .blockers
        .iter()
        .map(|b| match b {
            Blocker::Obstacle(id) => serde_json::json!(id),
            Blocker::Voxels => serde_json::json!("voxels"),
        })
        .collect();
    let f = &p.features;
    let out = serde_json::json!({
        "x": x.to_array(),
        "in_search_space": lupp.space().contains(&x),
        "feasible": feasible,
        "reason": reason,
        "blockers": blockers,
        "sensor_position": <[f64; 3]>::from(p.pose.position.coords),
        "sensor_quaternion": canonical_xyzw(&p.pose.quaternion()),
        "viewer_position": <[f64; 3]>::from(p.pose.viewer_position.coords),
        "features": {"u": f.u, "v": f.v, "e": f.e, "s": f.s, "c": f.c,
                     "elevation": f.elevation, "bearing": f.bearing, "rho": f.rho},
        "R": p.r.to_rows(),
        "posterior": rows3(&p.posterior),
        "cost": cost,
    });
    crate::print_json(&out);
    Ok(())
}
