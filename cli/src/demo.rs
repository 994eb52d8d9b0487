//! `dyfos demo`: the paper's simulated evaluation (§V-B, SPEC §10) end to end.
//!
//! Starts `dyfosd` (its own service prefix and a temporary state directory), then
//! for each algorithm a `dyfos-viewer` and a `dyfos-rover` process on the same
//! mission with the same seeds, plus one rover without a viewer (dead reckoning)
//! as the baseline. This process listens to the simulation's ground truth and the
//! rover's estimate, prints the APE table of paper Table I and writes one SVG per
//! algorithm in the style of paper Fig. 5, and one MCAP file per run for Foxglove
//! or ROS 2 (`--mcap-profile`; the recorded truth and estimates, plus the viewer's
//! requests and the daemon's answers from its event log; see
//! [`dyfos_mission::eval::mission_mcap`]). Every child is
//! stopped on exit, on error and on Ctrl-C.
//!
//! With `--hosts 2` each algorithm's rover runs on a second "host" (a network
//! namespace with its own iceoryx2 domain, see [`crate::hosts`]) and the mission
//! crosses a `dyfos-link` pair over Zenoh; the table is the same. The
//! dead-reckoning baseline has no viewer, so it stays on the demo's host.

use crate::Failure;
use crate::hosts::{ROVER_ENDPOINT, TwoHosts};
use anyhow::{Context, anyhow, bail};
use dyfos_client::{Client, ClientConfig};
use dyfos_mission::eval::{ApeStats, McapMission, McapProfile, MissionTrace, Recorder, mean_std, render_svg};
use dyfos_mission::mission::Mission;
use dyfos_mission::mission::log::read_events;
use dyfos_mission::mission::topics::TopicsConfig;
use dyfos_process::child::KillOnDrop;
use dyfos_process::shutdown;
use dyfos_service::launch::DyfosdCommand;
use dyfos_shared::answer::Algorithm;
use dyfos_shared::params::ModelKind;
use dyfos_shared::wire::mission::Observation;
use std::io::{IsTerminal, Write};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// Flags of `dyfos demo`.
#[derive(Debug, clap::Args)]
pub struct DemoArgs {
    /// Mission file: a SPEC §11 scenario plus waypoints (format in `dyfos_mission::mission`).
    /// Default: the built-in mission of SPEC §10 (25 cylinders, 10 waypoints).
    #[arg(long)]
    pub mission: Option<PathBuf>,
    /// Algorithms to compare, comma-separated (dyfos, dyfos-scipy, brute, random, center).
    #[arg(long, value_delimiter = ',', default_value = "dyfos,random,center", value_parser = crate::offline::parse_algorithm)]
    pub algos: Vec<Algorithm>,
    /// First seed; each run uses the same seeds for every algorithm.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Number of seeds (runs per algorithm): the table then shows mean ± std over seeds.
    #[arg(long, default_value_t = 1)]
    pub seeds: u64,
    /// Simulated seconds per wall second; 0 runs as fast as the computer allows.
    #[arg(allow_hyphen_values = true, long, default_value_t = 20.0)]
    pub time_scale: f64,
    /// Directory for the SVGs, the MCAP files (one per run), a JSON summary and the processes' logs.
    #[arg(long, default_value = "dyfos-demo")]
    pub out: PathBuf,
    /// Encodings of the MCAP files, comma-separated: `foxglove` (mission-<run>.mcap,
    /// JSON for Foxglove) and/or `ros2` (mission-<run>-ros2.mcap, CDR as rosbag2 writes it).
    #[arg(long, value_enum, value_delimiter = ',', default_value = "foxglove")]
    pub mcap_profile: Vec<McapProfile>,
    /// Skip the dead-reckoning baseline (a rover without a viewer).
    #[arg(long)]
    pub no_baseline: bool,
    /// Model file of the learned SDSMM, for missions with `"model": "learned"`
    /// (given to dyfosd and to each viewer).
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// 2: run each rover on a second host (a network namespace; needs root) and
    /// carry the mission over `dyfos-link` (Zenoh), as on two robots.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u8).range(1..=2))]
    pub hosts: u8,
}

