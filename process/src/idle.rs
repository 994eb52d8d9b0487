//! Whether the machine has a core to spare, for the wait strategies of `dyfosd` and
//! of `dyfos-client`: polling for a reply (or a request) is only worth its CPU while a
//! core is idle. When every core is taken, a poller that yields keeps a runnable
//! thread in the scheduler's queue and delays whoever wakes next, often a robot
//! process with a cheap request (`bench/RESULTS.md`, "Why the scheduling defaults");
//! sleeping on an event costs that one wait a wake-up instead.
//!
//! Two questions: [`IdleCores::busy`], whether every core is taken at this moment
//! (a search asks it to make way for a thread that just woke), and
//! [`IdleCores::busy_lasting`], whether they have been taken for a while (the
//! pollers ask it before they stop polling). A client that spins 50 µs for its
//! reply or a timer thread that runs for a moment fills a core too, but is gone
//! before a poller that stopped for it would be woken again; searches and other
//! processes' work last.

use std::cell::Cell;
use std::time::{Duration, Instant};

/// Whether other runnable threads fill every core, from the count of runnable
/// threads in `/proc/loadavg` (kept open; one `pread` of a few bytes),
/// looked up at most every [`IdleCores::EVERY`]. Unknown (not Linux, no `/proc`)
/// counts as not busy: the callers then poll as they did before.
#[derive(Debug)]
pub struct IdleCores {
    file: Option<std::fs::File>,
    cores: usize,
    checked: Cell<Option<Instant>>,
    busy: Cell<bool>,
    /// The first of the looks, up to the last, that all said busy; `None` once one
    /// said idle.
    busy_since: Cell<Option<Instant>>,
}

impl IdleCores {
    /// How long a look-up is trusted.
    pub const EVERY: Duration = Duration::from_micros(100);

    /// How long every look must have said busy for [`IdleCores::busy_lasting`]:
    /// longer than a client's spin for its reply (50 µs) or a timed sender's spin
    /// before its send (150 µs in `dyfos-bench latency`), short next to a search
    /// (over a thousand candidates) or a process that computes.
    pub const LASTING: Duration = Duration::from_micros(300);

    /// For a machine with `cores` cores.
    pub fn new(cores: usize) -> Self {
        IdleCores {
            file: std::fs::File::open("/proc/loadavg").ok(),
            cores,
            checked: Cell::new(None),
            busy: Cell::new(false),
            busy_since: Cell::new(None),
        }
    }

    /// For this machine: as many cores as the process may use.
    pub fn of_this_machine() -> Self {
        Self::new(std::thread::available_parallelism().map_or(1, usize::from))
    }

    /// Whether other runnable threads than the caller fill every core (false when
    /// unknown).
    pub fn busy(&self) -> bool {
        self.busy_at(Instant::now())
    }

    fn busy_at(&self, now: Instant) -> bool {
        if self.checked.get().is_some_and(|t| now - t < Self::EVERY) {
            return self.busy.get();
        }
        let busy = self.runnable().is_some_and(|n| n.saturating_sub(1) >= self.cores);
        self.record(busy, now);
        busy
    }

    /// Whether other runnable threads fill every core now and every look since at
    /// least [`IdleCores::LASTING`] ago said so: a load that lasts, not a thread
    /// that runs for a moment. A caller kept off the CPU between two looks (it
    /// yielded, and others ran) saw the load go on; one that slept says so with
    /// [`IdleCores::slept`].
    pub fn busy_lasting(&self) -> bool {
        let now = Instant::now();
        self.busy_at(now) && self.lasting_at(now)
    }

    /// Tells that the caller slept since its last look: a busy moment seen before
    /// says nothing of the time since and starts over at the next look; a load that
    /// had lasted is taken to go on.
    pub fn slept(&self) {
        if let (Some(since), Some(last)) = (self.busy_since.get(), self.checked.get())
            && last.saturating_duration_since(since) < Self::LASTING
        {
            self.busy_since.set(None);
        }
    }

    fn record(&self, busy: bool, at: Instant) {
        self.checked.set(Some(at));
        self.busy.set(busy);
        match (busy, self.busy_since.get()) {
            (false, _) => self.busy_since.set(None),
            (true, None) => self.busy_since.set(Some(at)),
            (true, Some(_)) => {}
        }
    }

    fn lasting_at(&self, now: Instant) -> bool {
        self.busy_since.get().is_some_and(|since| now.saturating_duration_since(since) >= Self::LASTING)
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

    /// An `IdleCores` of 2 cores and a clock in µs from now, to feed it looks.
    fn looks() -> (IdleCores, impl Fn(u64) -> Instant) {
        let t = Instant::now();
        (IdleCores::new(2), move |us| t + Duration::from_micros(us))
    }

    #[test]
    fn a_load_lasts_only_while_every_look_says_busy() {
        let (cores, at) = looks();
        cores.record(true, at(0));
        assert!(!cores.lasting_at(at(100)), "busy for 100 µs is a moment");
        cores.record(true, at(200));
        assert!(!cores.lasting_at(at(299)));
        assert!(cores.lasting_at(at(300)), "busy at every look for 300 µs lasts");
        cores.record(false, at(400));
        assert!(!cores.lasting_at(at(5_000)), "one idle look ends it");
        cores.record(true, at(5_000));
        assert!(!cores.lasting_at(at(5_100)), "a new load starts from its first look");
        assert!(cores.lasting_at(at(5_300)));
    }

    #[test]
    fn after_a_sleep_a_lasting_load_goes_on_and_a_moment_does_not() {
        let (cores, at) = looks();
        // Busy at 0 and 100 µs, then the caller sleeps 4 ms: a moment, not a load.
        cores.record(true, at(0));
        cores.record(true, at(100));
        cores.slept();
        cores.record(true, at(4_100));
        assert!(!cores.lasting_at(at(4_100)), "two busy looks 4 ms apart are not 4 ms of load");
        assert!(!cores.lasting_at(at(4_300)));
        assert!(cores.lasting_at(at(4_400)), "busy at every look since 4.1 ms");
        // Busy at every look from 4.1 to 4.5 ms: a load; over the next sleep it goes on.
        cores.record(true, at(4_500));
        cores.slept();
        cores.record(true, at(9_000));
        assert!(cores.lasting_at(at(9_000)), "a load that had lasted is taken to go on over the sleep");
    }

    #[test]
    fn a_caller_kept_off_the_cpu_between_looks_saw_the_load_go_on() {
        let (cores, at) = looks();
        // A poller that yielded at 0 µs and ran again 2 ms later: others had the cores.
        cores.record(true, at(0));
        cores.record(true, at(2_000));
        assert!(cores.lasting_at(at(2_000)));
    }

    #[test]
    fn a_machine_with_more_cores_than_threads_is_not_busy() {
        // Nothing runs a million threads: if /proc/loadavg is there, it says "idle".
        let cores = IdleCores::new(1_000_000);
        assert!(!cores.busy());
        assert!(!cores.busy_lasting());
    }
}
