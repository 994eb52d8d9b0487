//! Replaying a recording (`dyfos replay FILE.mcap`): re-runs every query a
//! recording daemon answered (`dyfosd --record`) against this build and says, per
//! query, whether the answer is bit-identical. See `docs/record.md`.
//!
//! [`replay_file`] reads one file, rebuilds every map version it saw, answers each
//! recorded query with [`answer_query`] (the daemon's own function from a request
//! to a reply) and compares the reply with the recorded one. It says what it finds
//! line by line through a `report` callback (the command line prints them) and
//! returns the counts ([`Tally`]).
//!
//! ```no_run
//! use dyfos_service::daemon::record::replay::{ReplayOptions, replay_file};
//!
//! let options = ReplayOptions { set: Default::default(), model: None, threads: 1, quiet: true };
//! let tally = replay_file("dyfosd.mcap".as_ref(), &options, &mut |line| println!("{line}"))?;
//! assert_eq!(tally.different, 0);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

mod maps;
mod query;

use super::{MapState, topics};
use crate::learned::{ModelLoadError, load_model};
use dyfos_shared::wire::map::MapId;
use dyfos_shared::world::World;
use maps::apply_change;
use query::Replay;
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// How to replay.
#[derive(Debug, Clone, Default)]
pub struct ReplayOptions {
    /// SPEC §11 parameters to override in every query, by name (`--set NAME=VALUE`),
    /// already checked by the caller.
    pub set: serde_json::Map<String, serde_json::Value>,
    /// Model file of the learned SDSMM, for queries with model `learned`; `None`
    /// uses the file the recording daemon loaded, if it is still there.
    pub model: Option<PathBuf>,
    /// Worker threads for `brute` (the answer does not change).
    pub threads: usize,
    /// Report only the queries that differ and the summary.
    pub quiet: bool,
}

