//! What Zenoh does below the log's level that the link must report: handshakes it
//! refused or gave up on (a host opening connections without completing them), and
//! failed attempts to reach the other host.
//!
//! Zenoh exposes no counter for these, only `debug` and `trace` lines, one per
//! event. [`TALLIES`] counts those lines ([`dyfos_process::logging::Tally`]: counted,
//! not written) and [`Health`] turns the counts into a warning at most once per
//! [`dyfos_process::logging::WINDOW`], the first as soon as there is something to say.
//!
//! ```
//! use dyfos_link::health::{Counts, Health};
//! use std::time::{Duration, Instant};
//!
//! let mut health = Health::new(Duration::from_secs(10));
//! let t0 = Instant::now();
//! let mut counts = Counts { timed_out: 300, ..Counts::default() };
//! assert_eq!(health.report(t0, &counts).len(), 1);
//! counts.timed_out = 600;
//! assert!(health.report(t0 + Duration::from_secs(1), &counts).is_empty()); // not yet
//! assert!(health.report(t0 + Duration::from_secs(10), &counts)[0].contains("300 given up"));
//! ```

use crate::{HANDSHAKE_TIMEOUT, PENDING_HANDSHAKES};
use dyfos_process::logging::Tally;
use std::time::{Duration, Instant};
use tracing::Level;

/// Where Zenoh accepts links and gives up on handshakes.
const ACCEPTING: &str = "zenoh_transport::unicast::manager";

/// A connection closed at once because [`PENDING_HANDSHAKES`] were pending.
pub static HANDSHAKES_REFUSED: Tally = Tally::new(ACCEPTING, Level::TRACE, "Closing link for preventing potential DoS");

/// A connection closed because its handshake was not complete within [`HANDSHAKE_TIMEOUT`].
pub static HANDSHAKES_TIMED_OUT: Tally = Tally::new(ACCEPTING, Level::DEBUG, "Failed to accept link before deadline");

/// A failed attempt to reach a `--connect` endpoint (Zenoh retries).
pub static CONNECT_FAILED: Tally =
    Tally::new("zenoh::net::runtime::orchestrator", Level::DEBUG, "Unable to connect to configured peer");

/// The tallies to give [`dyfos_process::logging::init_with`].
pub static TALLIES: [&Tally; 3] = [&HANDSHAKES_REFUSED, &HANDSHAKES_TIMED_OUT, &CONNECT_FAILED];

/// The tallies' counts since the start.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Counts {
    /// Connections refused: too many handshakes pending.
    pub refused: u64,
    /// Handshakes given up on: not complete in time.
    pub timed_out: u64,
    /// Failed attempts to reach the other host.
    pub connect_failed: u64,
    /// Zenoh's line for the last failed attempt (it says why).
    pub connect_last: String,
}

impl Counts {
    /// The counts of [`TALLIES`] now.
    pub fn now() -> Self {
        Counts {
            refused: HANDSHAKES_REFUSED.count(),
            timed_out: HANDSHAKES_TIMED_OUT.count(),
            connect_failed: CONNECT_FAILED.count(),
            connect_last: CONNECT_FAILED.last(),
        }
    }
}

/// Turns the counts into warnings, rate-limited.
#[derive(Debug)]
pub struct Health {
    every: Duration,
    since: Option<Instant>,
    reported: Counts,
}

impl Health {
    /// Reports at most once per `every`.
    pub fn new(every: Duration) -> Self {
        Health { every, since: None, reported: Counts::default() }
    }

    /// The warnings to log at `now` given the `counts` since the start: nothing if
    /// nothing new happened or the last report is less than `every` old.
    pub fn report(&mut self, now: Instant, counts: &Counts) -> Vec<String> {
        if self.since.is_some_and(|at| now.duration_since(at) < self.every) {
            return Vec::new();
        }
        let refused = counts.refused.saturating_sub(self.reported.refused);
        let timed_out = counts.timed_out.saturating_sub(self.reported.timed_out);
        let failed = counts.connect_failed.saturating_sub(self.reported.connect_failed);
        let mut lines = Vec::new();
        let secs =
            self.since.map_or(String::new(), |at| format!(" in the last {} s", now.duration_since(at).as_secs()));
        let mut parts = Vec::new();
        if refused > 0 {
            parts.push(format!("{refused} refused ({PENDING_HANDSHAKES} handshakes were pending already)"));
        }
        if timed_out > 0 {
            parts.push(format!("{timed_out} given up (no handshake within {HANDSHAKE_TIMEOUT:?})"));
        }
        if !parts.is_empty() {
            lines.push(format!(
                "incoming connections{secs}: {}; a host is connecting without completing the link's handshake",
                parts.join(", ")
            ));
        }
        if failed > 0 {
            lines.push(format!(
                "cannot reach the other host: {failed} attempts failed{secs}, still trying; the last: {}",
                counts.connect_last
            ));
        }
        if !lines.is_empty() {
            self.since = Some(now);
            self.reported = counts.clone();
        }
        lines
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_first_event_is_reported_at_once_then_at_most_once_per_period() {
        let mut health = Health::new(Duration::from_secs(10));
        let t0 = Instant::now();
        assert!(health.report(t0, &Counts::default()).is_empty());
        let mut c = Counts { connect_failed: 1, connect_last: "Connection refused".into(), ..Counts::default() };
        let first = health.report(t0, &c);
        assert_eq!(first.len(), 1);
        assert!(first[0].contains("1 attempts failed, still trying; the last: Connection refused"), "{first:?}");
        c.connect_failed = 9;
        c.refused = 5;
        assert!(health.report(t0 + Duration::from_secs(9), &c).is_empty());
        let next = health.report(t0 + Duration::from_secs(10), &c);
        assert_eq!(next.len(), 2, "{next:?}");
        assert!(next[0].contains("in the last 10 s: 5 refused (512 handshakes were pending already);"), "{next:?}");
        assert!(next[1].contains("8 attempts failed in the last 10 s"), "{next:?}");
        // Quiet: nothing, and the next event is reported at once.
        assert!(health.report(t0 + Duration::from_secs(30), &c).is_empty());
        c.timed_out = 1;
        assert_eq!(health.report(t0 + Duration::from_secs(31), &c).len(), 1);
    }
}
