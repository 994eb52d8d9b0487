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

pub mod replay;

use dyfos_shared::answer::{Algorithm, StopReason};
use dyfos_shared::params::Params;
use dyfos_shared::posterior::Belief;
use dyfos_shared::wire::Status;
use dyfos_shared::wire::map::{MapId, world_from_content};
use dyfos_shared::wire::rendezvous::{Mode, RendezvousReply, RendezvousRequest};
use dyfos_shared::world::{Bounds, MapDelta, Sun, World};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufWriter, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, RecvTimeoutError, SyncSender, TrySendError};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};
use tracing::{error, info, warn};

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

/// `FILE.mcap` → `FILE.mcap.part`: where a file's head is written before the file
/// takes its name.
fn partial_path(path: &Path) -> PathBuf {
    let mut name = path.as_os_str().to_owned();
    name.push(".part");
    PathBuf::from(name)
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

/// The channels of a recording: topic, schema name and JSON Schema.
pub mod topics {
    /// The daemon's configuration and build, first message of every file.
    pub const CONFIG: &str = "/dyfosd/config";
    /// The full state of one map, after the configuration in every file.
    pub const MAP_STATE: &str = "/dyfosd/map_state";
    /// A change to a map and the version it produced.
    pub const MAP_CHANGE: &str = "/dyfosd/map_change";
    /// An accepted rendezvous query (solve or check) with its reply.
    pub const RENDEZVOUS: &str = "/dyfosd/rendezvous";
    /// An accepted map request with its reply.
    pub const MAP: &str = "/dyfosd/map";
    /// The recorder's own state: records dropped because the writer fell behind.
    pub const RECORDER: &str = "/dyfosd/recorder";
    /// Every channel, in the order its channel record is written.
    pub const ALL: [&str; 6] = [CONFIG, MAP_STATE, MAP_CHANGE, RENDEZVOUS, MAP, RECORDER];

    /// The schema name of a channel's messages.
    pub fn schema_name(topic: &str) -> &'static str {
        match topic {
            CONFIG => "dyfos.RecordingStart",
            MAP_STATE => "dyfos.MapState",
            MAP_CHANGE => "dyfos.MapChange",
            RENDEZVOUS => "dyfos.RendezvousExchange",
            MAP => "dyfos.MapExchange",
            _ => "dyfos.RecorderStatus",
        }
    }
}

/// What a recording's delta arrays hold.
const DELTAS_DESCRIPTION: &str =
    "map deltas, as in `dyfos map apply` files (docs/deltas.md), e.g. {\"remove_obstacle\": {\"id\": 3}}";

/// The JSON Schema (draft 2020-12) of a channel's messages: the top-level fields
/// and their types, for Foxglove's panels.
pub fn json_schema(topic: &str) -> serde_json::Value {
    use serde_json::json;
    let num = json!({"type": "number"});
    let int = json!({"type": "integer"});
    let nint = json!({"type": ["integer", "null"]});
    let arr = json!({"type": "array"});
    let obj = json!({"type": "object"});
    let str_ = json!({"type": "string"});
    let deltas = json!({"type": "array", "description": DELTAS_DESCRIPTION});
    let properties = match topic {
        topics::CONFIG => json!({
            "build": {"type": "object", "properties": {"name": str_, "version": str_, "profile": str_}},
            "config": obj, "pid": int, "file_index": int, "started_ns": int, "dropped_before": int,
        }),
        topics::MAP_STATE => json!({
            "map": int, "version": int, "bounds": arr, "sun": obj,
            "content": {"type": "array", "description": DELTAS_DESCRIPTION},
        }),
        topics::MAP_CHANGE => json!({
            "map": int, "cause": {"enum": ["create", "apply", "inline", "upload", "delete"]},
            "from_version": nint, "version": int, "deltas": deltas, "state": obj,
        }),
        topics::RENDEZVOUS => json!({
            "mode": {"enum": ["solve", "check"]}, "request_id": int, "received_ns": int, "replied_ns": int,
            "request": {"type": "object", "properties": {
                "map": int, "expected_version": nint, "belief": obj, "deltas": deltas, "algorithm": str_,
                "seed": int, "budget": nint, "deadline_ns": nint, "params": obj}},
            "reply": {"type": "object", "properties": {
                "status": str_, "algorithm": str_, "stop": str_, "map_version": int, "x": arr, "cost": num,
                "sensor_position": arr, "sensor_quaternion": arr, "viewer_position": arr, "viewer_yaw": num,
                "r": arr, "posterior": arr, "evaluations": arr, "micros": int, "daemon_micros": int,
                "error_index": nint, "message": str_}},
        }),
        topics::MAP => json!({
            "kind": {"enum": ["create", "apply", "upload", "snapshot", "delete", "list"]}, "request_id": int, "map": int,
            "received_ns": int, "replied_ns": int, "request": obj,
            "reply": {"type": "object", "properties": {
                "status": str_, "version": int, "chunk_index": int, "chunk_count": int, "map": int}},
        }),
        _ => json!({"dropped_total": int, "dropped_new": int, "reason": str_}),
    };
    json!({
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": topics::schema_name(topic),
        "type": "object",
        "properties": properties,
    })
}

