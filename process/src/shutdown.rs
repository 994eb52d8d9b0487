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
