//! `dyfos-link`: carries one mission's topics between the rover's host and the
//! viewer's host over Zenoh. Run one on each host. A thin layer over [`dyfos_link`].
//!
//! Exit codes: 0 when stopped by SIGINT/SIGTERM (or after `--exit-after`); 2 for
//! bad flags or credentials; 1 otherwise (Zenoh or iceoryx2 failure).

use clap::Parser;
use dyfos_link::health::{Counts, Health, TALLIES};
use dyfos_link::{Link, LinkConfig, LinkStartError, Side};
use dyfos_process::shutdown;
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

/// Carries a mission's topics (rendezvous, measurements, heartbeats, acknowledgements,
/// estimates) between the rover's and the viewer's hosts over Zenoh.
#[derive(Debug, Parser)]
#[command(name = "dyfos-link", version, about, long_about = None)]
struct Cli {
    /// Which host this is: `rover` or `viewer`.
    #[arg(long, value_parser = parse_side)]
    side: Side,
    #[command(flatten)]
    topics: dyfos_mission::cli::TopicArgs,
    /// Zenoh endpoint to listen on, e.g. tcp/0.0.0.0:7447 (repeatable).
    #[arg(long)]
    listen: Vec<String>,
    /// Zenoh endpoint of the other host, e.g. tcp/10.0.0.1:7447 (repeatable; retried until it answers).
    #[arg(long)]
    connect: Vec<String>,
    /// File with one line `user:password`, the same on both hosts: only peers with
    /// these credentials may connect, and only the mission's topics pass.
    #[arg(long)]
    credentials: Option<PathBuf>,
    /// Without --credentials, run anyway (a trusted, closed network only).
    #[arg(long)]
    insecure: bool,
    /// A peer silent for this many seconds is disconnected (and reconnected when it answers).
    #[arg(allow_hyphen_values = true, long, default_value_t = 3.0)]
    lease: f64,
    /// Exit after this many seconds (0: run until stopped).
    #[arg(allow_hyphen_values = true, long, default_value_t = 0.0)]
    exit_after: f64,
}

/// Where Zenoh logs a refused peer.
const REFUSALS: &str = "zenoh_transport::unicast::establishment::accept";

fn parse_side(s: &str) -> Result<Side, String> {
    match s {
        "rover" => Ok(Side::Rover),
        "viewer" => Ok(Side::Viewer),
        _ => Err(format!("unknown side `{s}`; choose rover or viewer")),
    }
}

fn config(cli: &Cli) -> anyhow::Result<(LinkConfig, Option<Duration>)> {
    if cli.credentials.is_none() && !cli.insecure {
        anyhow::bail!(
            "give the mission's credentials with --credentials FILE (one line `user:password`, the same file on both hosts), or --insecure on a closed network"
        );
    }
    let lease = Duration::try_from_secs_f64(cli.lease)
        .map_err(|_| anyhow::anyhow!("--lease = {} must be a number of seconds > 0", cli.lease))?;
    let exit_after = Duration::try_from_secs_f64(cli.exit_after)
        .map_err(|_| anyhow::anyhow!("--exit-after = {} must be a number of seconds ≥ 0", cli.exit_after))?;
    let topics = cli.topics.topics();
    let config = LinkConfig {
        listen: cli.listen.clone(),
        connect: cli.connect.clone(),
        credentials: cli.credentials.clone(),
        lease,
        ..LinkConfig::new(topics, cli.side)
    };
    Ok((config, (!exit_after.is_zero()).then_some(exit_after)))
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    // Zenoh says why it refused a peer (no or wrong credentials) only at debug
    // level: those lines are shown, rate-limited like warnings. Handshakes it gave
    // up on and failed attempts to reach the other host are counted and reported.
    dyfos_process::logging::init_with("info", &[REFUSALS], &TALLIES);
    let (config, exit_after) = match config(&cli) {
        Ok(c) => c,
        Err(e) => {
            eprintln!("dyfos-link: {e:#}");
            return ExitCode::from(2);
        }
    };
    shutdown::install();
    let link = match Link::start(&config) {
        Ok(l) => l,
        Err(e) => {
            eprintln!("dyfos-link: {e}");
            let bad_input = matches!(
                e,
                LinkStartError::MissionName(_) | LinkStartError::NoEndpoint | LinkStartError::Credentials { .. }
            );
            return ExitCode::from(if bad_input { 2 } else { 1 });
        }
    };
    let start = std::time::Instant::now();
    let mut connected = false;
    let mut health = Health::new(dyfos_process::logging::WINDOW);
    while !shutdown::requested() && exit_after.is_none_or(|d| start.elapsed() < d) {
        for line in health.report(std::time::Instant::now(), &Counts::now()) {
            tracing::warn!("{line}");
        }
        let now = link.connected();
        if now != connected {
            connected = now;
            if now {
                tracing::info!("the other host is connected");
            } else {
                tracing::warn!("the other host is not connected");
            }
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    let stats = link.stop();
    tracing::info!(sent = stats.sent, received = stats.received, dropped = stats.dropped, "link stopped");
    dyfos_process::logging::flush();
    ExitCode::SUCCESS
}

dyfos_process::numeric_flags_test!(super::Cli);
