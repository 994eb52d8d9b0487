//! How the daemon runs: one structure that is at once the file format of `dyfosd
//! --config`, the keys of `dyfosd --set KEY=VALUE`, what `dyfosd --print-config`
//! prints and what the head of a recording shows. Each key is documented once,
//! here; `docs/daemon.md` lists them, and a test keeps the two in step.
//!
//! Loaded once, in this order, each over the last: the defaults, the TOML file,
//! each `--set` (a dotted key, a TOML value), then `dyfosd`'s few flags. Then
//! [`DaemonConfig::validate`] checks every value in one place.
//!
//! ```
//! use dyfos_service::daemon::DaemonConfig;
//!
//! let config = DaemonConfig::load(None, &["limits.max_clients=8", "scheduling.cpu_latency_us=off"])?;
//! assert_eq!(config.limits.max_clients, 8);
//! assert_eq!(config.scheduling.cpu_latency_us.micros(), None);
//! config.validate()?;
//! assert!(DaemonConfig::load(None, &["limits.max_clientz=8"]).unwrap_err().to_string().contains("max_clients"));
//! # Ok::<(), dyfos_service::daemon::ConfigError>(())
//! ```

mod cpu_latency;
mod error;
mod former;
mod load;
#[cfg(test)]
mod tests;

pub use cpu_latency::CpuLatencyTarget;
pub use error::ConfigError;
pub use former::former_flag;

use super::record::{DEFAULT_KEEP, DEFAULT_MAX_BYTES, DEFAULT_QUEUE, RecordConfig};
use dyfos_shared::wire::{DEFAULT_PREFIX, ServiceNames};
use serde::{Deserialize, Serialize};
use std::path::PathBuf;
use std::time::Duration;

/// The daemon's configuration. [`DaemonConfig::default`] is what `dyfosd` runs with
/// when given nothing. Keys outside a table come first in a file; then the tables
/// `[limits]`, `[scheduling]` and `[recording]`.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DaemonConfig {
    /// Service-name prefix (`--prefix`): the services are `PREFIXrendezvous`,
    /// `PREFIXmap`, `PREFIXstats` and the events `PREFIXwake`, `PREFIXreply`;
    /// clients must use the same. Default `dyfos/`. Letters, digits and `_ - . /`,
    /// 1–200 bytes. Two daemons cannot share one.
    pub prefix: String,
    /// Directory where maps are persisted (`--state-dir`), created if missing.
    /// Default `$XDG_STATE_HOME/dyfos`, else `~/.local/state/dyfos`, else
    /// `./dyfos-state`.
    pub state_dir: PathBuf,
    /// iceoryx2 domain (`--domain`): the prefix of its shared-memory files; only
    /// processes of one domain see each other. Default unset: iceoryx2's `iox2_`.
    /// Letters, digits and `_`, 1–32 bytes.
    pub domain: Option<String>,
    /// Searches run at once (`--workers`), one per worker thread (each worker has a
    /// spare thread beside it, which stands in for a held search). Default 0: one
    /// per core. At least 2 whatever it says.
    pub workers: usize,
    /// Model file of the learned SDSMM, from `dyfos train` (`--model`), loaded at
    /// start. Default unset: queries for model `learned` are refused
    /// (`unsupported_model`).
    pub model: Option<PathBuf>,
    /// What the daemon holds for its clients.
    pub limits: Limits,
    /// How the daemon shares the CPU with its searches and with other processes.
    pub scheduling: Scheduling,
    /// Recording the daemon's traffic to MCAP files.
    pub recording: Recording,
}

/// `[limits]`: how much the daemon holds for its clients. Each is at least 1.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Limits {
    /// Most client connections per service; each client holds one of each
    /// service. Default 64. At least 1.
    pub max_clients: usize,
    /// Most requests one client connection may have in flight. Default 4. At
    /// least 1.
    pub max_requests_per_client: usize,
    /// Most queries waiting for a worker before new ones get `busy`, per class:
    /// `brute` queries and the others queue apart, so a flood of one class never
    /// makes the other busy. Default 256. At least 1.
    pub max_queued: usize,
    /// An upload with no new chunk for this long is abandoned, seconds. Default 30.
    pub upload_idle_timeout_s: u64,
}

