//! Ctrl-C and SIGTERM for the mission processes: noticed, latched, never fatal, so
//! that a process stops at its next check and closes its ports cleanly.
//!
//! ```
//! dyfos_process::shutdown::install();
//! assert!(!dyfos_process::shutdown::requested());
//! ```

use iceoryx2_bb_posix::signal::SignalHandler;
use std::sync::atomic::{AtomicBool, Ordering};

static REQUESTED: AtomicBool = AtomicBool::new(false);

/// Installs the SIGINT/SIGTERM handlers (idempotent). After this, those signals no
/// longer kill the process: it must poll [`requested`].
pub fn install() {
    let _ = requested();
}

/// Whether SIGINT or SIGTERM arrived since [`install`]. Stays true once true.
pub fn requested() -> bool {
    if REQUESTED.load(Ordering::Relaxed) {
        return true;
    }
    if SignalHandler::termination_requested() {
        REQUESTED.store(true, Ordering::Relaxed);
        return true;
    }
    false
}

/// Asks this process to stop, as a signal would (for callers that run a mission
/// loop on a thread).
pub fn request() {
    REQUESTED.store(true, Ordering::Relaxed);
}

/// Asks another process to stop with SIGTERM; `false` if it does not exist (or
/// may not be signalled).
pub fn terminate(pid: u32) -> bool {
    use iceoryx2_bb_posix::process::{Process, ProcessId};
    use iceoryx2_bb_posix::signal::Signal;
    let Ok(pid) = i32::try_from(pid) else { return false };
    Process::from_pid(ProcessId::new(pid)).send_signal(Signal::Terminate).is_ok()
}

/// Joins `threads`, waiting at most `grace` for all of them together; returns the
/// names of those still running then (unnamed ones as `?`), which are left
/// behind. A stopping process calls it so that a thread blocked in a call it cannot
/// interrupt (a peer that never answers, a full network queue) delays its exit by
/// `grace` at most instead of for good.
pub fn join_within(threads: Vec<std::thread::JoinHandle<()>>, grace: std::time::Duration) -> Vec<String> {
    let deadline = std::time::Instant::now() + grace;
    while threads.iter().any(|t| !t.is_finished()) && std::time::Instant::now() < deadline {
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    let mut stuck = Vec::new();
    for t in threads {
        if t.is_finished() {
            let _ = t.join();
        } else {
            stuck.push(t.thread().name().unwrap_or("?").to_string());
        }
    }
    stuck
}

#[cfg(test)]
mod tests {
    use super::join_within;
    use std::time::{Duration, Instant};

    #[test]
    fn a_thread_that_never_stops_is_named_and_left_behind_after_the_grace() {
        let (_keep, blocked) = std::sync::mpsc::channel::<()>();
        let stuck = std::thread::Builder::new().name("blocked".into()).spawn(move || while blocked.recv().is_ok() {});
        let done = std::thread::Builder::new().name("done".into()).spawn(|| {});
        let start = Instant::now();
        let left = join_within(vec![stuck.unwrap(), done.unwrap()], Duration::from_millis(200));
        let waited = start.elapsed();
        assert_eq!(left, ["blocked"]);
        assert!(waited >= Duration::from_millis(200), "gave up before the grace: {waited:?}");
    }

    #[test]
    fn threads_that_stop_are_joined_without_waiting_out_the_grace() {
        let quick = std::thread::spawn(|| std::thread::sleep(Duration::from_millis(20)));
        let start = Instant::now();
        assert!(join_within(vec![quick], Duration::from_secs(60)).is_empty());
        assert!(start.elapsed() < Duration::from_secs(30));
    }
}
