//! A flag kept current by a thread of its own, so that reading it never waits.
//!
//! Asking Zenoh whether the other host is connected blocks while its routing is
//! stalled; the link's main loop must still notice SIGTERM then. So a watcher
//! asks, and the loop reads what the watcher last stored: a stuck watcher leaves
//! the last known value, and a stopping link leaves the watcher behind.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;
use std::time::Duration;

/// Starts the thread `name`, which stores `probe()` in `value` every `nap` until `stop` is set.
pub(crate) fn watch(
    name: &str,
    value: Arc<AtomicBool>,
    stop: Arc<AtomicBool>,
    nap: Duration,
    mut probe: impl FnMut() -> bool + Send + 'static,
) -> std::io::Result<JoinHandle<()>> {
    std::thread::Builder::new().name(name.to_string()).spawn(move || {
        while !stop.load(Ordering::Relaxed) {
            value.store(probe(), Ordering::Relaxed);
            std::thread::sleep(nap);
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::mpsc;
    use std::time::Instant;

    #[test]
    fn a_stuck_watcher_leaves_the_last_value_and_is_left_behind_at_stop() {
        let (value, stop) = (Arc::new(AtomicBool::new(false)), Arc::new(AtomicBool::new(false)));
        let (stuck_tx, stuck) = mpsc::channel::<()>();
        let (_never_sent, blocked) = mpsc::channel::<()>();
        let mut asked = 0;
        let watcher = watch("watcher-test", value.clone(), stop.clone(), Duration::from_millis(10), move || {
            asked += 1;
            if asked > 1 {
                // The second question never gets an answer, as under a stalled Zenoh.
                let _ = stuck_tx.send(());
                let _ = blocked.recv();
            }
            true
        })
        .unwrap();
        stuck.recv_timeout(Duration::from_secs(5)).expect("the watcher asked a second time");
        let start = Instant::now();
        for _ in 0..100 {
            assert!(value.load(Ordering::Relaxed), "the last answer was lost while the watcher is stuck");
        }
        assert!(start.elapsed() < Duration::from_secs(1), "reading the value waited on the watcher");
        stop.store(true, Ordering::Relaxed);
        let left = dyfos_process::shutdown::join_within(vec![watcher], Duration::from_millis(200));
        assert_eq!(left, ["watcher-test"]);
    }

    #[test]
    fn a_watcher_follows_its_probe_and_ends_at_stop() {
        let (value, stop) = (Arc::new(AtomicBool::new(false)), Arc::new(AtomicBool::new(false)));
        let answer = Arc::new(AtomicBool::new(true));
        let probe = answer.clone();
        let watcher = watch("watcher-test", value.clone(), stop.clone(), Duration::from_millis(10), move || {
            probe.load(Ordering::Relaxed)
        })
        .unwrap();
        let became = |want: bool| {
            let deadline = Instant::now() + Duration::from_secs(5);
            while value.load(Ordering::Relaxed) != want && Instant::now() < deadline {
                std::thread::sleep(Duration::from_millis(5));
            }
            value.load(Ordering::Relaxed) == want
        };
        assert!(became(true));
        answer.store(false, Ordering::Relaxed);
        assert!(became(false));
        stop.store(true, Ordering::Relaxed);
        assert!(dyfos_process::shutdown::join_within(vec![watcher], Duration::from_secs(5)).is_empty());
    }
}