/// Nanoseconds since the Unix epoch of `t`.
pub fn unix_ns(t: SystemTime) -> u64 {
    t.duration_since(UNIX_EPOCH).map_or(0, |d| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX))
}

/// The wall-clock time `since.elapsed()` ago, in ns since the Unix epoch.
pub(crate) fn unix_ns_of(since: Instant) -> u64 {
    unix_ns(SystemTime::now().checked_sub(since.elapsed()).unwrap_or(UNIX_EPOCH))
}

/// Every SPEC §11 parameter by its scenario name (what
/// [`dyfos_shared::scenario::params_from_json`] reads back, bit for bit).
pub fn params_to_json(p: &Params) -> serde_json::Value {
    dyfos_shared::scenario::params_to_json(p)
}

/// A rendezvous request as recorded: the decoded, validated request.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct RecordedRequest {
    /// The map searched.
    pub map: MapId,
    /// The version the request expected before its deltas.
    pub expected_version: Option<u64>,
    /// The belief.
    pub belief: RecordedBelief,
    /// Inline deltas (applied before the search).
    #[serde(deserialize_with = "recorded_deltas")]
    pub deltas: Vec<MapDelta>,
    /// The algorithm's name.
    pub algorithm: String,
    /// The seed.
    pub seed: u64,
    /// The evaluation budget.
    pub budget: Option<u64>,
    /// The deadline from receipt, ns.
    pub deadline_ns: Option<u64>,
    /// Every parameter, SPEC §11 names.
    pub params: serde_json::Value,
}

/// A belief as recorded.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct RecordedBelief {
    /// Mean (x, y, θ).
    pub mean: [f64; 3],
    /// Covariance, rows.
    pub cov: [[f64; 3]; 3],
}

/// Why a recorded request cannot be rebuilt.
#[derive(Debug, thiserror::Error)]
pub enum RebuildError {
    /// A field is invalid.
    #[error("recorded request: {0}")]
    Invalid(String),
}

impl RecordedRequest {
    /// The request as recorded.
    pub fn of(r: &RendezvousRequest) -> Self {
        RecordedRequest {
            map: r.map,
            expected_version: r.expected_version,
            belief: RecordedBelief { mean: r.belief.mean.into(), cov: r.belief.cov.to_rows() },
            deltas: r.deltas.clone(),
            algorithm: r.algorithm.name().to_string(),
            seed: r.seed,
            budget: r.budget,
            deadline_ns: r.deadline.map(|d| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX)),
            params: params_to_json(&r.params),
        }
    }

    /// The request again, with `params` (SPEC §11 names) for the recorded ones.
    pub fn rebuild_with(&self, params: &serde_json::Value) -> Result<RendezvousRequest, RebuildError> {
        let bad = |e: &dyn std::fmt::Display| RebuildError::Invalid(e.to_string());
        let belief = Belief::new(self.belief.mean, self.belief.cov).map_err(|e| bad(&e))?;
        let algorithm = Algorithm::from_name(&self.algorithm)
            .ok_or_else(|| RebuildError::Invalid(format!("unknown algorithm `{}`", self.algorithm)))?;
        let params = dyfos_shared::scenario::params_from_json(&params.to_string()).map_err(|e| bad(&e))?;
        Ok(RendezvousRequest {
            map: self.map,
            expected_version: self.expected_version,
            belief,
            deltas: self.deltas.clone(),
            algorithm,
            seed: self.seed,
            budget: self.budget,
            deadline: self.deadline_ns.map(Duration::from_nanos),
            params,
        })
    }

    /// The request again, as the daemon decoded it.
    pub fn rebuild(&self) -> Result<RendezvousRequest, RebuildError> {
        self.rebuild_with(&self.params)
    }
}

