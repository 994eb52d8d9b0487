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

/// The counters a stats reply carries as they are, in wire order: those before
/// [`StatsReply::errors_by_code`], then those after it (added later, last so that
/// the fields before keep their offsets). [`StatsReply`], [`DaemonStats`] and the
/// decoding of one into the other are generated from this one list.
macro_rules! stats_types {
    (
        { $($(#[doc = $doc:literal])* $name:ident: $ty:ty,)* }
        { $($(#[doc = $later_doc:literal])* $later:ident: $later_ty:ty,)* }
    ) => {
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
            $($(#[doc = $doc])* pub $name: $ty,)*
            /// Error replies by [`Status`] code.
            pub errors_by_code: [u64; STATUS_SLOTS],
            $($(#[doc = $later_doc])* pub $later: $later_ty,)*
        }

        /// [`StatsReply`] decoded.
        #[derive(Debug, Clone, PartialEq, Eq)]
        pub struct DaemonStats {
            /// The daemon's process id.
            pub pid: u64,
            /// Time since the daemon started.
            pub uptime: std::time::Duration,
            $($(#[doc = $doc])* pub $name: $ty,)*
            /// Non-zero error counts by code.
            pub errors: Vec<(Status, u64)>,
            $($(#[doc = $later_doc])* pub $later: $later_ty,)*
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
                    $($name: r.$name,)*
                    errors,
                    $($later: r.$later,)*
                }
            }
        }
    };
}

stats_types! {
    {
        /// Rendezvous queries answered with a pose.
        queries_served: u64,
        /// Requests of any service answered with an error.
        requests_failed: u64,
        /// Map requests answered with success.
        map_requests: u64,
        /// Maps held.
        maps: u64,
        /// Queries waiting for a worker.
        queued: u64,
        /// Queries being searched.
        running: u64,
        /// Worker threads.
        workers: u64,
        /// Query latency from receipt to reply over the last queries answered
        /// (at most 4096), µs: median, 90th and 99th percentile, maximum.
        latency_micros: [u64; 4],
        /// Queries in that latency window.
        latency_samples: u64,
    }
    {
        /// Queries abandoned because their client went away (killed, or dropped its
        /// pending response) before the answer, mid-search or while they waited for a
        /// worker; they got no reply.
        queries_abandoned: u64,
        /// Times a receive from the daemon's ports failed, e.g. `ExceedsMaxBorrows`
        /// when a client keeps sending while its earlier requests still wait: the
        /// requests stay where they are and are taken later.
        receive_failures: u64,
        /// Warnings and errors the daemon's log saw (written or not).
        log_warnings: u64,
        /// Of those, iceoryx2's own (e.g. one per notification while a dead client's
        /// listener is still registered).
        ipc_warnings: u64,
        /// Log lines at `info` and above left out by the rate limit (the log says how
        /// many after each 10 s window).
        log_suppressed: u64,
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
