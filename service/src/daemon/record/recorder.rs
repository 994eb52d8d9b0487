//! The daemon's side of the recording: a bounded queue to one writer thread, which
//! the IPC thread and the workers never wait for, and that thread's loop.

use super::writer::{OpenError, Writer, error_text};
use super::{Record, RecordConfig};
use dyfos_shared::wire::map::MapId;
use dyfos_shared::world::World;
use std::collections::BTreeMap;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, RecvTimeoutError, SyncSender, TrySendError};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};
use tracing::{error, info, warn};

/// The daemon's side of the recorder: a bounded queue to the writer thread.
pub(crate) struct TrafficRecorder {
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

impl TrafficRecorder {
    /// Opens `config.path` (rotating an existing file away), writes its head and
    /// starts the writer thread.
    pub(crate) fn start(
        config: &RecordConfig,
        daemon_config: serde_json::Value,
        maps: BTreeMap<MapId, Arc<World>>,
    ) -> std::io::Result<(TrafficRecorder, Option<JoinHandle<()>>)> {
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
                return Ok((TrafficRecorder { tx, dropped, stopped, last_warning: Mutex::new(None) }, None));
            }
        }
        let stop = Arc::clone(&stopped);
        let handle = std::thread::Builder::new().name("dyfos-recorder".into()).spawn(move || {
            writer.run(rx);
            stop.store(true, Ordering::Relaxed);
        })?;
        info!(path = %config.path.display(), max_bytes = config.max_bytes, keep = config.keep, "recording the daemon's traffic");
        Ok((TrafficRecorder { tx, dropped, stopped, last_warning: Mutex::new(None) }, Some(handle)))
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

impl Writer {
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
    use super::super::ChangeCause;
    use super::super::topics;
    use super::*;
    use dyfos_process::scratch::Scratch;

    #[test]
    fn dropped_records_are_counted_and_recorded() {
        let dir = Scratch::new("record-drops");
        let config = RecordConfig { queue: 1, ..RecordConfig::new(dir.0.join("drops.mcap")) };
        // The writer is not draining yet: the queue holds one record, the rest drop.
        let (tx, rx) = std::sync::mpsc::sync_channel(config.queue);
        let dropped = Arc::new(AtomicU64::new(0));
        let recorder = TrafficRecorder {
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
    }
}
