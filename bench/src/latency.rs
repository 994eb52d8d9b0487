//! Query latency and throughput of `dyfosd`: the request mix, the
//! closed- and open-loop drivers the client processes of `dyfos-bench latency`
//! run, the in-process baseline, and iceoryx2's raw request-response floor.
//!
//! ```
//! use dyfos_bench::latency::{Arrivals, Latencies, drive, poisson_schedule};
//! use std::time::Duration;
//!
//! // Open-loop arrivals: a seeded Poisson process, about rate × duration of them.
//! let schedule = poisson_schedule(2000.0, Duration::from_secs(1), 7, 0);
//! assert!((1800..2200).contains(&schedule.len()));
//! assert_eq!(schedule, poisson_schedule(2000.0, Duration::from_secs(1), 7, 0));
//!
//! // A closed loop over a call that always succeeds.
//! let run = drive(Arrivals::Closed, Duration::from_millis(20), 1, 0, |_| Ok(None));
//! assert!(run.latency_ns.len() > 100 && run.errors.is_empty());
//!
//! let l = Latencies::of_nanos(&mut vec![1_000, 2_000, 3_000, 4_000]).unwrap();
//! assert_eq!((l.p50_us, l.max_us), (2.5, 4.0));
//! ```
//!
//! *What is measured.* A client process sends a request and waits for its reply
//! through [`dyfos_client::Client`], as a robot would (its default spin-then-sleep
//! wait). Closed loop: each client sends its next request as soon as the previous
//! one is answered. Open loop: every client follows its own Poisson schedule
//! (rate / clients each, so together they are a Poisson process of the full rate)
//! and a request's latency counts from its *scheduled* send time, so a request
//! that waits behind a slow one is charged for the wait (no coordinated omission).
//! Requests a client could not even send by the end of the run (twice the planned
//! duration) are counted as `unsent`.
//!
//! The requests: one `dyfos` query per SPEC §10 numerical map ([`RequestSet`],
//! maps from [`crate::numerical`]); client `c` starts at map `c` and cycles. The
//! null query is the same request in check mode ([`Mode::Check`]): the daemon
//! validates it (belief, parameters, map id and version) and answers without a
//! search, which isolates IPC and dispatch.

use crate::evaluation::query_seed;
use crate::numerical::{NumericalConfig, numerical_maps};
use crate::stats::quantile_sorted;
use dyfos_process::idle::IdleCores;
use dyfos_service::search::SearchControl;
use dyfos_service::solve;
use dyfos_shared::scenario::Scenario;
use dyfos_shared::sdsmm::NoiseModel;
use dyfos_shared::wire::map::{MapId, WireDelta};
use dyfos_shared::wire::rendezvous::{Mode, RendezvousReply, RendezvousRequest, RendezvousRequestHeader};
use dyfos_shared::wire::services::{self, Services};
use iceoryx2::prelude::*;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::collections::BTreeMap;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// What the client processes ask.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Workload {
    /// Check-mode rendezvous requests: validated, not searched.
    Null,
    /// `dyfos` queries on the numerical maps.
    Dyfos,
    /// iceoryx2's raw request-response round trip with the rendezvous payload types
    /// against a busy-polling server that only copies back a fixed reply.
    Floor,
    /// `stats` requests (answered by the IPC thread).
    Stats,
    /// Map snapshots of the numerical maps (answered by the IPC thread).
    Map,
    /// One greedy client: `dyfos` queries with [`GREEDY_IN_FLIGHT`] in flight at
    /// all times on one connection ([`GreedyClient`]).
    Greedy,
    /// Not a client: a process that burns one core (a CPU hog beside the daemon).
    Hog,
    /// A client that comes and goes: connects, asks for `stats` and leaves,
    /// [`CHURN_PER_SECOND`] times a second (a watchdog run from a shell); its
    /// latency is the whole visit.
    Churn,
}

/// Visits a second of the [`Workload::Churn`] client.
pub const CHURN_PER_SECOND: f64 = 10.0;

