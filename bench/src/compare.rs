//! Two builds of `dyfos`, same run: `dyfos-bench compare --baseline DIR`.
//!
//! A speed-up is only worth what it is measured against, and on a shared machine
//! two runs minutes apart disagree by more than most changes gain. So both builds'
//! `dyfos solve` run here, interleaved (baseline, new, baseline, new, … per query
//! and round), on the same scenario files with the same seeds and threads; each
//! run's `micros` (the search's wall time, as the answer reports it) and answer
//! (x, cost bits, evaluation counts) are read back. Per group (algorithm × map
//! kind × model) the medians, their ratio and whether every answer was identical
//! are printed.
//!
//! The scenarios are written to a directory first ([`write_cases`]): the SPEC §10
//! maps, hard maps, the repository's real OctoMap scenario, a synthetic OctoMap
//! building (as `dyfos-bench octomap` builds it) and cylinder maps as voxel grids,
//! each scored with the models asked for.
//!
//! `--through dyfosd` asks each build's own daemon instead ([`Through::Daemon`]):
//! one `dyfosd` per build, started once, each query sent by that build's `dyfos
//! query`. Its `micros` is the daemon's search in a process that is already running,
//! the time a robot waits; a fresh `dyfos solve` adds what a new process pays the
//! first time through the search's code (its pages faulted in, cold caches and
//! branch predictors, the CPU's features detected), the same for both builds.
//!
//! [`evaluation_floor`] is the other yardstick: the cost of one evaluation of a
//! feasible candidate on an empty map in a tight loop, in this process. A query's
//! time over (evaluations × floor) says how much of it is the search around the
//! pipeline rather than the pipeline itself.

use crate::numerical::{NumericalConfig, numerical_map, numerical_maps, voxelized};
use crate::octomap::{Building, RESOLUTION};
use crate::stats::quantile_sorted;
use crate::table::{self, Align};
use anyhow::{Context, bail};
use dyfos_process::child::KillOnDrop;
use dyfos_service::launch::DyfosdCommand;
use dyfos_service::learned::load_model;
use dyfos_service::lupp::{Evaluation, Lupp};
use dyfos_shared::answer::{Algorithm, EvalStats};
use dyfos_shared::params::ModelKind;
use dyfos_shared::scenario::Scenario;
use dyfos_shared::sdsmm::NoiseModel;
use dyfos_shared::sensor::SensorState;
use dyfos_shared::world::World;
use dyfos_shared::world::octomap::write_bt;
use std::fmt::Write;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

/// What kind of map a scenario holds (a column of the comparison).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum MapKind {
    /// SPEC §10's random maps: 25 cylinders on [−10, 10]².
    Numerical,
    /// Cluttered maps: the golden `hard_*` scenarios (cylinders, boxes, a floating
    /// box, low sun), then SPEC §10 maps with three times the cylinders.
    Hard,
    /// The repository's real OctoMap scenarios (`tests/data/octomap`).
    Octomap,
    /// A synthetic building written as an OctoMap `.bt` and read back.
    Building,
    /// SPEC §10 maps as 0.1 m occupancy grids: cylinders of the same clutter as voxels.
    Voxels,
    /// The same building as boxes ([`Building::boxes`]): its scene in the terms of
    /// a cylinder map.
    BuildingBoxes,
}

impl MapKind {
    /// Every kind, in table order.
    pub const ALL: [MapKind; 6] = [
        MapKind::Numerical,
        MapKind::Hard,
        MapKind::Octomap,
        MapKind::Building,
        MapKind::Voxels,
        MapKind::BuildingBoxes,
    ];

    /// The name used in flags and tables.
    pub fn name(self) -> &'static str {
        match self {
            MapKind::Numerical => "numerical",
            MapKind::Hard => "hard",
            MapKind::Octomap => "octomap",
            MapKind::Building => "building",
            MapKind::Voxels => "voxels",
            MapKind::BuildingBoxes => "building-boxes",
        }
    }

    /// The kind named `s`.
    pub fn from_name(s: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|k| k.name() == s)
    }
}

/// The SDSMM a scenario is scored with.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Model {
    /// `paper`, written into the scenario.
    Paper,
    /// `anisotropic`, written into the scenario.
    Anisotropic,
    /// `learned`: the scenario plus `dyfos solve --model FILE`.
    Learned,
}

impl Model {
    /// The name used in flags and tables.
    pub fn name(self) -> &'static str {
        match self {
            Model::Paper => "paper",
            Model::Anisotropic => "anisotropic",
            Model::Learned => "learned",
        }
    }

    /// The model named `s`.
    pub fn from_name(s: &str) -> Option<Self> {
        [Model::Paper, Model::Anisotropic, Model::Learned].into_iter().find(|m| m.name() == s)
    }
}

/// Which scenarios to write and how to run them.
#[derive(Debug, Clone, PartialEq)]
pub struct CompareConfig {
    /// Map kinds to include.
    pub kinds: Vec<MapKind>,
    /// Models to score every map with.
    pub models: Vec<Model>,
    /// Algorithms to run (`dyfos`, `brute`, …).
    pub algorithms: Vec<Algorithm>,
    /// Search seeds; every scenario runs once per seed and round.
    pub seeds: Vec<u64>,
    /// Interleaved rounds (baseline, new) per query.
    pub rounds: usize,
    /// `--threads` given to both builds' `dyfos solve` (only `brute` uses more than one).
    pub threads: usize,
    /// SPEC §10 maps (seed 1) of kind `numerical`; also the count of `voxels` and of
    /// the dense `hard` maps is derived from it (see [`write_cases`]).
    pub maps: usize,
    /// Occupied cells of the synthetic building.
    pub building_cells: u64,
    /// The repository's `tests/data` (golden hard maps, OctoMap scenario, learned model).
    pub data: PathBuf,
    /// Where each build answers.
    pub through: Through,
}

