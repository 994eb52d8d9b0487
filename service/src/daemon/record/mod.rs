//! `dyfosd --record FILE.mcap`: the daemon's traffic in MCAP files, for field
//! debugging and regression (`dyfos replay`). See `docs/record.md`.
//!
//! The IPC thread and the workers hand [`Record`]s to one writer thread through a
//! bounded queue and never wait for it: when the queue is full a record is dropped
//! and counted, and the count is itself recorded (channel `/dyfosd/recorder`), so a
//! replay knows the recording is incomplete. The writer writes unchunked,
//! uncompressed messages and flushes at most [`FLUSH_EVERY`] after each, so a
//! daemon killed mid-record leaves a file readable up to its last complete message
//! (losing at most that much). A file that
//! grows past [`RecordConfig::max_bytes`] is closed and rotated (`FILE.mcap` →
//! `FILE.1.mcap` → …, [`RecordConfig::keep`] old files kept); every file starts
//! with the daemon's configuration and build and the full state of every map, so
//! each replays on its own. A write error (a full disk) stops the recording with
//! one log line; the daemon carries on.
//!
//! Every message is JSON (`message_encoding` `json`) with a JSON Schema
//! (`jsonschema`), so Foxglove shows it as it is. Floating-point numbers are
//! written in the shortest form that parses back to the same bits. [`replay`]
//! re-runs a recording's queries against this build.

mod exchange;
mod format;
mod map_state;
mod recorder;
pub mod replay;
mod writer;

pub use exchange::{RebuildError, RecordedBelief, RecordedReply, RecordedRequest};
pub use format::{json_schema, params_to_json, topics};
pub use map_state::{ChangeCause, MapChange, MapState, content_of};
pub use recorder::FLUSH_EVERY;
pub(crate) use recorder::TrafficRecorder;

use dyfos_shared::wire::map::MapId;
use dyfos_shared::wire::rendezvous::{Mode, RendezvousReply, RendezvousRequest};
use dyfos_shared::world::{MapDelta, World};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Instant, SystemTime, UNIX_EPOCH};

/// One thing to record, handed from the daemon's threads to the writer.
pub(crate) enum Record {
    /// A map changed; `world` is its new state (`None`: deleted).
    MapChange {
        at: u64,
        map: MapId,
        cause: ChangeCause,
        deltas: Vec<MapDelta>,
        world: Option<Arc<World>>,
        from: Option<u64>,
        version: u64,
    },
    /// A rendezvous query was answered.
    Rendezvous {
        received: u64,
        replied: u64,
        mode: Mode,
        request_id: u64,
        request: Box<RendezvousRequest>,
        reply: Box<RendezvousReply>,
    },
    /// A map request was answered.
    Map { received: u64, replied: u64, message: serde_json::Value },
    /// Shut down: finish the file.
    Close,
}

/// How the recorder writes: the `[recording]` keys of
/// [`DaemonConfig`](super::DaemonConfig), and its queue.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RecordConfig {
    /// The file being written (`--record FILE.mcap`); rotated files are
    /// `FILE.1.mcap` (the newest) to `FILE.K.mcap`.
    pub path: PathBuf,
    /// A file is rotated once it is this large (`recording.max_bytes`, default
    /// [`DEFAULT_MAX_BYTES`]). The head of a file (configuration and map states)
    /// is written whole, so a file may exceed it by one head and one message.
    pub max_bytes: u64,
    /// Rotated files kept besides the current one (`recording.keep`, default
    /// [`DEFAULT_KEEP`]); 0 deletes a full file instead of keeping it.
    pub keep: usize,
    /// Records waiting for the writer before new ones are dropped (default
    /// [`DEFAULT_QUEUE`]).
    pub queue: usize,
}

/// Default [`RecordConfig::max_bytes`]: 256 MiB.
pub const DEFAULT_MAX_BYTES: u64 = 256 << 20;
/// Default [`RecordConfig::keep`].
pub const DEFAULT_KEEP: usize = 4;
/// Default [`RecordConfig::queue`].
pub const DEFAULT_QUEUE: usize = 4096;

impl RecordConfig {
    /// Recording to `path` with the default limits.
    pub fn new(path: impl Into<PathBuf>) -> Self {
        RecordConfig { path: path.into(), max_bytes: DEFAULT_MAX_BYTES, keep: DEFAULT_KEEP, queue: DEFAULT_QUEUE }
    }

    /// The `index`-th rotated file: `FILE.mcap` → `FILE.<index>.mcap` (0 is the
    /// current file itself).
    pub fn rotated(&self, index: usize) -> PathBuf {
        rotated_path(&self.path, index)
    }
}

/// `FILE.mcap` → `FILE.<index>.mcap`; 0 is `path` itself.
pub fn rotated_path(path: &Path, index: usize) -> PathBuf {
    if index == 0 {
        return path.to_path_buf();
    }
    let stem = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    let name = match path.extension() {
        Some(ext) => format!("{stem}.{index}.{}", ext.to_string_lossy()),
        None => format!("{stem}.{index}"),
    };
    path.with_file_name(name)
}

/// Nanoseconds since the Unix epoch of `t`.
pub fn unix_ns(t: SystemTime) -> u64 {
    t.duration_since(UNIX_EPOCH).map_or(0, |d| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX))
}

/// The wall-clock time `since.elapsed()` ago, in ns since the Unix epoch.
pub(crate) fn unix_ns_of(since: Instant) -> u64 {
    unix_ns(SystemTime::now().checked_sub(since.elapsed()).unwrap_or(UNIX_EPOCH))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rotated_files_are_numbered_before_the_extension() {
        let p = Path::new("/var/log/dyfos/traffic.mcap");
        assert_eq!(rotated_path(p, 0), p);
        assert_eq!(rotated_path(p, 2), Path::new("/var/log/dyfos/traffic.2.mcap"));
        assert_eq!(rotated_path(Path::new("raw"), 1), Path::new("raw.1"));
    }
}
