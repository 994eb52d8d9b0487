//! The rendezvous service: validate on the IPC thread, search on a worker.

use super::map::{check_version, guarded, invalid_delta, unknown_map};
use super::record::{ChangeCause, Record, unix_ns, unix_ns_of};
use super::{Daemon, Ipc, Shared};
use crate::search::{Checkpoint, SearchControl};
use crate::{SearchError, solve};
use dyfos_shared::answer::{Algorithm, StopReason};
use dyfos_shared::params::ModelKind;
use dyfos_shared::sdsmm::NoiseModel;
use dyfos_shared::wire::map::WireDelta;
use dyfos_shared::wire::rendezvous::{Mode, RendezvousReply, RendezvousRequest, RendezvousRequestHeader};
use dyfos_shared::wire::{Rejection, Status, join_u128};
use dyfos_shared::world::World;
use iceoryx2::active_request::ActiveRequest;
use std::cell::Cell;
use std::collections::VecDeque;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant, SystemTime};
use tracing::{debug, error, info, trace};

type RendezvousActive = ActiveRequest<Ipc, [WireDelta], RendezvousRequestHeader, RendezvousReply, ()>;

/// An accepted query waiting for (or on) a worker.
pub(crate) struct Job {
    active: RendezvousActive,
    request: RendezvousRequest,
    world: Arc<World>,
    received: Instant,
    reply_to: u128,
    request_id: u64,
    /// The client port that sent it: the unit of fairness of the queue.
    client: ClientKey,
}

/// Which client port sent a query (its iceoryx2 `UniqueClientId`).
type ClientKey = u128;

/// One worker's running query, as the IPC thread sees it: the worker lends it the
/// query's request for the time of the search, and the IPC thread raises `abandon`
/// once that request's client has gone (it died, or dropped its pending response).
/// `ActiveRequest` is `Send` but not `Sync`, so the search threads cannot ask it
/// themselves; they read the flag. One per worker, made once: nothing per query.
pub(crate) struct Watch {
    running: Mutex<Option<(u64, RendezvousActive)>>,
    abandon: AtomicBool,
    /// Raised (under the queue's lock) to ask the running search to hand its core
    /// to a query of a client with none running; see [`Queue::hold_for_starved`].
    hold: AtomicBool,
}

impl Watch {
    pub(crate) fn new() -> Self {
        Watch { running: Mutex::new(None), abandon: AtomicBool::new(false), hold: AtomicBool::new(false) }
    }

    /// Lends `active` to the IPC thread's watch, with the flag lowered.
    fn lend(&self, request_id: u64, active: RendezvousActive) {
        let mut running = lock(&self.running);
        self.abandon.store(false, Ordering::Relaxed);
        *running = Some((request_id, active));
    }

    /// Takes the lent request back.
    fn take_back(&self) -> Option<RendezvousActive> {
        lock(&self.running).take().map(|(_, active)| active)
    }

    /// On the IPC thread: raises the flag if the lent request's client has gone.
    pub(crate) fn check(&self) {
        let running = lock(&self.running);
        if let Some((request_id, active)) = running.as_ref()
            && !self.abandon.load(Ordering::Relaxed)
            && !active.is_connected()
        {
            // Raised under the lock: the worker's next `lend` cannot lower it before
            // this request is taken back.
            self.abandon.store(true, Ordering::Relaxed);
            debug!(request_id, "the client of a running query has gone; abandoning the search");
        }
    }
}