/// Where each build answers the queries.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Through {
    /// A fresh `dyfos solve` process per query.
    Solve,
    /// The build's own `dyfosd`, started once, asked by the build's `dyfos query`
    /// (`brute` then runs on the daemon's workers, not `threads`).
    #[serde(rename = "dyfosd")]
    Daemon,
}

impl Through {
    /// The name `--through` takes.
    pub fn name(self) -> &'static str {
        match self {
            Through::Solve => "solve",
            Through::Daemon => "dyfosd",
        }
    }

    /// The kind named `s`.
    pub fn from_name(s: &str) -> Option<Self> {
        [Through::Solve, Through::Daemon].into_iter().find(|t| t.name() == s)
    }
}

impl Default for CompareConfig {
    fn default() -> Self {
        CompareConfig {
            kinds: MapKind::ALL.to_vec(),
            models: vec![Model::Paper, Model::Learned],
            algorithms: vec![Algorithm::Dyfos, Algorithm::Brute],
            seeds: vec![1],
            rounds: 3,
            threads: 2,
            maps: 20,
            building_cells: 200_000,
            data: PathBuf::from("tests/data"),
            through: Through::Solve,
        }
    }
}

/// One scenario file with the model it is scored with.
#[derive(Debug, Clone, PartialEq)]
pub struct Case {
    /// Map kind.
    pub kind: MapKind,
    /// Model.
    pub model: Model,
    /// Short name, e.g. `numerical_03`.
    pub name: String,
    /// The scenario file.
    pub scenario: PathBuf,
    /// `--model FILE` for `learned`.
    pub model_file: Option<PathBuf>,
}

/// SPEC §10 maps of this seed are the `numerical` kind (as `dyfos-bench numerical` draws them).
pub const MAP_SEED: u64 = 1;
/// Cylinders of the dense `hard` maps, on the SPEC §10 square.
pub const HARD_CYLINDERS: usize = 75;
/// Golden hard scenarios under `tests/data`.
const GOLDEN_HARD: [&str; 2] = ["golden/scenarios/hard/hard_00.json", "golden/scenarios/hard/hard_01.json"];
/// Cell side of the `voxels` maps, m.
const VOXEL_RESOLUTION: f64 = 0.1;

fn read_scenario(path: &Path) -> anyhow::Result<Scenario> {
    let text = std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
    let base = path.parent().unwrap_or(Path::new("."));
    Scenario::from_json_with_files(&text, |f| std::fs::read(base.join(f)).map_err(|e| e.to_string()))
        .with_context(|| format!("{} is not a valid scenario", path.display()))
}

/// One map: its name, scenario JSON and the files to write beside it (name, bytes).
type MapFiles = (String, serde_json::Value, Vec<(String, Vec<u8>)>);

/// The maps of each kind.
fn maps_of(kind: MapKind, config: &CompareConfig) -> anyhow::Result<Vec<MapFiles>> {
    let plain = |name: String, s: &Scenario| -> anyhow::Result<_> {
        Ok((name, serde_json::from_str::<serde_json::Value>(&s.to_json())?, Vec::new()))
    };
    let mut out = Vec::new();
    match kind {
        MapKind::Numerical => {
            for (i, s) in numerical_maps(MAP_SEED, config.maps, &NumericalConfig::paper()).iter().enumerate() {
                out.push(plain(format!("numerical_{i:02}"), s)?);
            }
        }
        MapKind::Hard => {
            // Half as many as the numerical maps: the golden ones, then dense cylinder maps.
            let count = config.maps.div_ceil(2);
            for (i, file) in GOLDEN_HARD.iter().take(count).enumerate() {
                out.push(plain(format!("hard_{i:02}"), &read_scenario(&config.data.join(file))?)?);
            }
            let dense = NumericalConfig { cylinders: HARD_CYLINDERS, ..NumericalConfig::paper() };
            for i in GOLDEN_HARD.len()..count {
                out.push(plain(format!("hard_{i:02}"), &numerical_map(MAP_SEED, i as u64, &dense))?);
            }
        }
        MapKind::Octomap => {
            let path = config.data.join("octomap/geb079-scenario.json");
            let text = std::fs::read_to_string(&path).with_context(|| format!("cannot read {}", path.display()))?;
            let mut json: serde_json::Value = serde_json::from_str(&text)?;
            let bt = json["octomap"]["file"].as_str().context("the OctoMap scenario names no file")?.to_string();
            let bytes = std::fs::read(path.with_file_name(&bt)).with_context(|| format!("cannot read {bt}"))?;
            json["octomap"]["file"] = "geb079.bt".into();
            out.push(("geb079".to_string(), json, vec![("geb079.bt".to_string(), bytes)]));
        }
        MapKind::Building => {
            let building = Building::with_cells(config.building_cells);
            let world = World::new(0, building.bounds()?, Building::sun(), [], None)?;
            let scenario = building.scenario(world)?;
            let mut json: serde_json::Value = serde_json::from_str(&scenario.to_json())?;
            json["octomap"] = serde_json::json!({"file": "building.bt", "origin": [0.0, 0.0, 0.0]});
            out.push((
                "building".to_string(),
                json,
                vec![("building.bt".into(), write_bt(RESOLUTION, building.cells())?)],
            ));
        }
        MapKind::BuildingBoxes => {
            let building = Building::with_cells(config.building_cells);
            let world = World::new(0, building.bounds()?, Building::sun(), building.boxes(), None)?;
            out.push(plain("building-boxes".to_string(), &building.scenario(world)?)?);
        }
        MapKind::Voxels => {
            let count = config.maps.div_ceil(4);
            for (i, s) in numerical_maps(MAP_SEED, count, &NumericalConfig::paper()).iter().enumerate() {
                out.push(plain(format!("voxels_{i:02}"), &voxelized(s, VOXEL_RESOLUTION)?)?);
            }
        }
    }
    Ok(out)
}

