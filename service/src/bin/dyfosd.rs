//! `dyfosd`: the DyFOS optimizer daemon. Robot processes on this computer query it
//! over iceoryx2 shared memory (see `dyfos_client`).
//!
//! Configuration ([`DaemonConfig`], every key in docs/daemon.md): the defaults,
//! over them a TOML file (`--config`), over that each `--set KEY=VALUE`, over that
//! the flags below. Logs go to stderr through `tracing`; `RUST_LOG` filters them
//! (default `info`), iceoryx2's own log included (`IOX2_LOG_LEVEL`, default warn).
//!
//! Exit codes: 0 after SIGINT/SIGTERM once the queries in flight are answered;
//! 2 for a bad flag, configuration or model file; 1 if the daemon cannot start.

use clap::{CommandFactory, Parser};
use dyfos_service::daemon::{Daemon, DaemonConfig, DaemonCreateError, HOUSEKEEPING, WaitOutcome, former_flag};
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

/// The DyFOS optimizer daemon: answers rendezvous queries from robot processes.
#[derive(Debug, Parser)]
#[command(name = "dyfosd", version, long_about = None)]
struct Cli {
    /// Service-name prefix; clients must use the same (default `dyfos/`).
    #[arg(long)]
    prefix: Option<String>,
    /// Directory where maps are persisted (default `$XDG_STATE_HOME/dyfos` or `~/.local/state/dyfos`).
    #[arg(long)]
    state_dir: Option<PathBuf>,
    /// iceoryx2 file prefix: only processes of the same domain see each other (default iceoryx2's `iox2_`).
    #[arg(long)]
    domain: Option<String>,
    /// Search worker threads (default: one per core, at least 2).
    #[arg(long)]
    workers: Option<usize>,
    /// Model file of the learned SDSMM (from `dyfos train`), for queries with model `learned`.
    #[arg(long, value_name = "FILE")]
    model: Option<PathBuf>,
    /// Record every accepted request with its reply, every map change and the
    /// configuration to this MCAP file (off by default; see docs/record.md).
    #[arg(long, value_name = "FILE.mcap")]
    record: Option<PathBuf>,
    /// TOML file with any of the keys of docs/daemon.md, in tables `[limits]`,
    /// `[scheduling]`, `[recording]`; `--set` and the flags above win over it.
    #[arg(long, value_name = "FILE")]
    config: Option<PathBuf>,
    /// Set one key of the configuration, e.g. `--set scheduling.cpu_latency_us=200`
    /// or `--set limits.max_queued=64` (value in TOML; repeatable; wins over --config).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    set: Vec<String>,
    /// Print the configuration these flags make, as TOML, and exit.
    #[arg(long)]
    print_config: bool,
}

/// The configuration: defaults, file, `--set`s, then the flags; validated.
fn config(cli: &Cli) -> Result<DaemonConfig, dyfos_service::daemon::ConfigError> {
    let mut c = DaemonConfig::load(cli.config.as_deref(), &cli.set)?;
    if let Some(p) = &cli.prefix {
        c.prefix = p.clone();
    }
    if let Some(d) = &cli.state_dir {
        c.state_dir = d.clone();
    }
    if let Some(d) = &cli.domain {
        c.domain = Some(d.clone());
    }
    if let Some(w) = cli.workers {
        c.workers = w;
    }
    if let Some(m) = &cli.model {
        c.model = Some(m.clone());
    }
    if let Some(r) = &cli.record {
        c.recording.path = Some(r.clone());
    }
    c.validate()?;
    Ok(c)
}

/// For a command line clap refused: what became of the first flag in it that
/// `dyfosd` no longer has.
fn former_flag_in(args: &[String]) -> Option<String> {
    let command = Cli::command();
    let current: Vec<&str> = command.get_arguments().filter_map(|a| a.get_long()).collect();
    args.iter()
        .filter(|a| a.starts_with("--"))
        .filter(|a| !current.contains(&a[2..].split('=').next().unwrap_or("")))
        .find_map(|a| former_flag(a))
}

