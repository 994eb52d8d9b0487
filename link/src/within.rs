//! A job on a thread of its own, waited for at most a grace, then left behind.
//!
//! Some of Zenoh's calls block forever while its routing is stalled (a lock held
//! under peer churn); only the end of the process ends them. A stopping link runs
//! such a call here, so that the stop returns, and the process exits, whether or
//! not the call ever does.

use std::panic::AssertUnwindSafe;
use std::sync::mpsc::{self, RecvTimeoutError};
use std::sync::{Arc, Mutex};
use std::time::Duration;

/// How a job run with [`run_within`] ended, as far as the waiting thread knows.
#[derive(Debug, PartialEq, Eq)]
pub(crate) enum Outcome<T> {
    /// The job returned this within the grace.
    Finished(T),
    /// The job panicked within the grace, with this message (the panic stays on its thread).
    Panicked(String),
    /// The job had not ended when the grace ran out; its thread was left running.
    LeftBehind,
}

/// Runs `job` on the thread `name` and waits for it at most `grace`; a job still
/// running then is left behind on its thread. If no thread can be started, the
/// job runs on this one, without a bound.
pub(crate) fn run_within<T, F>(name: &str, grace: Duration, job: F) -> Outcome<T>
where
    T: Send + 'static,
    F: FnOnce() -> T + Send + 'static,
{
    // The job stays reachable here, so that it can still run when the thread does not start.
    let slot = Arc::new(Mutex::new(Some(job)));
    let theirs = slot.clone();
    let (done, ended) = mpsc::channel();
    let spawned = std::thread::Builder::new().name(name.to_string()).spawn(move || {
        let job = theirs.lock().unwrap_or_else(|p| p.into_inner()).take();
        if let Some(job) = job {
            let _ = done.send(caught(job));
        }
    });
    match spawned {
        Ok(_) => match ended.recv_timeout(grace) {
            Ok(outcome) => outcome,
            Err(RecvTimeoutError::Timeout) => Outcome::LeftBehind,
            // Not expected (a panic is caught): the thread ended without a word.
            Err(RecvTimeoutError::Disconnected) => Outcome::Panicked("ended without an answer".into()),
        },
        Err(_) => match slot.lock().unwrap_or_else(|p| p.into_inner()).take() {
            Some(job) => caught(job),
            None => Outcome::Panicked("the thread that did not start took the job".into()),
        },
    }
}

/// Runs `job`, turning a panic into its message.
fn caught<T>(job: impl FnOnce() -> T) -> Outcome<T> {
    match std::panic::catch_unwind(AssertUnwindSafe(job)) {
        Ok(value) => Outcome::Finished(value),
        Err(payload) => Outcome::Panicked(
            dyfos_process::panic::panic_text(payload.as_ref()).unwrap_or("a panic without a message").to_string(),
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Instant;

    /// Slack over the grace: these tests check that the wait ends, not how fast.
    const SLACK: Duration = Duration::from_secs(5);

    /// Runs [`run_within`] on a thread of the test's, so that a wait that never
    /// ends fails the test after `grace` + [`SLACK`] instead of hanging it.
    fn run_watched<T: Send + std::fmt::Debug + 'static>(
        grace: Duration,
        job: impl FnOnce() -> T + Send + 'static,
    ) -> (Outcome<T>, Duration) {
        let (tx, rx) = mpsc::channel();
        std::thread::spawn(move || {
            let start = Instant::now();
            let outcome = run_within("within-test", grace, job);
            let _ = tx.send((outcome, start.elapsed()));
        });
        rx.recv_timeout(grace + SLACK).expect("the wait did not return within the grace and its slack")
    }

    #[test]
    fn a_job_that_blocks_forever_is_left_behind_after_the_grace() {
        let (_never_sent, blocked) = mpsc::channel::<()>();
        let grace = Duration::from_millis(300);
        let (outcome, waited) = run_watched(grace, move || blocked.recv().is_ok());
        assert_eq!(outcome, Outcome::LeftBehind);
        assert!(waited >= grace, "gave up before the grace: {waited:?}");
    }

    #[test]
    fn a_job_that_finishes_gives_its_result_without_waiting_out_the_grace() {
        let grace = Duration::from_secs(60);
        let (tx, rx) = mpsc::channel::<Duration>();
        let start = Instant::now();
        let waiting = std::thread::spawn(move || {
            let outcome = run_within("within-test", grace, || 42);
            let _ = tx.send(start.elapsed());
            outcome
        });
        let waited = rx.recv_timeout(SLACK).expect("a finished job was waited for as if it blocked");
        assert_eq!(waiting.join().unwrap(), Outcome::Finished(42));
        assert!(waited < SLACK, "{waited:?}");
    }

    #[test]
    fn a_job_that_panics_is_reported_and_its_panic_stays_on_its_thread() {
        let grace = Duration::from_secs(60);
        let (outcome, waited) = run_watched(grace, || -> u8 { panic!("the close fell over") });
        assert_eq!(outcome, Outcome::Panicked("the close fell over".into()));
        assert!(waited < SLACK, "a panicked job was waited for as if it blocked: {waited:?}");
        let (outcome, _) = run_watched(grace, || -> u8 { panic!("{} fell over", "the close") });
        assert_eq!(outcome, Outcome::Panicked("the close fell over".into()));
    }
}
