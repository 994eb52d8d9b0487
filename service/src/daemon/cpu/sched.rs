//! Scheduling of the daemon's threads: the IPC thread sleeps at a
//! real-time priority, so a request that wakes it preempts running searches at once,
//! and polls at normal priority, so its polling never takes a core from anything.
//! Where real-time is refused it asks for a short time slice instead, and the search
//! workers ask for a long one: Linux's EEVDF scheduler (6.12 on) lets a waking thread
//! with a shorter slice than the running one preempt it.
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
    /// Real-time scheduling was turned off (`scheduling.ipc_priority = 0`).
    Off,
    /// The system refused real-time scheduling; the IPC thread asks for a short
    /// time slice instead ([`IPC_SLICE`]), which the kernel took (Linux 6.12 and
    /// later): a request still preempts a running search, no privilege needed.
    ShortSlice,
    /// The system refused real-time scheduling and a short slice; the fallback
    /// (niced workers) is in effect.
    Refused,
}

/// The IPC thread's time slice when it may not run real-time: the shortest the
/// kernel takes, so that it preempts a running search (whose slice is longer) at
/// its wake-up, as a real-time thread would.
pub const IPC_SLICE: Duration = Duration::from_micros(100);

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
                let how = "it needs CAP_SYS_NICE (`setcap cap_sys_nice+ep dyfosd`) or an RLIMIT_RTPRIO";
                if set_slice(IPC_SLICE).is_ok() && slice() == Some(IPC_SLICE) {
                    warn!(
                        "IPC thread: real-time priority {priority} refused ({e}): {how} of at least {priority} (`ulimit -r {priority}`); it runs at normal priority with a {IPC_SLICE:?} time slice instead, so a request still preempts a running search, though less surely (see docs/daemon.md, Priorities)"
                    );
                    return (p, IpcScheduling::ShortSlice);
                }
                warn!(
                    "IPC thread: real-time priority {priority} refused ({e}): {how} of at least {priority} (`ulimit -r {priority}`); this kernel takes no time slice either (Linux 6.12 and later do), so the search workers are niced instead (see docs/daemon.md, Priorities)"
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

/// `SCHED_FLAG_RESET_ON_FORK` of `sched_attr.sched_flags` (libc has no constant).
/// (`SCHED_FLAG_KEEP_POLICY` would spare reading the policy first, but the kernel
/// then ignores this flag.)
#[cfg(target_os = "linux")]
const SCHED_FLAG_RESET_ON_FORK: u64 = 0x01;

/// `sched_attr` as of Linux 4.x (`SCHED_ATTR_SIZE_VER0`, 48 bytes): libc does not
/// define it.
#[cfg(target_os = "linux")]
#[repr(C)]
#[derive(Default)]
struct SchedAttr {
    size: u32,
    sched_policy: u32,
    sched_flags: u64,
    sched_nice: i32,
    sched_priority: u32,
    sched_runtime: u64,
    sched_deadline: u64,
    sched_period: u64,
}

/// Asks the kernel for a time slice of `slice` for the calling thread, keeping its
/// policy and nice level. Its share of the CPU
/// stays that of its nice level; what changes is who waits at a wake-up: EEVDF
/// (Linux 6.12 on) lets a thread with a shorter slice preempt the running one at
/// once, so any normal thread that wakes on a core where a search runs (a client
/// with its reply, a robot process's timer) takes it then, not at the search's next
/// checkpoint. Kernels before 6.12 take the call and ignore the slice.
#[cfg(target_os = "linux")]
#[allow(unsafe_code)]
pub(crate) fn set_slice(slice: Duration) -> std::io::Result<()> {
    // The call sets the policy and nice level too: pass the thread's own.
    let now = attr()?;
    let attr = SchedAttr {
        size: std::mem::size_of::<SchedAttr>() as u32,
        sched_policy: now.sched_policy,
        // Threads it starts later get the kernel's slice, not this one.
        sched_flags: SCHED_FLAG_RESET_ON_FORK,
        sched_nice: now.sched_nice,
        sched_runtime: u64::try_from(slice.as_nanos()).unwrap_or(u64::MAX),
        ..SchedAttr::default()
    };
    // SAFETY: `attr` is a valid, initialized `sched_attr` (VER0 layout, its `size`
    // says so) that outlives the call; pid 0 names the calling thread; the call's
    // flags are 0. The kernel reads `attr` and nothing else.
    let r = unsafe { libc::syscall(libc::SYS_sched_setattr, 0, &attr as *const SchedAttr, 0) };
    if r == 0 { Ok(()) } else { Err(std::io::Error::last_os_error()) }
}

/// The calling thread's time slice as the kernel reports it: `None` where it
/// reports none (before Linux 6.12, which also ignore a slice asked for).
#[cfg(target_os = "linux")]
pub(crate) fn slice() -> Option<Duration> {
    attr().ok().filter(|a| a.sched_runtime > 0).map(|a| Duration::from_nanos(a.sched_runtime))
}

/// The calling thread's scheduling attributes (`sched_getattr`).
#[cfg(target_os = "linux")]
#[allow(unsafe_code)]
fn attr() -> std::io::Result<SchedAttr> {
    let mut attr = SchedAttr::default();
    let size = std::mem::size_of::<SchedAttr>() as libc::c_uint;
    // SAFETY: `attr` is a valid, writable `sched_attr` of `size` bytes (VER0 layout)
    // that outlives the call; pid 0 names the calling thread; flags 0. The kernel
    // writes at most `size` bytes of it.
    let r = unsafe { libc::syscall(libc::SYS_sched_getattr, 0, &mut attr as *mut SchedAttr, size, 0) };
    if r == 0 { Ok(attr) } else { Err(std::io::Error::last_os_error()) }
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
pub(crate) fn set_slice(_slice: Duration) -> std::io::Result<()> {
    Err(std::io::Error::new(std::io::ErrorKind::Unsupported, "time slices are set on Linux only"))
}

#[cfg(not(target_os = "linux"))]
pub(crate) fn slice() -> Option<Duration> {
    None
}

#[cfg(all(test, target_os = "linux"))]
mod tests {
    use super::*;

    /// The calling thread's policy number, from `/proc/thread-self/sched`.
    fn policy() -> u32 {
        let text = std::fs::read_to_string("/proc/thread-self/sched").unwrap();
        let line = text.lines().find(|l| l.starts_with("policy")).unwrap();
        line.rsplit(':').next().unwrap().trim().parse().unwrap()
    }

    /// A worker's slice is what it asked for, and asking keeps its nice level and
    /// policy (the call sets the nice level, so a wrong one would either fail
    /// unprivileged or change the searches' share). Kernels that report no slice
    /// (before 6.12) ignore it.
    #[test]
    fn a_slice_asked_for_is_taken_and_keeps_the_nice_level() {
        std::thread::spawn(|| {
            if slice().is_none() {
                eprintln!("this kernel reports no time slice; nothing to check");
                return;
            }
            let tid = rustix::thread::gettid();
            rustix::process::setpriority_process(Some(tid), 3).unwrap();
            set_slice(Duration::from_millis(3)).unwrap();
            assert_eq!(slice(), Some(Duration::from_millis(3)));
            assert_eq!(rustix::process::getpriority_process(Some(tid)).unwrap(), 3);
            assert_eq!(policy(), libc::SCHED_OTHER as u32);
            set_slice(Duration::from_millis(2)).unwrap();
            assert_eq!((slice(), policy()), (Some(Duration::from_millis(2)), libc::SCHED_OTHER as u32));
            set_slice(IPC_SLICE).unwrap();
            assert_eq!(slice(), Some(IPC_SLICE));
            // The IPC thread starts the workers and the cleanup thread after asking:
            // they must not inherit its short slice.
            let child = std::thread::spawn(slice).join().unwrap();
            assert!(child.is_some_and(|c| c != IPC_SLICE), "{child:?}");
        })
        .join()
        .unwrap();
    }
}