/// The queries waiting for workers, in two classes: `brute` (heavy) may occupy
/// all workers but one, so a cheap query always finds a free worker. Within a
/// class, a free worker takes the oldest query of the client with the fewest
/// searches running (so a client with many queries in flight takes its turn with
/// the others).
///
/// Nor does a client wait for another's searches to end:
/// when every core searches and a query comes from a client with none running, one
/// `dyfos`-class search of the client with the most running is held at its next
/// checkpoint (within 64 candidates), and a spare worker runs the new query on its
/// core. Held searches go on, oldest first, as cores free up. At most `cores`
/// searches run at a time; the spares only ever stand in for held ones.
pub(crate) struct Queue {
    light: VecDeque<Job>,
    heavy: VecDeque<Job>,
    /// Taken and not finished, held ones included.
    running: usize,
    running_heavy: usize,
    heavy_limit: usize,
    /// Searches that may run at once: one per core.
    cores: usize,
    /// Running and not held.
    active: usize,
    closed: bool,
    /// Clients with searches running and how many each: at most one entry per
    /// worker, allocated once.
    running_by: Vec<(ClientKey, usize)>,
    /// What each worker runs: its client, and whether it is heavy or held (or
    /// asked to be).
    on_worker: Vec<Option<OnWorker>>,
}

#[derive(Debug, Clone, Copy)]
struct OnWorker {
    client: ClientKey,
    heavy: bool,
    held: bool,
}

impl Queue {
    /// For `cores` searches at a time, on `workers` worker threads (those beyond
    /// `cores` are the spares).
    pub(crate) fn new(cores: usize, workers: usize) -> Self {
        Queue {
            light: VecDeque::new(),
            heavy: VecDeque::new(),
            running: 0,
            running_heavy: 0,
            heavy_limit: cores.saturating_sub(1).max(1),
            cores,
            active: 0,
            closed: false,
            running_by: Vec::with_capacity(workers),
            on_worker: vec![None; workers],
        }
    }

    /// Searches running and not held.
    pub(crate) fn active(&self) -> usize {
        self.active
    }

    /// Searches `client` has running (held ones included).
    fn running_of(&self, client: ClientKey) -> usize {
        self.running_by.iter().find(|(c, _)| *c == client).map_or(0, |(_, n)| *n)
    }

    /// Whether a light query waits whose client has no search running: it goes
    /// before held searches.
    fn starved(&self) -> bool {
        self.light.iter().any(|j| self.running_of(j.client) == 0)
    }

    /// The worker whose search should be held for a starved query, if every core
    /// searches: a light search of the client with the most running (at least 2),
    /// not held yet. Marks it asked.
    pub(crate) fn hold_for_starved(&mut self) -> Option<usize> {
        if self.active < self.cores || !self.starved() {
            return None;
        }
        let asked = self.on_worker.iter().filter(|w| w.is_some_and(|w| w.held)).count();
        if asked >= self.on_worker.len() - self.cores {
            return None; // no spare worker left to run the starved query
        }
        let (worker, _) = self
            .on_worker
            .iter()
            .enumerate()
            .filter_map(|(i, w)| w.filter(|w| !w.heavy && !w.held).map(|w| (i, self.running_of(w.client))))
            .filter(|(_, n)| *n >= 2)
            .max_by_key(|(i, n)| (*n, std::cmp::Reverse(*i)))?;
        if let Some(w) = self.on_worker[worker].as_mut() {
            w.held = true;
        }
        Some(worker)
    }

    /// The search on `worker` stops at its checkpoint: its core is free.
    fn hold(&mut self) {
        self.active -= 1;
    }

    /// Searches held at their checkpoint.
    fn held(&self) -> usize {
        self.running - self.active
    }

    /// Whether a held search may go on: a core is free and no starved query is
    /// waiting for it.
    fn may_go_on(&self) -> bool {
        self.active < self.cores && !self.starved()
    }

    /// The held search on `worker` goes on.
    fn go_on(&mut self, worker: usize) {
        self.active += 1;
        if let Some(w) = self.on_worker[worker].as_mut() {
            w.held = false;
        }
    }

    pub(crate) fn queued(&self) -> usize {
        self.light.len() + self.heavy.len()
    }

    pub(crate) fn running(&self) -> usize {
        self.running
    }

    /// Queued or running.
    pub(crate) fn pending(&self) -> usize {
        self.queued() + self.running
    }

