//! The health and statistics service (`<prefix>stats`): liveness, uptime, queries
//! served and abandoned, errors by code and latency percentiles.
//!
//! ```
//! use dyfos_shared::wire::stats::{DaemonStats, StatsReply};
//! use dyfos_shared::wire::Status;
//!
//! let mut reply = StatsReply::default();
//! reply.errors_by_code[Status::UnknownMap as usize] = 2;
//! reply.queries_served = 5;
//! let stats = DaemonStats::from(&reply);
//! assert_eq!(stats.errors, vec![(Status::UnknownMap, 2)]);
//! assert_eq!(stats.queries_served, 5);
//! ```

use super::Status;
use iceoryx2::prelude::ZeroCopySend;

/// Slots of [`StatsReply::errors_by_code`] (codes beyond are counted in the last).
pub const STATUS_SLOTS: usize = 32;

/// A stats request.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, ZeroCopySend)]
#[type_name("dyfos::StatsRequest")]
#[repr(C)]
pub struct StatsRequest {
    /// The client's id for this request, echoed in the reply.
    pub request_id: u64,
    /// The client's reply listener id ([`super::split_u128`]).
    pub reply_to: [u64; 2],
}

/// The daemon's health and counters; `Default` is all zeros.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, ZeroCopySend)]
#[type_name("dyfos::StatsReply")]
#[repr(C)]
pub struct StatsReply {
    /// The request's id.
    pub request_id: u64,
    /// The daemon's process id.
    pub pid: u64,
    /// Time since the daemon started, µs.
    pub uptime_micros: u64,
    /// Rendezvous queries answered with a pose.
    pub queries_served: u64,
    /// Requests of any service answered with an error.
    pub requests_failed: u64,
    /// Map requests answered with success.
    pub map_requests: u64,
    /// Maps held.
    pub maps: u64,
    /// Queries waiting for a worker.
    pub queued: u64,
    /// Queries being searched.
    pub running: u64,
    /// Worker threads.
    pub workers: u64,
    /// Query latency from receipt to reply over the last queries answered
    /// (at most 4096), µs: median, 90th and 99th percentile, maximum.
    pub latency_micros: [u64; 4],
    /// Queries in that latency window.
    pub latency_samples: u64,
    /// Error replies by [`Status`] code.
    pub errors_by_code: [u64; STATUS_SLOTS],
    /// Queries abandoned because their client went away (killed, or dropped its
    /// pending response) before the answer, mid-search or while they waited for a
    /// worker; they got no reply.
    /// Last, so the fields before keep their offsets.
    pub queries_abandoned: u64,
    /// Times a receive from the daemon's ports failed, e.g. `ExceedsMaxBorrows`
    /// when a client keeps sending while its earlier requests still wait: the
    /// requests stay where they are and are taken later.
    pub receive_failures: u64,
    /// Warnings and errors the daemon's log saw (written or not).
    pub log_warnings: u64,
    /// Of those, iceoryx2's own (e.g. one per notification while a dead client's
    /// listener is still registered).
    pub ipc_warnings: u64,
    /// Log lines at `info` and above left out by the rate limit (the log says how
    /// many after each 10 s window).
    pub log_suppressed: u64,
}

/// [`StatsReply`] decoded.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DaemonStats {
    /// The daemon's process id.
    pub pid: u64,
    /// Time since the daemon started.
    pub uptime: std::time::Duration,
    /// Rendezvous queries answered with a pose.
    pub queries_served: u64,
    /// Queries abandoned because their client went away, mid-search or while they
    /// waited for a worker (no reply).
    pub queries_abandoned: u64,
    /// Requests answered with an error.
    pub requests_failed: u64,
    /// Successful map requests.
    pub map_requests: u64,
    /// Maps held.
    pub maps: u64,
    /// Queries waiting for a worker.
    pub queued: u64,
    /// Queries being searched.
    pub running: u64,
    /// Worker threads.
    pub workers: u64,
    /// Latency median, p90, p99, max, µs (receipt to reply).
    pub latency_micros: [u64; 4],
    /// Queries in the latency window.
    pub latency_samples: u64,
    /// Non-zero error counts by code.
    pub errors: Vec<(Status, u64)>,
    /// Failed receives from the daemon's ports (a client sending past its limit).
    pub receive_failures: u64,
    /// Warnings and errors the daemon's log saw.
    pub log_warnings: u64,
    /// Of those, iceoryx2's own.
    pub ipc_warnings: u64,
    /// Log lines left out by the rate limit.
    pub log_suppressed: u64,
}

impl From<&StatsReply> for DaemonStats {
    fn from(r: &StatsReply) -> Self {
        let errors = r
            .errors_by_code
            .iter()
            .enumerate()
            .filter(|(_, n)| **n > 0)
            .filter_map(|(code, n)| Status::try_from(code as u32).ok().map(|s| (s, *n)))
            .collect();
        DaemonStats {
            pid: r.pid,
            uptime: std::time::Duration::from_micros(r.uptime_micros),
            queries_served: r.queries_served,
            queries_abandoned: r.queries_abandoned,
            requests_failed: r.requests_failed,
            map_requests: r.map_requests,
            maps: r.maps,
            queued: r.queued,
            running: r.running,
            workers: r.workers,
            latency_micros: r.latency_micros,
            latency_samples: r.latency_samples,
            errors,
            receive_failures: r.receive_failures,
            log_warnings: r.log_warnings,
            ipc_warnings: r.ipc_warnings,
            log_suppressed: r.log_suppressed,
        }
    }
}

impl DaemonStats {
    /// As JSON, for `dyfos stats`.
    pub fn to_json(&self) -> serde_json::Value {
        let errors: serde_json::Map<String, serde_json::Value> =
            self.errors.iter().map(|(s, n)| (s.name().to_string(), serde_json::json!(n))).collect();
        let [p50, p90, p99, max] = self.latency_micros;
        serde_json::json!({
            "pid": self.pid,
            "uptime_s": self.uptime.as_secs_f64(),
            "queries_served": self.queries_served,
            "queries_abandoned": self.queries_abandoned,
            "requests_failed": self.requests_failed,
            "map_requests": self.map_requests,
            "maps": self.maps,
            "queued": self.queued,
            "running": self.running,
            "workers": self.workers,
            "latency_us": {"p50": p50, "p90": p90, "p99": p99, "max": max, "samples": self.latency_samples},
            "errors": errors,
            "receive_failures": self.receive_failures,
            "log": {"warnings": self.log_warnings, "ipc_warnings": self.ipc_warnings, "suppressed": self.log_suppressed},
        })
    }
}