/// One configuration of the table: an algorithm or the baseline.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Arm {
    Viewer(Algorithm),
    DeadReckoning,
}

impl Arm {
    fn name(self) -> &'static str {
        match self {
            Arm::Viewer(a) => a.name(),
            Arm::DeadReckoning => "dead-reckoning",
        }
    }
}

/// The binaries the demo starts, next to this executable.
struct Binaries {
    dyfosd: PathBuf,
    rover: PathBuf,
    viewer: PathBuf,
    link: Option<PathBuf>,
}

impl Binaries {
    fn locate(link: bool) -> anyhow::Result<Self> {
        let exe = std::env::current_exe().context("cannot find this executable's path")?;
        let dir = exe.parent().ok_or_else(|| anyhow!("{} has no directory", exe.display()))?;
        let find = |name: &str| {
            let p = dir.join(name);
            if p.is_file() {
                Ok(p)
            } else {
                Err(anyhow!(
                    "`dyfos demo` needs `{name}` next to `dyfos` in {}; build every binary with `cargo build --release --workspace` and run ./target/release/dyfos demo",
                    dir.display()
                ))
            }
        };
        Ok(Binaries {
            dyfosd: find("dyfosd")?,
            rover: find("dyfos-rover")?,
            viewer: find("dyfos-viewer")?,
            link: if link { Some(find("dyfos-link")?) } else { None },
        })
    }
}

/// A child process stopped when dropped: SIGTERM, a grace period, then SIGKILL.
struct Proc {
    name: String,
    child: KillOnDrop,
}

impl Proc {
    fn spawn(name: &str, cmd: &mut Command, log: &Path) -> anyhow::Result<Proc> {
        let file = std::fs::File::create(log).with_context(|| format!("cannot create {}", log.display()))?;
        let child = KillOnDrop::spawn(cmd.stdin(Stdio::null()).stdout(Stdio::null()).stderr(file))
            .with_context(|| format!("cannot start {name}"))?;
        Ok(Proc { name: name.to_string(), child })
    }

    /// `Some(success)` once it has exited.
    fn exited(&mut self) -> Option<bool> {
        self.child.try_wait().map(|status| status.success())
    }

    /// Whether it has not been seen to exit.
    fn running(&mut self) -> bool {
        self.child.child_mut().is_some()
    }

    /// SIGTERM, up to `grace` to exit, then SIGKILL. Returns whether it exited cleanly.
    fn stop(&mut self, grace: Duration) -> bool {
        if !self.running() {
            return true;
        }
        match self.child.terminate(grace) {
            Some(status) => status.success(),
            None => {
                tracing::warn!("{} did not stop within {grace:?}; it was killed", self.name);
                false
            }
        }
    }
}

impl Drop for Proc {
    fn drop(&mut self) {
        self.stop(Duration::from_secs(3));
    }
}

/// What one run produced.
struct RunResult {
    arm: Arm,
    seed: u64,
    trace: MissionTrace,
    ape: ApeStats,
}

/// Everything one demo needs, shared by its runs.
struct Demo<'a> {
    args: &'a DemoArgs,
    bins: Binaries,
    mission: &'a Mission,
    prefix: String,
    logs: PathBuf,
    mission_arg: Option<PathBuf>,
    model_arg: Option<PathBuf>,
    waypoints: usize,
    interactive: bool,
    hosts: Option<TwoHosts>,
}

fn interrupted() -> anyhow::Error {
    anyhow!("interrupted; every process it started has been stopped")
}

