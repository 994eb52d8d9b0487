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
//! Where things are: `ports.rs` (the iceoryx2 ports), `state.rs` (what the
//! handlers change), one folder or file per service (`rendezvous/`, `map/`,
//! `stats.rs`), `reject.rs` (the refusals they share), `pool.rs` (the workers),
//! `cpu/` (how the daemon shares the CPU), `record/` (`--record`), `config/` (the configuration, loaded once).
//!
//! Threading: one IPC thread (the caller's) owns the maps, validates every request,
//! applies map changes and answers map and stats requests itself. Searches go to a
//! pool of worker threads, which reply to the client directly (the ports are the
//! thread-safe iceoryx2 variant, so an accepted request can move to a worker). A
//! `brute` query may hold at most all workers but one, so a cheap query from another
//! client always finds a free worker. Free workers take queries fairly across
//! clients (`rendezvous::Queue`). Real-time scheduling is per thread: call
//! [`Daemon::spin`] and [`Daemon::wait`] on the thread that called
//! [`Daemon::create`] (see `cpu/` for the whole policy).
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
mod cpu;
mod error;
mod janitor;
mod map;
mod pool;
mod ports;
pub mod record;
mod reject;
mod rendezvous;
mod state;
mod stats;

pub use config::{
    ConfigError, CpuLatencyTarget, DEFAULT_IPC_PRIORITY, DEFAULT_WORKER_SLICE, DEFAULT_WORKER_YIELD, DaemonConfig,
    Limits, Recording, Scheduling, default_state_dir, former_flag,
};
pub use cpu::{FALLBACK_WORKER_NICE, IPC_SLICE, IpcScheduling};
pub use error::{DaemonCreateError, IpcError};
pub use record::RecordConfig;
pub use rendezvous::answer_query;

use cpu::IpcPacing;
use dyfos_shared::wire::ServiceNames;
use dyfos_shared::wire::services::{ServiceLimits, iceoryx_config};
use iceoryx2::port::update_connections::UpdateConnections;
use iceoryx2::prelude::*;
use iceoryx2::waitset::WaitSetRunResult;
use map::Maps;
use pool::Pool;
use ports::{Ports, Replies};
use record::TrafficRecorder;
use state::State;
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};
use tracing::{debug, info, warn};

/// How often the daemon expires idle uploads and cleans up after dead clients.
pub const HOUSEKEEPING: Duration = Duration::from_secs(5);

/// While searches run, how often the IPC thread checks that their clients are still
/// there (and so, at most, how long [`Daemon::wait`] sleeps meanwhile).
pub const CLIENT_CHECK: Duration = Duration::from_millis(10);

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

/// The daemon: its ports, the state its handlers change, and its threads.
pub struct Daemon {
    config: DaemonConfig,
    names: ServiceNames,
    ports: Ports,
    replies: Arc<Replies>,
    state: State,
    /// The worker threads (spares included).
    threads: Vec<JoinHandle<()>>,
    pacing: IpcPacing,
    last_housekeeping: Instant,
    last_client_check: Instant,
    /// The recorder's writer thread, if recording.
    recorder_thread: Option<JoinHandle<()>>,
    /// The dead-process cleanup, off the IPC thread.
    janitor: janitor::Janitor,
}

