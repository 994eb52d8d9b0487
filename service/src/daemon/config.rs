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

use super::record::{DEFAULT_KEEP, DEFAULT_MAX_BYTES, DEFAULT_QUEUE, RecordConfig};
use dyfos_shared::wire::{DEFAULT_PREFIX, ServiceNames};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
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

/// `scheduling.cpu_latency_us`: µs, or `"off"`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CpuLatencyTarget {
    /// Idle cores wake within this many µs while traffic is steady.
    Micros(u32),
    /// No request: idle cores wake as the kernel decides.
    Off,
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

impl CpuLatencyTarget {
    /// The target in µs; `None` for `"off"`.
    pub fn micros(self) -> Option<u32> {
        match self {
            CpuLatencyTarget::Micros(us) => Some(us),
            CpuLatencyTarget::Off => None,
        }
    }
}

impl Serialize for CpuLatencyTarget {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match self {
            CpuLatencyTarget::Micros(us) => s.serialize_u32(*us),
            CpuLatencyTarget::Off => s.serialize_str("off"),
        }
    }
}

impl<'de> Deserialize<'de> for CpuLatencyTarget {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct Visitor;
        impl serde::de::Visitor<'_> for Visitor {
            type Value = CpuLatencyTarget;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("a number of µs or \"off\"")
            }
            fn visit_u64<E: serde::de::Error>(self, v: u64) -> Result<Self::Value, E> {
                u32::try_from(v)
                    .map(CpuLatencyTarget::Micros)
                    .map_err(|_| E::invalid_value(serde::de::Unexpected::Unsigned(v), &self))
            }
            fn visit_i64<E: serde::de::Error>(self, v: i64) -> Result<Self::Value, E> {
                u64::try_from(v)
                    .map_err(|_| E::invalid_value(serde::de::Unexpected::Signed(v), &self))
                    .and_then(|v| self.visit_u64(v))
            }
            fn visit_str<E: serde::de::Error>(self, v: &str) -> Result<Self::Value, E> {
                match v {
                    "off" => Ok(CpuLatencyTarget::Off),
                    other => Err(E::invalid_value(serde::de::Unexpected::Str(other), &self)),
                }
            }
        }
        d.deserialize_any(Visitor)
    }
}

/// Why a configuration was not taken. Each names the key and what to write
/// instead.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// The file cannot be read.
    #[error("cannot read {}: {source}", path.display())]
    Read {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The file is not TOML.
    #[error("{}: not a TOML file: {message}", path.display())]
    Syntax {
        /// The file.
        path: PathBuf,
        /// The parser's message, with the line.
        message: String,
    },
    /// A `--set` that is not `KEY=VALUE`.
    #[error(
        "--set `{0}`: write KEY=VALUE, e.g. `--set scheduling.cpu_latency_us=200` (`dyfosd --print-config` shows every key)"
    )]
    Set(String),
    /// A key that does not exist, or a value of the wrong type, in the file or a
    /// `--set`.
    #[error("{origin}: `{key}`: {message}")]
    Key {
        /// The file, or the `--set`.
        origin: String,
        /// The dotted key.
        key: String,
        /// What is wrong and what to write.
        message: String,
    },
    /// A value out of its range.
    #[error("{key} = {value} {rule}")]
    Invalid {
        /// The dotted key.
        key: &'static str,
        /// The value given.
        value: String,
        /// What it must be.
        rule: String,
    },
}

/// Keys of earlier versions, which had no tables and a flag per key, and where
/// each went: a dotted key, or why it is gone. An unknown key or flag that is here
/// gets this in its error.
const FORMER_KEYS: [(&str, Former); 17] = [
    ("spin_us", Former::Moved("scheduling.poll_us")),
    ("spin_max_us", Former::Moved("scheduling.poll_max_us")),
    ("ipc_priority", Former::Moved("scheduling.ipc_priority")),
    ("worker_yield_us", Former::Moved("scheduling.worker_yield_us")),
    ("worker_slice_us", Former::Moved("scheduling.worker_slice_us")),
    ("cpu_latency_us", Former::Moved("scheduling.cpu_latency_us")),
    ("max_clients", Former::Moved("limits.max_clients")),
    ("max_requests_per_client", Former::Moved("limits.max_requests_per_client")),
    ("max_queued", Former::Moved("limits.max_queued")),
    ("upload_idle_timeout_s", Former::Moved("limits.upload_idle_timeout_s")),
    ("record", Former::Moved("recording.path")),
    ("record_max_bytes", Former::Moved("recording.max_bytes")),
    ("record_keep", Former::Moved("recording.keep")),
    (
        "worker_nice",
        Former::Removed(
            "the search workers run below the IPC thread by themselves where it may neither run real-time nor take a short time slice",
        ),
    ),
    ("queue", Former::Removed("the search queue is always fair across clients")),
    ("worker_batch", Former::Removed("search workers are SCHED_OTHER with a long time slice")),
    (
        "legacy_scheduling",
        Former::Removed(
            "to compare with an earlier daemon, build it in a git worktree (`dyfos-bench latency --compare-dyfosd`)",
        ),
    ),
];