    pub(crate) fn close(&mut self) {
        self.closed = true;
    }

    /// Queries of one class waiting. Each class has its own `max_queued`, so a
    /// flood of `brute` queries cannot make a cheap query `busy`.
    pub(crate) fn queued_of(&self, heavy: bool) -> usize {
        if heavy { self.heavy.len() } else { self.light.len() }
    }

    fn push(&mut self, job: Job) {
        if is_heavy(job.request.algorithm) {
            self.heavy.push_back(job);
        } else {
            self.light.push_back(job);
        }
    }

    /// The next job free worker `worker` may take, and whether it is heavy.
    fn take(&mut self, worker: usize) -> Option<(Job, bool)> {
        if self.active >= self.cores {
            return None;
        }
        // Held searches go on before new queries, except a starved one's.
        let (job, heavy) = if !self.light.is_empty() && (self.held() == 0 || self.starved()) {
            let i = self.next_of(false);
            (self.light.remove(i)?, false)
        } else if self.held() == 0 && self.running_heavy < self.heavy_limit && !self.heavy.is_empty() {
            let i = self.next_of(true);
            (self.heavy.remove(i)?, true)
        } else {
            return None;
        };
        self.running += 1;
        self.active += 1;
        self.running_heavy += usize::from(heavy);
        match self.running_by.iter_mut().find(|(c, _)| *c == job.client) {
            Some((_, n)) => *n += 1,
            None => self.running_by.push((job.client, 1)),
        }
        self.on_worker[worker] = Some(OnWorker { client: job.client, heavy, held: false });
        Some((job, heavy))
    }

    /// Index of the job to take next from one class's queue.
    fn next_of(&self, heavy: bool) -> usize {
        let queue = if heavy { &self.heavy } else { &self.light };
        fair_pick(queue.iter().map(|j| j.client), &self.running_by)
    }

    fn finish(&mut self, worker: usize, heavy: bool, client: ClientKey) {
        self.running -= 1;
        self.active -= 1;
        self.on_worker[worker] = None;
        self.running_heavy -= usize::from(heavy);
        if let Some(i) = self.running_by.iter().position(|(c, _)| *c == client) {
            self.running_by[i].1 -= 1;
            if self.running_by[i].1 == 0 {
                self.running_by.swap_remove(i);
            }
        }
    }
}

/// Of queued jobs from `clients` (oldest first), the index of the first whose
/// client has the fewest searches running (`running`: client and count; absent
/// means none). 0 for an empty queue.
fn fair_pick<K: PartialEq>(clients: impl Iterator<Item = K>, running: &[(K, usize)]) -> usize {
    let mut best = (usize::MAX, 0);
    for (i, client) in clients.enumerate() {
        let n = running.iter().find(|(c, _)| *c == client).map_or(0, |(_, n)| *n);
        if n < best.0 {
            best = (n, i);
            if n == 0 {
                break;
            }
        }
    }
    best.1
}

/// Whether queries of `algorithm` are heavy: they may hold all workers but one,
/// and queue apart from the others.
fn is_heavy(algorithm: Algorithm) -> bool {
    algorithm == Algorithm::Brute
}

fn lock<T>(m: &std::sync::Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
}

