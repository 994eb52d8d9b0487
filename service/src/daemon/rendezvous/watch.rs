//! Abandoning a search whose client has gone: the IPC thread watches each running
//! query's request and raises a flag the search reads at its checkpoints.

use crate::daemon::pool::lock;
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, Ordering};
use tracing::debug;

/// A request whose client may go away mid-search.
pub(crate) trait Connected {
    /// Whether the client that sent it still waits for its reply.
    fn is_connected(&self) -> bool;
}

/// One thread's running query, as the IPC thread sees it: the thread lends it the
/// query's request `R` for the time of the search, and the IPC thread raises
/// `abandon` once that request's client has gone (it died, or dropped its pending
/// response). An iceoryx2 `ActiveRequest` is `Send` but not `Sync`, so the search
/// threads cannot ask it themselves; they read the flag. One per thread, made
/// once: nothing per query.
pub(crate) struct Watch<R> {
    running: Mutex<Option<(u64, R)>>,
    pub(crate) abandon: AtomicBool,
    /// Raised (under the queue's lock) to ask the running search to hand its core
    /// to a query of a client with none running; see
    /// [`Queue::hold_for_starved`](super::queue::Queue::hold_for_starved).
    pub(crate) hold: AtomicBool,
}

impl<R: Connected> Watch<R> {
    pub(crate) fn new() -> Self {
        Watch { running: Mutex::new(None), abandon: AtomicBool::new(false), hold: AtomicBool::new(false) }
    }

    /// On the IPC thread: raises the flag if the lent request's client has gone.
    pub(crate) fn check(&self) {
        let running = lock(&self.running);
        if let Some((request_id, request)) = running.as_ref()
            && !self.abandon.load(Ordering::Relaxed)
            && !request.is_connected()
        {
            // Raised under the lock: the thread's next `lend` cannot lower it before
            // this request is taken back.
            self.abandon.store(true, Ordering::Relaxed);
            debug!(request_id, "the client of a running query has gone; abandoning the search");
        }
    }

    /// Lends `request` to the IPC thread's watch, with the flag lowered.
    pub(crate) fn lend(&self, request_id: u64, request: R) {
        let mut running = lock(&self.running);
        self.abandon.store(false, Ordering::Relaxed);
        *running = Some((request_id, request));
    }

    /// Takes the lent request back.
    pub(crate) fn take_back(&self) -> Option<R> {
        lock(&self.running).take().map(|(_, request)| request)
    }

    /// Whether the search should stop: its client has gone.
    pub(crate) fn abandoned(&self) -> bool {
        self.abandon.load(Ordering::Relaxed)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Arc;

    /// A request whose client leaves when the test says so.
    #[derive(Clone)]
    struct Fake(Arc<AtomicBool>);

    impl Connected for Fake {
        fn is_connected(&self) -> bool {
            self.0.load(Ordering::Relaxed)
        }
    }

    #[test]
    fn a_running_query_is_abandoned_once_its_client_has_gone() {
        let watch = Watch::new();
        let client = Arc::new(AtomicBool::new(true));
        watch.check();
        assert!(!watch.abandoned(), "nothing lent, nothing abandoned");
        watch.lend(1, Fake(Arc::clone(&client)));
        watch.check();
        assert!(!watch.abandoned(), "the client is there");
        client.store(false, Ordering::Relaxed);
        watch.check();
        assert!(watch.abandoned());
        assert!(watch.take_back().is_some());
        // The next query starts with the flag lowered, and a request taken back is
        // no longer watched.
        watch.lend(2, Fake(Arc::new(AtomicBool::new(true))));
        assert!(!watch.abandoned());
        let gone = watch.take_back().unwrap();
        gone.0.store(false, Ordering::Relaxed);
        watch.check();
        assert!(!watch.abandoned());
    }
}