/// A rendezvous reply as recorded (and as `dyfos replay` compares it).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RecordedReply {
    /// The status name (`ok`, `no_feasible_pose`, …).
    pub status: String,
    /// The algorithm's name.
    pub algorithm: String,
    /// Why the search stopped.
    pub stop: String,
    /// The map version searched (or checked), after the inline deltas.
    pub map_version: u64,
    /// x = (ρ, ψ, φ, ψ_v).
    pub x: [f64; 4],
    /// E = ln det Σ⁺.
    pub cost: f64,
    /// p_s.
    pub sensor_position: [f64; 3],
    /// R_ws (x, y, z, w).
    pub sensor_quaternion: [f64; 4],
    /// p_v.
    pub viewer_position: [f64; 3],
    /// ψ_v.
    pub viewer_yaw: f64,
    /// R, rows.
    pub r: [[f64; 2]; 2],
    /// Σ⁺, rows.
    pub posterior: [[f64; 3]; 3],
    /// Evaluations: total, workspace, collision, occlusion.
    pub evaluations: [u64; 4],
    /// Search time, µs (not compared).
    pub micros: u64,
    /// Receipt to reply, µs (not compared).
    pub daemon_micros: u64,
    /// The failing delta's index, if any.
    pub error_index: Option<u64>,
    /// The detail text of an error.
    pub message: String,
}

impl RecordedReply {
    /// The reply as sent.
    pub fn of(r: &RendezvousReply) -> Self {
        RecordedReply {
            status: Status::try_from(r.status).map_or_else(|_| format!("status_{}", r.status), |s| s.name().into()),
            algorithm: Algorithm::try_from(r.algorithm).map_or("?", Algorithm::name).to_string(),
            stop: StopReason::try_from(r.stop).map_or("?", StopReason::name).to_string(),
            map_version: r.map_version,
            x: r.x,
            cost: r.cost,
            sensor_position: r.sensor_position,
            sensor_quaternion: r.sensor_quaternion,
            viewer_position: r.viewer_position,
            viewer_yaw: r.viewer_yaw,
            r: r.r,
            posterior: r.posterior,
            evaluations: r.evaluations,
            micros: r.micros,
            daemon_micros: r.daemon_micros,
            error_index: (r.error_index != u64::MAX).then_some(r.error_index),
            message: if r.status == Status::Ok as u32 { String::new() } else { r.detail.text() },
        }
    }

    /// Every floating-point number of the reply.
    fn floats(&self) -> impl Iterator<Item = f64> + '_ {
        self.x
            .iter()
            .chain(std::iter::once(&self.cost))
            .chain(&self.sensor_position)
            .chain(&self.sensor_quaternion)
            .chain(&self.viewer_position)
            .chain(std::iter::once(&self.viewer_yaw))
            .chain(self.r.iter().flatten())
            .chain(self.posterior.iter().flatten())
            .copied()
    }

    /// Whether `other` is the same answer bit for bit (every number compared by its
    /// bits; the timings `micros` and `daemon_micros` left out).
    pub fn identical(&self, other: &RecordedReply) -> bool {
        self.status == other.status
            && self.algorithm == other.algorithm
            && self.stop == other.stop
            && self.map_version == other.map_version
            && self.evaluations == other.evaluations
            && self.error_index == other.error_index
            && self.message == other.message
            && self.floats().map(f64::to_bits).eq(other.floats().map(f64::to_bits))
    }
}

/// A `/dyfosd/rendezvous` message, serialized straight from its parts.
#[derive(Serialize)]
struct RendezvousMessage {
    mode: &'static str,
    request_id: u64,
    received_ns: u64,
    replied_ns: u64,
    request: RecordedRequest,
    reply: RecordedReply,
}

/// Deltas as recorded: in the spelling of `docs/deltas.md`, or in serde's derived
/// one that recordings made before it hold, so that those still replay.
fn recorded_deltas<'de, D: serde::Deserializer<'de>>(d: D) -> Result<Vec<MapDelta>, D::Error> {
    Vec::<serde_json::Value>::deserialize(d)?
        .into_iter()
        .map(|v| dyfos_shared::map_json::recorded_delta_from_value(v).map_err(serde::de::Error::custom))
        .collect()
}

/// A map's content as recorded: obstacle upserts, then one voxel run if it has a
/// grid (what [`world_from_content`] rebuilds).
pub fn content_of(world: &World) -> Vec<MapDelta> {
    let mut out: Vec<MapDelta> =
        world.obstacles().iter().map(|(id, o)| MapDelta::UpsertObstacle { id: *id, obstacle: *o }).collect();
    if let Some(grid) = world.voxels() {
        out.push(MapDelta::SetVoxelBlocks {
            resolution: grid.resolution(),
            origin: grid.origin(),
            blocks: grid.blocks().collect(),
            occupied: true,
        });
    }
    out
}

/// A map's full state (`/dyfosd/map_state`, and the content of `create` and
/// `upload` changes).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct MapState {
    /// The map.
    pub map: MapId,
    /// Its version.
    pub version: u64,
    /// Bounds (x_min, y_min, x_max, y_max).
    pub bounds: [f64; 4],
    /// The sun.
    pub sun: Sun,
    /// Obstacles and voxels, as [`content_of`] writes them.
    #[serde(deserialize_with = "recorded_deltas")]
    pub content: Vec<MapDelta>,
}