/// A worker thread: takes jobs until the queue is closed. `index` names its
/// [`Watch`] in `shared.watches`.
pub(crate) fn worker(shared: &Shared, index: usize) {
    let watch = &shared.watches[index];
    loop {
        let (job, heavy) = {
            let mut q = lock(&shared.queue);
            loop {
                if let Some(taken) = q.take(index) {
                    // A hold asked of this worker's last search, which ended before its
                    // next checkpoint, is not for this one (cleared under the lock the
                    // IPC thread asks under).
                    watch.hold.store(false, Ordering::Relaxed);
                    break taken;
                }
                if q.closed {
                    return;
                }
                q = shared.work.wait(q).unwrap_or_else(|poisoned| poisoned.into_inner());
            }
        };
        // A bug in a search must not take the worker (and the shutdown's count of
        // queries in flight) with it; `run` answers `internal_error` for a panic in
        // the search itself, this catches the rest.
        let client = job.client;
        let checkpoint =
            WorkerCheckpoint { shared, worker: index, holdable: !heavy && shared.workers > shared.threads };
        let checkpoint = checkpoint.wanted().then_some(&checkpoint as &dyn Checkpoint);
        CoreShare::resume();
        if std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| run(shared, watch, job, checkpoint))).is_err() {
            error!("a search panicked; its query was dropped");
        }
        let mut q = lock(&shared.queue);
        q.finish(index, heavy, client);
        let held = q.held() > 0;
        drop(q);
        // A core is free: a held search may go on, or a query start. This worker
        // takes the query itself (the loop above), so only held searches are woken.
        if held {
            shared.resume.notify_all();
        }
    }
}

/// The checkpoint of a search on worker `worker`, every
/// [`Evaluator::CLOCK_EVERY`](crate::search::Evaluator::CLOCK_EVERY) candidates (tens of µs):
///
/// - it **makes way**: when more threads are runnable than there are cores and the
///   thread has not yielded for [`Shared::worker_yield`], it yields its core. The
///   scheduler only looks again at a thread that woke while its core runs a search
///   at the next tick (4 ms at 250 Hz) unless the waking thread was owed time at
///   that instant; a robot process that just sent a request usually is not. A
///   yield lets the scheduler pick it within `worker_yield`; the search goes on
///   when it is its turn again (`bench/RESULTS.md`, "Why the scheduling defaults").
/// - it **holds** the search while the IPC thread asked it to give its core to a
///   starved query (see [`Queue`]; not `brute`).
struct WorkerCheckpoint<'s> {
    shared: &'s Shared,
    worker: usize,
    /// Whether the search may be held (spare workers, not heavy).
    holdable: bool,
}

impl WorkerCheckpoint<'_> {
    /// Whether it does anything.
    fn wanted(&self) -> bool {
        self.holdable || !self.shared.worker_yield.is_zero()
    }

    /// Every `worker_yield`, yields the core if another thread waits for one and
    /// this thread has had most of its core lately. Per thread: a search may run
    /// on several.
    ///
    /// A thread that wakes and needs its core briefly (a robot process sending a
    /// request, a client taking its reply) gets it at the next yield. CPU-bound
    /// threads (other processes' work, more searches than cores) are served by the
    /// scheduler's fair share, under which this thread has no more than
    /// [`MAKE_WAY_ABOVE`] of its core; a yield forfeits the rest of its time
    /// slice, so yielding to them too would hand them most of the search's share
    /// (`bench/RESULTS.md`, "Why the scheduling defaults").
    fn make_way(&self) {
        let every = self.shared.worker_yield;
        if every.is_zero() {
            return;
        }
        let now = Instant::now();
        let mut share = SHARE.get().unwrap_or_else(|| CoreShare::start(now, super::sched::thread_cpu_time()));
        if now - share.at < every {
            return;
        }
        share.update(now, super::sched::thread_cpu_time());
        SHARE.set(Some(share));
        if share.recent >= MAKE_WAY_ABOVE && CORES.with(dyfos_process::idle::IdleCores::busy) {
            std::thread::yield_now();
        }
    }
}

thread_local! {
    /// Whether the machine's cores are all taken, for [`WorkerCheckpoint::make_way`].
    static CORES: dyfos_process::idle::IdleCores = dyfos_process::idle::IdleCores::of_this_machine();
    /// How much of its core this thread had in its searches lately.
    static SHARE: Cell<Option<CoreShare>> = const { Cell::new(None) };
}

/// A search yields to waiting threads only while it has had at least this much of
/// its core lately: with CPU-bound work beside it the scheduler gives it less
/// (two hogs and two searches on two cores: a half each).
const MAKE_WAY_ABOVE: f64 = 0.65;

