//! The dead-process cleanup, on a thread of its own.
//!
//! iceoryx2 frees a killed client's resources, and so lets the daemon see that the
//! client has gone, only when a process of the domain runs a dead-node cleanup. A
//! cleanup walks the domain's nodes and takes milliseconds. On the real-time IPC
//! thread that would hold every request, and the whole core, for as long
//! (`bench/RESULTS.md`, "Why the scheduling defaults"). This thread runs it at
//! normal priority with a node of its own (any node of the domain may clean up after
//! a dead one) and raises a flag; the IPC thread then looks for searches whose
//! clients have gone.

use dyfos_shared::wire::services::Ipc;
use iceoryx2::prelude::*;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::thread::JoinHandle;
use std::time::Duration;
use tracing::{info, warn};

/// The cleanup thread: stopped and joined when dropped.
pub(crate) struct Janitor {
    stop: Arc<(Mutex<bool>, Condvar)>,
    cleaned: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

impl Janitor {
    /// Starts the thread: a cleanup every `every`, the first one `every` from now.
    /// Call it before the IPC thread turns real-time, so the thread does not inherit
    /// that.
    pub(crate) fn start(config: &iceoryx2::config::Config, every: Duration) -> std::io::Result<Janitor> {
        let stop = Arc::new((Mutex::new(false), Condvar::new()));
        let cleaned = Arc::new(AtomicBool::new(false));
        let thread = {
            let (stop, cleaned, config) = (Arc::clone(&stop), Arc::clone(&cleaned), config.clone());
            std::thread::Builder::new()
                .name("dyfos-janitor".into())
                .spawn(move || run(&config, every, &stop, &cleaned))?
        };
        Ok(Janitor { stop, cleaned, thread: Some(thread) })
    }

    /// Whether a cleanup removed dead processes' resources since the last call.
    pub(crate) fn take_cleaned(&self) -> bool {
        self.cleaned.load(Ordering::Relaxed) && self.cleaned.swap(false, Ordering::Relaxed)
    }
}

impl Drop for Janitor {
    fn drop(&mut self) {
        let (stopped, wake) = &*self.stop;
        *stopped.lock().unwrap_or_else(|p| p.into_inner()) = true;
        wake.notify_all();
        if let Some(thread) = self.thread.take()
            && thread.join().is_err()
        {
            warn!("the dead-process cleanup thread panicked");
        }
    }
}

fn run(config: &iceoryx2::config::Config, every: Duration, stop: &(Mutex<bool>, Condvar), cleaned: &AtomicBool) {
    let node = match NodeBuilder::new()
        .config(config)
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<Ipc>()
    {
        Ok(node) => node,
        Err(e) => {
            warn!(
                "the dead-process cleanup cannot start ({e:?}): a killed client's search is abandoned only once another process of the domain starts"
            );
            return;
        }
    };
    let (stopped, wake) = stop;
    loop {
        {
            let guard = stopped.lock().unwrap_or_else(|p| p.into_inner());
            let (guard, _) = wake.wait_timeout_while(guard, every, |stop| !*stop).unwrap_or_else(|p| p.into_inner());
            if *guard {
                return;
            }
        }
        let cleanup = node.try_cleanup_dead_nodes();
        if cleanup.cleanups > 0 {
            info!(cleaned = cleanup.cleanups, "removed resources of dead clients");
            cleaned.store(true, Ordering::Relaxed);
        }
    }
}
