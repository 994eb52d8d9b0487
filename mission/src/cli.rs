//! What every mission process shares: the rover, the viewer and the link between
//! hosts name a mission's topics the same way; the rover and the viewer read their
//! mission, pace and timeouts the same way and exit with the same codes.

use std::process::ExitCode;
use std::time::Duration;

/// The flags that name a mission's topics, the same in `dyfos-rover`, `dyfos-viewer`
/// and `dyfos-link` (`#[command(flatten)]`): the two ends of a mission, and the link
/// between hosts, find each other by them.
#[derive(Debug, Clone, clap::Args)]
pub struct TopicArgs {
    /// Service-name prefix of the mission topics (and of the daemon, for the rover and viewer).
    #[arg(long, default_value = dyfos_shared::wire::DEFAULT_PREFIX)]
    pub prefix: String,
    /// iceoryx2 domain (file prefix), as given to `dyfosd --domain`.
    #[arg(long)]
    pub domain: Option<String>,
    /// Mission name (letters, digits, `-`, `_`, `.`): the rover, its viewer and their links use the same.
    #[arg(long, default_value = "default")]
    pub mission_name: String,
}

impl TopicArgs {
    /// Where the mission's topics are.
    pub fn topics(&self) -> crate::mission::topics::TopicsConfig {
        crate::mission::topics::TopicsConfig {
            prefix: self.prefix.clone(),
            domain: self.domain.clone(),
            mission: self.mission_name.clone(),
        }
    }
}

/// The flags that say what a rover or viewer writes down, the same in both.
#[derive(Debug, Clone, clap::Args)]
pub struct OutputArgs {
    /// Write every event as a JSON line to this file.
    #[arg(long)]
    pub events: Option<std::path::PathBuf>,
    /// Write the mission as this process saw it as an MCAP file here at exit, for
    /// Foxglove: the rover its true and estimated poses, rendezvous, measurements and
    /// APE; the viewer the rendezvous beliefs, the daemon's answers, its measurements
    /// and poses.
    #[arg(long)]
    pub mcap: Option<std::path::PathBuf>,
    /// Encoding of the --mcap file: `foxglove` (JSON with Foxglove's schemas) or `ros2`
    /// (CDR with ROS 2 message definitions, as rosbag2 writes: `ros2 bag play`, RViz).
    #[arg(long, value_enum, default_value_t = crate::eval::McapProfile::Foxglove)]
    pub mcap_profile: crate::eval::McapProfile,
}

impl OutputArgs {
    /// What the flags ask to write.
    pub fn config(&self) -> crate::mission::output::OutputConfig {
        crate::mission::output::OutputConfig {
            events: self.events.clone(),
            mcap: self.mcap.clone(),
            mcap_profile: self.mcap_profile,
        }
    }
}

/// `--NAME = v` as a wall-clock duration (seconds ≥ 0).
pub fn seconds(name: &str, v: f64) -> anyhow::Result<Duration> {
    Duration::try_from_secs_f64(v).map_err(|_| anyhow::anyhow!("--{name} = {v} must be a number of seconds ≥ 0"))
}

/// `--time-scale`: simulated seconds per wall second, `None` (given as 0) for as fast
/// as possible.
pub fn time_scale(v: f64) -> anyhow::Result<Option<f64>> {
    if !(v.is_finite() && v >= 0.0) {
        anyhow::bail!("--time-scale = {v} must be ≥ 0 (0: as fast as possible)");
    }
    Ok((v > 0.0).then_some(v))
}

/// The `main` of a mission process: logging, its configuration from the flags (exit
/// 2 if they are wrong), the signal latch, the run (exit 0 if it succeeds, else 1,
/// the error after `name: ` on stderr with `context`), and the log's last count of
/// lines the rate limit left out.
pub fn main<C, R, E>(
    name: &str,
    context: &'static str,
    config: impl FnOnce() -> anyhow::Result<C>,
    run: impl FnOnce(&C, &dyn Fn() -> bool) -> Result<R, E>,
) -> ExitCode
where
    E: std::error::Error + Send + Sync + 'static,
{
    use anyhow::Context;
    dyfos_process::logging::init();
    let config = match config() {
        Ok(c) => c,
        Err(e) => {
            eprintln!("{name}: {e:#}");
            return ExitCode::from(2);
        }
    };
    dyfos_process::shutdown::install();
    let code = match run(&config, &dyfos_process::shutdown::requested).context(context) {
        Ok(_) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("{name}: {e:#}");
            ExitCode::from(1)
        }
    };
    dyfos_process::logging::flush();
    code
}