#[derive(Debug, Clone, Copy)]
enum Former {
    Moved(&'static str),
    Removed(&'static str),
}

/// What became of `dyfosd`'s former flag `flag` (`--spin-us`, `--queue=fifo`): a
/// sentence saying what to write instead, or `None` if it never was a flag.
pub fn former_flag(flag: &str) -> Option<String> {
    let name = flag.strip_prefix("--")?.split('=').next()?.replace('-', "_");
    match former(&name)? {
        Former::Moved(key) => Some(format!(
            "{flag} was replaced by the key `{key}`: write `--set {key}=VALUE`, or `{}` under `[{}]` in the --config file",
            key.rsplit_once('.').map_or(key, |(_, k)| k),
            key.split_once('.').map_or("", |(t, _)| t),
        )),
        Former::Removed(why) => Some(format!("{flag} was removed: {why}")),
    }
}

fn former(key: &str) -> Option<Former> {
    FORMER_KEYS.iter().find(|(k, _)| *k == key).map(|(_, f)| *f)
}

impl DaemonConfig {
    /// The defaults, over them the TOML file `file` (if any), over that each
    /// `KEY=VALUE` of `sets` in order (a dotted key; the value is read as TOML, and
    /// as a string if it is not TOML, so `prefix=lab/` needs no quotes). Values are
    /// not range-checked yet: see [`DaemonConfig::validate`].
    pub fn load(file: Option<&Path>, sets: &[impl AsRef<str>]) -> Result<DaemonConfig, ConfigError> {
        let mut table = toml::Table::new();
        if let Some(path) = file {
            let text =
                std::fs::read_to_string(path).map_err(|source| ConfigError::Read { path: path.into(), source })?;
            table = text.parse().map_err(|e: toml::de::Error| ConfigError::Syntax {
                path: path.into(),
                message: e.to_string().trim_end().to_string(),
            })?;
            // The file alone first, so that its mistakes are blamed on it.
            from_table(table.clone(), &|_| path.display().to_string())?;
        }
        let mut keys = Vec::new();
        for set in sets {
            let set = set.as_ref();
            let (key, value) = set.split_once('=').ok_or_else(|| ConfigError::Set(set.to_string()))?;
            let path: Vec<&str> = key.split('.').collect();
            if path.iter().any(|p| p.is_empty() || !p.bytes().all(|b| b.is_ascii_lowercase() || b == b'_')) {
                return Err(ConfigError::Set(set.to_string()));
            }
            let value = toml_value(value);
            insert(&mut table, &path, value).map_err(|parent| ConfigError::Key {
                origin: format!("--set {set}"),
                key: parent,
                message: "is not a table".into(),
            })?;
            keys.push((key.to_string(), set.to_string()));
        }
        // Blame the last `--set` of the key in error, or of a table holding it.
        let origin = |key: &str| {
            keys.iter()
                .rev()
                .find(|(k, _)| key == k || key.starts_with(&format!("{k}.")) || k.starts_with(&format!("{key}.")))
                .map_or_else(|| "--set".to_string(), |(_, set)| format!("--set {set}"))
        };
        from_table(table, &origin)
    }

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

/// `text` as a TOML value, or as a string if it is not one.
fn toml_value(text: &str) -> toml::Value {
    match format!("v = {text}").parse::<toml::Table>() {
        Ok(mut t) => t.remove("v").unwrap_or_else(|| toml::Value::String(text.to_string())),
        Err(_) => toml::Value::String(text.to_string()),
    }
}

/// Puts `value` at the dotted `path` of `table`, making tables on the way; the
/// error is the key on the way that holds something else.
fn insert(table: &mut toml::Table, path: &[&str], value: toml::Value) -> Result<(), String> {
    let (last, parents) = path.split_last().expect("a key has one part at least");
    let mut at = table;
    for (i, p) in parents.iter().enumerate() {
        let next = at.entry(p.to_string()).or_insert_with(|| toml::Value::Table(toml::Table::new()));
        at = next.as_table_mut().ok_or_else(|| path[..=i].join("."))?;
    }
    at.insert(last.to_string(), value);
    Ok(())
}

/// `table` as a configuration, the defaults under it; an error is blamed on
/// `origin(key)`.
fn from_table(table: toml::Table, origin: &dyn Fn(&str) -> String) -> Result<DaemonConfig, ConfigError> {
    serde_path_to_error::deserialize(toml::Value::Table(table)).map_err(|e| {
        let key = e.path().to_string();
        let mut message = dyfos_shared::scenario::suggest(e.inner().message().to_string());
        if message.starts_with("unknown field") {
            let name = key.rsplit('.').next().unwrap_or(&key);
            message = match former(name) {
                Some(Former::Moved(new)) => format!("is now `{new}`: write that instead"),
                Some(Former::Removed(why)) => format!("was removed: {why}; leave it out"),
                None => format!("is not a key: {message}"),
            };
        }
        ConfigError::Key { origin: origin(&key), key, message }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn load(sets: &[&str]) -> Result<DaemonConfig, String> {
        DaemonConfig::load(None, sets).map_err(|e| e.to_string())
    }

    /// A file of this test's own, removed when dropped.
    struct File(PathBuf);

    impl File {
        fn new(name: &str, text: &str) -> File {
            let path = std::env::temp_dir().join(format!("dyfosd-config-{}-{name}.toml", std::process::id()));
            std::fs::write(&path, text).unwrap();
            File(path)
        }
    }

    impl Drop for File {
        fn drop(&mut self) {
            let _ = std::fs::remove_file(&self.0);
        }
    }

    #[test]
    fn the_defaults() {
        let d = DaemonConfig::default();
        assert_eq!((d.prefix.as_str(), d.domain.as_deref(), d.workers, d.model.as_deref()), ("dyfos/", None, 0, None));
        assert_eq!(d.state_dir, default_state_dir());
        assert_eq!(
            d.limits,
            Limits { max_clients: 64, max_requests_per_client: 4, max_queued: 256, upload_idle_timeout_s: 30 }
        );
        let s = &d.scheduling;
        assert_eq!(
            (s.ipc_priority, s.poll(), s.poll_max()),
            (10, Duration::from_micros(200), Duration::from_millis(2))
        );
        assert_eq!((s.worker_yield(), s.worker_slice()), (Duration::from_micros(50), Duration::from_millis(3)));
        assert_eq!(s.cpu_latency_us.micros(), Some(0));
        assert_eq!((d.recording.path.as_deref(), d.recording.max_bytes, d.recording.keep), (None, 256 << 20, 4));
        assert_eq!(d.recording.record_config(), None);
        d.validate().unwrap();
        assert_eq!(load(&[]).unwrap(), d);
    }

    #[test]
    fn sets_override_the_file_which_overrides_the_defaults() {
        let file = File::new(
            "precedence",
            "prefix = \"from-file/\"\nworkers = 3\n[limits]\nupload_idle_timeout_s = 9\n[scheduling]\npoll_us = 50\nipc_priority = 3\n",
        );
        let c = DaemonConfig::load(Some(&file.0), &["workers=5", "scheduling.poll_us=70", "scheduling.poll_us=80"])
            .unwrap();
        assert_eq!((c.prefix.as_str(), c.workers), ("from-file/", 5));
        assert_eq!((c.scheduling.poll_us, c.scheduling.ipc_priority), (80, 3), "the last --set wins");
        assert_eq!(c.limits.upload_idle_timeout(), Duration::from_secs(9));
        assert_eq!(c.limits.max_clients, 64, "a key the file leaves out keeps its default");
        assert_eq!(c.scheduling.poll_max_us, 2000);
        // Values are TOML; a bare word is a string.
        let c = load(&["prefix=lab/", "domain=\"lab_1\"", "recording.path=/tmp/t.mcap", "recording.keep=2"]).unwrap();
        assert_eq!((c.prefix.as_str(), c.domain.as_deref()), ("lab/", Some("lab_1")));
        let r = c.recording.record_config().unwrap();
        assert_eq!((r.path, r.keep, r.max_bytes), (PathBuf::from("/tmp/t.mcap"), 2, 256 << 20));
        assert_eq!(load(&["scheduling={ poll_us = 7 }"]).unwrap().scheduling.poll_us, 7);
        for (set, want) in [("off", None), ("\"off\"", None), ("20", Some(20))] {
            let c = load(&[&format!("scheduling.cpu_latency_us={set}")]).unwrap();
            assert_eq!(c.scheduling.cpu_latency_us.micros(), want, "{set}");
        }
    }

    #[test]
    fn an_unknown_key_is_named_with_what_to_write() {
        for (sets, want) in [
            (&["prefx=a/"][..], ["--set prefx=a/: `prefx`", "did you mean `prefix`?"]),
            (&["limits.max_clientz=8"], ["`limits.max_clientz`", "did you mean `max_clients`?"]),
            (&["spin_us=5"], ["`spin_us`", "is now `scheduling.poll_us`"]),
            (&["worker_nice=5"], ["`worker_nice`", "was removed"]),
            (
                &["limits.max_queued=x"],
                ["--set limits.max_queued=x: `limits.max_queued`", "invalid type: string \"x\""],
            ),
            (&["scheduling.cpu_latency_us=on"], ["`scheduling.cpu_latency_us`", "expected a number of µs or \"off\""]),
            (&["scheduling.poll_us=-1"], ["`scheduling.poll_us`", "-1"]),
            (&["prefix=a/", "prefix.x=1"], ["--set prefix.x=1: `prefix`", "is not a table"]),
            (&["workers"], ["--set `workers`", "KEY=VALUE"]),
            (&["Workers=2"], ["--set `Workers=2`", "KEY=VALUE"]),
        ] {
            let err = load(sets).unwrap_err();
            for w in want {
                assert!(err.contains(w), "{sets:?}: `{w}` not in: {err}");
            }
        }
        // A file of an earlier version (no tables) is told where each key went.
        let file = File::new("old", "prefix = \"a/\"\nmax_queued = 3\n");
        let err = DaemonConfig::load(Some(&file.0), &[] as &[&str]).unwrap_err().to_string();
        assert!(err.contains(&file.0.display().to_string()) && err.contains("is now `limits.max_queued`"), "{err}");
        let file = File::new("syntax", "prefix = \n");
        let err = DaemonConfig::load(Some(&file.0), &[] as &[&str]).unwrap_err().to_string();
        assert!(err.contains("not a TOML file") && err.contains("line 1"), "{err}");
        let err = DaemonConfig::load(Some(Path::new("/nonexistent/dyfosd.toml")), &[] as &[&str]).unwrap_err();
        assert!(err.to_string().contains("cannot read /nonexistent/dyfosd.toml"), "{err}");
    }

    #[test]
    fn values_out_of_range_are_refused_with_the_range() {
        for (set, want) in [
            ("prefix=\"a b\"", "prefix = \"a b\" is refused: service prefix"),
            ("domain=\"a/b\"", "domain = \"a/b\" is refused"),
            ("limits.max_clients=0", "limits.max_clients = 0 must be at least 1"),
            ("limits.max_requests_per_client=0", "limits.max_requests_per_client = 0 must be at least 1"),
            ("limits.max_queued=0", "limits.max_queued = 0 must be at least 1"),
            ("scheduling.ipc_priority=100", "scheduling.ipc_priority = 100 must be 1–99"),
            ("scheduling.worker_yield_us=1000001", "scheduling.worker_yield_us = 1000001 must be at most 1000000"),
            ("scheduling.worker_slice_us=99", "scheduling.worker_slice_us = 99 must be 100–100000"),
            ("scheduling.worker_slice_us=100001", "scheduling.worker_slice_us = 100001 must be 100–100000"),
            ("scheduling.cpu_latency_us=1000001", "scheduling.cpu_latency_us = 1000001 must be at most 1000000"),
            ("recording.max_bytes=0", "recording.max_bytes = 0 must be at least 1"),
        ] {
            let err = load(&[set]).unwrap().validate().unwrap_err().to_string();
            assert!(err.contains(want), "{set}: {err}");
        }
        // The edges of each range are taken.
        let edges = [
            "scheduling.ipc_priority=0",
            "scheduling.ipc_priority=99",
            "scheduling.worker_yield_us=1000000",
            "scheduling.worker_slice_us=0",
            "scheduling.worker_slice_us=100",
            "scheduling.worker_slice_us=100000",
            "scheduling.cpu_latency_us=1000000",
            "recording.max_bytes=1",
            "limits.max_queued=1",
        ];
        for set in edges {
            load(&[set]).unwrap().validate().unwrap_or_else(|e| panic!("{set}: {e}"));
        }
        assert!(load(&["scheduling.ipc_priority=256"]).is_err(), "u8");
    }

    #[test]
    fn a_former_flag_says_what_replaced_it() {
        let moved = former_flag("--spin-us").unwrap();
        assert!(
            moved.contains("--set scheduling.poll_us=VALUE") && moved.contains("`poll_us` under `[scheduling]`"),
            "{moved}"
        );
        assert!(former_flag("--record-keep=3").unwrap().contains("recording.keep"));
        assert!(former_flag("--queue").unwrap().contains("removed: the search queue is always fair"));
        assert!(former_flag("--legacy-scheduling").unwrap().contains("git worktree"));
        assert_eq!(former_flag("--prefx"), None);
        assert_eq!(former_flag("spin-us"), None);
    }

    /// The TOML printed and the JSON of a recording's head hold every key, and the
    /// TOML reads back as the same configuration.
    #[test]
    fn printed_toml_reads_back_and_the_json_has_every_key() {
        let c =
            load(&["domain=d_1", "model=/m.bin", "recording.path=/r.mcap", "scheduling.cpu_latency_us=off"]).unwrap();
        let file = File::new("roundtrip", &c.to_toml());
        assert_eq!(DaemonConfig::load(Some(&file.0), &[] as &[&str]).unwrap(), c);
        let json = c.to_json(7);
        assert_eq!(json["workers"], 7, "workers as started");
        assert_eq!((json["prefix"].as_str(), json["model"].as_str()), (Some("dyfos/"), Some("/m.bin")));
        assert_eq!(json["scheduling"]["cpu_latency_us"], "off");
        assert_eq!(keys(&json), keys(&DaemonConfig::default().to_json(2)));
        assert!(DaemonConfig::default().to_json(2)["domain"].is_null());
    }

    /// Every key as a dotted path, in order.
    fn keys(v: &serde_json::Value) -> Vec<String> {
        let mut out = Vec::new();
        for (k, v) in v.as_object().expect("an object") {
            match v.as_object() {
                Some(_) => out.extend(keys(v).into_iter().map(|sub| format!("{k}.{sub}"))),
                None => out.push(k.clone()),
            }
        }
        out
    }

    /// The key table of docs/daemon.md: key, default, meaning.
    #[test]
    fn the_documented_keys_and_defaults_are_the_structs() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/daemon.md");
        let doc = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let defaults = DaemonConfig::default().to_json(0);
        let want = keys(&defaults);
        let rows: Vec<Vec<&str>> = doc
            .lines()
            .skip_while(|l| !l.starts_with("| key |"))
            .skip(2)
            .take_while(|l| l.starts_with('|'))
            .map(|l| l.trim_matches('|').split(" | ").map(str::trim).collect())
            .collect();
        let documented: Vec<String> = rows.iter().map(|r| r[0].trim_matches('`').to_string()).collect();
        assert_eq!(documented, want, "docs/daemon.md's key table lists every key once, in the struct's order");
        for row in &rows {
            let key = row[0].trim_matches('`');
            let value = key.split('.').fold(&defaults, |v, k| &v[k]);
            let default = row[1];
            match default.strip_prefix('`').and_then(|d| d.strip_suffix('`')).filter(|d| !d.contains('`')) {
                // A literal default is the struct's, as TOML writes it.
                Some(literal) => {
                    assert_eq!(literal, toml::Value::try_from(value).unwrap().to_string(), "default of {key}")
                }
                // Prose: a default that is unset or depends on the environment.
                None => assert!(value.is_null() || key == "state_dir", "{key}: write its default as `{value}`"),
            }
            assert!(row.len() == 3 && row[2].len() > 20, "{key} has a meaning");
        }
        // Every former flag or key is in the table of what replaced it.
        let former = doc.split("## Former flags").nth(1).expect("a section on former flags");
        for (key, _) in FORMER_KEYS {
            let (flag, key) = (format!("`--{}`", key.replace('_', "-")), format!("`{key}`"));
            assert!(former.contains(&flag) || former.contains(&key), "{key} is not among the former flags");
        }
    }

    /// The example file in the repository loads, sets every key it can to its
    /// default, and names every other one.
    #[test]
    fn the_example_file_loads_and_shows_the_defaults() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("dyfosd.example.toml");
        let example = DaemonConfig::load(Some(&path), &[] as &[&str]).unwrap();
        example.validate().unwrap();
        assert_eq!(example, DaemonConfig { state_dir: default_state_dir(), ..DaemonConfig::default() });
        let text = std::fs::read_to_string(&path).unwrap();
        for key in keys(&DaemonConfig::default().to_json(0)) {
            let name = key.rsplit('.').next().unwrap();
            assert!(
                text.lines().any(|l| l.trim_start_matches("# ").starts_with(&format!("{name} = "))),
                "{key} is not in the example"
            );
        }
    }
}
