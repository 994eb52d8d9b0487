//! `dyfos-rover`: a simulated perception-denied rover playing the paper's rendezvous
//! loop (SPEC §9) with a `dyfos-viewer`. A thin layer over [`dyfos_mission::rover`].
//!
//! Exit codes: 0 at the goal; 2 for bad flags or a bad mission file; 1 otherwise
//! (no viewer, stopped by a signal, iceoryx2 failure).

use clap::Parser;
use dyfos_mission::cli;
use dyfos_mission::mission::Mission;
use dyfos_mission::rover::{RoverConfig, run_rover};
use std::path::PathBuf;
use std::process::ExitCode;

/// A simulated rover with no exteroception: dead-reckons between waypoints and asks
/// a viewer to measure it at each one.
#[derive(Debug, Parser)]
#[command(name = "dyfos-rover", version, about, long_about = None)]
struct Cli {
    #[command(flatten)]
    topics: cli::TopicArgs,
    /// Mission file (scenario + waypoints, see `dyfos_mission::mission`); default: the built-in mission.
    #[arg(long)]
    mission: Option<PathBuf>,
    /// Seed of the true start pose and of the wheel slip.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Simulated seconds per wall second; 0 runs as fast as possible.
    #[arg(allow_hyphen_values = true, long, default_value_t = 20.0)]
    time_scale: f64,
    /// Longest wait for a measurement at a waypoint, wall seconds.
    #[arg(allow_hyphen_values = true, long, default_value_t = 10.0)]
    measurement_timeout: f64,
    /// Longest wait at the start for a viewer, wall seconds.
    #[arg(allow_hyphen_values = true, long, default_value_t = 10.0)]
    viewer_timeout: f64,
    /// A viewer without a heartbeat for this many wall seconds is gone (the rover
    /// dead-reckons until it is back).
    #[arg(allow_hyphen_values = true, long, default_value_t = 2.0)]
    presence_timeout: f64,
    /// At the goal, how long at most to keep offering the finish to a viewer that
    /// has not acknowledged it (and to wait for the estimates' readers), wall
    /// seconds; by default as long as a viewer waits for a silent rover.
    #[arg(allow_hyphen_values = true, long, default_value_t = dyfos_mission::rover::LINGER.as_secs_f64())]
    linger: f64,
    /// Drive without a viewer (no rendezvous, no measurements): the baseline.
    #[arg(long)]
    dead_reckoning: bool,
    #[command(flatten)]
    output: cli::OutputArgs,
}

fn config(cli: &Cli) -> anyhow::Result<RoverConfig> {
    let mission = Mission::load(cli.mission.as_deref())?;
    let time_scale = cli::time_scale(cli.time_scale)?;
    Ok(RoverConfig {
        time_scale,
        measurement_timeout: cli::seconds("measurement-timeout", cli.measurement_timeout)?,
        viewer_timeout: cli::seconds("viewer-timeout", cli.viewer_timeout)?,
        presence_timeout: cli::seconds("presence-timeout", cli.presence_timeout)?,
        linger: cli::seconds("linger", cli.linger)?,
        dead_reckoning: cli.dead_reckoning,
        output: cli.output.config(),
        ..RoverConfig::new(cli.topics.topics(), mission, cli.seed)
    })
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    cli::main("dyfos-rover", "mission failed", || config(&cli), |config, stop| run_rover(config, &stop))
}

dyfos_process::numeric_flags_test!(super::Cli);