/// Queries the greedy client keeps in flight: `dyfosd`'s default limit per client.
pub const GREEDY_IN_FLIGHT: usize = 4;

impl Workload {
    /// Every workload.
    pub const ALL: [Workload; 8] = [
        Workload::Null,
        Workload::Dyfos,
        Workload::Floor,
        Workload::Stats,
        Workload::Map,
        Workload::Greedy,
        Workload::Hog,
        Workload::Churn,
    ];

    /// The name used on the command line and in tables.
    pub fn name(self) -> &'static str {
        match self {
            Workload::Null => "null",
            Workload::Dyfos => "dyfos",
            Workload::Floor => "floor",
            Workload::Stats => "stats",
            Workload::Map => "map",
            Workload::Greedy => "greedy",
            Workload::Hog => "hog",
            Workload::Churn => "churn",
        }
    }

    /// The workload called `name`.
    pub fn from_name(name: &str) -> Option<Workload> {
        Workload::ALL.into_iter().find(|w| w.name() == name)
    }
}

/// The map id under which numerical map `i` is stored in the daemon.
pub fn map_id(i: usize) -> MapId {
    i as MapId + 1
}

/// The benchmark's requests: one `dyfos` query per numerical map (SPEC §10 seed
/// `seed`), each with the map's belief and parameters and its own search seed.
#[derive(Debug, Clone)]
pub struct RequestSet {
    /// The maps, map `i` stored as [`map_id`]`(i)`.
    pub scenarios: Vec<Scenario>,
    /// Request `i` asks about map `i`.
    pub requests: Vec<RendezvousRequest>,
}

impl RequestSet {
    /// `maps` numerical maps of seed `seed` and their queries.
    pub fn new(seed: u64, maps: usize) -> Self {
        let scenarios = numerical_maps(seed, maps.max(1), &NumericalConfig::paper());
        let requests = scenarios
            .iter()
            .enumerate()
            .map(|(i, s)| RendezvousRequest {
                seed: query_seed(seed, i),
                params: s.params,
                ..RendezvousRequest::new(map_id(i), s.belief)
            })
            .collect();
        RequestSet { scenarios, requests }
    }

    /// The request client `client` sends `k`-th.
    pub fn pick(&self, client: usize, k: usize) -> (usize, &RendezvousRequest) {
        let i = (client + k) % self.requests.len();
        (i, &self.requests[i])
    }
}

/// How requests are issued.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Arrivals {
    /// The next request as soon as the previous reply arrived.
    Closed,
    /// A Poisson process of `rate` requests per second.
    Open {
        /// Requests per second.
        rate: f64,
    },
}

/// The arrival times of a Poisson process of `rate` per second within
/// `[0, duration)`: exponential gaps drawn from ChaCha stream (`seed`, `stream`).
pub fn poisson_schedule(rate: f64, duration: Duration, seed: u64, stream: u64) -> Vec<Duration> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(stream);
    let end = duration.as_secs_f64();
    let mut t = 0.0;
    let mut out = Vec::new();
    if !(rate > 0.0 && rate.is_finite()) {
        return out;
    }
    loop {
        let u: f64 = rng.random();
        t += -(1.0 - u).ln() / rate; // 1 − u ∈ (0, 1]: finite
        if t >= end {
            return out;
        }
        out.push(Duration::from_secs_f64(t));
    }
}

/// What one request's call returned: the search time the daemon reported (µs,
/// `dyfos` only), or the name of the error.
pub type CallOutcome = Result<Option<u64>, String>;