/// How much of its core the calling thread had lately: its CPU time over wall
/// time, averaged with a time constant of [`CoreShare::TAU`].
#[derive(Debug, Clone, Copy, PartialEq)]
struct CoreShare {
    at: Instant,
    cpu: Duration,
    recent: f64,
}

impl CoreShare {
    const TAU: Duration = Duration::from_millis(10);

    /// Counting from `now`, when the thread had used `cpu`; a whole core so far.
    fn start(now: Instant, cpu: Duration) -> Self {
        CoreShare { at: now, cpu, recent: 1.0 }
    }

    /// The thread had used `cpu` at `now`.
    fn update(&mut self, now: Instant, cpu: Duration) {
        let wall = now.saturating_duration_since(self.at).as_secs_f64();
        if wall > 0.0 {
            let share = (cpu.saturating_sub(self.cpu).as_secs_f64() / wall).min(1.0);
            let weight = (wall / Self::TAU.as_secs_f64()).min(1.0);
            self.recent += weight * (share - self.recent);
        }
        self.at = now;
        self.cpu = cpu;
    }

    /// A search starts on this thread: the time it slept waiting for a job is not
    /// time it was kept off its core.
    fn resume() {
        let (now, cpu) = (Instant::now(), super::sched::thread_cpu_time());
        SHARE.set(Some(SHARE.get().map_or(CoreShare::start(now, cpu), |s| CoreShare { at: now, cpu, ..s })));
    }
}

impl std::fmt::Debug for WorkerCheckpoint<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("WorkerCheckpoint")
            .field("worker", &self.worker)
            .field("holdable", &self.holdable)
            .finish_non_exhaustive()
    }
}

impl Checkpoint for WorkerCheckpoint<'_> {
    fn checkpoint(&self) {
        self.make_way();
        if !self.holdable {
            return;
        }
        let watch = &self.shared.watches[self.worker];
        if !watch.hold.load(Ordering::Relaxed) {
            return;
        }
        let mut q = lock(&self.shared.queue);
        watch.hold.store(false, Ordering::Relaxed);
        q.hold();
        // This core is free for the starved query: one idle (spare) worker takes it.
        self.shared.work.notify_one();
        let held = Instant::now();
        // An abandoned search goes on at once, to see the flag and stop.
        while !q.may_go_on() && !watch.abandon.load(Ordering::Relaxed) {
            q = self
                .shared
                .resume
                .wait_timeout(q, Duration::from_millis(10))
                .map_or_else(|p| p.into_inner().0, |r| r.0);
        }
        q.go_on(self.worker);
        drop(q);
        trace!(worker = self.worker, micros = held.elapsed().as_micros() as u64, "held search goes on");
    }
}

