//! The stats service: counters kept by the IPC thread and the workers.

use super::ports::{Replies, StatsActive};
use super::state::State;
use dyfos_shared::wire::stats::{STATUS_SLOTS, StatsReply, StatsRequest};
use dyfos_shared::wire::{Status, join_u128};
use tracing::debug;

/// Answers one stats request.
pub(super) fn on_request(state: &State, replies: &Replies, active: StatsActive) {
    let request = *active.payload();
    let reply = reply(state, &request);
    match active.loan_uninit() {
        Ok(loan) => {
            if let Err(e) = loan.write_payload(reply).send() {
                debug!("stats reply not delivered: {e:?}");
            }
        }
        Err(e) => debug!("stats reply not delivered: {e:?}"),
    }
    replies.notify(join_u128(request.reply_to));
}

/// The counters now, as the reply to `request`.
fn reply(state: &State, request: &StatsRequest) -> StatsReply {
    let log = dyfos_process::logging::counters();
    let (queued, running) = {
        let q = state.pool.queue();
        (q.queued() as u64, q.running() as u64)
    };
    let mut s = state.pool.stats();
    StatsReply {
        request_id: request.request_id,
        pid: u64::from(std::process::id()),
        uptime_micros: u64::try_from(s.started.elapsed().as_micros()).unwrap_or(u64::MAX),
        queries_served: s.queries_served,
        requests_failed: s.requests_failed,
        map_requests: s.map_requests,
        maps: state.maps.len() as u64,
        queued,
        running,
        workers: state.pool.workers as u64,
        latency_micros: s.percentiles(PERCENTILES_MAX_AGE),
        latency_samples: s.latencies.len() as u64,
        errors_by_code: s.errors,
        queries_abandoned: s.queries_abandoned,
        receive_failures: s.receive_failures,
        log_warnings: log.warnings,
        ipc_warnings: log.ipc_warnings,
        log_suppressed: log.suppressed,
    }
}

/// Latencies kept for the percentiles.
const WINDOW: usize = 4096;

/// How stale the percentiles a `stats` reply carries may be: sorting the window
/// costs tens of µs on the IPC thread, so a watchdog polling `stats` a thousand
/// times a second must not pay it every time.
const PERCENTILES_MAX_AGE: std::time::Duration = std::time::Duration::from_millis(20);

/// Counters and the latency window.
pub(crate) struct Stats {
    started: std::time::Instant,
    queries_served: u64,
    queries_abandoned: u64,
    requests_failed: u64,
    map_requests: u64,
    receive_failures: u64,
    errors: [u64; STATUS_SLOTS],
    latencies: Vec<u64>,
    next: usize,
    /// The last percentiles, when they were computed, whether samples came since,
    /// and the buffer they were sorted in (allocated once).
    cached: [u64; 4],
    computed: Option<std::time::Instant>,
    dirty: bool,
    scratch: Vec<u64>,
}

impl Stats {
    pub(crate) fn new() -> Self {
        Stats {
            started: std::time::Instant::now(),
            queries_served: 0,
            queries_abandoned: 0,
            requests_failed: 0,
            map_requests: 0,
            receive_failures: 0,
            errors: [0; STATUS_SLOTS],
            latencies: Vec::with_capacity(WINDOW),
            next: 0,
            cached: [0; 4],
            computed: None,
            dirty: false,
            scratch: Vec::with_capacity(WINDOW),
        }
    }

    /// A query answered with a pose after `micros` in the daemon.
    pub(crate) fn served(&mut self, micros: u64) {
        self.queries_served += 1;
        if self.latencies.len() < WINDOW {
            self.latencies.push(micros);
        } else {
            self.latencies[self.next] = micros;
        }
        self.next = (self.next + 1) % WINDOW;
        self.dirty = true;
    }

    /// A query abandoned because its client had gone, mid-search or while it waited
    /// for a worker (no reply).
    pub(crate) fn abandoned(&mut self) {
        self.queries_abandoned += 1;
    }

    /// A request answered with an error.
    pub(crate) fn failed(&mut self, status: Status) {
        self.requests_failed += 1;
        self.errors[(status as usize).min(STATUS_SLOTS - 1)] += 1;
    }

    /// A receive from one of the daemon's ports failed.
    pub(crate) fn receive_failed(&mut self) {
        self.receive_failures += 1;
    }

    /// A map request answered with success.
    pub(crate) fn map_ok(&mut self) {
        self.map_requests += 1;
    }

    /// p50, p90, p99 and max of the window, recomputed only when samples came and
    /// the last computation is older than `max_age`.
    fn percentiles(&mut self, max_age: std::time::Duration) -> [u64; 4] {
        if self.latencies.is_empty() {
            return [0; 4];
        }
        if !self.dirty || self.computed.is_some_and(|t| t.elapsed() < max_age) {
            return self.cached;
        }
        let v = &mut self.scratch;
        v.clear();
        v.extend_from_slice(&self.latencies);
        v.sort_unstable();
        let at = |q: f64| v[((v.len() - 1) as f64 * q).round() as usize];
        self.cached = [at(0.5), at(0.9), at(0.99), v[v.len() - 1]];
        self.computed = Some(std::time::Instant::now());
        self.dirty = false;
        self.cached
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentiles_over_the_window() {
        let fresh = std::time::Duration::ZERO;
        let mut s = Stats::new();
        assert_eq!(s.percentiles(fresh), [0; 4]);
        for v in 1..=100 {
            s.served(v);
        }
        assert_eq!(s.percentiles(fresh), [51, 90, 99, 100]);
        for _ in 0..WINDOW {
            s.served(7);
        }
        // Within the maximum age, the last figures; then the new ones.
        assert_eq!(s.percentiles(std::time::Duration::from_secs(3600)), [51, 90, 99, 100]);
        assert_eq!(s.percentiles(fresh), [7; 4]);
        s.failed(Status::UnknownMap);
        assert_eq!(s.errors[Status::UnknownMap as usize], 1);
    }
}