/// The samples of one client's run.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RunSamples {
    /// Latency of every successful request, ns (open loop: from the scheduled time).
    pub latency_ns: Vec<u64>,
    /// For `dyfos`, per successful request: the search time the daemon reported, µs
    /// (same order as `latency_ns`).
    pub search_us: Vec<u64>,
    /// Requests answered with an error, by error name.
    pub errors: BTreeMap<String, u64>,
    /// Open loop: how late each request was sent after its scheduled time, ns (the
    /// client process's own scheduling delay; part of its latency).
    pub late_ns: Vec<u64>,
    /// Open loop: each answered request's latency from its actual send, ns: the
    /// latency without the client's own wake-up delay.
    #[serde(default)]
    pub from_send_ns: Vec<u64>,
    /// Open loop: scheduled requests never sent (the client fell too far behind).
    pub unsent: u64,
    /// Wall time of the measured part, s.
    pub elapsed_s: f64,
    /// CPU time the process used over the measured part, s (hogs only).
    #[serde(default)]
    pub cpu_s: f64,
}

/// Waits until `target`: sleeps while it is far; spins for the last stretch (a
/// sleep overshoots by tens of µs, which an open loop would charge as latency)
/// unless every core has been taken for a while ([`IdleCores::busy_lasting`]).
/// When they are, spinning would take CPU from the daemon under test, and a thread
/// that has just spun is the one the scheduler lets wait longest; it then sleeps to
/// the target (with a 1 ns timer slack, see [`precise_timers`]), as a robot's
/// timed loop would. Another sender spinning for a moment, or the daemon polling,
/// is not such a load: sleeping for them made many of the sparse run's sends late
/// by a timer wake-up, which the open loop charges as latency (`bench/RESULTS.md`,
/// "Why the scheduling defaults").
fn wait_until(target: Instant, cores: &IdleCores) {
    const SPIN: Duration = Duration::from_micros(150);
    loop {
        let now = Instant::now();
        if now >= target {
            return;
        }
        let left = target - now;
        if cores.busy_lasting() {
            std::thread::sleep(left);
            cores.slept();
        } else if left > SPIN {
            std::thread::sleep(left - SPIN);
            cores.slept();
        } else {
            std::hint::spin_loop();
        }
    }
}

/// Asks for timer wake-ups of the calling thread within 1 ns of their time rather
/// than the default 50 µs slack, so an open loop's sleep ends on schedule.
#[cfg(target_os = "linux")]
#[allow(unsafe_code)]
fn precise_timers() {
    // SAFETY: PR_SET_TIMERSLACK takes one integer argument and touches no memory.
    let _ = unsafe { libc::prctl(libc::PR_SET_TIMERSLACK, 1 as libc::c_ulong) };
}

#[cfg(not(target_os = "linux"))]
fn precise_timers() {}

/// Runs `call(k)` for requests `k = 0, 1, …` for `duration`, closed or open loop
/// (open: schedule from ChaCha stream (`seed`, `stream`)), and times each.
pub fn drive(
    arrivals: Arrivals,
    duration: Duration,
    seed: u64,
    stream: u64,
    mut call: impl FnMut(usize) -> CallOutcome,
) -> RunSamples {
    let mut out = RunSamples::default();
    let record = |out: &mut RunSamples, outcome: CallOutcome, from: Instant| {
        let ns = u64::try_from(from.elapsed().as_nanos()).unwrap_or(u64::MAX);
        match outcome {
            Ok(search) => {
                out.latency_ns.push(ns);
                if let Some(us) = search {
                    out.search_us.push(us);
                }
            }
            Err(e) => *out.errors.entry(e).or_default() += 1,
        }
    };
    let start = Instant::now();
    match arrivals {
        Arrivals::Closed => {
            let mut k = 0;
            while start.elapsed() < duration {
                let t0 = Instant::now();
                let outcome = call(k);
                record(&mut out, outcome, t0);
                k += 1;
            }
        }
        Arrivals::Open { rate } => {
            let schedule = poisson_schedule(rate, duration, seed, stream);
            let cores = IdleCores::of_this_machine();
            precise_timers();
            let give_up = start + 2 * duration;
            for (k, at) in schedule.iter().enumerate() {
                let target = start + *at;
                wait_until(target, &cores);
                if Instant::now() >= give_up {
                    out.unsent = (schedule.len() - k) as u64;
                    break;
                }
                let sent = Instant::now();
                out.late_ns.push(u64::try_from((sent - target).as_nanos()).unwrap_or(u64::MAX));
                let outcome = call(k);
                if outcome.is_ok() {
                    out.from_send_ns.push(u64::try_from(sent.elapsed().as_nanos()).unwrap_or(u64::MAX));
                }
                record(&mut out, outcome, target);
            }
        }
    }
    out.elapsed_s = start.elapsed().as_secs_f64();
    out
}