impl Demo<'_> {
    fn run_one(&self, arm: Arm, seed: u64, index: usize) -> anyhow::Result<RunResult> {
        let name = format!("{}-s{seed}", arm.name());
        let topics = TopicsConfig { prefix: self.prefix.clone(), domain: None, mission: name.clone() };
        let mut recorder = Recorder::open(&topics)?;
        let scale = self.args.time_scale.to_string();
        let common = |cmd: &mut Command| {
            cmd.args(["--prefix", &self.prefix, "--mission-name", &name, "--seed", &seed.to_string()])
                .args(["--time-scale", &scale])
                .env("RUST_LOG", std::env::var("RUST_LOG").unwrap_or_else(|_| "info".into()));
            if let Some(m) = &self.mission_arg {
                cmd.arg("--mission").arg(m);
            }
        };
        // Across two hosts: the links first, the viewer in the viewer's namespace,
        // the rover in the rover's, with its own domain.
        let two = self.hosts.as_ref().filter(|_| arm != Arm::DeadReckoning);
        let mut _links = Vec::new();
        if let (Some(h), Some(link)) = (two, &self.bins.link) {
            for (ns, side, domain, endpoint) in [
                (&h.rover, "rover", Some(h.rover_domain.as_str()), ["--listen", "tcp/0.0.0.0:7447"]),
                (&h.viewer, "viewer", None, ["--connect", ROVER_ENDPOINT]),
            ] {
                let mut cmd = ns.command(link);
                cmd.args(["--side", side, "--prefix", &self.prefix, "--mission-name", &name])
                    .args(endpoint)
                    .arg("--credentials")
                    .arg(&h.credentials)
                    .env("RUST_LOG", std::env::var("RUST_LOG").unwrap_or_else(|_| "info".into()));
                if let Some(d) = domain {
                    cmd.args(["--domain", d]);
                }
                let log = self.logs.join(format!("{name}-link-{side}.log"));
                _links.push(Proc::spawn("dyfos-link", &mut cmd, &log)?);
            }
        }
        let mut viewer = match arm {
            Arm::DeadReckoning => None,
            Arm::Viewer(algo) => {
                let mut cmd = match two {
                    Some(h) => h.viewer.command(&self.bins.viewer),
                    None => Command::new(&self.bins.viewer),
                };
                common(&mut cmd);
                if let Some(m) = &self.model_arg {
                    cmd.arg("--model").arg(m);
                }
                cmd.args(["--algo", algo.name(), "--map-id", &(index + 1).to_string()])
                    .arg("--events")
                    .arg(self.logs.join(format!("{name}-viewer.jsonl")));
                Some(Proc::spawn("dyfos-viewer", &mut cmd, &self.logs.join(format!("{name}-viewer.log")))?)
            }
        };
        let mut cmd = match two {
            Some(h) => {
                let mut cmd = h.rover.command(&self.bins.rover);
                cmd.args(["--domain", &h.rover_domain]);
                cmd
            }
            None => Command::new(&self.bins.rover),
        };
        common(&mut cmd);
        cmd.args(["--viewer-timeout", "30", "--measurement-timeout", "30"])
            .arg("--events")
            .arg(self.logs.join(format!("{name}-rover.jsonl")));
        if arm == Arm::DeadReckoning {
            cmd.arg("--dead-reckoning");
        }
        let rover_log = self.logs.join(format!("{name}-rover.log"));
        let mut rover = Proc::spawn("dyfos-rover", &mut cmd, &rover_log)?;

        let mut shown = (u32::MAX, usize::MAX);
        let ok = loop {
            if shutdown::requested() {
                return Err(interrupted());
            }
            recorder.poll();
            let t = recorder.trace();
            let now = (t.step(), t.updates());
            if now != shown && self.interactive {
                shown = now;
                eprint!(
                    "\r  {:<15} seed {seed}: waypoint {}/{}, {} measured   ",
                    arm.name(),
                    now.0,
                    self.waypoints,
                    now.1
                );
                let _ = std::io::stderr().flush();
            }
            if let Some(ok) = rover.exited() {
                break ok;
            }
            if let Some(v) = viewer.as_mut()
                && v.exited() == Some(false)
                && !recorder.trace().finished()
            {
                bail!("dyfos-viewer ({name}) failed:\n{}", tail(&self.logs.join(format!("{name}-viewer.log"))));
            }
            recorder.wait(Duration::from_millis(100));
        };
        if self.interactive {
            eprint!("\r{:80}\r", "");
        }
        if !ok {
            bail!("dyfos-rover ({name}) failed:\n{}", tail(&rover_log));
        }
        if let Some(v) = viewer.as_mut() {
            // The viewer leaves when the rover says it finished.
            let start = Instant::now();
            while v.running() && v.exited().is_none() && start.elapsed() < Duration::from_secs(10) {
                std::thread::sleep(Duration::from_millis(10));
            }
            v.stop(Duration::from_secs(3));
        }
        let trace = recorder.finish();
        let ape = trace.ape().ok_or_else(|| anyhow!("no samples were recorded for {name}"))?;
        let mut mcap = McapMission::new(self.mission);
        mcap.record_trace(&trace);
        if arm != Arm::DeadReckoning {
            let log = self.logs.join(format!("{name}-viewer.jsonl"));
            let events = read_events(&log).with_context(|| format!("cannot read {}", log.display()))?;
            mcap.record_viewer_events(&events);
        }
        for profile in profiles(&self.args.mcap_profile) {
            mcap.write(&self.args.out.join(mcap_file(&name, profile)), profile)?;
        }
        let observed =
            trace.measurements.iter().filter(|m| matches!(m.observation, Observation::Observed { .. })).count();
        eprintln!(
            "  {:<15} seed {seed}: APE RMSE {:5.1} cm, max {:5.1} cm; {}/{} rendezvous measured",
            arm.name(),
            ape.rmse * 100.0,
            ape.max * 100.0,
            if arm == Arm::DeadReckoning { 0 } else { observed },
            self.waypoints
        );
        Ok(RunResult { arm, seed, trace, ape })
    }
}

