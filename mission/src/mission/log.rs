//! The mission event log: one JSON object per line, flushed as written, so that a
//! killed process leaves every event it got to.
//!
//! ```
//! use dyfos_mission::mission::log::{EventLog, read_events};
//!
//! let path = std::env::temp_dir().join(format!("dyfos-log-doc-{}.jsonl", std::process::id()));
//! let log = EventLog::create(Some(&path), "rover")?;
//! log.record("arrived", 12.5, serde_json::json!({"step": 3}));
//! let events = read_events(&path)?;
//! assert_eq!(events[0]["event"], "arrived");
//! assert_eq!(events[0]["step"], 3);
//! # std::fs::remove_file(&path)?;
//! # Ok::<(), std::io::Error>(())
//! ```

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;
use std::sync::Mutex;

/// A JSON-lines event log (or nothing, when no file was asked for).
#[derive(Debug, Default)]
pub struct EventLog {
    out: Option<Mutex<BufWriter<File>>>,
    process: &'static str,
}

impl EventLog {
    /// Writes to `path` (created or truncated), each line tagged with `process`.
    pub fn create(path: Option<&Path>, process: &'static str) -> std::io::Result<Self> {
        let out = match path {
            Some(p) => Some(Mutex::new(BufWriter::new(File::create(p)?))),
            None => None,
        };
        Ok(EventLog { out, process })
    }

    /// Appends `{"process": .., "event": event, "sim_time": t, ..fields}`.
    pub fn record(&self, event: &str, sim_time: f64, fields: serde_json::Value) {
        let Some(out) = &self.out else { return };
        let mut line = serde_json::json!({"process": self.process, "event": event, "sim_time": sim_time});
        if let (Some(obj), serde_json::Value::Object(extra)) = (line.as_object_mut(), fields) {
            obj.extend(extra);
        }
        let mut out = out.lock().unwrap_or_else(|p| p.into_inner());
        // A log that cannot be written must not stop the robot.
        let _ = writeln!(out, "{line}").and_then(|()| out.flush());
    }
}

/// Reads an event log back (for tests and evaluations); malformed lines (a
/// process killed mid-write) are skipped.
pub fn read_events(path: &Path) -> std::io::Result<Vec<serde_json::Value>> {
    let text = std::fs::read_to_string(path)?;
    Ok(text.lines().filter_map(|l| serde_json::from_str(l).ok()).collect())
}