/// Latency percentiles, µs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Latencies {
    /// Samples.
    pub count: usize,
    /// Median.
    pub p50_us: f64,
    /// 90th percentile.
    pub p90_us: f64,
    /// 99th percentile.
    pub p99_us: f64,
    /// 99.9th percentile.
    pub p999_us: f64,
    /// Largest.
    pub max_us: f64,
    /// Mean.
    pub mean_us: f64,
}

impl Latencies {
    /// Percentiles (linearly interpolated, as numpy) of `samples` in ns; sorts them.
    pub fn of_nanos(samples: &mut [u64]) -> Option<Self> {
        if samples.is_empty() {
            return None;
        }
        samples.sort_unstable();
        let us: Vec<f64> = samples.iter().map(|n| *n as f64 / 1e3).collect();
        let q = |p| quantile_sorted(&us, p);
        Some(Latencies {
            count: us.len(),
            p50_us: q(0.5),
            p90_us: q(0.9),
            p99_us: q(0.99),
            p999_us: q(0.999),
            max_us: us[us.len() - 1],
            mean_us: us.iter().sum::<f64>() / us.len() as f64,
        })
    }
}

/// The same requests as library calls on this thread, no daemon: a `dyfos` query
/// is [`solve`] (one thread, as on a daemon worker); a null query is what the
/// daemon does for a check (decode and validate the header, look the map up,
/// compare its version).
pub fn in_process(workload: Workload, set: &RequestSet, duration: Duration) -> RunSamples {
    let models: Vec<Option<NoiseModel>> =
        set.scenarios.iter().map(|s| NoiseModel::from_params(&s.params).ok()).collect();
    drive(Arrivals::Closed, duration, 0, 0, |k| {
        let (i, request) = set.pick(0, k);
        let world = &set.scenarios[i].world;
        match workload {
            Workload::Dyfos => {
                let Some(model) = &models[i] else { return Err("unsupported_model".into()) };
                let control =
                    SearchControl { budget: request.budget, threads: 1, ..SearchControl::seeded(request.seed) };
                solve(world, &request.belief, &request.params, model, request.algorithm, &control)
                    .map(|a| Some(a.micros))
                    .map_err(|_| "no_feasible_pose".into())
            }
            _ => {
                let header = request.header(Mode::Check, k as u64, [0, 0]);
                let (decoded, _) = RendezvousRequest::decode(&header, &[]).map_err(|r| r.status.name().to_string())?;
                let found = set.scenarios.get((decoded.map as usize).wrapping_sub(1)).map(|s| s.world.version());
                match (found, decoded.expected_version) {
                    (None, _) => Err("unknown_map".into()),
                    (Some(v), Some(e)) if v != e => Err("map_version_mismatch".into()),
                    _ => Ok(std::hint::black_box(None)),
                }
            }
        }
    })
}

type FloorService = ipc::Service;

/// The iceoryx2 configuration of a domain (iceoryx2's file prefix).
fn domain_config(domain: &str) -> Result<iceoryx2::config::Config, String> {
    services::iceoryx_config(Some(domain)).map_err(|e| e.to_string())
}

fn node(domain: &str) -> Result<Node<FloorService>, String> {
    NodeBuilder::new()
        .config(&domain_config(domain)?)
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<FloorService>()
        .map_err(|e| format!("iceoryx2 node: {e:?}"))
}

