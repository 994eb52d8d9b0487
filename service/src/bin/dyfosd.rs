//! `dyfosd`: the DyFOS optimizer daemon. Robot processes on this computer query it
//! over iceoryx2 shared memory (see `dyfos_client`).
//!
//! Configuration: flags, over an optional TOML file (`--config`), over defaults.
//! Logs go to stderr through `tracing`; `RUST_LOG` filters them (default `info`),
//! iceoryx2's own log included (`IOX2_LOG_LEVEL`, default warn).
//!
//! Exit codes: 0 after SIGINT/SIGTERM once the queries in flight are answered;
//! 2 for a bad flag, configuration or model file; 1 if the daemon cannot start.

use anyhow::Context;
use clap::Parser;
use dyfos_service::daemon::{Daemon, DaemonConfig, DaemonCreateError, HOUSEKEEPING, RecordConfig, WaitOutcome};
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::{Duration, Instant};

/// The DyFOS optimizer daemon: answers rendezvous queries from robot processes.
#[derive(Debug, Parser)]
#[command(name = "dyfosd", version, about, long_about = None)]
struct Cli {
    /// Service-name prefix; clients must use the same (default `dyfos/`).
    #[arg(long)]
    prefix: Option<String>,
    /// Directory where maps are persisted (default `$XDG_STATE_HOME/dyfos` or `~/.local/state/dyfos`).
    #[arg(long)]
    state_dir: Option<PathBuf>,
    /// TOML file with any of: prefix, state_dir, domain, workers, spin_us,
    /// max_clients, max_requests_per_client, max_queued, upload_idle_timeout_s, model,
    /// worker_nice, ipc_priority, spin_max_us, queue, worker_batch, worker_yield_us,
    /// worker_slice_us, cpu_latency_us, record,
    /// record_max_bytes, record_keep.
    #[arg(long)]
    config: Option<PathBuf>,
    /// iceoryx2 file prefix: only processes of the same domain see each other (default iceoryx2's `iox2_`).
    #[arg(long)]
    domain: Option<String>,
    /// Search worker threads (default: one per core, at least 2).
    #[arg(long)]
    workers: Option<usize>,
    /// Microseconds to keep polling after a request before sleeping (default 200).
    #[arg(long)]
    spin_us: Option<u64>,
    /// Most client connections per service (default 64).
    #[arg(long)]
    max_clients: Option<usize>,
    /// Most queries waiting for a worker before `busy`, brute and the others each (default 256).
    #[arg(long)]
    max_queued: Option<usize>,
    /// Model file of the learned SDSMM (from `dyfos train`), for queries with model `learned`.
    #[arg(long, value_name = "FILE")]
    model: Option<PathBuf>,
    /// Nice levels the search workers run below the daemon's IPC thread, 0–19
    /// (default 0): cheap queries then preempt running searches, which also yield to
    /// other processes. 10 suits a mix of cheap and long queries on few cores.
    #[arg(long, value_parser = clap::value_parser!(u8).range(0..=19))]
    worker_nice: Option<u8>,
    /// SCHED_FIFO priority of the thread that answers requests while it sleeps,
    /// 1–99 (default 10), so a request preempts running searches; 0 turns it off.
    /// Needs CAP_SYS_NICE or `ulimit -r`; refused, it asks for a 0.1 ms time slice
    /// instead (Linux 6.12 and later), else the workers are niced by 5.
    #[arg(long, value_parser = clap::value_parser!(u8).range(0..=99))]
    ipc_priority: Option<u8>,
    /// Longest time to keep polling after a request while traffic is steady, µs
    /// (default 2000); 0 keeps to --spin-us always.
    #[arg(long)]
    spin_max_us: Option<u64>,
    /// How free workers pick queued searches: `fair` (default: the client with the
    /// fewest running first, and a search of the busiest client held while a client
    /// with none running gets a core) or `fifo` (oldest first, nothing held).
    #[arg(long, value_parser = ["fair", "fifo"])]
    queue: Option<String>,
    /// Run the search workers as SCHED_BATCH.
    #[arg(long)]
    worker_batch: bool,
    /// How often, at most, a running search yields its core to a thread waiting for
    /// one, µs (default 50; 0: never). Only while more threads are runnable than
    /// there are cores: a request sent meanwhile then waits at most about this long
    /// for its process to run, not a scheduler tick.
    #[arg(long, value_name = "MICROS")]
    worker_yield_us: Option<u64>,
    /// Time slice the search workers ask for, µs (default 3000; 0: the kernel's;
    /// else 100–100000). Longer than other threads' slices, so on Linux 6.12 and
    /// later a thread that wakes where a search runs preempts it at once.
    #[arg(long, value_name = "MICROS")]
    worker_slice_us: Option<u64>,
    /// While requests arrive steadily, ask that idle cores wake within this many µs
    /// (default 0: idle cores poll, a wake-up takes µs), until 50 ms after the last
    /// request; `off` leaves the kernel's choice. Needs root (/dev/cpu_dma_latency).
    #[arg(long, value_name = "MICROS|off", value_parser = parse_cpu_latency)]
    cpu_latency_us: Option<CpuLatency>,
    /// dyfosd's earlier scheduling, for comparisons: no real-time IPC
    /// thread, a fixed --spin-us window, a FIFO queue, searches that never yield
    /// and keep the kernel's slice, idle cores as the kernel likes (same as
    /// `--ipc-priority 0 --spin-max-us 0 --queue fifo --worker-yield-us 0
    /// --worker-slice-us 0 --cpu-latency-us off`;
    /// those flags win if given too).
    #[arg(long)]
    legacy_scheduling: bool,
    /// Record every accepted request with its reply, every map change and the
    /// configuration to this MCAP file (off by default; see `dyfos replay` and
    /// docs/record.md). An existing file is rotated away first.
    #[arg(long, value_name = "FILE.mcap")]
    record: Option<PathBuf>,
    /// Rotate the recording once it is this many bytes (default 268435456, 256 MiB):
    /// FILE.mcap becomes FILE.1.mcap, and so on.
    #[arg(long, value_name = "BYTES")]
    record_max_bytes: Option<u64>,
    /// Rotated recordings kept besides the current one (default 4).
    #[arg(long, value_name = "K")]
    record_keep: Option<usize>,
}

