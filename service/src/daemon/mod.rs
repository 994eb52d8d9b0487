//! The optimizer daemon behind `dyfosd`: iceoryx2 services under one prefix, a
//! worker pool for the searches, maps persisted in a state directory.
//!
//! [`Daemon::create`] opens every port (creating the services with the daemon's own
//! limits); [`Daemon::spin`] answers whatever is pending and returns at once;
//! [`Daemon::wait`] sleeps until a client sends something; [`Daemon::shutdown`]
//! finishes the queries in flight. `dyfosd` owns the loop around them.
//!
//! ```no_run
//! use dyfos_service::daemon::{Daemon, DaemonConfig, WaitOutcome};
//! use std::time::Duration;
//!
//! let mut daemon = Daemon::create(&DaemonConfig::default())?;
//! loop {
//!     daemon.spin();
//!     if daemon.wait(Duration::from_secs(1)) == WaitOutcome::Terminate {
//!         break;
//!     }
//! }
//! daemon.shutdown();
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! Threading: one IPC thread (the caller's) owns the maps, validates every request,
//! applies map changes and answers map and stats requests itself. Searches go to a
//! pool of worker threads, which reply to the client directly (the ports are the
//! thread-safe iceoryx2 variant, so an accepted request can move to a worker). A
//! `brute` query may hold at most all workers but one, so a cheap query from another
//! client always finds a free worker. Free workers take queries fairly across
//! clients (`rendezvous::Queue`).
//!
//! Priorities: the IPC thread sleeps at `SCHED_FIFO`
//! ([`Scheduling::ipc_priority`]), so a request wakes it ahead of running
//! searches, and polls for the next request at normal priority, for a window that
//! grows to [`Scheduling::poll_max_us`] while traffic is steady and is zero while
//! every worker searches. Real-time scheduling is per thread: call [`Daemon::spin`]
//! and [`Daemon::wait`] on the thread that called [`Daemon::create`]. Where the
//! system refuses it, the IPC thread asks for a short time slice ([`IPC_SLICE`])
//! and, on kernels that ignore slices, the workers run [`FALLBACK_WORKER_NICE`]
//! nice levels lower. The workers ask for a long slice
//! ([`Scheduling::worker_slice_us`]), so any thread that wakes beside a search
//! preempts it. While traffic is steady, idle cores are asked to poll
//! ([`Scheduling::cpu_latency_us`]), so a request after a pause wakes the IPC
//! thread in µs.
//!
//! A client that goes away mid-query (killed, or dropping its pending response)
//! frees its worker: while searches run, the IPC thread looks every
//! [`CLIENT_CHECK`] whether their clients are still connected and abandons the
//! search of one that is not; a worker skips a queued query whose client has gone
//! (no reply either way; both count as `queries_abandoned` in the stats). iceoryx2
//! sees a killed client as gone only once its resources are cleaned up: at the
//! daemon's next [`HOUSEKEEPING`], or sooner when any process of the domain creates
//! a node.

mod config;
mod cpu_latency;
mod janitor;
mod map;
pub mod record;
mod rendezvous;
mod sched;
mod stats;

pub use config::{
    ConfigError, CpuLatencyTarget, DEFAULT_IPC_PRIORITY, DEFAULT_WORKER_SLICE, DEFAULT_WORKER_YIELD, DaemonConfig,
    Limits, Recording, Scheduling, default_state_dir, former_flag,
};
pub use record::RecordConfig;
pub use rendezvous::answer_query;
pub use sched::{IPC_SLICE, IpcScheduling};

use crate::store::{Store, StoreOpenError};
use dyfos_shared::limits::{MAX_MAPS, SNAPSHOT_PAGE_RECORDS};
use dyfos_shared::wire::map::{MapReplyHeader, MapRequestHeader, WireDelta};
use dyfos_shared::wire::rendezvous::{RendezvousReply, RendezvousRequestHeader};
use dyfos_shared::wire::stats::{StatsReply, StatsRequest};
use dyfos_shared::wire::{PrefixError, ServiceNames};
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::server::Server;
use iceoryx2::port::update_connections::UpdateConnections;
use iceoryx2::prelude::*;
use iceoryx2::waitset::WaitSetRunResult;
use std::path::PathBuf;
use std::sync::{Arc, Condvar, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};
use tracing::{debug, info, warn};

/// The iceoryx2 service variant of the daemon's ports: thread-safe, so accepted
/// requests can move to worker threads. Shares memory with `ipc::Service` peers.
pub type Ipc = ipc_threadsafe::Service;

type RendezvousServer = Server<Ipc, [WireDelta], RendezvousRequestHeader, RendezvousReply, ()>;
type MapServer = Server<Ipc, [WireDelta], MapRequestHeader, [WireDelta], MapReplyHeader>;
type StatsServer = Server<Ipc, StatsRequest, (), StatsReply, ()>;

/// How often the daemon expires idle uploads and cleans up after dead clients.
pub const HOUSEKEEPING: Duration = Duration::from_secs(5);

/// While searches run, how often the IPC thread checks that their clients are still
/// there (and so, at most, how long [`Daemon::wait`] sleeps meanwhile).
pub const CLIENT_CHECK: Duration = Duration::from_millis(10);

/// Nice levels the workers drop when the IPC thread may neither run real-time nor
/// have a short time slice.
pub const FALLBACK_WORKER_NICE: u8 = 5;

/// Why the daemon could not start.
#[derive(Debug, thiserror::Error)]
pub enum DaemonCreateError {
    /// `--prefix` cannot name services.
    #[error(transparent)]
    InvalidPrefix(#[from] PrefixError),
    /// `--domain` is not a valid file-name prefix.
    #[error("iceoryx2 domain `{0}` is not a valid file-name prefix; use letters, digits and `_`, at most 32")]
    InvalidDomain(String),
    /// A configuration value is out of its range.
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// The state directory is unusable.
    #[error(transparent)]
    Store(#[from] StoreOpenError),
    /// Another daemon serves this prefix.
    #[error("another dyfosd already serves prefix `{0}`; stop it, or start this one with another --prefix")]
    AlreadyRunning(String),
    /// A service exists with other types or smaller limits (a daemon of another
    /// version or configuration, kept alive by its clients).
    #[error(
        "service `{service}` exists with other types or limits ({reason}); stop the clients of the old daemon, or use another --prefix"
    )]
    Incompatible {
        /// The service.
        service: String,
        /// iceoryx2's reason.
        reason: String,
    },
    /// Any other iceoryx2 failure.
    #[error("iceoryx2: {0}")]
    Ipc(String),
    /// The learned model file is missing, corrupt or of the wrong shape.
    #[error(transparent)]
    Model(#[from] crate::learned::ModelLoadError),
    /// The recording file (`--record`) cannot be created.
    #[error("cannot record to {path}: {source}; check the directory exists and is writable, or drop --record")]
    Record {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
}

fn ipc_err(e: impl std::fmt::Debug) -> DaemonCreateError {
    DaemonCreateError::Ipc(format!("{e:?}"))
}

/// What [`Daemon::wait`] saw.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum WaitOutcome {
    /// A client woke the daemon (or a request was already pending).
    Work,
    /// The timeout passed, or a signal other than SIGINT and SIGTERM ended the wait.
    Idle,
    /// SIGINT or SIGTERM: call [`Daemon::shutdown`].
    Terminate,
}

/// The iceoryx2 configuration of a domain.
pub fn iceoryx_config(domain: Option<&str>) -> Result<iceoryx2::config::Config, DaemonCreateError> {
    let mut config = iceoryx2::config::Config::default();
    if let Some(d) = domain {
        let valid = !d.is_empty() && d.len() <= 32 && d.bytes().all(|b| b.is_ascii_alphanumeric() || b == b'_');
        config.global.prefix = match FileName::new(d.as_bytes()) {
            Ok(name) if valid => name,
            _ => return Err(DaemonCreateError::InvalidDomain(d.to_string())),
        };
    }
    Ok(config)
}

/// Lowers the calling thread's priority by `levels` nice levels (from the
/// process's, at most to 19). Lowering needs no privilege; a failure is logged and
/// the worker runs at the IPC thread's priority.
fn lower_priority(levels: u8) {
    if levels == 0 {
        return;
    }
    #[cfg(target_os = "linux")]
    {
        use rustix::process::{getpriority_process, setpriority_process};
        // On Linux, nice is per thread: `Some(tid)` names this thread only.
        let tid = rustix::thread::gettid();
        let nice = getpriority_process(Some(tid)).unwrap_or(0) + i32::from(levels);
        if let Err(e) = setpriority_process(Some(tid), nice.min(19)) {
            warn!("cannot lower the priority of a search worker ({e}); it runs at the daemon's priority");
        }
    }
    #[cfg(not(target_os = "linux"))]
    debug!("worker priority is left as is on this system");
}

/// State shared by the IPC thread and the workers.
pub(crate) struct Shared {
    pub(crate) queue: Mutex<rendezvous::Queue>,
    /// Idle workers wait here for a job. Any idle worker may take any job, so one
    /// is woken per job queued or core handed over, not all of them.
    pub(crate) work: Condvar,
    /// Held searches wait here for a core (see `rendezvous::Queue`).
    pub(crate) resume: Condvar,
    pub(crate) reply: Notifier<Ipc>,
    pub(crate) stats: Mutex<stats::Stats>,
    pub(crate) threads: usize,
    /// Worker threads: `threads`, and as many spares (they run queries on the
    /// cores of held searches, see `rendezvous::Queue`).
    pub(crate) workers: usize,
    /// One per worker: its running query, watched by the IPC thread.
    pub(crate) watches: Box<[rendezvous::Watch]>,
    /// [`Scheduling::worker_yield_us`].
    pub(crate) worker_yield: Duration,
    /// Weights of the learned SDSMM, if `--model` was given.
    pub(crate) learned: Option<Arc<dyfos_shared::sdsmm::Learned>>,
    /// The recorder, if `--record` was given.
    pub(crate) recorder: Option<Arc<record::Recorder>>,
}

impl Shared {
    /// Wakes the client whose reply listener has id `listener`.
    pub(crate) fn notify(&self, listener: u128) {
        self.reply.for_each_listener(|m, details| {
            if details.listener_id.value() == listener {
                if let Err(e) = m.notify() {
                    debug!("reply notification failed: {e:?}");
                }
                CallbackProgression::Stop
            } else {
                CallbackProgression::Continue
            }
        });
    }
}

/// The daemon: its ports, maps and workers.
pub struct Daemon {
    config: DaemonConfig,
    names: ServiceNames,
    node: Node<Ipc>,
    rendezvous: RendezvousServer,
    map: MapServer,
    stats: StatsServer,
    wake: Listener<Ipc>,
    /// Where the IPC thread sleeps: on `wake`, attached once, and on SIGINT/SIGTERM.
    waitset: WaitSet<Ipc>,
    shared: Arc<Shared>,
    workers: Vec<JoinHandle<()>>,
    maps: map::Maps,
    last_housekeeping: Instant,
    last_client_check: Instant,
    closing: bool,
    /// The IPC thread's real-time switch.
    priority: sched::IpcPriority,
    ipc_scheduling: IpcScheduling,
    /// When requests last arrived, and the mean gap between arrivals (µs,
    /// exponentially weighted), which sizes the polling window.
    last_arrival: Instant,
    arrival_gap_us: f64,
    /// The CPU latency request, held while traffic is steady.
    cpu_latency: cpu_latency::CpuLatency,
    /// Whether other work fills every core (and has for a while), looked up at most
    /// every [`IdleCores::EVERY`](dyfos_process::idle::IdleCores::EVERY).
    cores: dyfos_process::idle::IdleCores,
    /// The recorder's writer thread, if recording.
    recorder_thread: Option<JoinHandle<()>>,
    /// The dead-process cleanup, off the IPC thread.
    janitor: janitor::Janitor,
}

impl std::fmt::Debug for Daemon {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Daemon").field("prefix", &self.names.prefix).field("maps", &self.maps.len()).finish()
    }
}

impl Daemon {
    /// Loads the maps, cleans up after dead processes (a daemon killed by SIGKILL
    /// leaves its shared memory behind), creates the services with the daemon's
    /// limits and starts the workers.
    pub fn create(config: &DaemonConfig) -> Result<Daemon, DaemonCreateError> {
        config.validate()?;
        let names = ServiceNames::new(&config.prefix)?;
        let learned = config.model.as_deref().map(crate::learned::load_model).transpose()?;
        let iox = iceoryx_config(config.domain.as_deref())?;
        let store = Store::open(&config.state_dir)?;
        let loaded = store.load_all();
        for q in &loaded.quarantined {
            warn!(file = %q.file.display(), moved_to = ?q.moved_to, "map file could not be loaded and was quarantined: {}", q.reason);
        }
        for (journal, torn) in &loaded.repaired {
            warn!(file = %journal.display(), "map journal ended in a torn record (a crash while writing an unacknowledged change); cut off: {torn}");
        }
        if loaded.maps.len() > MAX_MAPS {
            warn!(
                "{} maps in the state directory, more than the limit of {MAX_MAPS}; only the first are served",
                loaded.maps.len()
            );
        }
        let node = NodeBuilder::new().config(&iox).create::<Ipc>().map_err(ipc_err)?;
        let cleanup = node.try_cleanup_dead_nodes();
        if cleanup.cleanups > 0 || cleanup.failed_cleanups > 0 {
            info!(cleaned = cleanup.cleanups, failed = cleanup.failed_cleanups, "removed resources of dead processes");
        }
        let clients = config.limits.max_clients;
        let nodes = clients + 2;
        let service_name = |s: &str| ServiceName::new(s).map_err(ipc_err);
        macro_rules! create_rr {
            ($name:expr, $builder:expr) => {
                $builder
                    .enable_fire_and_forget_requests(false)
                    .max_servers(1)
                    .max_clients(clients)
                    .max_nodes(nodes)
                    .max_active_requests_per_client(config.limits.max_requests_per_client)
                    .max_response_buffer_size(2)
                    .max_loaned_requests(2)
                    .max_borrowed_responses_per_pending_response(2)
                    .open_or_create()
                    .map_err(|e| DaemonCreateError::Incompatible { service: $name.clone(), reason: format!("{e:?}") })?
            };
        }
        let rendezvous = create_rr!(
            names.rendezvous,
            node.service_builder(&service_name(&names.rendezvous)?)
                .request_response::<[WireDelta], RendezvousReply>()
                .request_user_header::<RendezvousRequestHeader>()
        );
        let map = create_rr!(
            names.map,
            node.service_builder(&service_name(&names.map)?)
                .request_response::<[WireDelta], [WireDelta]>()
                .request_user_header::<MapRequestHeader>()
                .response_user_header::<MapReplyHeader>()
        );
        let stats = create_rr!(
            names.stats,
            node.service_builder(&service_name(&names.stats)?).request_response::<StatsRequest, StatsReply>()
        );
        let event = |name: &String| {
            node.service_builder(&service_name(name)?)
                .event()
                .max_nodes(nodes)
                .max_notifiers(clients + 1)
                .max_listeners(clients + 1)
                .open_or_create()
                .map_err(|e| DaemonCreateError::Incompatible { service: name.clone(), reason: format!("{e:?}") })
        };
        let wake_service = event(&names.wake)?;
        let reply_service = event(&names.reply)?;
        let already = |e: &dyn std::fmt::Debug| {
            let text = format!("{e:?}");
            if text.contains("ExceedsMaxSupported") {
                DaemonCreateError::AlreadyRunning(config.prefix.clone())
            } else {
                DaemonCreateError::Ipc(text)
            }
        };
        // The daemon sends exactly one response to every request, so a client port
        // holds at most one response per request it may have in flight or have
        // dropped unanswered (2 × `max_requests_per_client`); iceoryx2 would otherwise
        // preallocate for every response buffer and borrow slot as well (6× more).
        let responses = clients * 2 * config.limits.max_requests_per_client + 1;
        macro_rules! create_server {
            ($builder:expr) => {
                $builder
                    .max_loaned_responses_per_request(1)
                    .override_response_preallocation(move |_| responses)
                    .create()
                    .map_err(|e| already(&e))?
            };
        }
        let rendezvous_server = create_server!(rendezvous.server_builder());
        // A fixed-size segment of snapshot-page-sized replies: iceoryx2 keeps the
        // bookkeeping of a resizable segment for all of its 255 possible segments per
        // connected client (8 MB of /dev/shm per client, written and swept by this
        // thread each time one connects or leaves, stalling every other client's
        // requests).
        let map_server = create_server!(
            map.server_builder()
                .initial_max_slice_len(SNAPSHOT_PAGE_RECORDS)
                .allocation_strategy(AllocationStrategy::Static)
        );
        let stats_server = create_server!(stats.server_builder());
        let wake = wake_service.listener_builder().create().map_err(ipc_err)?;
        let reply = reply_service.notifier_builder().create().map_err(ipc_err)?;
        let waitset = WaitSetBuilder::new().create::<Ipc>().map_err(ipc_err)?;
        // Attached once, for the daemon's life. iceoryx2 0.10's `attach` reads
        // /proc/sys/fs/epoll/max_user_watches every time, so attaching and detaching
        // around each sleep made 6 of the 10 system calls of a wake-up, at real-time
        // priority, on a core whose client may be waiting for it to sleep again
        // (bench/RESULTS.md, "Why the scheduling defaults"). Forgetting the guard
        // only skips its detach: the wait set and the listener go together when the
        // daemon is dropped. It is the wait set's only attachment, so any
        // event it reports is a wake-up (an attachment id would not do: iceoryx2's
        // ids hold the wait set's address, which changes when the daemon moves).
        std::mem::forget(waitset.attach_notification(&wake).map_err(ipc_err)?);

        let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
        let threads = if config.workers == 0 { cores } else { config.workers }.max(2);
        // A spare worker per core runs the query of a starved client while a held
        // search waits (see `rendezvous::Queue`).
        let workers = 2 * threads;
        let mut maps =
            map::Maps::new(store, loaded.maps.into_iter().take(MAX_MAPS), config.limits.upload_idle_timeout());
        let (recorder, recorder_thread) = match config.recording.record_config() {
            None => (None, None),
            Some(rc) => {
                let maps = maps.arcs().collect();
                let (recorder, thread) = record::Recorder::start(&rc, config.to_json(threads), maps)
                    .map_err(|source| DaemonCreateError::Record { path: rc.path.clone(), source })?;
                (Some(Arc::new(recorder)), thread)
            }
        };
        let shared = Arc::new(Shared {
            queue: Mutex::new(rendezvous::Queue::new(threads, workers)),
            work: Condvar::new(),
            resume: Condvar::new(),
            reply,
            stats: Mutex::new(stats::Stats::new()),
            threads,
            workers,
            watches: (0..workers).map(|_| rendezvous::Watch::new()).collect(),
            worker_yield: config.scheduling.worker_yield(),
            learned,
            recorder: recorder.clone(),
        });
        // The IPC thread is this one: try real-time once, then poll-ready (normal)
        // until the first wait. Threads it starts are normal (SCHED_RESET_ON_FORK).
        let (mut priority, ipc_scheduling) = sched::IpcPriority::start(config.scheduling.ipc_priority);
        priority.lower();
        let worker_nice = if ipc_scheduling == IpcScheduling::Refused { FALLBACK_WORKER_NICE } else { 0 };
        let (worker_yield, worker_slice) = (config.scheduling.worker_yield(), config.scheduling.worker_slice());
        info!(
            workers = threads,
            nice = worker_nice,
            yield_us = config.scheduling.worker_yield_us,
            slice_us = config.scheduling.worker_slice_us,
            "search workers: {} nice level(s) below the IPC thread; queue served fairly across clients; {}",
            worker_nice,
            if worker_yield.is_zero() {
                "a search keeps its core until the scheduler takes it".to_string()
            } else {
                format!("a search yields its core to a waiting thread at most every {worker_yield:?}")
            }
        );
        let janitor = janitor::Janitor::start(&iox, HOUSEKEEPING)
            .map_err(|e| DaemonCreateError::Ipc(format!("cannot start the cleanup thread: {e}")))?;
        let workers = (0..workers)
            .map(|i| {
                let shared = Arc::clone(&shared);
                std::thread::Builder::new()
                    .name(format!("dyfos-worker-{i}"))
                    .spawn(move || {
                        if !worker_slice.is_zero()
                            && let Err(e) = sched::set_slice(worker_slice)
                        {
                            warn!("cannot set a search worker's time slice to {worker_slice:?} ({e}); it keeps the kernel's");
                        }
                        lower_priority(worker_nice);
                        rendezvous::worker(&shared, i)
                    })
                    .map_err(|e| DaemonCreateError::Ipc(format!("cannot start worker thread: {e}")))
            })
            .collect::<Result<Vec<_>, _>>()?;
        maps.recorder = recorder;
        for (id, world) in maps.iter() {
            info!(map = id, version = world.version(), obstacles = world.obstacles().len(), "map loaded");
        }
        info!(
            prefix = %names.prefix,
            state_dir = %config.state_dir.display(),
            workers = threads,
            maps = maps.len(),
            pid = std::process::id(),
            "dyfosd ready"
        );
        Ok(Daemon {
            config: config.clone(),
            names,
            node,
            rendezvous: rendezvous_server,
            map: map_server,
            stats: stats_server,
            wake,
            waitset,
            shared,
            workers,
            maps,
            last_housekeeping: Instant::now(),
            last_client_check: Instant::now(),
            closing: false,
            priority,
            ipc_scheduling,
            last_arrival: Instant::now(),
            arrival_gap_us: f64::INFINITY,
            cpu_latency: cpu_latency::CpuLatency::open(
                config.scheduling.cpu_latency_us.micros(),
                std::path::Path::new(cpu_latency::CpuLatency::DEVICE),
            ),
            cores: dyfos_process::idle::IdleCores::new(cores),
            recorder_thread,
            janitor,
        })
    }

    /// The service names served.
    pub fn names(&self) -> &ServiceNames {
        &self.names
    }

    /// The configuration.
    pub fn config(&self) -> &DaemonConfig {
        &self.config
    }

    /// Answers (or hands to a worker) every request pending now; returns how many
    /// requests it took. Never blocks.
    pub fn spin(&mut self) -> usize {
        let mut handled = 0;
        loop {
            let before = handled;
            match self.rendezvous.receive() {
                Ok(Some(active)) => {
                    handled += 1;
                    rendezvous::on_request(self, active);
                }
                Ok(None) => {}
                Err(e) => self.receive_failed("rendezvous", e),
            }
            match self.map.receive() {
                Ok(Some(active)) => {
                    handled += 1;
                    map::on_request(self, active);
                }
                Ok(None) => {}
                Err(e) => self.receive_failed("map", e),
            }
            match self.stats.receive() {
                Ok(Some(active)) => {
                    handled += 1;
                    stats::on_request(self, active);
                }
                Ok(None) => {}
                Err(e) => self.receive_failed("stats", e),
            }
            if handled == before {
                break;
            }
        }
        if handled > 0 {
            let now = Instant::now();
            let gap = (now - self.last_arrival).as_secs_f64() * 1e6;
            self.last_arrival = now;
            self.arrival_gap_us =
                if self.arrival_gap_us.is_finite() { 0.875 * self.arrival_gap_us + 0.125 * gap } else { gap };
            if self.steady() {
                self.cpu_latency.hold();
            }
        }
        if self.last_housekeeping.elapsed() >= HOUSEKEEPING {
            self.housekeeping();
        }
        if self.janitor.take_cleaned() {
            // Dead clients' resources are gone: their running queries can be abandoned.
            self.check_clients();
        }
        if self.last_client_check.elapsed() >= CLIENT_CHECK {
            self.check_clients();
        }
        handled
    }

    /// A receive failed, e.g. `ExceedsMaxBorrows`: a client sent more while the
    /// daemon still holds as many of its requests as it may (they wait for a
    /// worker). Its new requests stay in the port and are taken once those are
    /// done; other clients are served meanwhile (iceoryx2 skips the full one). The
    /// client decides how often this happens, so it is counted and logged under the
    /// rate limit, never once per pass.
    fn receive_failed(&self, service: &str, e: iceoryx2::port::ReceiveError) {
        if let Ok(mut s) = self.shared.stats.lock() {
            s.receive_failed();
        }
        warn!("{service} receive failed: {e:?} (a client sends more requests than it may have in flight; they wait)");
    }

    /// Abandons the running searches whose clients have gone.
    fn check_clients(&mut self) {
        self.last_client_check = Instant::now();
        if self.shared.queue.lock().map_or(0, |q| q.running()) == 0 {
            return;
        }
        // Take in the clients that came or went since the last receive (a dead-node
        // cleanup may just have removed some).
        if let Err(e) = self.rendezvous.update_connections() {
            debug!("rendezvous connections updated only in part: {e:?}");
        }
        for watch in self.shared.watches.iter() {
            watch.check();
        }
    }

    /// The dead-node cleanup runs on the janitor's thread, not here.
    fn housekeeping(&mut self) {
        self.last_housekeeping = Instant::now();
        self.maps.expire_uploads();
    }

    /// What scheduling the IPC thread got at start.
    pub fn ipc_scheduling(&self) -> IpcScheduling {
        self.ipc_scheduling
    }

    /// How long the IPC thread should keep polling after the last request before
    /// it sleeps: [`Scheduling::poll_max_us`] while requests arrive about that often,
    /// else [`Scheduling::poll_us`]. Unless real-time scheduling is off, zero while
    /// every worker searches or other threads have filled every core for a while
    /// ([`IdleCores::LASTING`](dyfos_process::idle::IdleCores::LASTING)): a polling
    /// thread that yields waits a whole time slice behind the busy ones, where a
    /// sleeping one is woken ahead of them (real-time, or above the niced workers).
    /// A client that spins a moment for its reply does not end the poll: stopping
    /// for it cost the next request a wake-up (`bench/RESULTS.md`, "Why the
    /// scheduling defaults"). A non-zero window returns the thread to normal
    /// priority first, so its polling yields to every other thread.
    pub fn poll_window(&mut self) -> Duration {
        let window = if self.steady() { self.config.scheduling.poll_max() } else { self.config.scheduling.poll() };
        if window.is_zero() || self.ipc_scheduling == IpcScheduling::Off {
            return window;
        }
        if self.shared.queue.lock().map_or(0, |q| q.active()) >= self.shared.threads || self.cores.busy_lasting() {
            return Duration::ZERO;
        }
        self.priority.lower();
        if self.priority.is_realtime() {
            return Duration::ZERO;
        }
        window
    }

    /// Whether requests arrive about every [`Scheduling::poll_max_us`] or more often.
    fn steady(&self) -> bool {
        let s = &self.config.scheduling;
        s.poll_max_us > s.poll_us && self.arrival_gap_us <= s.poll_max().as_secs_f64() * 1e6
    }

    /// Whether SIGINT or SIGTERM arrived.
    pub fn termination_requested(&self) -> bool {
        self.node.wait(Duration::ZERO).is_err()
    }

    /// Sleeps until a client notifies the wake-up event, `timeout` passes, or a
    /// termination signal arrives. Uses no CPU while it sleeps. While searches run it
    /// sleeps at most [`CLIENT_CHECK`], so that [`Daemon::spin`] can see their
    /// clients go.
    pub fn wait(&mut self, timeout: Duration) -> WaitOutcome {
        self.priority.raise();
        let mut timeout =
            if self.shared.queue.lock().map_or(0, |q| q.running()) > 0 { timeout.min(CLIENT_CHECK) } else { timeout };
        // Traffic stopped: end the CPU latency request, or wake when it is due.
        if let Some(left) = self.cpu_latency.release_if_quiet(self.last_arrival, Instant::now()) {
            timeout = timeout.min(left);
        }
        // Consume stale notifications first, then look once more: a request sent
        // before its notification was consumed is seen here, one sent after wakes us.
        let _ = self.wake.try_wait(|_| {});
        if self.spin() > 0 {
            return WaitOutcome::Work;
        }
        let mut woke = false;
        let result = self.waitset.wait_and_process_once_with_timeout(
            |_| {
                woke = true;
                CallbackProgression::Continue
            },
            timeout,
        );
        self.cores.slept();
        match result {
            Ok(WaitSetRunResult::TerminationRequest) => WaitOutcome::Terminate,
            // Any signal that interrupts the wait ends up here, not only SIGINT: the
            // SIGCONT after a Ctrl-Z, a debugger or `strace` attaching. Only SIGINT
            // and SIGTERM stop the daemon; the rest just end this wait.
            Ok(WaitSetRunResult::Interrupt) if self.termination_requested() => WaitOutcome::Terminate,
            Ok(WaitSetRunResult::Interrupt) => WaitOutcome::Idle,
            Ok(_) if woke => WaitOutcome::Work,
            Ok(_) => WaitOutcome::Idle,
            Err(e) => {
                warn!("waiting for requests failed: {e:?}");
                WaitOutcome::Idle
            }
        }
    }

    /// Stops taking queries (new ones get `shutting_down`), keeps answering map and
    /// stats requests until every accepted query is answered, then stops the
    /// workers and closes the ports, removing the daemon's shared memory.
    pub fn shutdown(mut self) {
        self.closing = true;
        let pending = self.shared.queue.lock().map_or(0, |q| q.pending());
        info!(pending, "shutting down: finishing the queries in flight");
        loop {
            let busy = self.shared.queue.lock().map_or(0, |q| q.pending());
            if busy == 0 {
                break;
            }
            self.spin();
            std::thread::sleep(Duration::from_millis(2));
        }
        if let Ok(mut q) = self.shared.queue.lock() {
            q.close();
        }
        self.shared.work.notify_all();
        self.shared.resume.notify_all();
        for w in self.workers.drain(..) {
            if w.join().is_err() {
                warn!("a worker thread panicked");
            }
        }
        if let (Some(recorder), Some(thread)) = (&self.shared.recorder, self.recorder_thread.take()) {
            recorder.close(thread);
        }
        info!("dyfosd stopped");
    }
}