/// Serves until SIGINT/SIGTERM: answer, keep polling for the daemon's polling
/// window after the last request (the next one of a burst or of steady traffic
/// then costs no wake-up), then sleep.
fn serve(mut daemon: Daemon) {
    let mut last_work = Instant::now();
    let mut rounds: u32 = 0;
    loop {
        rounds = rounds.wrapping_add(1);
        if daemon.spin() > 0 {
            last_work = Instant::now();
            if rounds.is_multiple_of(64) && daemon.termination_requested() {
                break;
            }
            continue;
        }
        if last_work.elapsed() < daemon.poll_window() {
            if daemon.termination_requested() {
                break;
            }
            // Yield rather than burn the core: a worker or a client may need it.
            std::thread::yield_now();
            continue;
        }
        // Signals end the wait at once; the timeout only paces housekeeping.
        match daemon.wait(HOUSEKEEPING) {
            WaitOutcome::Terminate => break,
            WaitOutcome::Work => last_work = Instant::now(),
            WaitOutcome::Idle => {}
        }
    }
    daemon.shutdown();
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args_os().map(|a| a.to_string_lossy().into_owned()).collect();
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) if e.use_stderr() => match former_flag_in(&args) {
            Some(what) => {
                eprintln!("dyfosd: {what}");
                return ExitCode::from(2);
            }
            None => e.exit(),
        },
        Err(e) => e.exit(),
    };
    dyfos_process::logging::init();
    let config = match config(&cli) {
        Ok(c) => c,
        Err(e) => {
            eprintln!("dyfosd: {e}");
            return ExitCode::from(2);
        }
    };
    if cli.print_config {
        print!("{}", config.to_toml());
        return ExitCode::SUCCESS;
    }
    match Daemon::create(&config) {
        Ok(daemon) => {
            serve(daemon);
            // Say how many lines the rate limit left out in the last window.
            dyfos_process::logging::flush();
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("dyfosd: {e:#}");
            // A bad model file is a configuration error, like a bad flag.
            ExitCode::from(if matches!(e, DaemonCreateError::Model(_)) { 2 } else { 1 })
        }
    }
}

dyfos_process::numeric_flags_test!(super::Cli);

#[cfg(test)]
mod tests {
    use super::*;

    fn cli(args: &[&str]) -> Cli {
        Cli::try_parse_from(std::iter::once("dyfosd").chain(args.iter().copied())).unwrap()
    }

    #[test]
    fn flags_win_over_sets_which_win_over_the_file() {
        let file = std::env::temp_dir().join(format!("dyfosd-flags-{}.toml", std::process::id()));
        std::fs::write(&file, "prefix = \"from-file/\"\nworkers = 3\n[scheduling]\npoll_us = 50\n").unwrap();
        let path = file.to_str().unwrap();
        let c =
            config(&cli(&["--config", path, "--set", "workers=4", "--set", "prefix=set/", "--workers", "5"])).unwrap();
        assert_eq!((c.prefix.as_str(), c.workers, c.scheduling.poll_us), ("set/", 5, 50));
        let c = config(&cli(&["--config", path, "--record", "/tmp/t.mcap", "--set", "recording.keep=2"])).unwrap();
        assert_eq!((c.recording.path.as_deref(), c.recording.keep), (Some(std::path::Path::new("/tmp/t.mcap")), 2));
        std::fs::remove_file(&file).unwrap();
        // The flags are validated with the rest.
        let err = config(&cli(&["--prefix", "a b"])).unwrap_err().to_string();
        assert!(err.contains("prefix = \"a b\" is refused"), "{err}");
        assert!(config(&cli(&["--set", "scheduling.worker_slice_us=99"])).is_err());
    }

    /// `dyfosd --help` shows an operator's few flags; the rest are keys.
    #[test]
    fn at_most_ten_flags_and_former_ones_say_which_key_replaced_them() {
        let flags = Cli::command().get_arguments().count();
        assert!(flags <= 10, "{flags} flags");
        let args = |a: &[&str]| a.iter().map(|s| s.to_string()).collect::<Vec<_>>();
        for (line, want) in [
            (&["dyfosd", "--spin-us", "50"][..], "--spin-us was replaced by the key `scheduling.poll_us`"),
            (
                &["dyfosd", "--workers", "2", "--max-queued=3"],
                "--max-queued=3 was replaced by the key `limits.max_queued`",
            ),
            (&["dyfosd", "--record-max-bytes", "9"], "`recording.max_bytes`"),
            (&["dyfosd", "--legacy-scheduling"], "--legacy-scheduling was removed"),
        ] {
            assert!(Cli::try_parse_from(line).is_err(), "{line:?} parses");
            let said = former_flag_in(&args(line)).unwrap_or_default();
            assert!(said.contains(want), "{line:?}: {said}");
        }
        // A current flag used wrongly is clap's to explain, not taken for a former one.
        assert_eq!(former_flag_in(&args(&["dyfosd", "--record"])), None);
        assert_eq!(former_flag_in(&args(&["dyfosd", "--sett", "x=1"])), None);
    }
}
