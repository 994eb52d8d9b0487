//! What a rover or viewer writes down about its mission: the event log and the MCAP
//! file, configured the same way in both.

use crate::eval::{McapMission, McapProfile, McapWriteError};
use crate::mission::Mission;
use crate::mission::log::EventLog;
use std::path::PathBuf;

/// Where a mission process writes what it saw; by default nothing.
#[derive(Debug, Clone, Default)]
pub struct OutputConfig {
    /// JSON-lines event log.
    pub events: Option<PathBuf>,
    /// MCAP file of the mission as this process saw it, written at exit (also after
    /// a failure, with what was recorded).
    pub mcap: Option<PathBuf>,
    /// Encoding of [`OutputConfig::mcap`]: Foxglove's JSON (default) or ROS 2's CDR.
    pub mcap_profile: McapProfile,
}

impl OutputConfig {
    /// Runs `run` with the MCAP recording, if asked for, and writes it when `run` ends.
    pub fn around<R, E: From<McapWriteError>>(
        &self,
        mission: &Mission,
        run: impl FnOnce(&mut Option<McapMission>) -> Result<R, E>,
    ) -> Result<R, E> {
        McapMission::around(self.mcap.as_deref(), self.mcap_profile, mission, run)
    }

    /// The event log of the process `who` (none if not asked for).
    pub fn event_log(&self, who: &'static str) -> std::io::Result<EventLog> {
        EventLog::create(self.events.as_deref(), who)
    }
}
