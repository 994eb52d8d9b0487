//! The queries waiting for a worker, and which one a free worker takes.

use dyfos_shared::answer::Algorithm;
use std::collections::VecDeque;

/// Which client port sent a query (its iceoryx2 `UniqueClientId`): the unit of
/// fairness of the [`Queue`].
pub(crate) type ClientKey = u128;

/// Whether queries of `algorithm` are heavy: they may hold all workers but one,
/// and queue apart from the others.
pub(crate) fn is_heavy(algorithm: Algorithm) -> bool {
    algorithm == Algorithm::Brute
}

/// The queries (`J`) waiting for workers, in two classes: `brute` (heavy) may
/// occupy all workers but one, so a cheap query always finds a free worker. Within
/// a class, a free worker takes the oldest query of the client with the fewest
/// searches running (so a client with many queries in flight takes its turn with
/// the others).
///
/// Nor does a client wait for another's searches to end:
/// when every worker searches and a query comes from a client with none running,
/// one `dyfos`-class search of the client with the most running is held at its next
/// checkpoint (within 64 candidates), and a spare runs the new query on its core.
/// Held searches go on, oldest first, as workers free up. At most `workers`
/// searches run at a time; the spares only ever stand in for held ones.
pub(crate) struct Queue<J> {
    light: VecDeque<(ClientKey, J)>,
    heavy: VecDeque<(ClientKey, J)>,
    /// Taken and not finished, held ones included.
    running: usize,
    running_heavy: usize,
    heavy_limit: usize,
    /// Searches that may run at once (`--workers`).
    workers: usize,
    /// Running and not held.
    active: usize,
    closed: bool,
    /// Clients with searches running and how many each: at most one entry per
    /// thread, allocated once.
    running_by: Vec<(ClientKey, usize)>,
    /// What each thread (worker or spare) runs: its client, and whether it is heavy
    /// or held (or asked to be).
    on_thread: Vec<Option<OnThread>>,
}

#[derive(Debug, Clone, Copy)]
struct OnThread {
    client: ClientKey,
    heavy: bool,
    held: bool,
}

impl<J> Queue<J> {
    /// For `workers` searches at a time, on `workers + spares` threads (numbered
    /// from 0, the spares last).
    pub(crate) fn new(workers: usize, spares: usize) -> Self {
        Queue {
            light: VecDeque::new(),
            heavy: VecDeque::new(),
            running: 0,
            running_heavy: 0,
            heavy_limit: workers.saturating_sub(1).max(1),
            workers,
            active: 0,
            closed: false,
            running_by: Vec::with_capacity(workers + spares),
            on_thread: vec![None; workers + spares],
        }
    }

    /// Queues `job` of `client`.
    pub(crate) fn push(&mut self, client: ClientKey, heavy: bool, job: J) {
        if heavy {
            self.heavy.push_back((client, job));
        } else {
            self.light.push_back((client, job));
        }
    }