impl MapState {
    /// The state of `world` as map `map`.
    pub fn of(map: MapId, world: &World) -> Self {
        MapState {
            map,
            version: world.version(),
            bounds: world.bounds().to_array(),
            sun: *world.sun(),
            content: content_of(world),
        }
    }

    /// The map again.
    pub fn rebuild(&self) -> Result<World, String> {
        let bounds = Bounds::new(self.bounds).map_err(|e| e.to_string())?;
        world_from_content(self.version, bounds, self.sun, &self.content).map_err(|e| e.to_string())
    }
}

/// What changed a map (`/dyfosd/map_change`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ChangeCause {
    /// `create`: a new empty map (content in the record).
    Create,
    /// A map request's deltas.
    Apply,
    /// A rendezvous query's inline deltas.
    Inline,
    /// A completed upload (content in the record).
    Upload,
    /// The map was deleted.
    Delete,
}

/// A map change as recorded.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct MapChange {
    /// The map.
    pub map: MapId,
    /// What changed it.
    pub cause: ChangeCause,
    /// The version the deltas were applied to (`apply`, `inline`).
    pub from_version: Option<u64>,
    /// The version it produced (for `delete`, the version deleted).
    pub version: u64,
    /// The deltas (`apply`, `inline`).
    #[serde(default, skip_serializing_if = "Vec::is_empty", deserialize_with = "recorded_deltas")]
    pub deltas: Vec<MapDelta>,
    /// The whole new map (`create`, `upload`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub state: Option<MapState>,
}

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

/// The daemon's side of the recorder: a bounded queue to the writer thread.
pub(crate) struct Recorder {
    tx: SyncSender<Record>,
    dropped: Arc<AtomicU64>,
    stopped: Arc<AtomicBool>,
    last_warning: Mutex<Option<Instant>>,
}

/// How long written messages may wait in the writer's buffer (what a killed daemon
/// may lose): the file is flushed this often while records keep coming, and this
/// long after the last one. Flushing per record would cost a system call each.
pub const FLUSH_EVERY: Duration = Duration::from_millis(20);

/// How often at most a dropped record is logged.
const DROP_LOG_EVERY: Duration = Duration::from_secs(5);

impl Recorder {
    /// Opens `config.path` (rotating an existing file away), writes its head and
    /// starts the writer thread.
    pub(crate) fn start(
        config: &RecordConfig,
        daemon_config: serde_json::Value,
        maps: BTreeMap<MapId, Arc<World>>,
    ) -> std::io::Result<(Recorder, Option<JoinHandle<()>>)> {
        let (tx, rx) = std::sync::mpsc::sync_channel(config.queue.max(1));
        let dropped = Arc::new(AtomicU64::new(0));
        let stopped = Arc::new(AtomicBool::new(false));
        let mut writer = Writer::new(config, daemon_config, maps, Arc::clone(&dropped));
        match writer.open() {
            Ok(()) => {}
            // A path that cannot be created is a mistake to see at start.
            Err(OpenError::Create(e)) => return Err(e),
            // A full disk is not: the daemon serves without recording.
            Err(OpenError::Write(e)) => {
                error!(path = %config.path.display(), "recording stopped: {} (the daemon carries on without recording)", error_text(&e));
                stopped.store(true, Ordering::Relaxed);
                return Ok((Recorder { tx, dropped, stopped, last_warning: Mutex::new(None) }, None));
            }
        }
        let stop = Arc::clone(&stopped);
        let handle = std::thread::Builder::new().name("dyfos-recorder".into()).spawn(move || {
            writer.run(rx);
            stop.store(true, Ordering::Relaxed);
        })?;
        info!(path = %config.path.display(), max_bytes = config.max_bytes, keep = config.keep, "recording the daemon's traffic");
        Ok((Recorder { tx, dropped, stopped, last_warning: Mutex::new(None) }, Some(handle)))
    }

    /// Hands `record` to the writer; never waits. A full queue drops it (counted).
    pub(crate) fn record(&self, record: Record) {
        if self.stopped.load(Ordering::Relaxed) {
            return;
        }
        match self.tx.try_send(record) {
            Ok(()) => {}
            Err(TrySendError::Full(_)) => {
                let total = self.dropped.fetch_add(1, Ordering::Relaxed) + 1;
                let mut last = self.last_warning.lock().unwrap_or_else(|p| p.into_inner());
                if last.is_none_or(|t| t.elapsed() >= DROP_LOG_EVERY) {
                    *last = Some(Instant::now());
                    warn!(
                        dropped = total,
                        "the recorder falls behind: records dropped (the recording says so; replay reports it incomplete)"
                    );
                }
            }
            Err(TrySendError::Disconnected(_)) => self.stopped.store(true, Ordering::Relaxed),
        }
    }