/// Why a file cannot be replayed at all. Everything else (a broken message, a map
/// that cannot be rebuilt, a truncated file) is reported and counted instead.
#[derive(Debug, thiserror::Error)]
pub enum ReplayError {
    /// The file cannot be read.
    #[error("cannot read recording {}", path.display())]
    Read {
        /// The recording.
        path: PathBuf,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// The file is not MCAP.
    #[error("{} is not an MCAP file: {error}", path.display())]
    NotMcap {
        /// The recording.
        path: PathBuf,
        /// What the MCAP reader said.
        error: mcap::McapError,
    },
    /// The model file given in [`ReplayOptions::model`] cannot be loaded.
    #[error(transparent)]
    Model(#[from] ModelLoadError),
}

/// Counts of one file's replay.
#[derive(Debug, Default, Clone, PartialEq, Eq)]
pub struct Tally {
    /// Messages read.
    pub messages: u64,
    /// Queries whose replayed answer is bit-identical.
    pub identical: u64,
    /// Queries whose replayed answer differs (checks included).
    pub different: u64,
    /// Stopped at their deadline: not reproducible.
    pub deadline: u64,
    /// Their map (version) could not be rebuilt, or their request not.
    pub unreplayable: u64,
    /// Check-mode queries compared.
    pub checks: u64,
    /// Map changes read.
    pub map_changes: u64,
    /// Map requests read.
    pub map_requests: u64,
    /// Records the recorder dropped (its queue was full).
    pub dropped: u64,
    /// The file has no proper end (a killed daemon, or unreadable from some point).
    pub truncated: bool,
    /// Map states or changes that could not be rebuilt.
    pub broken_changes: u64,
}

impl Tally {
    /// Whether the recording is incomplete: truncated, records dropped, or maps or
    /// queries that could not be rebuilt.
    pub fn incomplete(&self) -> bool {
        self.truncated || self.dropped > 0 || self.unreplayable > 0 || self.broken_changes > 0
    }
}

/// Replays one recording, reporting what it finds line by line to `report`.
pub fn replay_file(path: &Path, options: &ReplayOptions, report: &mut dyn FnMut(&str)) -> Result<Tally, ReplayError> {
    let bytes = std::fs::read(path).map_err(|source| ReplayError::Read { path: path.to_owned(), source })?;
    let stream = mcap::MessageStream::new_with_options(&bytes, mcap::read::Options::IgnoreEndMagic.into())
        .map_err(|error| ReplayError::NotMcap { path: path.to_owned(), error })?;
    let name = path.display().to_string();
    let mut t = Tally::default();
    // Every map at every version seen: queries answered by workers are recorded
    // after later changes may have been.
    let mut worlds: HashMap<(MapId, u64), Arc<World>> = HashMap::new();
    let mut learned = match &options.model {
        Some(m) => Some(load_model(m)?),
        None => None,
    };
    let mut ended_cleanly = true;
    for message in stream {
        let message = match message {
            Ok(m) => m,
            Err(e) => {
                report(&format!("{name}: truncated after {} messages ({e}); replaying what was read", t.messages));
                ended_cleanly = false;
                break;
            }
        };
        t.messages += 1;
        let json: serde_json::Value = match serde_json::from_slice(&message.data) {
            Ok(j) => j,
            Err(e) => {
                report(&format!(
                    "{name}: message {} on {} is not JSON ({e}); skipped",
                    t.messages, message.channel.topic
                ));
                t.unreplayable += 1;
                continue;
            }
        };
        match message.channel.topic.as_str() {
            topics::CONFIG => {
                let model = json["config"]["model"].as_str().map(PathBuf::from);
                if learned.is_none()
                    && let Some(m) = model.filter(|m| m.exists())
                {
                    learned = load_model(&m).ok();
                }
                if !options.quiet {
                    report(&format!(
                        "{name}: recorded by dyfosd {} (pid {}, file {} of its run); replayed by dyfos {}",
                        json["build"]["version"].as_str().unwrap_or("?"),
                        json["pid"],
                        json["file_index"],
                        env!("CARGO_PKG_VERSION")
                    ));
                }
                t.dropped = t.dropped.max(json["dropped_before"].as_u64().unwrap_or(0));
            }
            topics::MAP_STATE => match serde_json::from_value::<MapState>(json).map_err(|e| e.to_string()) {
                Ok(state) => match state.rebuild() {
                    Ok(w) => {
                        worlds.insert((state.map, state.version), Arc::new(w));
                    }
                    Err(e) => {
                        report(&format!(
                            "{name}: map {} at version {} cannot be rebuilt: {e}",
                            state.map, state.version
                        ));
                        t.broken_changes += 1;
                    }
                },
                Err(e) => {
                    report(&format!("{name}: unreadable map state: {e}"));
                    t.broken_changes += 1;
                }
            },
            topics::MAP_CHANGE => {
                t.map_changes += 1;
                if let Err(e) = apply_change(json, &mut worlds) {
                    report(&format!("{name}: {e}"));
                    t.broken_changes += 1;
                }
            }
            topics::MAP => t.map_requests += 1,
            topics::RECORDER => {
                t.dropped = t.dropped.max(json["dropped_total"].as_u64().unwrap_or(0));
            }
            topics::RENDEZVOUS => {
                let replay = Replay { name: &name, worlds: &worlds, options, learned: learned.as_ref() };
                replay.query(&json, &mut t, report);
            }
            other => {
                if !options.quiet {
                    report(&format!("{name}: channel {other} is not dyfosd's; skipped"));
                }
            }
        }
    }
    let complete = ended_cleanly && bytes.ends_with(mcap::MAGIC);
    if ended_cleanly && !complete {
        report(&format!(
            "{name}: truncated after {} messages (no end of file: the daemon was killed); replayed them",
            t.messages
        ));
    }
    t.truncated = !complete;
    let queries = t.identical + t.different + t.deadline + t.unreplayable;
    report(&format!(
        "{name}: {queries} queries replayed: {} identical, {} different, {} stopped at their deadline (not reproducible), {} not replayable; {} checks, {} map changes, {} map requests; {}{}",
        t.identical,
        t.different,
        t.deadline,
        t.unreplayable,
        t.checks,
        t.map_changes,
        t.map_requests,
        if complete {
            "recording complete".to_string()
        } else {
            format!("recording truncated after {} messages", t.messages)
        },
        if t.dropped > 0 || t.broken_changes > 0 {
            format!(
                "; INCOMPLETE: {} records dropped by the recorder, {} map changes not rebuilt",
                t.dropped, t.broken_changes
            )
        } else {
            String::new()
        }
    ));
    Ok(t)
}

#[cfg(test)]
mod tests {
    use super::*;
    use dyfos_process::scratch::Scratch;

    /// A scratch directory of its own, and `name` in it.
    fn scratch(name: &str) -> (Scratch, PathBuf) {
        let dir = Scratch::new(&format!("replay-unit-{name}"));
        let path = dir.0.join(name);
        (dir, path)
    }

    #[test]
    fn a_missing_file_is_a_read_error_naming_it() {
        let (_dir, path) = scratch("missing.mcap");
        let mut lines = Vec::new();
        let err = replay_file(&path, &ReplayOptions::default(), &mut |l| lines.push(l.to_string())).unwrap_err();
        assert!(matches!(err, ReplayError::Read { .. }), "{err:?}");
        assert!(err.to_string().starts_with("cannot read recording "), "{err}");
        assert!(lines.is_empty(), "{lines:?}");
    }

    /// The MCAP reader finds the bad magic at the first record, not on opening: such a
    /// file replays nothing and is reported as truncated (incomplete, `dyfos replay`
    /// exits 4), as the command always did.
    #[test]
    fn a_file_that_is_not_mcap_replays_nothing_and_is_incomplete() {
        let (_dir, path) = scratch("not-mcap.mcap");
        std::fs::write(&path, b"{\"not\": \"mcap\"}").unwrap();
        let mut lines = Vec::new();
        let t = replay_file(&path, &ReplayOptions::default(), &mut |l| lines.push(l.to_string())).unwrap();
        assert_eq!(t, Tally { truncated: true, ..Tally::default() });
        assert!(t.incomplete());
        assert_eq!(lines.len(), 2, "{lines:?}");
        assert!(lines[0].contains("truncated after 0 messages"), "{lines:?}");
        assert!(lines[1].ends_with("recording truncated after 0 messages"), "{lines:?}");
    }

    #[test]
    fn an_empty_recording_replays_nothing_and_is_complete() {
        let (_dir, path) = scratch("empty.mcap");
        let mut writer = mcap::Writer::new(std::io::BufWriter::new(std::fs::File::create(&path).unwrap())).unwrap();
        writer.finish().unwrap();
        drop(writer);
        let mut lines = Vec::new();
        let t = replay_file(&path, &ReplayOptions::default(), &mut |l| lines.push(l.to_string())).unwrap();
        assert_eq!(t, Tally::default());
        assert!(!t.incomplete());
        assert_eq!(lines.len(), 1, "{lines:?}");
        assert!(lines[0].ends_with("0 queries replayed: 0 identical, 0 different, 0 stopped at their deadline (not reproducible), 0 not replayable; 0 checks, 0 map changes, 0 map requests; recording complete"), "{lines:?}");
    }
}