/// Searches for `job` and replies, unless its client goes away first: a query whose
/// client left while it waited for a worker is skipped, one whose client leaves during
/// the search (seen by the IPC thread through `watch`) abandons the search. Neither gets
/// a reply, as nobody is there to receive it. Both count as abandoned in the stats, so
/// that every accepted query shows there as served, failed or abandoned.
fn run(shared: &Shared, watch: &Watch, job: Job, checkpoint: Option<&dyn Checkpoint>) {
    let Job { active, request, world, received, reply_to, request_id, client: _ } = job;
    let deadline = request.deadline.map(|d| received + d);
    if !active.is_connected() {
        lock(&shared.stats).abandoned();
        info!(
            request_id,
            algorithm = request.algorithm.name(),
            "query skipped: its client left while it waited for a worker"
        );
        return;
    }
    let (mut reply, active) = if deadline.is_some_and(|d| Instant::now() >= d) {
        let reply = RendezvousReply::rejected(
            request_id,
            &Rejection {
                map_version: Some(world.version()),
                ..Rejection::new(
                    Status::DeadlineExceeded,
                    format!(
                        "the deadline of {:?} passed while the query waited for a worker; give it more time or ask for less (a budget, a cheaper algorithm)",
                        request.deadline.unwrap_or_default()
                    ),
                )
            },
        );
        (reply, active)
    } else {
        watch.lend(request_id, active);
        let control = SearchControl {
            seed: request.seed,
            budget: request.budget,
            deadline,
            threads: shared.threads,
            abandon: Some(&watch.abandon),
            checkpoint,
        };
        let reply = answer_query(&world, &request, request_id, shared.learned.as_ref(), &control);
        let Some(active) = watch.take_back() else {
            error!(request_id, "a running query's request went missing; it gets no reply");
            return;
        };
        let Some(reply) = reply else {
            lock(&shared.stats).abandoned();
            let micros = u64::try_from(received.elapsed().as_micros()).unwrap_or(u64::MAX);
            info!(request_id, micros, algorithm = request.algorithm.name(), "query abandoned: its client has gone");
            return;
        };
        (reply, active)
    };
    let micros = u64::try_from(received.elapsed().as_micros()).unwrap_or(u64::MAX);
    reply.daemon_micros = micros;
    {
        let mut stats = lock(&shared.stats);
        match Status::try_from(reply.status) {
            Ok(Status::Ok) => stats.served(micros),
            Ok(s) => stats.failed(s),
            Err(_) => {}
        }
    }
    debug!(request_id, status = reply.status, micros, map = request.map, version = world.version(), "query answered");
    // Recorded before it is sent: a query a client sends after this reply is
    // recorded after it, whichever thread answers it.
    if let Some(recorder) = &shared.recorder {
        recorder.record(Record::Rendezvous {
            received: unix_ns_of(received),
            replied: unix_ns(SystemTime::now()),
            mode: Mode::Solve,
            request_id,
            request: Box::new(request),
            reply: Box::new(reply),
        });
    }
    send(shared, &active, reply, reply_to);
}

/// Searches for an accepted query's answer in `world` (the map after the query's
/// inline deltas) and makes the reply the daemon sends, without its timing
/// (`daemon_micros` 0): the one function from a request to a reply, used by the
/// daemon's workers and by `dyfos replay`. `None` when the search was abandoned
/// (`control.abandon` raised), as nobody wants its answer. A panic in the search
/// becomes `internal_error`.
pub fn answer_query(
    world: &World,
    request: &RendezvousRequest,
    request_id: u64,
    learned: Option<&Arc<dyfos_shared::sdsmm::Learned>>,
    control: &SearchControl,
) -> Option<RendezvousReply> {
    let searched = guarded("rendezvous", || {
        let model = NoiseModel::from_params_and_weights(&request.params, learned)
            .map_err(|e| Rejection::new(Status::UnsupportedModel, e.to_string()))?;
        Ok(solve(world, &request.belief, &request.params, &model, request.algorithm, control))
    });
    let stop = match &searched {
        Ok(Ok(answer)) => Some(answer.stop),
        Ok(Err(SearchError::NoFeasiblePose { stop, .. })) => Some(*stop),
        Err(_) => None,
    };
    if stop == Some(StopReason::Abandoned) {
        return None;
    }
    Some(
        match searched.and_then(|solved| {
            solved.map_err(|e @ SearchError::NoFeasiblePose { stop, .. }| {
                let status =
                    if stop == StopReason::Deadline { Status::DeadlineExceeded } else { Status::NoFeasiblePose };
                Rejection::new(status, e.to_string())
            })
        }) {
            Ok(answer) => RendezvousReply::answer(request_id, &answer),
            // The inline deltas (if any) were committed on accepting the query: the
            // reply says which version they made, whatever the search found.
            Err(rejection) => {
                RendezvousReply::rejected(request_id, &Rejection { map_version: Some(world.version()), ..rejection })
            }
        },
    )
}

