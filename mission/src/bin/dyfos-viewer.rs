//! `dyfos-viewer`: a simulated flying viewer that asks `dyfosd` where to put its
//! camera for each of the rover's rendezvous, flies there and measures the rover
//! (SPEC §9). A thin layer over [`dyfos_mission::viewer`].
//!
//! Exit codes: 0 when the rover finishes; 2 for bad flags or a bad mission file;
//! 1 otherwise (no daemon, no rover, stopped by a signal).

use anyhow::Context;
use clap::Parser;
use dyfos_client::ClientConfig;
use dyfos_mission::cli;
use dyfos_mission::mission::Mission;
use dyfos_mission::viewer::{ViewerConfig, run_viewer};
use dyfos_shared::answer::Algorithm;
use dyfos_shared::params::ModelKind;
use dyfos_shared::sdsmm::Learned;
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;

/// A simulated viewer: finds the optimal sensor pose with dyfosd, flies there and
/// measures the rover.
#[derive(Debug, Parser)]
#[command(name = "dyfos-viewer", version, about, long_about = None)]
struct Cli {
    #[command(flatten)]
    topics: cli::TopicArgs,
    /// Mission file (scenario + waypoints, see `dyfos_mission::mission`); default: the built-in mission.
    #[arg(long)]
    mission: Option<PathBuf>,
    /// Search algorithm: dyfos, dyfos-scipy, brute, random or center.
    #[arg(long, default_value = "dyfos", value_parser = parse_algorithm)]
    algo: Algorithm,
    /// Seed of the searches and of the camera noise.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// The daemon map id this viewer owns (uploaded at start, replacing any map with this id).
    #[arg(long, default_value_t = 1)]
    map_id: u64,
    /// Simulated seconds per wall second; 0 runs as fast as possible.
    #[arg(allow_hyphen_values = true, long, default_value_t = 20.0)]
    time_scale: f64,
    /// Longest wait for the daemon's answer, wall seconds.
    #[arg(allow_hyphen_values = true, long, default_value_t = 30.0)]
    query_timeout: f64,
    /// Deadline given to the daemon per query, seconds (the best pose so far when it passes).
    #[arg(allow_hyphen_values = true, long, default_value_t = 20.0)]
    deadline: f64,
    /// Longest wait for the rover to reach a rendezvous, wall seconds.
    #[arg(allow_hyphen_values = true, long, default_value_t = 10.0)]
    observe_timeout: f64,
    /// Exit after this many wall seconds without a word from the rover.
    #[arg(allow_hyphen_values = true, long, default_value_t = 120.0)]
    idle_timeout: f64,
    /// A rover without a heartbeat for this many wall seconds is lost (the viewer waits for it).
    #[arg(allow_hyphen_values = true, long, default_value_t = 2.0)]
    presence_timeout: f64,
    /// Exit after this many wall seconds without the rover's heartbeat (it went away).
    #[arg(allow_hyphen_values = true, long, default_value_t = 20.0)]
    rover_timeout: f64,
    /// Longest wait for the daemon at start, wall seconds.
    #[arg(allow_hyphen_values = true, long, default_value_t = 10.0)]
    connect_timeout: f64,
    #[command(flatten)]
    output: cli::OutputArgs,
    /// Model file of the learned SDSMM (from `dyfos train`), for missions with
    /// `"model": "learned"`; give dyfosd the same file.
    #[arg(long)]
    model: Option<PathBuf>,
}

fn parse_algorithm(s: &str) -> Result<Algorithm, String> {
    Algorithm::from_name(s).ok_or_else(|| {
        let names: Vec<_> = Algorithm::ALL.iter().map(|a| a.name()).collect();
        format!("unknown algorithm `{s}`; choose one of {}", names.join(", "))
    })
}

fn config(cli: &Cli) -> anyhow::Result<ViewerConfig> {
    let mission = Mission::load(cli.mission.as_deref())?;
    let time_scale = cli::time_scale(cli.time_scale)?;
    let client = ClientConfig {
        prefix: cli.topics.prefix.clone(),
        domain: cli.topics.domain.clone(),
        connect_timeout: cli::seconds("connect-timeout", cli.connect_timeout)?,
        ..ClientConfig::default()
    };
    let learned = match &cli.model {
        None if mission.params.model == ModelKind::Learned => anyhow::bail!(
            "the mission uses the learned SDSMM (`\"model\": \"learned\"`); pass its weights with --model FILE, the same file as dyfosd's"
        ),
        None => None,
        Some(path) => {
            let bytes = std::fs::read(path).with_context(|| format!("cannot read model file {}", path.display()))?;
            let model = Learned::from_bytes(&bytes).with_context(|| format!("{}", path.display()))?;
            Some(Arc::new(model))
        }
    };
    Ok(ViewerConfig {
        learned,
        map_id: cli.map_id,
        time_scale,
        query_timeout: cli::seconds("query-timeout", cli.query_timeout)?,
        query_deadline: Some(cli::seconds("deadline", cli.deadline)?).filter(|d| !d.is_zero()),
        observe_timeout: cli::seconds("observe-timeout", cli.observe_timeout)?,
        idle_timeout: cli::seconds("idle-timeout", cli.idle_timeout)?,
        presence_timeout: cli::seconds("presence-timeout", cli.presence_timeout)?,
        rover_timeout: cli::seconds("rover-timeout", cli.rover_timeout)?,
        output: cli.output.config(),
        ..ViewerConfig::new(client, cli.topics.topics(), mission, cli.algo, cli.seed)
    })
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    cli::main("dyfos-viewer", "viewer failed", || config(&cli), |config, stop| run_viewer(config, &stop))
}

dyfos_process::numeric_flags_test!(super::Cli);