    /// Finishes the file (the writer writes what is queued first).
    pub(crate) fn close(&self, handle: JoinHandle<()>) {
        if !self.stopped.load(Ordering::Relaxed) {
            // Blocking is fine here: the daemon is stopping.
            let _ = self.tx.send(Record::Close);
        }
        if handle.join().is_err() {
            warn!("the recorder thread panicked; the recording may lack its summary");
        }
    }
}

/// The file, counting its bytes where the writer thread can read them while the
/// MCAP writer owns the file.
struct Counted {
    inner: BufWriter<File>,
    position: Arc<AtomicU64>,
}

impl Write for Counted {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        let n = self.inner.write(buf)?;
        self.position.fetch_add(n as u64, Ordering::Relaxed);
        Ok(n)
    }
    fn flush(&mut self) -> std::io::Result<()> {
        self.inner.flush()
    }
}

impl Seek for Counted {
    fn seek(&mut self, pos: SeekFrom) -> std::io::Result<u64> {
        let at = self.inner.seek(pos)?;
        self.position.store(at, Ordering::Relaxed);
        Ok(at)
    }
}

/// The open file and its channel ids by topic.
struct Open {
    mcap: mcap::Writer<Counted>,
    channels: BTreeMap<&'static str, u16>,
    /// Messages after the head: a file is rotated only once it has some.
    body_messages: u64,
    /// Bytes written.
    position: Arc<AtomicU64>,
}

/// An error with its causes, `: `-separated (the MCAP crate's own text hides the
/// I/O error, e.g. "No space left on device").
fn error_text(e: &mcap::McapError) -> String {
    let mut text = e.to_string();
    let mut source = std::error::Error::source(e);
    while let Some(cause) = source {
        text.push_str(": ");
        text.push_str(&cause.to_string());
        source = cause.source();
    }
    text
}

/// Why a file could not be started.
#[derive(Debug)]
enum OpenError {
    /// It could not be created.
    Create(std::io::Error),
    /// Its head could not be written.
    Write(mcap::McapError),
}

/// The writer thread's state.
struct Writer {
    config: RecordConfig,
    daemon_config: serde_json::Value,
    /// The current state of every map, for the head of the next file.
    maps: BTreeMap<MapId, Arc<World>>,
    file: Option<Open>,
    file_index: u64,
    dropped: Arc<AtomicU64>,
    dropped_written: u64,
    started: u64,
    sequence: u32,
}

impl Writer {
    fn new(
        config: &RecordConfig,
        daemon_config: serde_json::Value,
        maps: BTreeMap<MapId, Arc<World>>,
        dropped: Arc<AtomicU64>,
    ) -> Writer {
        Writer {
            config: config.clone(),
            daemon_config,
            maps,
            file: None,
            file_index: 0,
            dropped,
            dropped_written: 0,
            started: unix_ns(SystemTime::now()),
            sequence: 0,
        }
    }

    /// Whether the recording's path is a regular file: only those are rotated
    /// (`--record /dev/…` writes to the device as it is, never renames it).
    fn is_regular(&self) -> bool {
        std::fs::symlink_metadata(&self.config.path).is_ok_and(|m| m.is_file())
    }

    /// `FILE.(k-1)` → `FILE.k`, …, `FILE` → `FILE.1`; the oldest beyond `keep` is deleted.
    fn shift(&self) -> std::io::Result<()> {
        if !self.is_regular() {
            return Ok(());
        }
        let keep = self.config.keep;
        let oldest = self.config.rotated(keep.max(1));
        if keep == 0 {
            return std::fs::remove_file(&self.config.path);
        }
        if oldest.exists() {
            std::fs::remove_file(&oldest)?;
        }
        for i in (0..keep).rev() {
            let from = self.config.rotated(i);
            if from.exists() {
                std::fs::rename(&from, self.config.rotated(i + 1))?;
            }
        }
        Ok(())
    }

    /// Starts the next current file: writes its head, finishes the full one if any,
    /// rotates the file there (the full one, or one left by an earlier run) away and
    /// puts the new one in its place.
    /// The head is written under a temporary name first, so a daemon killed at any
    /// moment never leaves a current file without its head (at most a
    /// `FILE.mcap.part`, which the next start overwrites), and the name is without a
    /// current file only between two renames.
    fn open(&mut self) -> Result<(), OpenError> {
        let full = self.file.take();
        if std::fs::symlink_metadata(&self.config.path).is_ok_and(|m| !m.is_file()) {
            let file = File::create(&self.config.path).map_err(OpenError::Create)?;
            return self.write_head(file).map_err(OpenError::Write);
        }
        let partial = partial_path(&self.config.path);
        let head = File::create(&partial)
            .map_err(OpenError::Create)
            .and_then(|file| self.write_head(file).map_err(OpenError::Write));
        // The full file is finished only now, just before it is renamed away, and also
        // when the next one could not be started: it keeps its summary either way.
        if let Some(mut f) = full {
            f.mcap.finish().map_err(OpenError::Write)?;
        }
        head?;
        self.shift().map_err(OpenError::Create)?;
        std::fs::rename(&partial, &self.config.path).map_err(OpenError::Create)
    }

