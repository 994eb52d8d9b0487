//! `dyfos-rover`: a simulated perception-denied rover playing the paper's rendezvous
//! loop (SPEC §9) with a `dyfos-viewer`. A thin layer over [`dyfos_mission::rover`].
//!
//! Exit codes: 0 at the goal; 2 for bad flags or a bad mission file; 1 otherwise
//! (no viewer, stopped by a signal, iceoryx2 failure).

use anyhow::Context;
use clap::Parser;
use dyfos_mission::eval::McapProfile;
use dyfos_mission::mission::Mission;
use dyfos_mission::rover::{RoverConfig, run_rover};
use dyfos_process::shutdown;
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

/// A simulated rover with no exteroception: dead-reckons between waypoints and asks
/// a viewer to measure it at each one.
#[derive(Debug, Parser)]
#[command(name = "dyfos-rover", version, about, long_about = None)]
struct Cli {
    #[command(flatten)]
    topics: dyfos_mission::cli::TopicArgs,
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
    /// Write every event as a JSON line to this file.
    #[arg(long)]
    events: Option<PathBuf>,
    /// Write the mission as an MCAP file here at exit (its true and estimated poses, rendezvous, measurements and APE), for Foxglove.
    #[arg(long)]
    mcap: Option<PathBuf>,
    /// Encoding of the --mcap file: `foxglove` (JSON with Foxglove's schemas) or `ros2`
    /// (CDR with ROS 2 message definitions, as rosbag2 writes: `ros2 bag play`, RViz).
    #[arg(long, value_enum, default_value_t = McapProfile::Foxglove)]
    mcap_profile: McapProfile,
}

fn seconds(name: &str, v: f64) -> anyhow::Result<Duration> {
    Duration::try_from_secs_f64(v).map_err(|_| anyhow::anyhow!("--{name} = {v} must be a number of seconds ≥ 0"))
}

fn config(cli: &Cli) -> anyhow::Result<RoverConfig> {
    let mission = Mission::load(cli.mission.as_deref())?;
    if !(cli.time_scale.is_finite() && cli.time_scale >= 0.0) {
        anyhow::bail!("--time-scale = {} must be ≥ 0 (0: as fast as possible)", cli.time_scale);
    }
    let topics = cli.topics.topics();
    Ok(RoverConfig {
        time_scale: (cli.time_scale > 0.0).then_some(cli.time_scale),
        measurement_timeout: seconds("measurement-timeout", cli.measurement_timeout)?,
        viewer_timeout: seconds("viewer-timeout", cli.viewer_timeout)?,
        presence_timeout: seconds("presence-timeout", cli.presence_timeout)?,
        linger: seconds("linger", cli.linger)?,
        dead_reckoning: cli.dead_reckoning,
        events: cli.events.clone(),
        mcap: cli.mcap.clone(),
        mcap_profile: cli.mcap_profile,
        ..RoverConfig::new(topics, mission, cli.seed)
    })
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    dyfos_process::logging::init();
    let config = match config(&cli) {
        Ok(c) => c,
        Err(e) => {
            eprintln!("dyfos-rover: {e:#}");
            return ExitCode::from(2);
        }
    };
    shutdown::install();
    let code = match run_rover(&config, &shutdown::requested).context("mission failed") {
        Ok(_) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("dyfos-rover: {e:#}");
            ExitCode::from(1)
        }
    };
    // Say how many lines the rate limit left out in the last window.
    dyfos_process::logging::flush();
    code
}

#[cfg(test)]
mod cli_tests {
    /// Every number a dyfos command prints can be pasted back, `-7.08e-06` included.
    #[test]
    fn every_numeric_flag_takes_negative_numbers_in_any_notation() {
        dyfos_process::cli::assert_numeric_flags_take_signs(&<super::Cli as clap::CommandFactory>::command());
    }
}