/// `[scheduling]`: how cheap requests get a core while searches run (docs/daemon.md,
/// "Priorities"; `bench/RESULTS.md`, "Why the scheduling defaults").
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Scheduling {
    /// `SCHED_FIFO` priority of the thread that answers requests while it
    /// sleeps, so that a request wakes it ahead of running searches; it polls at
    /// normal priority. Default 10; 1–99, or 0: never real-time. Needs
    /// `CAP_SYS_NICE` or an `RLIMIT_RTPRIO` of at least this; when refused, it
    /// asks for a short time slice instead (Linux 6.12 and later), and where the
    /// kernel takes none the search workers run a few nice levels lower.
    pub ipc_priority: u8,
    /// How long the IPC thread keeps polling for the next request after one
    /// before it sleeps, µs. Default 200.
    pub poll_us: u64,
    /// Longest polling window while requests arrive steadily, µs: while they come
    /// about this often or more, the IPC thread polls this long after each, so
    /// sparse but steady traffic pays no wake-up. It stops polling while every
    /// worker searches and once traffic stops, so an idle daemon uses no CPU.
    /// Default 2000; at most `poll_us` (e.g. 0) keeps to `poll_us` always.
    pub poll_max_us: u64,
    /// How often, at most, a running search yields its core to a thread waiting
    /// for one, µs; only while more threads are runnable than there are cores, so
    /// a request sent meanwhile waits about this long for its process to run,
    /// not a scheduler tick. Default 50; 0: never; at most 1000000 (1 s). Linux
    /// only.
    pub worker_yield_us: u64,
    /// Time slice the search workers ask the kernel for, µs: longer than other
    /// threads' slices, so on Linux 6.12 and later a thread that wakes where a
    /// search runs preempts it at once; their share of the CPU is unchanged.
    /// Default 3000; 0: the kernel's; else 100–100000. Linux only.
    pub worker_slice_us: u64,
    /// While requests arrive steadily, ask that idle cores wake within this many
    /// µs (Linux PM QoS, `/dev/cpu_dma_latency`), until 50 ms after the last
    /// request: a request after a pause then finds the IPC thread's core awake.
    /// Default 0 (idle cores poll meanwhile); at most 1000000, or `"off"`: the
    /// kernel decides. Needs root; without, the daemon says so once and goes on.
    pub cpu_latency_us: CpuLatencyTarget,
}

/// `[recording]`: the daemon's traffic to MCAP files (docs/record.md).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Recording {
    /// The file written (`--record`); an existing one is rotated away first, and
    /// rotated files are `FILE.1.mcap` (the newest) to `FILE.K.mcap`. Default
    /// unset: no recording.
    pub path: Option<PathBuf>,
    /// Rotate the file once it is this many bytes. Default 268435456 (256 MiB).
    /// At least 1. A file's head (configuration and every map) is written whole,
    /// so a file may pass it by one head and one message.
    pub max_bytes: u64,
    /// Rotated files kept besides the current one. Default 4; 0 deletes a full
    /// file instead of keeping it.
    pub keep: usize,
}

/// The IPC thread's default real-time priority: low among real-time threads, above
/// every normal one.
pub const DEFAULT_IPC_PRIORITY: u8 = 10;

/// How often, at most, a search yields its core to a waiting thread by default: at
/// every checkpoint while the conditions hold, so a thread that wakes beside a
/// search waits for one checkpoint at most. Yielding less often lengthened the tail
/// of cheap requests beside the searches for the same throughput (`bench/RESULTS.md`,
/// "Why the scheduling defaults").
pub const DEFAULT_WORKER_YIELD: Duration = Duration::from_micros(50);

/// The search workers' time slice by default: above the kernel's default slice
/// for normal threads (0.7 ms × (1 + log2 of the cores, at most 8): 0.7–2.8 ms),
/// so a thread that wakes beside a search has the shorter one and preempts it.
pub const DEFAULT_WORKER_SLICE: Duration = Duration::from_millis(3);

/// `$XDG_STATE_HOME/dyfos`, else `~/.local/state/dyfos`, else `./dyfos-state`.
pub fn default_state_dir() -> PathBuf {
    if let Some(d) = std::env::var_os("XDG_STATE_HOME").filter(|d| !d.is_empty()) {
        return PathBuf::from(d).join("dyfos");
    }
    match std::env::var_os("HOME").filter(|d| !d.is_empty()) {
        Some(home) => PathBuf::from(home).join(".local/state/dyfos"),
        None => PathBuf::from("dyfos-state"),
    }
}

impl Default for DaemonConfig {
    fn default() -> Self {
        DaemonConfig {
            prefix: DEFAULT_PREFIX.to_string(),
            state_dir: default_state_dir(),
            domain: None,
            workers: 0,
            model: None,
            limits: Limits::default(),
            scheduling: Scheduling::default(),
            recording: Recording::default(),
        }
    }
}

impl Default for Limits {
    fn default() -> Self {
        Limits { max_clients: 64, max_requests_per_client: 4, max_queued: 256, upload_idle_timeout_s: 30 }
    }
}

impl Default for Scheduling {
    fn default() -> Self {
        Scheduling {
            ipc_priority: DEFAULT_IPC_PRIORITY,
            poll_us: 200,
            poll_max_us: 2000,
            worker_yield_us: micros(DEFAULT_WORKER_YIELD),
            worker_slice_us: micros(DEFAULT_WORKER_SLICE),
            cpu_latency_us: CpuLatencyTarget::Micros(0),
        }
    }
}