/// Writes the scenario files of `config` into `dir` (created): one file per map
/// and model. Counts: `maps` numerical maps (seed [`MAP_SEED`]); ⌈maps/2⌉ hard ones
/// (the golden `hard_*`, then [`HARD_CYLINDERS`]-cylinder maps); ⌈maps/4⌉ voxel
/// maps; one real OctoMap scenario; one building.
pub fn write_cases(config: &CompareConfig, dir: &Path) -> anyhow::Result<Vec<Case>> {
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let learned = config.data.join("learned/model.bin");
    if config.models.contains(&Model::Learned) && !learned.exists() {
        bail!("model `learned` needs {}: run from the repository root or give --data", learned.display());
    }
    let mut cases = Vec::new();
    for &kind in &config.kinds {
        for (name, json, files) in maps_of(kind, config)? {
            for (file, bytes) in &files {
                std::fs::write(dir.join(file), bytes).with_context(|| format!("cannot write {file}"))?;
            }
            for &model in &config.models {
                let mut json = json.clone();
                // `dyfos solve` chooses `learned` by its model file, so there the
                // scenario names a model valid without one; a daemon has the file
                // and is asked for `learned` by the scenario.
                let written = match (model, config.through) {
                    (Model::Anisotropic, _) => "anisotropic",
                    (Model::Learned, Through::Daemon) => "learned",
                    _ => "paper",
                };
                json["params"]["model"] = written.into();
                let scenario = dir.join(format!("{name}-{}.json", model.name()));
                std::fs::write(&scenario, serde_json::to_string_pretty(&json)?)?;
                let model_file = (model == Model::Learned).then(|| learned.clone());
                cases.push(Case { kind, model, name: name.clone(), scenario, model_file });
            }
        }
    }
    Ok(cases)
}

/// What must be identical between the builds: x and cost as bits, and the counts.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub struct AnswerBits {
    /// `x` as IEEE 754 bits; `None` when no feasible pose was found (exit code 3).
    pub x: Option<[u64; 4]>,
    /// The cost's bits.
    pub cost: Option<u64>,
    /// Candidates evaluated, by rejection (zero when infeasible: not printed).
    pub evaluations: EvalStats,
}

/// One `dyfos solve` run.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct SolveRun {
    /// The answer's `micros` (NaN when no feasible pose was found).
    pub micros: f64,
    /// The answer.
    pub answer: AnswerBits,
}

/// The `dyfosd` beside `dyfos`.
fn dyfosd_beside(dyfos: &Path) -> PathBuf {
    dyfos.with_file_name(format!("dyfosd{}", std::env::consts::EXE_SUFFIX))
}

/// The `dyfos` binary in `dir`, or an error saying what is missing.
pub fn dyfos_in(dir: &Path) -> anyhow::Result<PathBuf> {
    let path = dir.join(format!("dyfos{}", std::env::consts::EXE_SUFFIX));
    if !path.is_file() {
        bail!(
            "{} has no `dyfos` binary: give the directory a build puts its binaries in (e.g. target/release)",
            dir.display()
        );
    }
    Ok(path)
}

/// One build's `dyfos` and `dyfosd`, copied into a folder of their own (removed on
/// drop). Both builds are run from such copies, written the same way at the same
/// time: on a Linux guest a fresh process's time depended on how its executable's
/// pages were last written or read (a binary as the linker wrote it ran up to 14 %
/// slower than a copy of itself), which would favour one build for a whole run.
pub struct BuildCopy {
    /// The copied `dyfos`, `dyfosd` beside it.
    pub dyfos: PathBuf,
    dir: PathBuf,
}

impl BuildCopy {
    /// Copies the binaries of the build in `dir` (see [`dyfos_in`]).
    pub fn new(dir: &Path, tag: &str) -> anyhow::Result<Self> {
        let dyfos = dyfos_in(dir)?;
        let into = std::env::temp_dir().join(format!("cmp{}{tag}bin", std::process::id()));
        std::fs::create_dir_all(&into).with_context(|| format!("cannot create {}", into.display()))?;
        let copy = BuildCopy { dyfos: into.join(dyfos.file_name().unwrap_or_default()), dir: into };
        let dyfosd = dyfosd_beside(&dyfos);
        for from in [&dyfos, &dyfosd] {
            if from.is_file() {
                let to = copy.dir.join(from.file_name().unwrap_or_default());
                std::fs::copy(from, &to)
                    .with_context(|| format!("cannot copy {} to {}", from.display(), to.display()))?;
            }
        }
        Ok(copy)
    }
}