/// The TOML file's keys; each is optional and a flag overrides it.
#[derive(Debug, Default, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct FileConfig {
    prefix: Option<String>,
    state_dir: Option<PathBuf>,
    domain: Option<String>,
    workers: Option<usize>,
    spin_us: Option<u64>,
    max_clients: Option<usize>,
    max_requests_per_client: Option<usize>,
    max_queued: Option<usize>,
    upload_idle_timeout_s: Option<u64>,
    model: Option<PathBuf>,
    worker_nice: Option<u8>,
    ipc_priority: Option<u8>,
    spin_max_us: Option<u64>,
    queue: Option<String>,
    worker_batch: Option<bool>,
    worker_yield_us: Option<u64>,
    worker_slice_us: Option<u64>,
    cpu_latency_us: Option<CpuLatency>,
    record: Option<PathBuf>,
    record_max_bytes: Option<u64>,
    record_keep: Option<usize>,
}

/// `cpu_latency_us`: µs, or `"off"`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Deserialize)]
#[serde(untagged)]
enum CpuLatency {
    Micros(u32),
    #[serde(deserialize_with = "off")]
    Off,
}

fn off<'de, D: serde::Deserializer<'de>>(d: D) -> Result<(), D::Error> {
    match <String as serde::Deserialize>::deserialize(d)?.as_str() {
        "off" => Ok(()),
        other => Err(serde::de::Error::custom(format!("\"{other}\" is neither a number of µs nor \"off\""))),
    }
}

fn parse_cpu_latency(s: &str) -> Result<CpuLatency, String> {
    match s {
        "off" => Ok(CpuLatency::Off),
        n => n.parse().map(CpuLatency::Micros).map_err(|_| format!("{n} is neither a number of µs nor `off`")),
    }
}