    /// The next job free thread `thread` may take, and whether it is heavy.
    pub(crate) fn take(&mut self, thread: usize) -> Option<(J, bool)> {
        if self.active >= self.workers {
            return None;
        }
        // Held searches go on before new queries, except a starved one's.
        let ((client, job), heavy) = if !self.light.is_empty() && (self.held() == 0 || self.starved()) {
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
        match self.running_by.iter_mut().find(|(c, _)| *c == client) {
            Some((_, n)) => *n += 1,
            None => self.running_by.push((client, 1)),
        }
        self.on_thread[thread] = Some(OnThread { client, heavy, held: false });
        Some((job, heavy))
    }

    /// The search on `thread` ended (answered, failed or abandoned).
    pub(crate) fn finish(&mut self, thread: usize) {
        let Some(OnThread { client, heavy, .. }) = self.on_thread[thread].take() else {
            debug_assert!(false, "thread {thread} finished a search it had not taken");
            return;
        };
        self.running -= 1;
        self.active -= 1;
        self.running_heavy -= usize::from(heavy);
        if let Some(i) = self.running_by.iter().position(|(c, _)| *c == client) {
            self.running_by[i].1 -= 1;
            if self.running_by[i].1 == 0 {
                self.running_by.swap_remove(i);
            }
        }
    }

    /// The thread whose search should be held for a starved query, if every worker
    /// searches: a light search of the client with the most running (at least 2),
    /// not held yet. Marks it asked.
    pub(crate) fn hold_for_starved(&mut self) -> Option<usize> {
        if self.active < self.workers || !self.starved() {
            return None;
        }
        let asked = self.on_thread.iter().filter(|w| w.is_some_and(|w| w.held)).count();
        if asked >= self.on_thread.len() - self.workers {
            return None; // no spare left to run the starved query
        }
        let (thread, _) = self
            .on_thread
            .iter()
            .enumerate()
            .filter_map(|(i, w)| w.filter(|w| !w.heavy && !w.held).map(|w| (i, self.running_of(w.client))))
            .filter(|(_, n)| *n >= 2)
            .max_by_key(|(i, n)| (*n, std::cmp::Reverse(*i)))?;
        if let Some(w) = self.on_thread[thread].as_mut() {
            w.held = true;
        }
        Some(thread)
    }

    /// The search asked to hold stops at its checkpoint: its core is free.
    pub(crate) fn hold(&mut self) {
        self.active -= 1;
    }

    /// Whether a held search may go on: a worker is free and no starved query is
    /// waiting for it.
    pub(crate) fn may_go_on(&self) -> bool {
        self.active < self.workers && !self.starved()
    }

    /// The held search on `thread` goes on.
    pub(crate) fn go_on(&mut self, thread: usize) {
        self.active += 1;
        if let Some(w) = self.on_thread[thread].as_mut() {
            w.held = false;
        }
    }

    /// Searches running and not held.
    pub(crate) fn active(&self) -> usize {
        self.active
    }

    /// Searches held at their checkpoint.
    pub(crate) fn held(&self) -> usize {
        self.running - self.active
    }

    pub(crate) fn queued(&self) -> usize {
        self.light.len() + self.heavy.len()
    }

    /// Queries of one class waiting. Each class has its own `max_queued`, so a
    /// flood of `brute` queries cannot make a cheap query `busy`.
    pub(crate) fn queued_of(&self, heavy: bool) -> usize {
        if heavy { self.heavy.len() } else { self.light.len() }
    }

    pub(crate) fn running(&self) -> usize {
        self.running
    }

    /// Queued or running.
    pub(crate) fn pending(&self) -> usize {
        self.queued() + self.running
    }

    /// No more jobs: idle threads end.
    pub(crate) fn close(&mut self) {
        self.closed = true;
    }

    pub(crate) fn is_closed(&self) -> bool {
        self.closed
    }

    /// Searches `client` has running (held ones included).
    fn running_of(&self, client: ClientKey) -> usize {
        self.running_by.iter().find(|(c, _)| *c == client).map_or(0, |(_, n)| *n)
    }

    /// Whether a light query waits whose client has no search running: it goes
    /// before held searches.
    fn starved(&self) -> bool {
        self.light.iter().any(|(client, _)| self.running_of(*client) == 0)
    }

    /// Index of the job to take next from one class's queue.
    fn next_of(&self, heavy: bool) -> usize {
        let queue = if heavy { &self.heavy } else { &self.light };
        fair_pick(queue.iter().map(|(client, _)| *client), &self.running_by)
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

#[cfg(test)]
mod tests {
    use super::*;

    /// Jobs are `(client, number)`, so a test sees whose job a thread took.
    type Q = Queue<(ClientKey, u32)>;

    fn push(q: &mut Q, client: ClientKey, n: u32) {
        q.push(client, false, (client, n));
    }

    /// Two workers (and `spares` spares), both searching for client 1.
    fn client_1_on_both_workers(spares: usize) -> Q {
        let mut q = Q::new(2, spares);
        push(&mut q, 1, 0);
        push(&mut q, 1, 1);
        q.take(0).unwrap();
        q.take(1).unwrap();
        q
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

    #[test]
    fn free_workers_take_turns_across_clients() {
        let mut q = Q::new(3, 3);
        for n in 0..4 {
            push(&mut q, 1, n);
        }
        push(&mut q, 2, 0);
        push(&mut q, 3, 0);
        // Client 1 queued first and most, but each client gets a worker before
        // client 1 gets a second.
        let taken: Vec<_> = (0..3).map(|t| q.take(t).unwrap().0).collect();
        assert_eq!(taken, [(1, 0), (2, 0), (3, 0)]);
        assert!(q.take(3).is_none(), "three workers: a fourth search waits");
        q.finish(1);
        assert_eq!(q.take(1).unwrap().0, (1, 1), "client 1's oldest next");
        assert_eq!((q.running(), q.queued(), q.pending()), (3, 2, 5));
    }

    #[test]
    fn heavy_jobs_leave_one_worker_free() {
        assert_eq!(Q::new(8, 8).heavy_limit, 7);
        let mut q = Q::new(2, 2);
        q.push(1, true, (1, 0));
        q.push(1, true, (1, 1));
        assert_eq!(q.take(0), Some(((1, 0), true)));
        assert!(q.take(1).is_none(), "the second worker stays free of heavy jobs");
        push(&mut q, 2, 0);
        assert_eq!(q.take(1), Some(((2, 0), false)));
        assert_eq!(q.queued_of(true), 1);
        q.finish(0);
        q.finish(1);
        assert_eq!((q.running, q.active, q.running_heavy, q.running_by.len()), (0, 0, 0, 0));
        assert!(q.on_thread.iter().all(Option::is_none));
    }

    #[test]
    fn a_starved_client_gets_the_core_of_a_held_search() {
        let mut q = client_1_on_both_workers(2);
        assert_eq!(q.hold_for_starved(), None, "nobody starves");
        // Client 2 queues while client 1 holds both workers.
        push(&mut q, 2, 0);
        assert!(q.take(2).is_none(), "every worker searches");
        let held = q.hold_for_starved().expect("a search of client 1 is held");
        assert_eq!(held, 0, "the lowest-numbered thread of the busiest client");
        // At its checkpoint the held search frees its core for a spare.
        q.hold();
        assert!(!q.may_go_on(), "the starved query goes first");
        assert_eq!(q.take(2).unwrap().0, (2, 0));
        assert_eq!((q.running(), q.active(), q.held()), (3, 2, 1));
        // Once a worker is free and nobody starves, the held search goes on,
        // before any new query.
        q.finish(2);
        push(&mut q, 3, 0);
        assert!(!q.may_go_on(), "client 3 starves: it goes before the held search");
        assert_eq!(q.take(2).unwrap().0, (3, 0));
        q.finish(2);
        assert!(q.may_go_on());
        push(&mut q, 1, 2);
        assert!(q.take(2).is_none(), "a new query of a client with searches waits for the held one");
        q.go_on(held);
        assert_eq!((q.active(), q.held()), (2, 0));
    }

    #[test]
    fn no_search_is_held_without_a_spare_to_stand_in() {
        let mut q = client_1_on_both_workers(0);
        push(&mut q, 2, 0);
        assert_eq!(q.hold_for_starved(), None);
    }
}