/// The floor's server: creates request-response service `service` with the
/// rendezvous payload types and answers every request with a fixed check reply,
/// busy-polling, until `stop` is set. Call it on its own thread; returns the
/// number of requests answered.
pub fn serve_floor(domain: &str, service: &str, max_clients: usize, stop: &AtomicBool) -> Result<u64, String> {
    let node = node(domain)?;
    let server = services::rendezvous_named(&node, service)
        .map_err(|e| e.to_string())?
        .enable_fire_and_forget_requests(false)
        .max_clients(max_clients.max(1))
        .max_nodes(max_clients.max(1) + 1)
        .create()
        .map_err(|e| format!("create {service}: {e:?}"))?
        .server_builder()
        .create()
        .map_err(|e| format!("floor server: {e:?}"))?;
    let mut answered = 0;
    while !stop.load(Ordering::Relaxed) {
        match server.receive() {
            Ok(Some(active)) => {
                let id = active.user_header().request_id;
                let loan = active.loan_uninit().map_err(|e| format!("loan: {e:?}"))?;
                // A client that left is not the floor's problem.
                let _ = loan.write_payload(RendezvousReply::checked(id, 0)).send();
                answered += 1;
            }
            Ok(None) => std::hint::spin_loop(),
            Err(e) => return Err(format!("receive: {e:?}")),
        }
    }
    Ok(answered)
}

/// The floor's client: sends a rendezvous header (no records) and busy-polls for
/// the reply, nothing else.
pub struct FloorClient {
    _node: Node<FloorService>,
    port: iceoryx2::port::client::Client<FloorService, [WireDelta], RendezvousRequestHeader, RendezvousReply, ()>,
    header: RendezvousRequestHeader,
}

impl std::fmt::Debug for FloorClient {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("FloorClient").finish_non_exhaustive()
    }
}

impl FloorClient {
    /// Opens the floor service, waiting up to `timeout` for the server.
    pub fn open(domain: &str, service: &str, request: &RendezvousRequest, timeout: Duration) -> Result<Self, String> {
        let node = node(domain)?;
        let builder = services::rendezvous_named(&node, service).map_err(|e| e.to_string())?;
        let start = Instant::now();
        let service = loop {
            match builder.clone().open() {
                Ok(s) => break s,
                Err(e) if start.elapsed() > timeout => return Err(format!("open {service}: {e:?}")),
                Err(_) => std::thread::sleep(Duration::from_millis(5)),
            }
        };
        let port = service.client_builder().create().map_err(|e| format!("floor client: {e:?}"))?;
        let header = request.header(Mode::Check, 0, [0, 0]);
        Ok(FloorClient { _node: node, port, header })
    }

    /// One round trip; gives up after `timeout`.
    pub fn call(&mut self, timeout: Duration) -> CallOutcome {
        self.header.request_id = self.header.request_id.wrapping_add(1);
        let mut loan = self.port.loan_slice_uninit(0).map_err(|e| format!("loan: {e:?}"))?;
        *loan.user_header_mut() = self.header;
        let pending = loan.write_from_slice(&[]).send().map_err(|e| format!("send: {e:?}"))?;
        let start = Instant::now();
        loop {
            if let Some(reply) = pending.receive().map_err(|e| format!("receive: {e:?}"))? {
                return if reply.payload().request_id == self.header.request_id {
                    Ok(None)
                } else {
                    Err("wrong_reply".into())
                };
            }
            if start.elapsed() > timeout {
                return Err("timeout".into());
            }
            std::hint::spin_loop();
        }
    }
}

/// A greedy client: keeps [`GREEDY_IN_FLIGHT`] `dyfos` queries in flight on one
/// client port of the daemon's rendezvous service (raw iceoryx2, as
/// `dyfos_client::Client` sends one at a time), polling for replies every 50 µs.
pub struct GreedyClient {
    _node: Node<FloorService>,
    port: iceoryx2::port::client::Client<FloorService, [WireDelta], RendezvousRequestHeader, RendezvousReply, ()>,
    wake: iceoryx2::port::notifier::Notifier<FloorService>,
    next_id: u64,
}

