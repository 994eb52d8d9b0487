//! A search's checkpoint on a worker thread: where it makes way for other threads
//! and where it is held for a starved client's query.

use super::sched::thread_cpu_time;
use crate::daemon::pool::{Pool, lock};
use crate::search::Checkpoint;
use std::cell::Cell;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};
use tracing::trace;

/// The checkpoint of a search on worker `worker`, every
/// [`Evaluator::CLOCK_EVERY`](crate::search::Evaluator::CLOCK_EVERY) candidates (tens of µs):
///
/// - it **makes way**: when more threads are runnable than there are cores and the
///   thread has not yielded for [`Pool::worker_yield`], it yields its core. The
///   scheduler only looks again at a thread that woke while its core runs a search
///   at the next tick (4 ms at 250 Hz) unless the waking thread was owed time at
///   that instant; a robot process that just sent a request usually is not. A
///   yield lets the scheduler pick it within `worker_yield`; the search goes on
///   when it is its turn again (`bench/RESULTS.md`, "Why the scheduling defaults").
/// - it **holds** the search while the IPC thread asked it to give its core to a
///   starved query (see [`Queue`](crate::daemon::rendezvous::Queue); not `brute`).
pub(crate) struct WorkerCheckpoint<'p> {
    pool: &'p Pool,
    worker: usize,
    /// Whether the search may be held (spare workers, not heavy).
    holdable: bool,
}

impl<'p> WorkerCheckpoint<'p> {
    /// For the search on thread `worker` of `pool`; `holdable` if it may be held
    /// (there are spares and it is not heavy).
    pub(crate) fn new(pool: &'p Pool, worker: usize, holdable: bool) -> Self {
        WorkerCheckpoint { pool, worker, holdable }
    }

    /// Whether it does anything.
    pub(crate) fn wanted(&self) -> bool {
        self.holdable || !self.pool.worker_yield.is_zero()
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
        let every = self.pool.worker_yield;
        if every.is_zero() {
            return;
        }
        let now = Instant::now();
        let mut share = SHARE.get().unwrap_or_else(|| CoreShare::start(now, thread_cpu_time()));
        if now - share.at < every {
            return;
        }
        share.update(now, thread_cpu_time());
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
pub(crate) struct CoreShare {
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
    pub(crate) fn resume() {
        let (now, cpu) = (Instant::now(), thread_cpu_time());
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
        let watch = &self.pool.watches[self.worker];
        if !watch.hold.load(Ordering::Relaxed) {
            return;
        }
        let mut q = lock(&self.pool.queue);
        watch.hold.store(false, Ordering::Relaxed);
        q.hold();
        // This core is free for the starved query: one idle (spare) worker takes it.
        self.pool.work.notify_one();
        let held = Instant::now();
        // An abandoned search goes on at once, to see the flag and stop.
        while !q.may_go_on() && !watch.abandoned() {
            q = self.pool.resume.wait_timeout(q, Duration::from_millis(10)).map_or_else(|p| p.into_inner().0, |r| r.0);
        }
        q.go_on(self.worker);
        drop(q);
        trace!(worker = self.worker, micros = held.elapsed().as_micros() as u64, "held search goes on");
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
}