impl Default for Recording {
    fn default() -> Self {
        Recording { path: None, max_bytes: DEFAULT_MAX_BYTES, keep: DEFAULT_KEEP }
    }
}

fn micros(d: Duration) -> u64 {
    u64::try_from(d.as_micros()).unwrap_or(u64::MAX)
}

impl Limits {
    /// [`Limits::upload_idle_timeout_s`].
    pub fn upload_idle_timeout(&self) -> Duration {
        Duration::from_secs(self.upload_idle_timeout_s)
    }
}

impl Scheduling {
    /// [`Scheduling::poll_us`].
    pub fn poll(&self) -> Duration {
        Duration::from_micros(self.poll_us)
    }

    /// [`Scheduling::poll_max_us`].
    pub fn poll_max(&self) -> Duration {
        Duration::from_micros(self.poll_max_us)
    }

    /// [`Scheduling::worker_yield_us`].
    pub fn worker_yield(&self) -> Duration {
        Duration::from_micros(self.worker_yield_us)
    }

    /// [`Scheduling::worker_slice_us`].
    pub fn worker_slice(&self) -> Duration {
        Duration::from_micros(self.worker_slice_us)
    }
}

impl Recording {
    /// The recorder's settings, if a file is named.
    pub fn record_config(&self) -> Option<RecordConfig> {
        let path = self.path.clone()?;
        Some(RecordConfig { path, max_bytes: self.max_bytes, keep: self.keep, queue: DEFAULT_QUEUE })
    }
}

impl DaemonConfig {
    /// Checks every value against its range; the first one out of it is the error.
    pub fn validate(&self) -> Result<(), ConfigError> {
        let invalid = |key, value: &dyn std::fmt::Display, rule: &str| {
            Err(ConfigError::Invalid { key, value: value.to_string(), rule: rule.to_string() })
        };
        if let Err(e) = ServiceNames::new(&self.prefix) {
            return invalid("prefix", &format!("\"{}\"", self.prefix), &format!("is refused: {e}"));
        }
        if let Some(d) = &self.domain
            && let Err(e) = super::iceoryx_config(Some(d))
        {
            return invalid("domain", &format!("\"{d}\""), &format!("is refused: {e}"));
        }
        for (key, path) in [("state_dir", Some(&self.state_dir)), ("model", self.model.as_ref())] {
            if let Some(p) = path
                && p.to_str().is_none()
            {
                return invalid(key, &p.display(), "is not valid UTF-8: name a path that is");
            }
        }
        if let Some(p) = &self.recording.path
            && p.to_str().is_none()
        {
            return invalid("recording.path", &p.display(), "is not valid UTF-8: name a path that is");
        }
        let l = &self.limits;
        for (key, v) in [
            ("limits.max_clients", l.max_clients),
            ("limits.max_requests_per_client", l.max_requests_per_client),
            ("limits.max_queued", l.max_queued),
        ] {
            if v == 0 {
                return invalid(key, &v, "must be at least 1");
            }
        }
        let s = &self.scheduling;
        if s.ipc_priority > 99 {
            return invalid(
                "scheduling.ipc_priority",
                &s.ipc_priority,
                "must be 1–99 (SCHED_FIFO priorities), or 0 to stay at normal priority",
            );
        }
        if s.worker_yield_us > 1_000_000 {
            return invalid(
                "scheduling.worker_yield_us",
                &s.worker_yield_us,
                "must be at most 1000000 (1 s), or 0: never",
            );
        }
        if !matches!(s.worker_slice_us, 0 | 100..=100_000) {
            return invalid(
                "scheduling.worker_slice_us",
                &s.worker_slice_us,
                "must be 100–100000 (0.1–100 ms), or 0: the kernel's",
            );
        }
        if let CpuLatencyTarget::Micros(us) = s.cpu_latency_us
            && us > 1_000_000
        {
            return invalid("scheduling.cpu_latency_us", &us, "must be at most 1000000 (1 s), or \"off\"");
        }
        if self.recording.max_bytes == 0 {
            return invalid("recording.max_bytes", &0, "must be at least 1");
        }
        Ok(())
    }

    /// The configuration as TOML, every key that has a value (unset ones are left
    /// out, as they would be in a file).
    pub fn to_toml(&self) -> String {
        toml::to_string(self).unwrap_or_else(|e| format!("# cannot be shown as TOML: {e}\n"))
    }

    /// The configuration as JSON (every key; unset ones are `null`), with
    /// `workers` replaced by the number started: the head of a recording.
    pub fn to_json(&self, workers: usize) -> serde_json::Value {
        serde_json::to_value(DaemonConfig { workers, ..self.clone() })
            .unwrap_or_else(|e| serde_json::json!({ "error": e.to_string() }))
    }
}