impl std::fmt::Debug for Daemon {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Daemon").field("prefix", &self.names.prefix).field("maps", &self.state.maps.len()).finish()
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
        let mut maps = Maps::load(&config.state_dir, config.limits.upload_idle_timeout())?;
        let limits = ServiceLimits {
            max_clients: config.limits.max_clients,
            max_requests_per_client: config.limits.max_requests_per_client,
        };
        let (ports, replies) = Ports::open(&iox, &names, limits)?;
        let (recorder, recorder_thread) = start_recorder(config, &maps)?;
        let pool = Arc::new(Pool::new(config, learned, recorder.clone()));
        // The IPC thread is this one.
        let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
        let pacing = IpcPacing::start(&config.scheduling, cores);
        log_workers(&pool, &config.scheduling, pacing.worker_nice());
        let janitor = janitor::Janitor::start(&iox, HOUSEKEEPING)
            .map_err(|source| DaemonCreateError::Thread { what: "cleanup", source })?;
        let replies = Arc::new(replies);
        let threads = pool
            .start(&replies, config.scheduling.worker_slice(), pacing.worker_nice())
            .map_err(|source| DaemonCreateError::Thread { what: "worker", source })?;
        maps.recorder = recorder;
        for (id, world) in maps.iter() {
            info!(map = id, version = world.version(), obstacles = world.obstacles().len(), "map loaded");
        }
        info!(
            prefix = %names.prefix,
            state_dir = %config.state_dir.display(),
            workers = pool.workers,
            maps = maps.len(),
            pid = std::process::id(),
            "dyfosd ready"
        );
        Ok(Daemon {
            config: config.clone(),
            names,
            ports,
            replies,
            state: State { maps, pool, max_queued: config.limits.max_queued, closing: false },
            threads,
            pacing,
            last_housekeeping: Instant::now(),
            last_client_check: Instant::now(),
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
        let (ports, replies, state) = (&self.ports, &*self.replies, &mut self.state);
        loop {
            // One request of each service in turn, so that none waits behind another's burst.
            let took = [
                take(state, "rendezvous", ports.rendezvous.receive(), |s, a| rendezvous::on_request(s, replies, a)),
                take(state, "map", ports.map.receive(), |s, a| map::on_request(s, replies, a)),
                take(state, "stats", ports.stats.receive(), |s, a| stats::on_request(s, replies, a)),
            ];
            let took = took.into_iter().filter(|t| *t).count();
            if took == 0 {
                break;
            }
            handled += took;
        }
        if handled > 0 {
            self.pacing.arrived();
        }
        if self.last_housekeeping.elapsed() >= HOUSEKEEPING {
            // The dead-node cleanup runs on the janitor's thread, not here.
            self.last_housekeeping = Instant::now();
            self.state.maps.expire_uploads();
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

    /// Abandons the running searches whose clients have gone.
    fn check_clients(&mut self) {
        self.last_client_check = Instant::now();
        if self.state.pool.queue().running() == 0 {
            return;
        }
        // Take in the clients that came or went since the last receive (a dead-node
        // cleanup may just have removed some).
        if let Err(e) = self.ports.rendezvous.update_connections() {
            debug!("rendezvous connections updated only in part: {e:?}");
        }
        for watch in self.state.pool.watches.iter() {
            watch.check();
        }
    }

    /// What scheduling the IPC thread got at start.
    pub fn ipc_scheduling(&self) -> IpcScheduling {
        self.pacing.ipc_scheduling()
    }

    /// How long the IPC thread should keep polling after the last request before
    /// it sleeps: [`Scheduling::poll_max_us`] while requests arrive about that often,
    /// else [`Scheduling::poll_us`]. Unless real-time scheduling is off, zero while
    /// every worker searches or other threads have filled every core for a while
    /// ([`IdleCores::LASTING`](dyfos_process::idle::IdleCores::LASTING)): a polling
    /// thread that yields waits a whole time slice behind the busy ones, where a
    /// sleeping one is woken ahead of them (real-time, or above the niced workers).
    /// A client that polls a moment for its reply does not end the poll: stopping
    /// for it cost the next request a wake-up. A non-zero window returns the thread
    /// to normal priority first, so its polling yields to every other thread.
    pub fn poll_window(&mut self) -> Duration {
        let pool = &self.state.pool;
        self.pacing.poll_window(|| pool.queue().active(), pool.workers)
    }

    /// Whether SIGINT or SIGTERM arrived.
    pub fn termination_requested(&self) -> bool {
        self.ports.node.wait(Duration::ZERO).is_err()
    }

    /// Sleeps until a client notifies the wake-up event, `timeout` passes, or a
    /// termination signal arrives. Uses no CPU while it sleeps. While searches run it
    /// sleeps at most [`CLIENT_CHECK`], so that [`Daemon::spin`] can see their
    /// clients go.
    pub fn wait(&mut self, timeout: Duration) -> WaitOutcome {
        let running = self.state.pool.queue().running();
        let timeout = self.pacing.before_sleep(if running > 0 { timeout.min(CLIENT_CHECK) } else { timeout });
        // Consume stale notifications first, then look once more: a request sent
        // before its notification was consumed is seen here, one sent after wakes us.
        let _ = self.ports.wake.try_wait(|_| {});
        if self.spin() > 0 {
            return WaitOutcome::Work;
        }
        let mut woke = false;
        let result = self.ports.waitset.wait_and_process_once_with_timeout(
            |_| {
                woke = true;
                CallbackProgression::Continue
            },
            timeout,
        );
        self.pacing.slept();
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
        self.state.closing = true;
        let pending = self.state.pool.queue().pending();
        info!(pending, "shutting down: finishing the queries in flight");
        while self.state.pool.queue().pending() > 0 {
            self.spin();
            std::thread::sleep(Duration::from_millis(2));
        }
        self.state.pool.queue().close();
        self.state.pool.work.notify_all();
        self.state.pool.resume.notify_all();
        for w in self.threads.drain(..) {
            if w.join().is_err() {
                warn!("a worker thread panicked");
            }
        }
        if let (Some(recorder), Some(thread)) = (&self.state.pool.recorder, self.recorder_thread.take()) {
            recorder.close(thread);
        }
        info!("dyfosd stopped");
    }
}

/// The recorder, if recording, and its writer thread, if it writes.
type RecorderAndThread = (Option<Arc<TrafficRecorder>>, Option<JoinHandle<()>>);

/// Starts recording if the configuration says so: the file's head holds the
/// configuration and every map of `maps`.
fn start_recorder(config: &DaemonConfig, maps: &Maps) -> Result<RecorderAndThread, DaemonCreateError> {
    let Some(rc) = config.recording.record_config() else { return Ok((None, None)) };
    let (recorder, thread) = TrafficRecorder::start(&rc, config.to_json(pool::workers(config)), maps.arcs().collect())
        .map_err(|source| DaemonCreateError::Record { path: rc.path.clone(), source })?;
    Ok((Some(Arc::new(recorder)), thread))
}

/// Says how the workers will run.
fn log_workers(pool: &Pool, scheduling: &Scheduling, nice: u8) {
    let worker_yield = scheduling.worker_yield();
    info!(
        workers = pool.workers,
        nice,
        yield_us = scheduling.worker_yield_us,
        slice_us = scheduling.worker_slice_us,
        "search workers: {} nice level(s) below the IPC thread; queue served fairly across clients; {}",
        nice,
        if worker_yield.is_zero() {
            "a search keeps its core until the scheduler takes it".to_string()
        } else {
            format!("a search yields its core to a waiting thread at most every {worker_yield:?}")
        }
    );
}

/// A receive failed, e.g. `ExceedsMaxBorrows`: a client sent more while the
/// daemon still holds as many of its requests as it may (they wait for a
/// worker). Its new requests stay in the port and are taken once those are
/// done; other clients are served meanwhile (iceoryx2 skips the full one). The
/// client decides how often this happens, so it is counted and logged under the
/// rate limit, never once per pass.
/// Hands the request `received` from `service`, if any, to `handle`; whether there was one.
fn take<A>(
    state: &mut State,
    service: &str,
    received: Result<Option<A>, iceoryx2::port::ReceiveError>,
    handle: impl FnOnce(&mut State, A),
) -> bool {
    match received {
        Ok(Some(active)) => {
            handle(state, active);
            true
        }
        Ok(None) => false,
        Err(e) => {
            state.pool.stats().receive_failed();
            warn!(
                "{service} receive failed: {e:?} (a client sends more requests than it may have in flight; they wait)"
            );
            false
        }
    }
}
