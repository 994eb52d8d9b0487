//! Scheduling of the daemon's threads (issue 15): the IPC thread sleeps at a
//! real-time priority, so a request that wakes it preempts running searches at once,
//! and polls at normal priority, so its polling never takes a core from anything.
//!
//! Linux only; elsewhere every call here does nothing. The libc calls are the only
//! unsafe code of the daemon; each says why it is sound.

use std::time::Duration;
use tracing::{info, warn};

/// What the IPC thread got at start.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum IpcScheduling {
    /// `SCHED_FIFO` at this priority while it sleeps and answers what woke it.
    Realtime(u8),
    /// Real-time scheduling was turned off (`--ipc-priority 0`).
    Off,
    /// The system refused real-time scheduling; the fallback is in effect.
    Refused,
}

/// Switches the calling thread (the IPC thread) between `SCHED_FIFO` at a fixed
/// priority and its normal policy. Both switches are one system call, made only
/// when the state changes.
#[derive(Debug)]
pub(crate) struct IpcPriority {
    priority: u8,
    /// Whether the thread runs real-time now.
    realtime: bool,
    /// Whether the system lets it (false after a refusal, or when turned off).
    allowed: bool,
}

impl IpcPriority {
    /// Tries `SCHED_FIFO` at `priority` (0: off) on the calling thread once, and
    /// logs what it got. The thread is left real-time if it may.
    pub(crate) fn start(priority: u8) -> (IpcPriority, IpcScheduling) {
        let mut p = IpcPriority { priority, realtime: false, allowed: priority > 0 };
        if priority == 0 {
            return (p, IpcScheduling::Off);
        }
        match set_fifo(priority) {
            Ok(()) => {
                p.realtime = true;
                info!(
                    priority,
                    "IPC thread: SCHED_FIFO priority {priority} while it sleeps, so a request preempts running searches; it polls at normal priority"
                );
                (p, IpcScheduling::Realtime(priority))
            }
            Err(e) => {
                p.allowed = false;
                warn!(
                    "IPC thread: real-time priority {priority} refused ({e}): it needs CAP_SYS_NICE (`setcap cap_sys_nice+ep dyfosd`) or an RLIMIT_RTPRIO of at least {priority} (`ulimit -r {priority}`); falling back to normal priority with the search workers niced (see README, daemon priorities)"
                );
                (p, IpcScheduling::Refused)
            }
        }
    }

    /// Before sleeping: real-time, so that the wake-up preempts a search.
    pub(crate) fn raise(&mut self) {
        if self.allowed && !self.realtime {
            match set_fifo(self.priority) {
                Ok(()) => self.realtime = true,
                Err(e) => {
                    self.allowed = false;
                    warn!("IPC thread: real-time priority lost ({e}); it runs at normal priority from now on");
                }
            }
        }
    }

    /// Before polling: normal priority, so that polling yields to everything else.
    pub(crate) fn lower(&mut self) {
        if self.realtime {
            if let Err(e) = set_normal() {
                // Stay real-time; the next `raise` is then a no-op. Polling real-time
                // would hold a core, so the caller is told to sleep instead.
                warn!("IPC thread: cannot return to normal priority ({e}); it no longer polls");
                self.allowed = false;
                return;
            }
            self.realtime = false;
        }
    }

    /// Whether the thread runs real-time now (it must not poll then).
    pub(crate) fn is_realtime(&self) -> bool {
        self.realtime
    }
}

/// `SCHED_FIFO` at `priority` for the calling thread, reset to normal in any thread
/// it creates (`SCHED_RESET_ON_FORK`).
#[cfg(target_os = "linux")]
#[allow(unsafe_code)]
fn set_fifo(priority: u8) -> std::io::Result<()> {
    let param = libc::sched_param { sched_priority: i32::from(priority) };
    // SAFETY: `param` is a valid, initialized `sched_param` that outlives the call;
    // pid 0 names the calling thread; the call reads `param` and nothing else.
    let r = unsafe { libc::sched_setscheduler(0, libc::SCHED_FIFO | libc::SCHED_RESET_ON_FORK, &param) };
    if r == 0 { Ok(()) } else { Err(std::io::Error::last_os_error()) }
}

/// `SCHED_OTHER` (priority 0) for the calling thread.
#[cfg(target_os = "linux")]
#[allow(unsafe_code)]
fn set_normal() -> std::io::Result<()> {
    let param = libc::sched_param { sched_priority: 0 };
    // SAFETY: as in `set_fifo`: a valid `sched_param` on the stack, pid 0 = this thread.
    let r = unsafe { libc::sched_setscheduler(0, libc::SCHED_OTHER, &param) };
    if r == 0 { Ok(()) } else { Err(std::io::Error::last_os_error()) }
}

/// `SCHED_BATCH` for the calling thread (a search worker): CPU-bound, never
/// preempts on wake-up, same share of the CPU as normal threads.
#[cfg(target_os = "linux")]
#[allow(unsafe_code)]
pub(crate) fn set_batch() -> std::io::Result<()> {
    let param = libc::sched_param { sched_priority: 0 };
    // SAFETY: as in `set_fifo`: a valid `sched_param` on the stack, pid 0 = this thread.
    let r = unsafe { libc::sched_setscheduler(0, libc::SCHED_BATCH, &param) };
    if r == 0 { Ok(()) } else { Err(std::io::Error::last_os_error()) }
}

/// CPU time the calling thread has used (zero if unknown).
#[cfg(target_os = "linux")]
#[allow(unsafe_code)]
pub(crate) fn thread_cpu_time() -> Duration {
    let mut t = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: `t` is a valid, writable `timespec` on the stack; the call writes it
    // and nothing else.
    let r = unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut t) };
    if r != 0 {
        return Duration::ZERO;
    }
    Duration::new(u64::try_from(t.tv_sec).unwrap_or(0), u32::try_from(t.tv_nsec).unwrap_or(0))
}

/// CPU time the calling thread has used: unknown off Linux.
#[cfg(not(target_os = "linux"))]
pub(crate) fn thread_cpu_time() -> Duration {
    Duration::ZERO
}

#[cfg(not(target_os = "linux"))]
fn set_fifo(_priority: u8) -> std::io::Result<()> {
    Err(std::io::Error::new(std::io::ErrorKind::Unsupported, "real-time scheduling is used on Linux only"))
}

#[cfg(not(target_os = "linux"))]
fn set_normal() -> std::io::Result<()> {
    Ok(())
}

#[cfg(not(target_os = "linux"))]
pub(crate) fn set_batch() -> std::io::Result<()> {
    Err(std::io::Error::new(std::io::ErrorKind::Unsupported, "SCHED_BATCH is Linux only"))
}