/// Sends `reply` and wakes the client.
fn send(shared: &Shared, active: &RendezvousActive, reply: RendezvousReply, reply_to: u128) {
    match active.loan_uninit() {
        Ok(loan) => {
            if let Err(e) = loan.write_payload(reply).send() {
                debug!("rendezvous reply not delivered (client gone?): {e:?}");
            }
        }
        Err(e) => debug!("rendezvous reply not delivered (client gone?): {e:?}"),
    }
    shared.notify(reply_to);
}

enum Accepted {
    /// Checked: the version the query would search, and the request if recording.
    Checked(u64, Option<Box<RendezvousRequest>>),
    Queued(Box<RendezvousRequest>, Arc<World>),
}

fn accept(daemon: &mut Daemon, header: &RendezvousRequestHeader, records: &[WireDelta]) -> Result<Accepted, Rejection> {
    if daemon.closing {
        return Err(Rejection::new(Status::ShuttingDown, "dyfosd is shutting down; retry when it is back"));
    }
    let (request, mode) = RendezvousRequest::decode(header, records)?;
    if request.params.model == ModelKind::Learned && daemon.shared.learned.is_none() {
        return Err(Rejection::new(
            Status::UnsupportedModel,
            "params.model = learned needs trained weights, which this daemon has not loaded; start dyfosd with --model FILE (from `dyfos train`), or use paper or anisotropic",
        ));
    }
    let world = daemon.maps.get(request.map).ok_or_else(|| unknown_map(request.map))?;
    check_version(request.map, &world, request.expected_version)?;
    if mode == Mode::Solve {
        let heavy = is_heavy(request.algorithm);
        let queued = lock(&daemon.shared.queue).queued_of(heavy);
        if queued >= daemon.config.limits.max_queued {
            let class = if heavy { "brute" } else { "non-brute" };
            return Err(Rejection::new(
                Status::Busy,
                format!(
                    "{queued} {class} queries are waiting for a worker; retry shortly or start dyfosd with more --workers"
                ),
            ));
        }
    }
    let world = if request.deltas.is_empty() {
        world
    } else {
        let next = world.apply(&request.deltas).map_err(invalid_delta)?;
        match mode {
            Mode::Check => Arc::new(next),
            Mode::Solve => daemon.maps.commit_deltas(
                request.map,
                &world,
                &request.deltas,
                next,
                "inline deltas",
                ChangeCause::Inline,
            )?,
        }
    };
    Ok(match mode {
        Mode::Check => Accepted::Checked(world.version(), daemon.shared.recorder.is_some().then(|| Box::new(request))),
        Mode::Solve => Accepted::Queued(Box::new(request), world),
    })
}