    fn write_head(&mut self, file: File) -> Result<(), mcap::McapError> {
        let position = Arc::new(AtomicU64::new(0));
        let out = Counted { inner: BufWriter::with_capacity(1 << 16, file), position: Arc::clone(&position) };
        let options = mcap::WriteOptions::new()
            .use_chunks(false)
            .compression(None)
            .profile("")
            .library(concat!("dyfosd ", env!("CARGO_PKG_VERSION")));
        let mut mcap = options.create(out)?;
        let mut channels = BTreeMap::new();
        for topic in topics::ALL {
            let schema = json_schema(topic).to_string();
            let schema_id = mcap.add_schema(topics::schema_name(topic), "jsonschema", schema.as_bytes())?;
            let id = mcap.add_channel(schema_id, topic, "json", &BTreeMap::new())?;
            channels.insert(topic, id);
        }
        self.file = Some(Open { mcap, channels, body_messages: 0, position });
        let now = unix_ns(SystemTime::now());
        let head = serde_json::json!({
            "build": {
                "name": "dyfosd",
                "version": env!("CARGO_PKG_VERSION"),
                "profile": if cfg!(debug_assertions) { "debug" } else { "release" },
            },
            "config": self.daemon_config,
            "pid": std::process::id(),
            "file_index": self.file_index,
            "started_ns": self.started,
            "dropped_before": self.dropped_written,
        });
        self.write(topics::CONFIG, now, now, &head)?;
        let states: Vec<MapState> = self.maps.iter().map(|(id, w)| MapState::of(*id, w)).collect();
        for state in states {
            self.write(topics::MAP_STATE, now, now, &state)?;
        }
        if let Some(f) = &mut self.file {
            f.body_messages = 0;
            f.mcap.flush()?;
        }
        Ok(())
    }

    fn write(
        &mut self,
        topic: &'static str,
        log: u64,
        publish: u64,
        message: &impl Serialize,
    ) -> Result<(), mcap::McapError> {
        let Some(f) = &mut self.file else { return Ok(()) };
        let data = serde_json::to_vec(message).map_err(std::io::Error::other)?;
        let header = mcap::records::MessageHeader {
            channel_id: f.channels[topic],
            sequence: self.sequence,
            log_time: log,
            publish_time: publish,
        };
        self.sequence = self.sequence.wrapping_add(1);
        f.mcap.write_to_known_channel(&header, &data)?;
        f.body_messages += 1;
        Ok(())
    }

    fn flush(&mut self) -> Result<(), mcap::McapError> {
        match &mut self.file {
            Some(f) => f.mcap.flush(),
            None => Ok(()),
        }
    }

    /// Writes one record; `false` on `Close`.
    fn write_record(&mut self, record: Record) -> Result<bool, mcap::McapError> {
        match record {
            Record::Close => return Ok(false),
            Record::MapChange { at, map, cause, deltas, world, from, version } => {
                let state = match (&world, cause) {
                    (Some(w), ChangeCause::Create | ChangeCause::Upload) => Some(MapState::of(map, w)),
                    _ => None,
                };
                match world {
                    Some(w) => self.maps.insert(map, w),
                    None => self.maps.remove(&map),
                };
                let change = MapChange { map, cause, from_version: from, version, deltas, state };
                self.write(topics::MAP_CHANGE, at, at, &change)?;
            }
            Record::Rendezvous { received, replied, mode, request_id, request, reply } => {
                let message = RendezvousMessage {
                    mode: if mode == Mode::Check { "check" } else { "solve" },
                    request_id,
                    received_ns: received,
                    replied_ns: replied,
                    request: RecordedRequest::of(&request),
                    reply: RecordedReply::of(&reply),
                };
                self.write(topics::RENDEZVOUS, received, replied, &message)?;
            }
            Record::Map { received, replied, message } => self.write(topics::MAP, received, replied, &message)?,
        }
        Ok(true)
    }

    /// Records the drop count if it grew.
    fn write_drops(&mut self) -> Result<(), mcap::McapError> {
        let total = self.dropped.load(Ordering::Relaxed);
        if total > self.dropped_written {
            let now = unix_ns(SystemTime::now());
            let message = serde_json::json!({
                "dropped_total": total,
                "dropped_new": total - self.dropped_written,
                "reason": "the recorder's queue was full",
            });
            self.dropped_written = total;
            self.write(topics::RECORDER, now, now, &message)?;
        }
        Ok(())
    }