fn config(cli: &Cli) -> anyhow::Result<DaemonConfig> {
    let file = match &cli.config {
        None => FileConfig::default(),
        Some(path) => {
            let text = std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
            toml::from_str(&text).with_context(|| format!("{}", path.display()))?
        }
    };
    let d = DaemonConfig::default();
    Ok(DaemonConfig {
        prefix: cli.prefix.clone().or(file.prefix).unwrap_or(d.prefix),
        domain: cli.domain.clone().or(file.domain).or(d.domain),
        state_dir: cli.state_dir.clone().or(file.state_dir).unwrap_or(d.state_dir),
        workers: cli.workers.or(file.workers).unwrap_or(d.workers),
        spin: cli.spin_us.or(file.spin_us).map_or(d.spin, Duration::from_micros),
        max_clients: cli.max_clients.or(file.max_clients).unwrap_or(d.max_clients),
        max_requests_per_client: file.max_requests_per_client.unwrap_or(d.max_requests_per_client),
        max_queued: cli.max_queued.or(file.max_queued).unwrap_or(d.max_queued),
        upload_idle_timeout: file.upload_idle_timeout_s.map_or(d.upload_idle_timeout, Duration::from_secs),
        model: cli.model.clone().or(file.model).or(d.model),
        worker_nice: match cli.worker_nice.or(file.worker_nice) {
            Some(n) if n > 19 => anyhow::bail!("worker_nice = {n} must be 0–19"),
            n => n.unwrap_or(d.worker_nice),
        },
        ipc_priority: match cli.ipc_priority.or(file.ipc_priority) {
            Some(n) if n > 99 => anyhow::bail!("ipc_priority = {n} must be 0–99"),
            Some(n) => n,
            None if cli.legacy_scheduling => 0,
            None => d.ipc_priority,
        },
        spin_max: match cli.spin_max_us.or(file.spin_max_us) {
            Some(us) => Duration::from_micros(us),
            None if cli.legacy_scheduling => Duration::ZERO,
            None => d.spin_max,
        },
        fair_queue: match cli.queue.as_deref().or(file.queue.as_deref()) {
            Some("fair") => true,
            Some("fifo") => false,
            Some(q) => anyhow::bail!("queue = \"{q}\" must be \"fair\" or \"fifo\""),
            None => d.fair_queue && !cli.legacy_scheduling,
        },
        worker_batch: cli.worker_batch || file.worker_batch.unwrap_or(d.worker_batch),
        worker_yield: match cli.worker_yield_us.or(file.worker_yield_us) {
            Some(us) if us > 1_000_000 => anyhow::bail!("worker_yield_us = {us} must be at most 1000000 (1 s)"),
            Some(us) => Duration::from_micros(us),
            None if cli.legacy_scheduling => Duration::ZERO,
            None => d.worker_yield,
        },
        worker_slice: match cli.worker_slice_us.or(file.worker_slice_us) {
            Some(us @ (0 | 100..=100_000)) => Duration::from_micros(us),
            Some(us) => anyhow::bail!("worker_slice_us = {us} must be 0 (the kernel's) or 100–100000 (0.1–100 ms)"),
            None if cli.legacy_scheduling => Duration::ZERO,
            None => d.worker_slice,
        },
        cpu_latency_us: match cli.cpu_latency_us.or(file.cpu_latency_us) {
            Some(CpuLatency::Micros(us)) if us > 1_000_000 => {
                anyhow::bail!("cpu_latency_us = {us} must be at most 1000000 (1 s), or \"off\"")
            }
            Some(CpuLatency::Micros(us)) => Some(us),
            Some(CpuLatency::Off) => None,
            None if cli.legacy_scheduling => None,
            None => d.cpu_latency_us,
        },
        record: match cli.record.clone().or(file.record) {
            None => None,
            Some(path) => {
                let mut r = RecordConfig::new(path);
                r.max_bytes = cli.record_max_bytes.or(file.record_max_bytes).unwrap_or(r.max_bytes);
                r.keep = cli.record_keep.or(file.record_keep).unwrap_or(r.keep);
                if r.max_bytes == 0 {
                    anyhow::bail!("record_max_bytes must be at least 1");
                }
                Some(r)
            }
        },
    })
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
    let cli = Cli::parse();
    dyfos_process::logging::init();
    let config = match config(&cli) {
        Ok(c) => c,
        Err(e) => {
            eprintln!("dyfosd: {e:#}");
            return ExitCode::from(2);
        }
    };
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_numeric_flag_takes_negative_numbers_in_any_notation() {
        dyfos_process::cli::assert_numeric_flags_take_signs(&<Cli as clap::CommandFactory>::command());
    }

    fn cli(args: &[&str]) -> Cli {
        Cli::try_parse_from(std::iter::once("dyfosd").chain(args.iter().copied())).unwrap()
    }

    #[test]
    fn flags_override_the_file_which_overrides_defaults() {
        let dir = std::env::temp_dir().join(format!("dyfosd-config-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let file = dir.join("dyfosd.toml");
        std::fs::write(&file, "prefix = \"from-file/\"\nworkers = 3\nspin_us = 50\nupload_idle_timeout_s = 9\n")
            .unwrap();
        let c = config(&cli(&["--config", file.to_str().unwrap(), "--workers", "5"])).unwrap();
        assert_eq!(c.prefix, "from-file/");
        assert_eq!(c.workers, 5);
        assert_eq!(c.spin, Duration::from_micros(50));
        assert_eq!(c.upload_idle_timeout, Duration::from_secs(9));
        assert_eq!(c.max_clients, DaemonConfig::default().max_clients);
        assert_eq!(c.worker_nice, 0);
        assert_eq!(config(&cli(&["--worker-nice", "10"])).unwrap().worker_nice, 10);
        assert!(Cli::try_parse_from(["dyfosd", "--worker-nice", "20"]).is_err());
        // The scheduling defaults, the legacy switch, and flags over it.
        let d = config(&cli(&[])).unwrap();
        assert_eq!((d.ipc_priority, d.spin_max, d.fair_queue), (10, Duration::from_millis(2), true));
        let legacy = config(&cli(&["--legacy-scheduling"])).unwrap();
        assert_eq!((legacy.ipc_priority, legacy.spin_max, legacy.fair_queue), (0, Duration::ZERO, false));
        assert_eq!((d.worker_yield, legacy.worker_yield), (Duration::from_micros(50), Duration::ZERO));
        assert_eq!(config(&cli(&["--worker-yield-us", "0"])).unwrap().worker_yield, Duration::ZERO);
        assert!(config(&cli(&["--worker-yield-us", "2000000"])).is_err());
        assert_eq!((d.worker_slice, legacy.worker_slice), (Duration::from_millis(3), Duration::ZERO));
        assert_eq!(config(&cli(&["--worker-slice-us", "0"])).unwrap().worker_slice, Duration::ZERO);
        assert!(config(&cli(&["--worker-slice-us", "99"])).is_err());
        assert!(config(&cli(&["--worker-slice-us", "100001"])).is_err());
        assert_eq!((d.cpu_latency_us, legacy.cpu_latency_us), (Some(0), None));
        assert_eq!(config(&cli(&["--cpu-latency-us", "off"])).unwrap().cpu_latency_us, None);
        assert_eq!(config(&cli(&["--cpu-latency-us", "20"])).unwrap().cpu_latency_us, Some(20));
        assert!(Cli::try_parse_from(["dyfosd", "--cpu-latency-us", "soon"]).is_err());
        assert!(config(&cli(&["--cpu-latency-us", "1000001"])).is_err());
        for (line, want) in [
            ("cpu_latency_us = \"off\"", Ok(None)),
            ("cpu_latency_us = 5", Ok(Some(5))),
            ("cpu_latency_us = \"on\"", Err(())),
        ] {
            std::fs::write(&file, line).unwrap();
            let got = config(&cli(&["--config", file.to_str().unwrap()])).map(|c| c.cpu_latency_us).map_err(|_| ());
            assert_eq!(got, want, "{line}");
        }
        let mixed = config(&cli(&["--legacy-scheduling", "--queue", "fair", "--ipc-priority", "3"])).unwrap();
        assert_eq!((mixed.ipc_priority, mixed.fair_queue), (3, true));
        assert!(Cli::try_parse_from(["dyfosd", "--queue", "lifo"]).is_err());
        // Recording: off by default; the limits default unless given.
        assert_eq!(d.record, None);
        let r = config(&cli(&["--record", "/tmp/t.mcap", "--record-keep", "2"])).unwrap().record.unwrap();
        assert_eq!((r.path, r.keep, r.max_bytes), (PathBuf::from("/tmp/t.mcap"), 2, 256 << 20));
        assert!(config(&cli(&["--record", "/tmp/t.mcap", "--record-max-bytes", "0"])).is_err());
        assert!(Cli::try_parse_from(["dyfosd", "--ipc-priority", "100"]).is_err());
        std::fs::write(&file, "prefx = \"typo/\"\n").unwrap();
        let err = format!("{:#}", config(&cli(&["--config", file.to_str().unwrap()])).unwrap_err());
        assert!(err.contains("unknown field `prefx`"), "{err}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
