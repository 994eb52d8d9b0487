//! Whether the machine has a core to spare, for the wait strategies of `dyfosd` and
//! of this client: polling for a reply (or a request) is only worth its CPU while a
//! core is idle. When every core is taken, a poller that yields keeps a runnable
//! thread in the scheduler's queue and delays whoever wakes next, often a robot
//! process with a cheap request (`bench/RESULTS.md`, "Cheap requests while searches
//! run"); sleeping on an event costs that one wait a wake-up (50–100 µs) instead.

use std::cell::Cell;
use std::time::{Duration, Instant};

/// Whether other runnable threads fill every core, from the count of runnable
/// threads in `/proc/loadavg` (kept open; one `pread` of a few bytes, about 2 µs),
/// looked up at most every [`IdleCores::EVERY`]. Unknown (not Linux, no `/proc`)
/// counts as not busy: the callers then poll as they did before.
#[derive(Debug)]
pub struct IdleCores {
    file: Option<std::fs::File>,
    cores: usize,
    checked: Cell<Option<Instant>>,
    busy: Cell<bool>,
}

impl IdleCores {
    /// How long a look-up is trusted.
    pub const EVERY: Duration = Duration::from_micros(100);

    /// For a machine with `cores` cores.
    pub fn new(cores: usize) -> Self {
        IdleCores {
            file: std::fs::File::open("/proc/loadavg").ok(),
            cores,
            checked: Cell::new(None),
            busy: Cell::new(false),
        }
    }

    /// For this machine: as many cores as the process may use.
    pub fn of_this_machine() -> Self {
        Self::new(std::thread::available_parallelism().map_or(1, usize::from))
    }

    /// Whether other runnable threads than the caller fill every core (false when
    /// unknown).
    pub fn busy(&self) -> bool {
        if self.checked.get().is_some_and(|t| t.elapsed() < Self::EVERY) {
            return self.busy.get();
        }
        self.checked.set(Some(Instant::now()));
        let busy = self.runnable().is_some_and(|n| n.saturating_sub(1) >= self.cores);
        self.busy.set(busy);
        busy
    }

    /// Runnable threads now, the caller included: `/proc/loadavg`'s fourth field
    /// is `RUNNABLE/TOTAL`.
    fn runnable(&self) -> Option<usize> {
        #[cfg(unix)]
        {
            use std::os::unix::fs::FileExt;
            let mut buf = [0u8; 64];
            let n = self.file.as_ref()?.read_at(&mut buf, 0).ok()?;
            runnable_of(&buf[..n])
        }
        #[cfg(not(unix))]
        None
    }
}

/// The runnable-thread count of `/proc/loadavg`'s text, e.g. `0.52 0.58 0.59 3/467 12345`.
fn runnable_of(text: &[u8]) -> Option<usize> {
    std::str::from_utf8(text).ok()?.split_whitespace().nth(3)?.split('/').next()?.parse().ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_runnable_count_is_the_fourth_field() {
        assert_eq!(runnable_of(b"0.52 0.58 0.59 3/467 12345\n"), Some(3));
        assert_eq!(runnable_of(b"0.52 0.58 0.59 17/467 12345"), Some(17));
        assert_eq!(runnable_of(b"0.52 0.58"), None);
        assert_eq!(runnable_of(b"a b c x/467 1"), None);
    }

    #[test]
    fn a_machine_with_more_cores_than_threads_is_not_busy() {
        // Nothing runs a million threads: if /proc/loadavg is there, it says "idle".
        assert!(!IdleCores::new(1_000_000).busy());
    }
}