/// The last lines of a log, and where the rest is.
fn tail(log: &Path) -> String {
    let text = std::fs::read_to_string(log).unwrap_or_default();
    let last: Vec<&str> = text.lines().rev().take(5).collect();
    format!("{}\n(whole log: {})", last.into_iter().rev().collect::<Vec<_>>().join("\n"), log.display())
}

fn start_daemon(bins: &Binaries, prefix: &str, state: &Path, model: Option<&Path>, log: &Path) -> anyhow::Result<Proc> {
    let file = std::fs::File::create(log).with_context(|| format!("cannot create {}", log.display()))?;
    let child = DyfosdCommand::new(&bins.dyfosd, prefix, state)
        .log(&std::env::var("RUST_LOG").unwrap_or_else(|_| "info".into()), file)
        .args(model.into_iter().flat_map(|m| [std::ffi::OsStr::new("--model"), m.as_os_str()]))
        .spawn()
        .context("cannot start dyfosd")?;
    let mut daemon = Proc { name: "dyfosd".into(), child };
    let config = ClientConfig {
        prefix: prefix.to_string(),
        connect_timeout: Duration::from_millis(100),
        ..ClientConfig::default()
    };
    let start = Instant::now();
    loop {
        if shutdown::requested() {
            return Err(interrupted());
        }
        if daemon.exited().is_some() {
            bail!("dyfosd exited at start; see {}", log.display());
        }
        if Client::connect(&config).is_ok() {
            return Ok(daemon);
        }
        if start.elapsed() > Duration::from_secs(30) {
            bail!("dyfosd did not come up within 30 s; see {}", log.display());
        }
    }
}

/// The table of paper Table I: one column per arm, rows RMSE, median, mean, std,
/// max in cm; with several seeds, mean ± std over seeds.
fn table(results: &[RunResult], arms: &[Arm]) -> String {
    let columns: Vec<(&str, Vec<[f64; 5]>)> = arms
        .iter()
        .map(|arm| (arm.name(), results.iter().filter(|r| r.arm == *arm).map(|r| r.ape.centimetres()).collect()))
        .collect();
    ape_table(&columns)
}