impl Drop for BuildCopy {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

/// One build's `dyfosd`, on its own prefix, domain and state directory (removed on
/// drop), asked through that build's `dyfos`.
pub struct BuildDaemon {
    dyfos: PathBuf,
    prefix: String,
    domain: String,
    dir: PathBuf,
    process: KillOnDrop,
}

impl BuildDaemon {
    /// Starts the `dyfosd` beside `dyfos` (with the learned model `model`, if any)
    /// and waits until it answers `dyfos stats`.
    pub fn start(dyfos: &Path, tag: &str, model: Option<&Path>) -> anyhow::Result<Self> {
        let dyfosd = dyfosd_beside(dyfos);
        let name = format!("cmp{}{tag}", std::process::id());
        let dir = std::env::temp_dir().join(&name);
        std::fs::create_dir_all(&dir).with_context(|| format!("cannot create {}", dir.display()))?;
        let log = std::fs::File::create(dir.join("dyfosd.log"))?;
        let (prefix, domain) = (format!("{name}/"), format!("{name}_"));
        let mut command = DyfosdCommand::new(&dyfosd, &prefix, &dir.join("state")).domain(&domain).log("warn", log);
        if let Some(model) = model {
            command = command.args([std::ffi::OsStr::new("--model"), model.as_os_str()]);
        }
        let process = command.spawn().with_context(|| format!("cannot start {}", dyfosd.display()))?;
        let mut daemon = BuildDaemon { dyfos: dyfos.to_path_buf(), prefix, domain, dir, process };
        let started = Instant::now();
        loop {
            let status = Command::new(dyfos)
                .arg("stats")
                .args(["--prefix", &daemon.prefix, "--domain", &daemon.domain, "--timeout", "2"])
                .output()?;
            if status.status.success() {
                return Ok(daemon);
            }
            if !daemon.process.is_running() || started.elapsed() > Duration::from_secs(60) {
                bail!("{} did not come up; its log: {}", dyfosd.display(), daemon.dir.join("dyfosd.log").display());
            }
            std::thread::sleep(Duration::from_millis(100));
        }
    }
}

impl Drop for BuildDaemon {
    fn drop(&mut self) {
        self.process.terminate(Duration::from_secs(10));
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

/// One build as the comparison asks it ([`Through`]).
enum Build {
    /// Its `dyfos`, one `dyfos solve` per query.
    Solve(PathBuf),
    /// Its running daemon.
    Daemon(BuildDaemon),
}

impl Build {
    /// The build's answer to `case`; `threads` for `dyfos solve` (a daemon uses its workers).
    fn answer(&self, case: &Case, algorithm: Algorithm, seed: u64, threads: usize) -> anyhow::Result<SolveRun> {
        match self {
            Build::Solve(dyfos) => solve_once(dyfos, case, algorithm, seed, threads),
            Build::Daemon(daemon) => query_once(daemon, case, algorithm, seed),
        }
    }
}

/// Runs `dyfos solve` of `dyfos` on `case` and reads its answer.
pub fn solve_once(
    dyfos: &Path,
    case: &Case,
    algorithm: Algorithm,
    seed: u64,
    threads: usize,
) -> anyhow::Result<SolveRun> {
    let mut cmd = Command::new(dyfos);
    cmd.arg("solve").arg(&case.scenario).args(["--algo", algorithm.name()]);
    cmd.args(["--seed", &seed.to_string(), "--threads", &threads.to_string()]);
    if let Some(f) = &case.model_file {
        cmd.arg("--model").arg(f);
    }
    run_answer(cmd, || format!("{} solve {} --algo {}", dyfos.display(), case.scenario.display(), algorithm.name()))
}

/// Asks `daemon` for `case` through its build's `dyfos query` and reads the answer.
pub fn query_once(daemon: &BuildDaemon, case: &Case, algorithm: Algorithm, seed: u64) -> anyhow::Result<SolveRun> {
    let mut cmd = Command::new(&daemon.dyfos);
    cmd.arg("query").arg(&case.scenario).args(["--algo", algorithm.name(), "--seed", &seed.to_string()]);
    cmd.args(["--prefix", &daemon.prefix, "--domain", &daemon.domain]);
    run_answer(cmd, || {
        format!("{} query {} --algo {}", daemon.dyfos.display(), case.scenario.display(), algorithm.name())
    })
}

/// Runs `cmd`, a `dyfos` printing an answer as `solve` does, and reads the answer.
fn run_answer(mut cmd: Command, what: impl Fn() -> String) -> anyhow::Result<SolveRun> {
    let out = cmd.output().with_context(|| format!("cannot run {}", what()))?;
    match out.status.code() {
        Some(0) => {}
        // No feasible pose: an answer too, to be compared.
        Some(3) => {
            return Ok(SolveRun {
                micros: f64::NAN,
                answer: AnswerBits { x: None, cost: None, evaluations: EvalStats::default() },
            });
        }
        _ => bail!("{} failed ({}): {}", what(), out.status, String::from_utf8_lossy(&out.stderr).trim()),
    }
    let json: serde_json::Value =
        serde_json::from_slice(&out.stdout).with_context(|| format!("{} printed no JSON answer", what()))?;
    let number = |v: &serde_json::Value| v.as_f64().with_context(|| format!("{}: `{v}` is not a number", what()));
    let xs = json["x"].as_array().filter(|a| a.len() == 4).with_context(|| format!("{}: no `x`", what()))?;
    let mut x = [0u64; 4];
    for (bits, v) in x.iter_mut().zip(xs) {
        *bits = number(v)?.to_bits();
    }
    let evaluations: EvalStats =
        serde_json::from_value(json["evaluations"].clone()).with_context(|| format!("{}: no `evaluations`", what()))?;
    Ok(SolveRun {
        micros: number(&json["micros"])?,
        answer: AnswerBits { x: Some(x), cost: Some(number(&json["cost"])?.to_bits()), evaluations },
    })
}

/// Both builds' runs of one query (case, algorithm, seed).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct QueryRuns {
    /// Scenario name.
    pub name: String,
    /// Map kind.
    pub kind: MapKind,
    /// Model.
    pub model: Model,
    /// Algorithm name.
    pub algorithm: String,
    /// Search seed.
    pub seed: u64,
    /// The baseline's runs, one per round.
    pub baseline: Vec<SolveRun>,
    /// This build's runs, one per round.
    pub new: Vec<SolveRun>,
}

impl QueryRuns {
    /// Whether every run of both builds gave the same answer.
    pub fn identical(&self) -> bool {
        let first = self.baseline.first().map(|r| r.answer);
        self.baseline.iter().chain(&self.new).all(|r| Some(r.answer) == first)
    }
}

fn median(values: &mut [f64]) -> f64 {
    values.sort_by(f64::total_cmp);
    if values.is_empty() { f64::NAN } else { quantile_sorted(values, 0.5) }
}

fn median_micros(runs: &[SolveRun]) -> f64 {
    median(&mut runs.iter().map(|r| r.micros).filter(|m| !m.is_nan()).collect::<Vec<_>>())
}

/// One line of the table: a group of queries (algorithm × kind × model).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct GroupRow {
    /// Algorithm name.
    pub algorithm: String,
    /// Map kind.
    pub kind: MapKind,
    /// Model.
    pub model: Model,
    /// Queries (scenarios × seeds).
    pub queries: usize,
    /// Median over the queries of each query's median baseline `micros`.
    pub baseline_micros: f64,
    /// The same for this build.
    pub new_micros: f64,
    /// `baseline_micros / new_micros`: > 1 is faster.
    pub ratio: f64,
    /// Median over the queries of the per-query ratio (baseline median / new median).
    pub median_query_ratio: f64,
    /// Whether every answer of both builds was identical (x, cost bits, counts).
    pub identical: bool,
    /// Queries whose answers differed.
    pub differing: usize,
    /// Median evaluations of this build's answers.
    pub evaluations: f64,
    /// Median over the queries of new `micros` / (evaluations × floor), when the
    /// floor was measured (see [`evaluation_floor`]).
    pub new_floor_multiple: Option<f64>,
    /// The same for the baseline's `micros` against this build's floor.
    pub baseline_floor_multiple: Option<f64>,
}

/// The whole comparison.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Comparison {
    /// The baseline's binary directory.
    pub baseline: PathBuf,
    /// This build's binary directory.
    pub new: PathBuf,
    /// Rounds run.
    pub rounds: usize,
    /// Threads given to `dyfos solve`.
    pub threads: usize,
    /// Where each build answered.
    pub through: Through,
    /// The evaluation floor per model, µs, when measured.
    pub floors: Vec<(Model, f64)>,
    /// One line per group.
    pub groups: Vec<GroupRow>,
    /// Voxel and OctoMap maps against the cylinder maps, per build.
    pub against_cylinders: Vec<AgainstCylinders>,
    /// Every query's runs.
    pub queries: Vec<QueryRuns>,
}

