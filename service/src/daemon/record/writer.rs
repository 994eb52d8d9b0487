//! The MCAP file of a recording: its head (configuration and every map), its
//! messages, and its rotation once it is full.

use super::exchange::{RecordedReply, RecordedRequest, RendezvousMessage};
use super::format::{json_schema, topics};
use super::map_state::{MapChange, MapState};
use super::{ChangeCause, Record, RecordConfig, unix_ns};
use dyfos_shared::wire::map::MapId;
use dyfos_shared::wire::rendezvous::Mode;
use dyfos_shared::world::World;
use serde::Serialize;
use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufWriter, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::SystemTime;

/// `FILE.mcap` → `FILE.mcap.part`: where a file's head is written before the file
/// takes its name.
fn partial_path(path: &Path) -> PathBuf {
    let mut name = path.as_os_str().to_owned();
    name.push(".part");
    PathBuf::from(name)
}

/// The file, counting its bytes where the writer thread can read them while the
/// MCAP writer owns the file.
pub(super) struct Counted {
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
pub(super) struct Open {
    pub(super) mcap: mcap::Writer<Counted>,
    channels: BTreeMap<&'static str, u16>,
    /// Messages after the head: a file is rotated only once it has some.
    body_messages: u64,
    /// Bytes written.
    position: Arc<AtomicU64>,
}

/// An error with its causes, `: `-separated (the MCAP crate's own text hides the
/// I/O error, e.g. "No space left on device").
pub(super) fn error_text(e: &mcap::McapError) -> String {
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
pub(super) enum OpenError {
    /// It could not be created.
    Create(std::io::Error),
    /// Its head could not be written.
    Write(mcap::McapError),
}

/// The writer thread's state.
pub(super) struct Writer {
    pub(super) config: RecordConfig,
    daemon_config: serde_json::Value,
    /// The current state of every map, for the head of the next file.
    maps: BTreeMap<MapId, Arc<World>>,
    pub(super) file: Option<Open>,
    file_index: u64,
    dropped: Arc<AtomicU64>,
    dropped_written: u64,
    started: u64,
    sequence: u32,
}

impl Writer {
    pub(super) fn new(
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
    pub(super) fn open(&mut self) -> Result<(), OpenError> {
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

    pub(super) fn flush(&mut self) -> Result<(), mcap::McapError> {
        match &mut self.file {
            Some(f) => f.mcap.flush(),
            None => Ok(()),
        }
    }

    /// Writes one record; `false` on `Close`.
    pub(super) fn write_record(&mut self, record: Record) -> Result<bool, mcap::McapError> {
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
    pub(super) fn write_drops(&mut self) -> Result<(), mcap::McapError> {
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
    pub(super) fn rotate_if_full(&mut self) -> Result<(), mcap::McapError> {
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
}