impl std::fmt::Debug for GreedyClient {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GreedyClient").finish_non_exhaustive()
    }
}

impl GreedyClient {
    /// Opens the rendezvous service and wake-up event of the daemon at `prefix`.
    pub fn open(domain: &str, prefix: &str) -> Result<Self, String> {
        let node = node(domain)?;
        let names = dyfos_shared::wire::ServiceNames::new(prefix).map_err(|e| e.to_string())?;
        let services = Services::new(&node, &names);
        // Each service opened as the daemon made it, then the port on it.
        macro_rules! port {
            ($service:ident, $builder:ident, $port:literal) => {
                services
                    .$service()
                    .map_err(|e| e.to_string())?
                    .open()
                    .map_err(|e| format!("open {}: {e:?}", names.$service))?
                    .$builder()
                    .create()
                    .map_err(|e| format!("{}: {e:?}", $port))?
            };
        }
        let port = port!(rendezvous, client_builder, "greedy client");
        let wake = port!(wake, notifier_builder, "wake notifier");
        Ok(GreedyClient { _node: node, port, wake, next_id: 1 << 40 })
    }

    /// Sends the requests of `set` in turn, [`GREEDY_IN_FLIGHT`] at a time, for
    /// `duration`; each answered query is one sample (latency from its send).
    pub fn run(&mut self, set: &RequestSet, index: usize, duration: Duration) -> Result<RunSamples, String> {
        type Pending = iceoryx2::pending_response::PendingResponse<
            FloorService,
            [WireDelta],
            RendezvousRequestHeader,
            RendezvousReply,
            (),
        >;
        let mut out = RunSamples::default();
        let mut in_flight: Vec<(Pending, u64, Instant)> = Vec::with_capacity(GREEDY_IN_FLIGHT);
        let start = Instant::now();
        let mut k = 0;
        while start.elapsed() < duration || !in_flight.is_empty() {
            while in_flight.len() < GREEDY_IN_FLIGHT && start.elapsed() < duration {
                let (_, request) = set.pick(index, k);
                k += 1;
                self.next_id += 1;
                let header = request.header(Mode::Solve, self.next_id, [0, 0]);
                let loan = self.port.loan_slice_uninit(0).map_err(|e| format!("loan: {e:?}"))?;
                let mut loan = loan;
                *loan.user_header_mut() = header;
                let pending = loan.write_from_slice(&[]).send().map_err(|e| format!("send: {e:?}"))?;
                self.wake.notify().map_err(|e| format!("notify: {e:?}"))?;
                in_flight.push((pending, self.next_id, Instant::now()));
            }
            let mut i = 0;
            while i < in_flight.len() {
                let reply = in_flight[i].0.receive().map_err(|e| format!("receive: {e:?}"))?.map(|r| *r.payload());
                match reply {
                    Some(r) if r.request_id == in_flight[i].1 => {
                        let (_, _, sent) = in_flight.swap_remove(i);
                        let ns = u64::try_from(sent.elapsed().as_nanos()).unwrap_or(u64::MAX);
                        if r.status == 0 {
                            out.latency_ns.push(ns);
                        } else {
                            *out.errors.entry(format!("status {}", r.status)).or_default() += 1;
                        }
                    }
                    _ => i += 1,
                }
            }
            if start.elapsed() > duration * 4 + Duration::from_secs(30) {
                return Err("the greedy client's queries were not answered".into());
            }
            std::thread::sleep(Duration::from_micros(50));
        }
        out.elapsed_s = start.elapsed().as_secs_f64();
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn poisson_schedule_has_the_rate_and_exponential_gaps() {
        let s = poisson_schedule(10_000.0, Duration::from_secs(2), 3, 1);
        let n = s.len() as f64;
        // Poisson count: mean 20 000, std ≈ 141.
        assert!((n - 20_000.0).abs() < 700.0, "{n}");
        assert!(s.windows(2).all(|w| w[0] <= w[1]) && *s.last().unwrap() < Duration::from_secs(2));
        // Exponential gaps: the fraction above the mean gap is e^-1 ≈ 0.368.
        let above = s.windows(2).filter(|w| (w[1] - w[0]).as_secs_f64() > 1e-4).count() as f64 / (n - 1.0);
        assert!((above - (-1f64).exp()).abs() < 0.02, "{above}");
        assert_ne!(s, poisson_schedule(10_000.0, Duration::from_secs(2), 3, 2));
        assert!(poisson_schedule(0.0, Duration::from_secs(1), 3, 1).is_empty());
    }

    #[test]
    fn open_loop_charges_the_wait_behind_a_slow_request() {
        // Requests every ~1 ms, the first one takes 30 ms: those scheduled during it
        // are charged from their scheduled time, not from when they could be sent.
        let run = drive(Arrivals::Open { rate: 1000.0 }, Duration::from_millis(60), 5, 0, |k| {
            if k == 0 {
                std::thread::sleep(Duration::from_millis(30));
            }
            Ok(None)
        });
        let mut l = run.latency_ns.clone();
        let s = Latencies::of_nanos(&mut l).unwrap();
        assert!(s.max_us >= 30_000.0, "{s:?}");
        // About half the requests were scheduled during the slow one.
        let late = run.latency_ns.iter().filter(|n| **n > 1_000_000).count();
        assert!(late >= 10, "only {late} requests charged for the wait");
        assert_eq!(run.unsent, 0);
        assert_eq!(run.late_ns.len(), run.latency_ns.len());
        // Sent late exactly when charged for the wait.
        let late = run.late_ns.iter().filter(|n| **n > 1_000_000).count();
        assert!(late >= 10, "{late}");
        // From the send, only the slow request itself took long: the wait is not
        // counted, and latency = lateness + the rest.
        assert_eq!(run.from_send_ns.len(), run.latency_ns.len());
        assert_eq!(run.from_send_ns.iter().filter(|n| **n > 1_000_000).count(), 1);
        for ((all, late), sent) in run.latency_ns.iter().zip(&run.late_ns).zip(&run.from_send_ns) {
            assert!(late + sent <= *all && all - late - sent < 1_000_000, "{all} {late} {sent}");
        }
    }

    #[test]
    fn errors_are_counted_not_timed() {
        let run = drive(Arrivals::Closed, Duration::from_millis(5), 0, 0, |k| {
            if k % 2 == 0 { Err("busy".into()) } else { Ok(Some(7)) }
        });
        let busy = run.errors["busy"] as usize;
        assert!(busy.abs_diff(run.latency_ns.len()) <= 1);
        assert_eq!(run.search_us.len(), run.latency_ns.len());
        assert!(run.search_us.iter().all(|s| *s == 7));
    }

    #[test]
    fn percentiles_interpolate() {
        let mut v: Vec<u64> = (1..=1000).rev().map(|i| i * 1000).collect();
        let l = Latencies::of_nanos(&mut v).unwrap();
        assert_eq!((l.count, l.max_us, l.mean_us), (1000, 1000.0, 500.5));
        assert!((l.p50_us - 500.5).abs() < 1e-9 && (l.p99_us - 990.01).abs() < 1e-9, "{l:?}");
        assert!((l.p999_us - 999.001).abs() < 1e-9);
        assert!(Latencies::of_nanos(&mut []).is_none());
    }

    #[test]
    fn requests_cycle_over_the_maps_and_validate_in_process() {
        let set = RequestSet::new(1, 3);
        assert_eq!(set.pick(2, 0).0, 2);
        assert_eq!(set.pick(2, 1).0, 0);
        assert_eq!(set.requests[1].map, map_id(1));
        assert_eq!(set.requests[0].expected_version, None);
        let null = in_process(Workload::Null, &set, Duration::from_millis(5));
        assert!(null.errors.is_empty() && null.latency_ns.len() > 10, "{:?}", null.errors);
    }
}