/// Runs every case × algorithm × seed on both builds, interleaved per round
/// (baseline then new, for every query, then the next round), and groups the
/// results. `floors` (µs per model) adds the floor multiples.
pub fn compare(
    config: &CompareConfig,
    cases: &[Case],
    baseline_dir: &Path,
    new_dir: &Path,
    floors: &[(Model, f64)],
    mut progress: impl FnMut(&str),
) -> anyhow::Result<Comparison> {
    // Declared before the builds: a daemon stops before its binaries are removed.
    let copies = (BuildCopy::new(baseline_dir, "base")?, BuildCopy::new(new_dir, "new")?);
    let model = cases.iter().find_map(|c| c.model_file.as_deref());
    let mut build = |copy: &BuildCopy, tag: &str| -> anyhow::Result<Build> {
        Ok(match config.through {
            Through::Solve => Build::Solve(copy.dyfos.clone()),
            Through::Daemon => {
                progress(&format!("starting the {tag} build's dyfosd"));
                Build::Daemon(BuildDaemon::start(&copy.dyfos, tag, model)?)
            }
        })
    };
    let (a, b) = (build(&copies.0, "base")?, build(&copies.1, "new")?);
    let mut queries = Vec::new();
    for case in cases {
        for &algorithm in &config.algorithms {
            for &seed in &config.seeds {
                queries.push((
                    case,
                    algorithm,
                    QueryRuns {
                        name: case.name.clone(),
                        kind: case.kind,
                        model: case.model,
                        algorithm: algorithm.name().to_string(),
                        seed,
                        baseline: Vec::new(),
                        new: Vec::new(),
                    },
                ));
            }
        }
    }
    for round in 0..config.rounds.max(1) {
        progress(&format!("round {}/{}: {} queries on each build", round + 1, config.rounds.max(1), queries.len()));
        for (case, algorithm, runs) in &mut queries {
            runs.baseline.push(a.answer(case, *algorithm, runs.seed, config.threads)?);
            runs.new.push(b.answer(case, *algorithm, runs.seed, config.threads)?);
        }
    }
    let queries: Vec<QueryRuns> = queries.into_iter().map(|(_, _, q)| q).collect();
    let mut keys: Vec<(String, MapKind, Model)> =
        queries.iter().map(|q| (q.algorithm.clone(), q.kind, q.model)).collect();
    keys.sort();
    keys.dedup();
    let groups = keys
        .into_iter()
        .map(|(algorithm, kind, model)| {
            let members: Vec<&QueryRuns> =
                queries.iter().filter(|q| q.algorithm == algorithm && q.kind == kind && q.model == model).collect();
            group_row(&algorithm, kind, model, &members, floors.iter().find(|f| f.0 == model).map(|f| f.1))
        })
        .collect();
    let against_cylinders = against_cylinders(&queries);
    Ok(Comparison {
        baseline: baseline_dir.to_path_buf(),
        new: new_dir.to_path_buf(),
        rounds: config.rounds.max(1),
        threads: config.threads,
        through: config.through,
        floors: floors.to_vec(),
        groups,
        against_cylinders,
        queries,
    })
}