/// The APE table: one column per (name, runs' `ApeStats::centimetres`), rows RMSE,
/// median, mean, std, max in cm; a column of several runs shows mean ± std over them.
pub fn ape_table(columns: &[(&str, Vec<[f64; 5]>)]) -> String {
    let rows = ["RMSE", "Median", "Mean", "Std", "Max"];
    let mut cells: Vec<Vec<String>> = Vec::new();
    for (_, per_seed) in columns {
        let col = (0..5)
            .map(|k| {
                let v: Vec<f64> = per_seed.iter().map(|s| s[k]).collect();
                let (m, s) = mean_std(&v);
                if v.len() > 1 { format!("{m:.1} ± {s:.1}") } else { format!("{m:.1}") }
            })
            .collect();
        cells.push(col);
    }
    let width = cells
        .iter()
        .flatten()
        .map(|c| c.chars().count())
        .chain(columns.iter().map(|(name, _)| name.chars().count()))
        .max()
        .unwrap_or(8)
        + 2;
    let mut out = format!("{:<8}", "APE (cm)");
    for (name, _) in columns {
        out += &format!("{name:>width$}");
    }
    out.push('\n');
    for (k, row) in rows.iter().enumerate() {
        out += &format!("{row:<8}");
        for col in &cells {
            out += &format!("{:>width$}", col[k]);
        }
        out.push('\n');
    }
    out
}

fn summary_json(results: &[RunResult]) -> serde_json::Value {
    let runs: Vec<serde_json::Value> = results
        .iter()
        .map(|r| {
            serde_json::json!({
                "arm": r.arm.name(), "seed": r.seed, "ape_m": r.ape,
                "ape_after_updates_m": r.trace.ape_after_updates(),
                "updates": r.trace.updates(),
                "rendezvous": r.trace.measurements.len(),
            })
        })
        .collect();
    serde_json::json!({ "runs": runs })
}

/// `dyfos demo`. Exit code 130 when interrupted.
pub fn demo(args: &DemoArgs) -> Result<(), Failure> {
    run(args).map_err(|f| if shutdown::requested() { Failure { code: 130, error: f.error } } else { f })
}