pub(super) fn on_request(daemon: &mut Daemon, active: RendezvousActive) {
    let received = Instant::now();
    // Copy the header out of shared memory once; validate the copy.
    let header = *active.user_header();
    let request_id = header.request_id;
    let reply_to = join_u128(header.reply_to);
    trace!(request_id, records = active.payload().len(), "rendezvous request");
    match guarded("rendezvous", || accept(daemon, &header, active.payload())) {
        Err(rejection) => {
            debug!(request_id, status = %rejection.status, "rendezvous request rejected: {}", rejection.message);
            lock(&daemon.shared.stats).failed(rejection.status);
            // Refused before any delta was applied: the map is as it was.
            let map_version = daemon.maps.get(header.map_id).map(|w| w.version());
            let mut reply = RendezvousReply::rejected(request_id, &Rejection { map_version, ..rejection });
            reply.daemon_micros = u64::try_from(received.elapsed().as_micros()).unwrap_or(u64::MAX);
            send(&daemon.shared, &active, reply, reply_to);
        }
        Ok(Accepted::Checked(version, recorded)) => {
            let mut reply = RendezvousReply::checked(request_id, version);
            reply.daemon_micros = u64::try_from(received.elapsed().as_micros()).unwrap_or(u64::MAX);
            if let (Some(recorder), Some(request)) = (&daemon.shared.recorder, recorded) {
                recorder.record(Record::Rendezvous {
                    received: unix_ns_of(received),
                    replied: unix_ns(SystemTime::now()),
                    mode: Mode::Check,
                    request_id,
                    request,
                    reply: Box::new(reply),
                });
            }
            send(&daemon.shared, &active, reply, reply_to);
        }
        Ok(Accepted::Queued(request, world)) => {
            let client = active.origin().value();
            let mut q = lock(&daemon.shared.queue);
            q.push(Job { active, request: *request, world, received, reply_to, request_id, client });
            if let Some(worker) = q.hold_for_starved() {
                daemon.shared.watches[worker].hold.store(true, Ordering::Relaxed);
                trace!(request_id, worker, "every core searches: holding a search of the busiest client");
            }
            drop(q);
            // One job: one idle worker may take it. Queuing never lets a held search
            // go on, so those are not woken.
            daemon.shared.work.notify_one();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_searchs_core_share_falls_while_it_is_kept_off_its_core_and_recovers() {
        let t0 = Instant::now();
        let ms = Duration::from_millis;
        let mut s = CoreShare::start(t0, ms(100));
        // A whole core: stays at 1.
        s.update(t0 + ms(1), ms(101));
        assert!((s.recent - 1.0).abs() < 1e-12);
        // Half of it, as beside a CPU hog on each core, for 50 ms in 0.2 ms steps:
        // below the threshold, so it stops making way.
        let (mut now, mut cpu) = (t0 + ms(1), ms(101));
        for _ in 0..250 {
            now += Duration::from_micros(200);
            cpu += Duration::from_micros(100);
            s.update(now, cpu);
        }
        assert!((s.recent - 0.5).abs() < 0.01, "{}", s.recent);
        assert!(s.recent < MAKE_WAY_ABOVE);
        // 90 %, as beside clients that wake briefly: above it again within ~20 ms.
        for _ in 0..100 {
            now += Duration::from_micros(200);
            cpu += Duration::from_micros(180);
            s.update(now, cpu);
        }
        assert!(s.recent > MAKE_WAY_ABOVE && s.recent < 0.9, "{}", s.recent);
        // One long gap off the core weighs as much as its length: 10 ms at 0.
        s.update(now + ms(10), cpu);
        assert!(s.recent < 1e-9, "{}", s.recent);
        // A clock that did not move changes nothing.
        let before = s;
        s.update(s.at, s.cpu);
        assert_eq!(s, before);
    }

    #[test]
    fn heavy_jobs_leave_one_worker_free() {
        let mut q = Queue::new(2, 4);
        assert_eq!(q.heavy_limit, 1);
        assert_eq!(Queue::new(8, 16).heavy_limit, 7);
        assert_eq!(q.pending(), 0);
        q.running_heavy = 1;
        q.running = 1;
        q.active = 1;
        // No heavy job can start while one runs on a 2-worker pool.
        assert!(q.take(1).is_none());
        q.running_by.clear();
        q.running_by.push((7, 1));
        q.on_worker[0] = Some(OnWorker { client: 7, heavy: true, held: false });
        q.finish(0, true, 7);
        assert_eq!((q.running, q.active, q.running_heavy, q.running_by.len()), (0, 0, 0, 0));
        assert!(q.on_worker[0].is_none());
    }

    #[test]
    fn the_fair_pick_serves_the_client_with_fewest_searches_running() {
        // Client 1 has two searches running and three queued; client 2 queued last.
        let running = [(1, 2)];
        assert_eq!(fair_pick([1, 1, 1, 2].into_iter(), &running), 3);
        // Both running one: the oldest.
        assert_eq!(fair_pick([2, 1].into_iter(), &[(1, 1), (2, 1)]), 0);
        assert_eq!(fair_pick([1, 2, 3].into_iter(), &[(1, 3), (2, 1), (3, 2)]), 1);
        // Nobody running: the oldest.
        assert_eq!(fair_pick([5, 4].into_iter(), &[]), 0);
        assert_eq!(fair_pick(std::iter::empty::<u8>(), &running), 0);
    }
}