    /// Closes a full file and opens the next.
    fn rotate_if_full(&mut self) -> Result<(), mcap::McapError> {
        let full = self
            .file
            .as_mut()
            .is_some_and(|f| f.body_messages > 0 && f.position.load(Ordering::Relaxed) >= self.config.max_bytes);
        if !full || !self.is_regular() {
            return Ok(());
        }
        self.file_index += 1;
        self.open().map_err(|e| match e {
            OpenError::Create(e) => e.into(),
            OpenError::Write(e) => e,
        })
    }

    /// Writes what arrives until `Close` (or every sender is gone), then finishes
    /// the file.
    fn write_all(&mut self, rx: &Receiver<Record>) -> Result<(), mcap::McapError> {
        let mut last_flush = Instant::now();
        let mut dirty = false;
        loop {
            // Unflushed messages: flush once no record came for FLUSH_EVERY.
            let first = if dirty {
                match rx.recv_timeout(FLUSH_EVERY) {
                    Ok(r) => r,
                    Err(RecvTimeoutError::Timeout) => {
                        self.flush()?;
                        (last_flush, dirty) = (Instant::now(), false);
                        continue;
                    }
                    Err(RecvTimeoutError::Disconnected) => break,
                }
            } else {
                match rx.recv() {
                    Ok(r) => r,
                    Err(_) => break,
                }
            };
            let mut more = self.write_record(first)?;
            // Drain what is queued; a full file is rotated at the message that filled
            // it, so a burst cannot carry a file far past its size.
            while more {
                self.rotate_if_full()?;
                match rx.try_recv() {
                    Ok(r) => more = self.write_record(r)?,
                    Err(_) => break,
                }
            }
            self.write_drops()?;
            dirty = true;
            // Messages are complete records in the file's order: whatever the buffer
            // last wrote, a killed daemon leaves every message before it readable.
            // Flushing is for how much a crash loses: at most FLUSH_EVERY's worth.
            if !more || last_flush.elapsed() >= FLUSH_EVERY {
                self.flush()?;
                (last_flush, dirty) = (Instant::now(), false);
            }
            if !more {
                break;
            }
            self.rotate_if_full()?;
        }
        self.write_drops()?;
        if let Some(mut f) = self.file.take() {
            f.mcap.finish()?;
        }
        Ok(())
    }