/// What a query on a voxel or OctoMap map costs against one on a cylinder map, in
/// each build: the measure of "an OctoMap map as cheap as cylinders".
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct AgainstCylinders {
    /// Algorithm name.
    pub algorithm: String,
    /// Model.
    pub model: Model,
    /// The voxel or OctoMap kind.
    pub kind: MapKind,
    /// Queries compared.
    pub queries: usize,
    /// The baseline's median ratio of `micros` (> 1: dearer than cylinders).
    pub baseline: f64,
    /// The same for this build.
    pub new: f64,
}

/// Per algorithm, model and voxel or OctoMap kind: a [`MapKind::Voxels`] query
/// against the same SPEC map as cylinders (`voxels_03` against `numerical_03`, same
/// seed), the median of those ratios; the building against itself as boxes
/// ([`MapKind::BuildingBoxes`], same seed) when that was run; the real scan (or the
/// building without its boxes) against the median of the SPEC maps' queries with
/// its seed (there is no same scene in cylinders), the median over its queries. Each
/// query's time is its median over the rounds.
pub fn against_cylinders(queries: &[QueryRuns]) -> Vec<AgainstCylinders> {
    // The queries of maps of `kind` asked as `q` is (algorithm, model, seed).
    fn asked_as<'a>(queries: &'a [QueryRuns], q: &'a QueryRuns, kind: MapKind) -> impl Iterator<Item = &'a QueryRuns> {
        queries
            .iter()
            .filter(move |c| c.kind == kind && c.algorithm == q.algorithm && c.model == q.model && c.seed == q.seed)
    }
    let ratios = |q: &QueryRuns, pick: fn(&QueryRuns) -> &[SolveRun]| -> Option<f64> {
        let on_cylinders = match (q.kind, asked_as(queries, q, MapKind::BuildingBoxes).next()) {
            (MapKind::Voxels, _) => {
                let same = q.name.strip_prefix("voxels_")?;
                median_micros(pick(
                    asked_as(queries, q, MapKind::Numerical)
                        .find(|c| c.name.strip_prefix("numerical_") == Some(same))?,
                ))
            }
            (MapKind::Building, Some(boxes)) => median_micros(pick(boxes)),
            _ => median(
                &mut asked_as(queries, q, MapKind::Numerical)
                    .map(|c| median_micros(pick(c)))
                    .filter(|m| m.is_finite())
                    .collect::<Vec<_>>(),
            ),
        };
        let ratio = median_micros(pick(q)) / on_cylinders;
        ratio.is_finite().then_some(ratio)
    };
    let mut keys: Vec<(String, Model, MapKind)> = queries
        .iter()
        .filter(|q| matches!(q.kind, MapKind::Voxels | MapKind::Octomap | MapKind::Building))
        .map(|q| (q.algorithm.clone(), q.model, q.kind))
        .collect();
    keys.sort();
    keys.dedup();
    keys.into_iter()
        .filter_map(|(algorithm, model, kind)| {
            let members: Vec<&QueryRuns> =
                queries.iter().filter(|q| q.algorithm == algorithm && q.model == model && q.kind == kind).collect();
            let mut base: Vec<f64> = members.iter().filter_map(|q| ratios(q, |q| &q.baseline)).collect();
            let mut new: Vec<f64> = members.iter().filter_map(|q| ratios(q, |q| &q.new)).collect();
            (!new.is_empty()).then(|| AgainstCylinders {
                algorithm,
                model,
                kind,
                queries: new.len(),
                baseline: median(&mut base),
                new: median(&mut new),
            })
        })
        .collect()
}

