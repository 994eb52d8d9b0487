//! The IPC thread's pace: when it runs real-time, how long it polls before it
//! sleeps, and when idle cores are asked to poll.

use super::FALLBACK_WORKER_NICE;
use super::cpu_latency::CpuLatency;
use super::sched::{IpcPriority, IpcScheduling};
use crate::daemon::Scheduling;
use dyfos_process::idle::IdleCores;
use std::time::{Duration, Instant};

/// The IPC thread's scheduling state. Made on the IPC thread (real-time scheduling
/// is per thread).
#[derive(Debug)]
pub(crate) struct IpcPacing {
    scheduling: Scheduling,
    /// The IPC thread's real-time switch.
    priority: IpcPriority,
    ipc_scheduling: IpcScheduling,
    /// When requests last arrived, and the mean gap between arrivals (µs,
    /// exponentially weighted), which sizes the polling window.
    last_arrival: Instant,
    arrival_gap_us: f64,
    /// The CPU latency request, held while traffic is steady.
    cpu_latency: CpuLatency,
    /// Whether other work fills every core (and has for a while), looked up at most
    /// every [`IdleCores::EVERY`].
    cores: IdleCores,
}

impl IpcPacing {
    /// Tries real-time scheduling on the calling thread once, then leaves it
    /// poll-ready (normal) until the first wait. Threads it starts later are normal
    /// (`SCHED_RESET_ON_FORK`).
    pub(crate) fn start(scheduling: &Scheduling, cores: usize) -> IpcPacing {
        let (mut priority, ipc_scheduling) = IpcPriority::start(scheduling.ipc_priority);
        priority.lower();
        IpcPacing {
            scheduling: scheduling.clone(),
            priority,
            ipc_scheduling,
            last_arrival: Instant::now(),
            arrival_gap_us: f64::INFINITY,
            cpu_latency: CpuLatency::open(scheduling.cpu_latency_us.micros(), std::path::Path::new(CpuLatency::DEVICE)),
            cores: IdleCores::new(cores),
        }
    }

    /// What the IPC thread got at start.
    pub(crate) fn ipc_scheduling(&self) -> IpcScheduling {
        self.ipc_scheduling
    }

    /// Nice levels the workers run below the IPC thread: the fallback when it got
    /// neither real-time scheduling nor a short slice.
    pub(crate) fn worker_nice(&self) -> u8 {
        if self.ipc_scheduling == IpcScheduling::Refused { FALLBACK_WORKER_NICE } else { 0 }
    }

    /// Requests arrived (one pass of the IPC thread took some).
    pub(crate) fn arrived(&mut self) {
        let now = Instant::now();
        let gap = (now - self.last_arrival).as_secs_f64() * 1e6;
        self.last_arrival = now;
        self.arrival_gap_us =
            if self.arrival_gap_us.is_finite() { 0.875 * self.arrival_gap_us + 0.125 * gap } else { gap };
        if self.steady() {
            self.cpu_latency.hold();
        }
    }

    /// How long the IPC thread should keep polling after the last request before
    /// it sleeps, with `active()` searches running on `workers`; see
    /// [`Daemon::poll_window`](crate::daemon::Daemon::poll_window).
    pub(crate) fn poll_window(&mut self, active: impl FnOnce() -> usize, workers: usize) -> Duration {
        let s = &self.scheduling;
        let window = if self.steady() { s.poll_max() } else { s.poll() };
        if window.is_zero() || self.ipc_scheduling == IpcScheduling::Off {
            return window;
        }
        if active() >= workers || self.cores.busy_lasting() {
            return Duration::ZERO;
        }
        self.priority.lower();
        if self.priority.is_realtime() {
            return Duration::ZERO;
        }
        window
    }

    /// The IPC thread is about to sleep for at most `timeout`: back to real-time,
    /// and, once traffic stopped, the CPU latency request ends (or the sleep ends
    /// when it is due). Returns the timeout to sleep for.
    pub(crate) fn before_sleep(&mut self, timeout: Duration) -> Duration {
        self.priority.raise();
        match self.cpu_latency.release_if_quiet(self.last_arrival, Instant::now()) {
            Some(left) => timeout.min(left),
            None => timeout,
        }
    }

    /// The IPC thread woke from a sleep.
    pub(crate) fn slept(&mut self) {
        self.cores.slept();
    }

    /// Whether requests arrive about every [`Scheduling::poll_max_us`] or more often.
    fn steady(&self) -> bool {
        let s = &self.scheduling;
        s.poll_max_us > s.poll_us && self.arrival_gap_us <= s.poll_max().as_secs_f64() * 1e6
    }
}