fn run(args: &DemoArgs) -> Result<(), Failure> {
    if !(args.time_scale.is_finite() && args.time_scale >= 0.0) {
        return Err(Failure::invalid(anyhow!(
            "--time-scale = {} must be ≥ 0 (0: as fast as possible)",
            args.time_scale
        )));
    }
    if args.seeds == 0 || args.algos.is_empty() {
        return Err(Failure::invalid(anyhow!("give at least one seed and one algorithm")));
    }
    let mission = Mission::load(args.mission.as_deref()).map_err(Failure::invalid)?;
    if mission.params.model == ModelKind::Learned && args.model.is_none() {
        return Err(Failure::invalid(anyhow!(
            "the mission uses the learned SDSMM (`\"model\": \"learned\"`); pass its weights with --model FILE (e.g. tests/data/learned/model.bin)"
        )));
    }
    let bins = Binaries::locate(args.hosts == 2)?;
    shutdown::install();
    let logs = args.out.join("logs");
    std::fs::create_dir_all(&logs).with_context(|| format!("cannot create {}", logs.display()))?;
    let pid = std::process::id();
    let prefix = format!("dyfos-demo-{pid}/");
    let state = std::env::temp_dir().join(format!("dyfos-demo-{pid}"));
    let _state_guard = RemoveOnDrop(state.clone());

    let mut arms: Vec<Arm> = args.algos.iter().map(|a| Arm::Viewer(*a)).collect();
    if !args.no_baseline {
        arms.push(Arm::DeadReckoning);
    }
    eprintln!(
        "dyfos demo: {} mission, {} waypoints over {:.1} m, {} obstacles; {} × {} seed(s); logs in {}",
        if args.mission.is_some() { "the given" } else { "the built-in" },
        mission.waypoints.len(),
        mission.path_length(),
        mission.world.obstacles().len(),
        arms.iter().map(|a| a.name()).collect::<Vec<_>>().join(", "),
        args.seeds,
        logs.display()
    );
    let started = Instant::now();
    let model_arg = args.model.as_ref().map(|p| std::path::absolute(p).unwrap_or_else(|_| p.clone()));
    let hosts = if args.hosts == 2 { Some(TwoHosts::create(&logs)?) } else { None };
    if hosts.is_some() {
        eprintln!("  two hosts: each rover in its own network namespace, the mission over dyfos-link (Zenoh)");
    }
    let mut daemon = start_daemon(&bins, &prefix, &state, model_arg.as_deref(), &logs.join("dyfosd.log"))?;
    let demo = Demo {
        args,
        bins,
        mission: &mission,
        prefix,
        logs: logs.clone(),
        mission_arg: args.mission.as_ref().map(|p| std::path::absolute(p).unwrap_or_else(|_| p.clone())),
        model_arg: model_arg.clone(),
        waypoints: mission.waypoints.len(),
        interactive: std::io::stderr().is_terminal(),
        hosts,
    };
    let mut results = Vec::new();
    for seed in args.seed..args.seed.saturating_add(args.seeds) {
        for (i, arm) in arms.iter().enumerate() {
            results.push(demo.run_one(*arm, seed, i)?);
        }
    }
    if !daemon.stop(Duration::from_secs(10)) {
        tracing::warn!("dyfosd did not stop cleanly; see {}", logs.join("dyfosd.log").display());
    }

    let where_ = if args.mission.is_some() { "given mission" } else { "built-in mission (SPEC §10)" };
    let seeds = if args.seeds == 1 {
        format!("seed {}", args.seed)
    } else {
        format!("seeds {}..={}, mean ± std over seeds", args.seed, args.seed + args.seeds - 1)
    };
    println!("\nAbsolute position error of the rover, {where_}, {seeds}:\n");
    print!("{}", table(&results, &arms));
    for arm in &arms {
        if let Some(r) = results.iter().find(|r| r.arm == *arm && r.seed == args.seed) {
            let title = format!(
                "{} — seed {}: APE RMSE {:.1} cm, max {:.1} cm",
                arm.name(),
                r.seed,
                r.ape.rmse * 100.0,
                r.ape.max * 100.0
            );
            let svg = render_svg(&mission.world, &mission.waypoints, &r.trace, &title);
            let path = args.out.join(format!("mission-{}.svg", arm.name()));
            std::fs::write(&path, svg).with_context(|| format!("cannot write {}", path.display()))?;
        }
    }
    let summary = args.out.join("summary.json");
    std::fs::write(&summary, serde_json::to_string_pretty(&summary_json(&results))?)
        .with_context(|| format!("cannot write {}", summary.display()))?;
    let mcaps: Vec<String> = profiles(&args.mcap_profile)
        .into_iter()
        .map(|p| format!("{} {}/{}", p.name(), args.out.display(), mcap_file("<algorithm>-s<seed>", p)))
        .collect();
    println!(
        "\nSVGs (paper Fig. 5 style): {}/mission-<algorithm>.svg; MCAP: {}; summary: {}; took {:.0} s",
        args.out.display(),
        mcaps.join(", "),
        summary.display(),
        started.elapsed().as_secs_f64()
    );
    Ok(())
}

/// The profiles asked for, each once.
fn profiles(asked: &[McapProfile]) -> Vec<McapProfile> {
    let mut profiles = asked.to_vec();
    profiles.sort();
    profiles.dedup();
    profiles
}

/// The MCAP file of run `name` in `profile`.
fn mcap_file(name: &str, profile: McapProfile) -> String {
    match profile {
        McapProfile::Foxglove => format!("mission-{name}.mcap"),
        McapProfile::Ros2 => format!("mission-{name}-ros2.mcap"),
    }
}

/// Removes a directory tree when dropped.
struct RemoveOnDrop(PathBuf);

impl Drop for RemoveOnDrop {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}
