//! The search workers and what they share with the IPC thread: the queue, the
//! watch on each thread's running query, the counters and the recorder. Nothing
//! here is an iceoryx2 port: replies go out through [`Replies`].

use super::config::DaemonConfig;
use super::cpu::prepare_worker_thread;
use super::ports::{RendezvousActive, Replies};
use super::record::TrafficRecorder;
use super::rendezvous::{Job, Queue, Watch, worker};
use super::stats::Stats;
use dyfos_shared::sdsmm::Learned;
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::Duration;

/// State shared by the IPC thread and the worker threads.
pub(crate) struct Pool {
    pub(crate) queue: Mutex<Queue<Job>>,
    /// Idle threads wait here for a job. Any idle thread may take any job, so one
    /// is woken per job queued or core handed over, not all of them.
    pub(crate) work: Condvar,
    /// Held searches wait here for a core (see [`Queue`]).
    pub(crate) resume: Condvar,
    pub(crate) stats: Mutex<Stats>,
    /// Searches that run at once (`--workers`; one per core by default).
    pub(crate) workers: usize,
    /// Threads beyond `workers`: they run queries on the cores of held searches
    /// (see [`Queue`]).
    pub(crate) spares: usize,
    /// One per thread: its running query, watched by the IPC thread.
    pub(crate) watches: Box<[Watch<RendezvousActive>]>,
    /// [`Scheduling::worker_yield_us`](super::Scheduling::worker_yield_us).
    pub(crate) worker_yield: Duration,
    /// Weights of the learned SDSMM, if `--model` was given.
    pub(crate) learned: Option<Arc<Learned>>,
    /// The recorder, if `--record` was given.
    pub(crate) recorder: Option<Arc<TrafficRecorder>>,
}

impl Pool {
    /// The pool `config` asks for, with as many spares as workers; no thread
    /// started yet.
    pub(crate) fn new(
        config: &DaemonConfig,
        learned: Option<Arc<Learned>>,
        recorder: Option<Arc<TrafficRecorder>>,
    ) -> Pool {
        let workers = workers(config);
        // A spare per worker runs the query of a starved client while a held
        // search waits (see `Queue`).
        let spares = workers;
        Pool {
            queue: Mutex::new(Queue::new(workers, spares)),
            work: Condvar::new(),
            resume: Condvar::new(),
            stats: Mutex::new(Stats::new()),
            workers,
            spares,
            watches: (0..workers + spares).map(|_| Watch::new()).collect(),
            worker_yield: config.scheduling.worker_yield(),
            learned,
            recorder,
        }
    }

    /// Starts the worker threads (and spares), each with time slice `slice` and
    /// `nice` levels below the IPC thread.
    pub(crate) fn start(
        self: &Arc<Self>,
        replies: &Arc<Replies>,
        slice: Duration,
        nice: u8,
    ) -> std::io::Result<Vec<JoinHandle<()>>> {
        (0..self.workers + self.spares)
            .map(|i| {
                let (pool, replies) = (Arc::clone(self), Arc::clone(replies));
                std::thread::Builder::new().name(format!("dyfos-worker-{i}")).spawn(move || {
                    prepare_worker_thread(slice, nice);
                    worker(&pool, &replies, i)
                })
            })
            .collect()
    }

    /// The queue, locked.
    pub(crate) fn queue(&self) -> MutexGuard<'_, Queue<Job>> {
        lock(&self.queue)
    }

    /// The counters, locked.
    pub(crate) fn stats(&self) -> MutexGuard<'_, Stats> {
        lock(&self.stats)
    }
}

/// Searches that run at once for `config`: `--workers`, or one per core (0), at
/// least 2.
pub(crate) fn workers(config: &DaemonConfig) -> usize {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    if config.workers == 0 { cores } else { config.workers }.max(2)
}

/// Locks `m`, whatever a panicking thread left in it (the daemon's state stays
/// consistent under every lock: each change is made whole or not at all).
pub(crate) fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
}