fn group_row(algorithm: &str, kind: MapKind, model: Model, members: &[&QueryRuns], floor: Option<f64>) -> GroupRow {
    let base: Vec<f64> = members.iter().map(|q| median_micros(&q.baseline)).collect();
    let new: Vec<f64> = members.iter().map(|q| median_micros(&q.new)).collect();
    let evaluations: Vec<f64> =
        members.iter().map(|q| q.new.first().map_or(f64::NAN, |r| r.answer.evaluations.total as f64)).collect();
    let finite = |v: Vec<f64>| -> Vec<f64> { v.into_iter().filter(|x| x.is_finite()).collect() };
    let ratios = finite(base.iter().zip(&new).map(|(b, n)| b / n).collect());
    let multiple = |micros: &[f64]| {
        floor.map(|f| median(&mut finite(micros.iter().zip(&evaluations).map(|(m, e)| m / (e * f)).collect())))
    };
    let differing = members.iter().filter(|q| !q.identical()).count();
    let (b, n) = (median(&mut finite(base.clone())), median(&mut finite(new.clone())));
    GroupRow {
        algorithm: algorithm.to_string(),
        kind,
        model,
        queries: members.len(),
        baseline_micros: b,
        new_micros: n,
        ratio: b / n,
        median_query_ratio: median(&mut ratios.clone()),
        identical: differing == 0,
        differing,
        evaluations: median(&mut finite(evaluations.clone())),
        new_floor_multiple: multiple(&new),
        baseline_floor_multiple: multiple(&base),
    }
}

impl Comparison {
    /// The table: one line per group, then the overall verdict on answers.
    pub fn table(&self) -> String {
        let mut out = String::new();
        for (model, floor) in &self.floors {
            let _ = writeln!(out, "floor ({}): {floor:.4} µs per evaluation of a feasible candidate", model.name());
        }
        out.push('\n');
        let (l, r) = (Align::Left, Align::Right);
        let columns = [("algorithm", l), ("maps", l), ("model", l), ("queries", r), ("baseline µs", r), ("new µs", r)];
        let more =
            [("ratio", r), ("median query ratio", r), ("evaluations", r), ("× floor (new / base)", r), ("answers", l)];
        table::header(&mut out, &[&columns[..], &more].concat());
        for g in &self.groups {
            let floor = match (g.new_floor_multiple, g.baseline_floor_multiple) {
                (Some(n), Some(b)) => format!("{n:.1} / {b:.1}"),
                _ => "–".into(),
            };
            let answers = if g.identical { "identical".to_string() } else { format!("{} DIFFER", g.differing) };
            let cells = [g.algorithm.clone(), g.kind.name().into(), g.model.name().into(), g.queries.to_string()];
            let numbers = [g.baseline_micros, g.new_micros].map(|v| format!("{v:.0}"));
            let ratios = [g.ratio, g.median_query_ratio].map(|v| format!("{v:.2}"));
            table::row(
                &mut out,
                &[&cells[..], &numbers, &ratios, &[format!("{:.0}", g.evaluations), floor, answers]].concat(),
            );
        }
        let differing: usize = self.groups.iter().map(|g| g.differing).sum();
        let via = match self.through {
            Through::Solve => format!("`dyfos solve` --threads {}", self.threads),
            Through::Daemon => "each build's `dyfosd`".to_string(),
        };
        let _ = writeln!(
            out,
            "\n{} queries, {} rounds, through {via}: {}",
            self.queries.len(),
            self.rounds,
            if differing == 0 { "every answer identical".to_string() } else { format!("{differing} queries DIFFER") }
        );
        if !self.against_cylinders.is_empty() {
            let _ = writeln!(
                out,
                "\nAgainst the cylinder maps (median `micros` ratio; voxels: each map against the same SPEC map as \
                 cylinders; building: against itself as boxes when `building-boxes` ran; else the SPEC maps' median):\n"
            );
            let columns = [("algorithm", l), ("maps", l), ("model", l), ("queries", r), ("baseline", r), ("new", r)];
            table::header(&mut out, &columns);
            for a in &self.against_cylinders {
                let cells = [a.algorithm.clone(), a.kind.name().into(), a.model.name().into(), a.queries.to_string()];
                table::row(&mut out, &[&cells[..], &[a.baseline, a.new].map(|v| format!("{v:.2}"))].concat());
            }
        }
        out
    }
}

/// A feasible candidate of `scenario` on its map without obstacles: the first of a
/// few fixed ones the workspace admits.
fn floor_candidate(lupp: &Lupp) -> Option<SensorState> {
    let s = lupp.space();
    let mid = 0.5 * (s.lo[0] + s.hi[0]);
    (0..8)
        .map(|k| SensorState::new(mid, 0.1, -0.1, -3.0 + 0.75 * f64::from(k)))
        .find(|x| matches!(lupp.evaluate(x), Evaluation::Feasible { .. }))
}