    fn run(&mut self, rx: Receiver<Record>) {
        let result = self.write_all(&rx);
        match result {
            Ok(()) => info!(path = %self.config.path.display(), "recording finished"),
            Err(e) => {
                error!(path = %self.config.path.display(), "recording stopped: {} (the daemon carries on; the file is readable up to its last complete message)", error_text(&e));
                // Dropping the writer would try to finish the file again: forget it.
                if let Some(f) = self.file.take() {
                    std::mem::forget(f.mcap);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use dyfos_shared::params::ModelKind;
    use dyfos_shared::world::{Obstacle, VerticalCylinder};

    /// Awkward numbers: no short decimal form, the smallest subnormal, -0.
    fn awkward() -> RendezvousRequest {
        let cov = [[0.1 + 0.2, 1e-3 / 3.0, 0.0], [1e-3 / 3.0, std::f64::consts::PI / 10.0, 0.0], [0.0, 0.0, 0.05]];
        let belief = Belief::new([1.0 / 3.0, -0.0, 2.0f64.sqrt()], cov).unwrap();
        let params = Params {
            rho_max: 6.0 + f64::EPSILON * 4.0,
            camera_pitch: 0.7f64.to_radians(),
            lambda: f64::from_bits(0x4008_0000_0000_0001),
            model: ModelKind::Anisotropic,
            ..Params::default()
        };
        let obstacle = Obstacle::Cylinder(VerticalCylinder {
            center: nalgebra::Point2::new(0.1 + 0.7, 5e-324),
            radius: 1.0 / 7.0,
            height: 2.5,
        });
        RendezvousRequest {
            expected_version: Some(3),
            deltas: vec![MapDelta::UpsertObstacle { id: 4, obstacle }],
            algorithm: Algorithm::DyfosScipy,
            seed: u64::MAX - 1,
            budget: Some(1234),
            deadline: Some(Duration::from_nanos(1_234_567_891)),
            params,
            ..RendezvousRequest::new(9, belief)
        }
    }

    #[test]
    fn a_recorded_request_is_rebuilt_bit_for_bit() {
        let request = awkward();
        let text = serde_json::to_string(&RecordedRequest::of(&request)).unwrap();
        let back: RecordedRequest = serde_json::from_str(&text).unwrap();
        let rebuilt = back.rebuild().unwrap();
        // `{:?}` prints every f64 in the shortest form that parses to the same bits
        // (-0.0 included): equal texts are equal bits.
        assert_eq!(format!("{rebuilt:?}"), format!("{request:?}"));
        assert_eq!(rebuilt.belief.mean.y.to_bits(), (-0.0f64).to_bits());
        assert_eq!(rebuilt.params.lambda.to_bits(), request.params.lambda.to_bits());
        // A changed parameter is seen.
        let mut params = back.params.clone();
        params["rho_max"] = serde_json::json!(5.0);
        assert_eq!(back.rebuild_with(&params).unwrap().params.rho_max, 5.0);
    }

    #[test]
    fn replies_are_compared_by_their_bits() {
        let answer = RendezvousReply { x: [1.0, 0.5, -0.25, 0.0], cost: -3.5, ..RendezvousReply::checked(1, 2) };
        let a = RecordedReply::of(&answer);
        let back: RecordedReply = serde_json::from_str(&serde_json::to_string(&a).unwrap()).unwrap();
        assert!(a.identical(&back));
        let timing = RecordedReply { micros: 99, daemon_micros: 7, ..a.clone() };
        assert!(a.identical(&timing), "timings are not compared");
        let signed_zero = RecordedReply { x: [1.0, 0.5, -0.25, -0.0], ..a.clone() };
        assert!(!a.identical(&signed_zero), "-0 and 0 differ in their bits");
        let next = RecordedReply { cost: f64::from_bits((-3.5f64).to_bits() + 1), ..a.clone() };
        assert!(!a.identical(&next));
    }

    #[test]
    fn dropped_records_are_counted_and_recorded() {
        let dir = std::env::temp_dir().join(format!("dyfos-record-drops-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let config = RecordConfig { queue: 1, ..RecordConfig::new(dir.join("drops.mcap")) };
        // The writer is not draining yet: the queue holds one record, the rest drop.
        let (tx, rx) = std::sync::mpsc::sync_channel(config.queue);
        let dropped = Arc::new(AtomicU64::new(0));
        let recorder = Recorder {
            tx,
            dropped: Arc::clone(&dropped),
            stopped: Arc::new(AtomicBool::new(false)),
            last_warning: Mutex::new(None),
        };
        let change = |v: u64| Record::MapChange {
            at: v,
            map: 1,
            cause: ChangeCause::Apply,
            deltas: Vec::new(),
            world: None,
            from: Some(v),
            version: v + 1,
        };
        for v in 0..3 {
            recorder.record(change(v));
        }
        assert_eq!(dropped.load(Ordering::Relaxed), 2);
        let mut writer = Writer::new(&config, serde_json::json!({}), BTreeMap::new(), dropped);
        writer.open().unwrap();
        let thread = std::thread::spawn(move || writer.run(rx));
        recorder.close(thread);
        let bytes = std::fs::read(&config.path).unwrap();
        let mut by_topic: BTreeMap<String, Vec<serde_json::Value>> = BTreeMap::new();
        for m in mcap::MessageStream::new(&bytes).unwrap() {
            let m = m.unwrap();
            by_topic.entry(m.channel.topic.clone()).or_default().push(serde_json::from_slice(&m.data).unwrap());
        }
        assert_eq!(by_topic[topics::MAP_CHANGE].len(), 1);
        assert_eq!(by_topic[topics::RECORDER].len(), 1);
        assert_eq!(by_topic[topics::RECORDER][0]["dropped_total"], 2);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn rotated_files_are_numbered_before_the_extension() {
        let p = Path::new("/var/log/dyfos/traffic.mcap");
        assert_eq!(rotated_path(p, 0), p);
        assert_eq!(rotated_path(p, 2), Path::new("/var/log/dyfos/traffic.2.mcap"));
        assert_eq!(rotated_path(Path::new("raw"), 1), Path::new("raw.1"));
    }

    #[test]
    fn a_map_state_rebuilds_the_map() {
        let bounds = Bounds::new([-5.0, -5.0, 5.0, 5.0]).unwrap();
        let world = World::empty(bounds, Sun::new(0.4, 0.1 + 0.2).unwrap())
            .apply(&awkward().deltas)
            .unwrap()
            .apply(&[MapDelta::SetVoxels {
                resolution: 0.3,
                origin: nalgebra::Point3::new(-1.0 / 3.0, 0.0, 0.0),
                cells: vec![[1, 2, 3], [4, 5, 6]],
                occupied: true,
            }])
            .unwrap();
        let state: MapState = serde_json::from_str(&serde_json::to_string(&MapState::of(4, &world)).unwrap()).unwrap();
        let rebuilt = state.rebuild().unwrap();
        assert!(rebuilt.same_content(&world));
        assert_eq!(rebuilt.version(), world.version());
    }
}
