//! `dyfos-bench compare --baseline DIR`: this build's `dyfos solve` against
//! another build's (DIR: its binaries, e.g. a `git worktree`'s `target/release`),
//! interleaved on the same scenarios; medians, ratios and whether every answer
//! is identical.

use anyhow::Context;
use dyfos_bench::compare::{CompareConfig, MapKind, Model, Through, compare, evaluation_floor, write_cases};
use dyfos_shared::answer::Algorithm;
use std::path::PathBuf;

/// Flags of `dyfos-bench compare`.
#[derive(Debug, clap::Args)]
pub struct CompareArgs {
    /// Directory holding the other build's `dyfos` binary.
    #[arg(long, value_name = "DIR")]
    baseline: PathBuf,
    /// Directory holding this build's `dyfos` (default: next to this executable).
    #[arg(long, value_name = "DIR")]
    new: Option<PathBuf>,
    /// Interleaved rounds (baseline, new) per query.
    #[arg(long, default_value_t = 3)]
    rounds: usize,
    /// Search seeds, comma-separated: every scenario runs once per seed and round.
    #[arg(long, value_delimiter = ',', default_value = "1")]
    seeds: Vec<u64>,
    /// Algorithms, comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "dyfos,brute", value_parser = parse_algorithm)]
    algos: Vec<Algorithm>,
    /// Models every map is scored with: paper, anisotropic, learned (the committed model file).
    #[arg(long, value_delimiter = ',', default_value = "paper,learned", value_parser = parse_model)]
    models: Vec<Model>,
    /// Map kinds: numerical (SPEC §10), hard, octomap (the real scan), building (a
    /// synthetic OctoMap), voxels (SPEC §10 maps as 0.1 m grids), building-boxes (the
    /// building as boxes, what the building is set against).
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "numerical,hard,octomap,building,voxels,building-boxes",
        value_parser = parse_kind
    )]
    maps: Vec<MapKind>,
    /// SPEC §10 maps (seed 1); the hard maps are half as many, the voxel maps a quarter.
    #[arg(long, default_value_t = 20)]
    count: usize,
    /// Occupied cells of the synthetic building.
    #[arg(long, default_value_t = 200_000)]
    building_cells: u64,
    /// `--threads` for both builds' `dyfos solve` (only `brute` uses more than one).
    #[arg(long, default_value_t = 2)]
    threads: usize,
    /// The repository's `tests/data` (golden hard maps, OctoMap scenario, learned model).
    #[arg(long, default_value = "tests/data")]
    data: PathBuf,
    /// Where the scenario files are written (default: a fresh directory under the system's temporary one).
    #[arg(long, value_name = "DIR")]
    scenarios: Option<PathBuf>,
    /// Skip the evaluation floor (one evaluation of a feasible candidate on an empty
    /// map, in this process, per model), and with it the "× floor" column: each
    /// query's `micros` over (its evaluations × the floor).
    #[arg(long)]
    no_floor: bool,
    /// Where each build answers: `solve` (a fresh `dyfos solve` process per query)
    /// or `dyfosd` (each build's daemon, started once, asked by its `dyfos query`:
    /// the time a running daemon's search takes).
    #[arg(long, default_value = "solve", value_parser = parse_through)]
    through: Through,
    /// Also write the whole comparison (every run) as JSON here.
    #[arg(long, value_name = "FILE")]
    json: Option<PathBuf>,
}

fn parse_algorithm(s: &str) -> Result<Algorithm, String> {
    Algorithm::from_name(s).ok_or_else(|| format!("unknown algorithm `{s}`"))
}

fn parse_model(s: &str) -> Result<Model, String> {
    Model::from_name(s).ok_or_else(|| format!("unknown model `{s}`: use paper, anisotropic or learned"))
}

fn parse_through(s: &str) -> Result<Through, String> {
    Through::from_name(s).ok_or_else(|| format!("unknown `--through {s}`: use solve or dyfosd"))
}

fn parse_kind(s: &str) -> Result<MapKind, String> {
    let names: Vec<&str> = MapKind::ALL.iter().map(|k| k.name()).collect();
    MapKind::from_name(s).ok_or_else(|| format!("unknown map kind `{s}`: use {}", names.join(", ")))
}

pub fn run(args: &CompareArgs) -> anyhow::Result<()> {
    let new = match &args.new {
        Some(dir) => dir.clone(),
        None => std::env::current_exe()?.parent().context("this executable's directory")?.to_path_buf(),
    };
    // Both binaries first: a wrong directory fails before minutes of scenario writing.
    dyfos_bench::compare::dyfos_in(&args.baseline)?;
    dyfos_bench::compare::dyfos_in(&new)?;
    let config = CompareConfig {
        kinds: args.maps.clone(),
        models: args.models.clone(),
        algorithms: args.algos.clone(),
        seeds: args.seeds.clone(),
        rounds: args.rounds,
        threads: args.threads.max(1),
        maps: args.count,
        building_cells: args.building_cells,
        data: args.data.clone(),
        through: args.through,
    };
    let dir = args
        .scenarios
        .clone()
        .unwrap_or_else(|| std::env::temp_dir().join(format!("dyfos-compare-{}", std::process::id())));
    let cases = write_cases(&config, &dir)?;
    eprintln!("{} scenario files in {}", cases.len(), dir.display());
    // The floor is this process's pipeline: meaningful for `--new` when it is this build.
    let floors = if args.no_floor {
        Vec::new()
    } else {
        args.models
            .iter()
            .map(|m| Ok((*m, evaluation_floor(*m, &args.data, 200_000)?)))
            .collect::<anyhow::Result<_>>()?
    };
    let comparison = compare(&config, &cases, &args.baseline, &new, &floors, |line| eprintln!("{line}"))?;
    print!("{}", comparison.table());
    if let Some(path) = &args.json {
        std::fs::write(path, serde_json::to_string_pretty(&comparison)?)
            .with_context(|| format!("cannot write {}", path.display()))?;
        eprintln!("wrote {}", path.display());
    }
    if args.scenarios.is_none() {
        let _ = std::fs::remove_dir_all(&dir);
    }
    Ok(())
}