/// The evaluation floor, µs: one [`Lupp::evaluate`] of a fixed feasible candidate,
/// on SPEC §10 map 0 (seed [`MAP_SEED`]) with its obstacles removed, scored with
/// `model` (`learned`: `data/learned/model.bin`); the median of 5 timed loops of `iterations` evaluations.
pub fn evaluation_floor(model: Model, data: &Path, iterations: u64) -> anyhow::Result<f64> {
    let kind = if model == Model::Anisotropic { ModelKind::Anisotropic } else { ModelKind::Paper };
    let mut scenario = numerical_map(MAP_SEED, 0, &NumericalConfig::paper().model(kind));
    let weights = match model {
        Model::Learned => {
            scenario.params.model = ModelKind::Learned;
            let file = data.join("learned/model.bin");
            Some(load_model(&file).with_context(|| format!("cannot load {}", file.display()))?)
        }
        _ => None,
    };
    let noise = NoiseModel::from_params_and_weights(&scenario.params, weights.as_ref())?;
    let world = World::new(0, *scenario.world.bounds(), *scenario.world.sun(), [], None)?;
    let lupp = Lupp::new(&world, &scenario.belief, &scenario.params, &noise);
    let x = floor_candidate(&lupp).context("no feasible candidate for the floor")?;
    let iterations = iterations.max(1);
    let mut times: Vec<f64> = (0..5)
        .map(|_| {
            let started = Instant::now();
            for _ in 0..iterations {
                std::hint::black_box(lupp.evaluate(std::hint::black_box(&x)));
            }
            started.elapsed().as_secs_f64() * 1e6 / iterations as f64
        })
        .collect();
    Ok(median(&mut times))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(micros: f64, cost: f64) -> SolveRun {
        let evaluations = EvalStats { total: 10, ..EvalStats::default() };
        SolveRun { micros, answer: AnswerBits { x: Some([1, 2, 3, 4]), cost: Some(cost.to_bits()), evaluations } }
    }

    fn query(baseline: Vec<SolveRun>, new: Vec<SolveRun>) -> QueryRuns {
        let (kind, model) = (MapKind::Numerical, Model::Paper);
        QueryRuns { name: "m".into(), kind, model, algorithm: "dyfos".into(), seed: 1, baseline, new }
    }

    #[test]
    fn one_differing_bit_is_a_differing_answer() {
        let same = query(vec![run(200.0, -3.0)], vec![run(100.0, -3.0)]);
        assert!(same.identical());
        let next = f64::from_bits((-3.0f64).to_bits() + 1);
        let differs = query(vec![run(200.0, -3.0)], vec![run(100.0, next)]);
        assert!(!differs.identical());
        let row = group_row("dyfos", MapKind::Numerical, Model::Paper, &[&same, &differs], Some(2.0));
        assert_eq!((row.queries, row.differing, row.identical), (2, 1, false));
        assert_eq!((row.baseline_micros, row.new_micros, row.ratio), (200.0, 100.0, 2.0));
        // 100 µs over 10 evaluations × 2 µs.
        assert_eq!(row.new_floor_multiple, Some(5.0));
    }

    #[test]
    fn voxel_maps_are_set_against_the_same_maps_as_cylinders() {
        let q = |name: &str, kind, base: f64, new: f64| QueryRuns {
            name: name.into(),
            kind,
            baseline: vec![run(base, -3.0)],
            new: vec![run(new, -3.0)],
            ..query(vec![], vec![])
        };
        let all = [
            q("numerical_00", MapKind::Numerical, 100.0, 50.0),
            q("numerical_01", MapKind::Numerical, 400.0, 200.0),
            q("numerical_02", MapKind::Numerical, 300.0, 100.0),
            q("voxels_00", MapKind::Voxels, 300.0, 100.0),
            q("voxels_01", MapKind::Voxels, 400.0, 300.0),
            q("geb079", MapKind::Octomap, 600.0, 150.0),
            q("building", MapKind::Building, 2000.0, 1200.0),
            q("building-boxes", MapKind::BuildingBoxes, 500.0, 400.0),
        ];
        let got = against_cylinders(&all);
        assert_eq!(got.len(), 3, "{got:?}");
        let building = got.iter().find(|a| a.kind == MapKind::Building).unwrap();
        // Against itself as boxes, not the SPEC maps.
        assert_eq!((building.baseline, building.new), (4.0, 3.0));
        let alone = against_cylinders(&all[..all.len() - 1]);
        let building = alone.iter().find(|a| a.kind == MapKind::Building).unwrap();
        assert_eq!((building.baseline, building.new), (2000.0 / 300.0, 12.0));
        let voxels = got.iter().find(|a| a.kind == MapKind::Voxels).unwrap();
        // Pairs by map: 300/100 and 400/400 against 100/50 and 300/200, not the medians' 350/300.
        assert_eq!((voxels.queries, voxels.baseline, voxels.new), (2, 2.0, 1.75));
        let octomap = got.iter().find(|a| a.kind == MapKind::Octomap).unwrap();
        // Against the SPEC maps' median: 300 µs and 100 µs.
        assert_eq!((octomap.baseline, octomap.new), (2.0, 1.5));
    }

    #[test]
    fn the_floor_is_a_positive_time_per_evaluation() {
        let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/data");
        for model in [Model::Paper, Model::Learned] {
            let floor = evaluation_floor(model, &data, 1000).unwrap();
            assert!(floor > 0.0 && floor < 1e4, "{model:?}: {floor}");
        }
        assert!(evaluation_floor(Model::Learned, Path::new("/nonexistent"), 10).is_err());
    }

    #[test]
    fn every_kind_and_model_has_a_name_it_is_read_back_from() {
        for k in MapKind::ALL {
            assert_eq!(MapKind::from_name(k.name()), Some(k));
        }
        for m in [Model::Paper, Model::Anisotropic, Model::Learned] {
            assert_eq!(Model::from_name(m.name()), Some(m));
        }
        for t in [Through::Solve, Through::Daemon] {
            assert_eq!(Through::from_name(t.name()), Some(t));
            assert_eq!(serde_json::to_value(t).unwrap(), t.name());
        }
    }
}
