//! How the daemon shares the CPU with its clients and the rest of the machine: the
//! whole policy, one file per mechanism.
//!
//! - **The IPC thread** ([`IpcPacing`], `pacing.rs`) sleeps at `SCHED_FIFO`
//!   ([`Scheduling::ipc_priority`]), so a request wakes it ahead of running
//!   searches, and polls for the next request at normal priority, for a window that
//!   grows to [`Scheduling::poll_max_us`] while traffic is steady and is zero while
//!   every worker searches or other work fills the cores (`dyfos_process::idle`).
//!   Real-time scheduling is per thread: the thread that created the daemon must
//!   spin and wait. Where the system refuses it, the IPC thread asks for a short
//!   time slice ([`IPC_SLICE`], `sched.rs`) and, on kernels that ignore slices, the
//!   workers run [`FALLBACK_WORKER_NICE`] nice levels lower ([`lower_priority`]).
//! - **Idle cores** are asked to poll while traffic is steady
//!   ([`Scheduling::cpu_latency_us`], `cpu_latency.rs`), so a request after a pause
//!   wakes the IPC thread in µs.
//! - **The workers** ask for a long slice ([`Scheduling::worker_slice_us`]), so any
//!   thread that wakes beside a search preempts it, and their searches make way at
//!   checkpoints ([`WorkerCheckpoint`], `checkpoint.rs`): they yield to a waiting
//!   thread while they have had most of their core ([`CoreShare`]) and stop while a
//!   starved client's query runs on their core.
//!
//! [`Scheduling::ipc_priority`]: super::Scheduling::ipc_priority
//! [`Scheduling::poll_max_us`]: super::Scheduling::poll_max_us
//! [`Scheduling::cpu_latency_us`]: super::Scheduling::cpu_latency_us
//! [`Scheduling::worker_slice_us`]: super::Scheduling::worker_slice_us

mod checkpoint;
mod cpu_latency;
mod pacing;
mod sched;

pub(crate) use checkpoint::{CoreShare, WorkerCheckpoint};
pub(crate) use pacing::IpcPacing;
pub use sched::{IPC_SLICE, IpcScheduling};

use std::time::Duration;
#[cfg(not(target_os = "linux"))]
use tracing::debug;
use tracing::warn;

/// Nice levels the workers drop when the IPC thread may neither run real-time nor
/// have a short time slice.
pub const FALLBACK_WORKER_NICE: u8 = 5;

/// Sets up the calling worker thread: its time slice (`slice`, zero keeps the
/// kernel's) and `nice` levels below the IPC thread.
pub(crate) fn prepare_worker_thread(slice: Duration, nice: u8) {
    if !slice.is_zero()
        && let Err(e) = sched::set_slice(slice)
    {
        warn!("cannot set a search worker's time slice to {slice:?} ({e}); it keeps the kernel's");
    }
    lower_priority(nice);
}

/// Lowers the calling thread's priority by `levels` nice levels (from the
/// process's, at most to 19). Lowering needs no privilege; a failure is logged and
/// the worker runs at the IPC thread's priority.
fn lower_priority(levels: u8) {
    if levels == 0 {
        return;
    }
    #[cfg(target_os = "linux")]
    {
        use rustix::process::{getpriority_process, setpriority_process};
        // On Linux, nice is per thread: `Some(tid)` names this thread only.
        let tid = rustix::thread::gettid();
        let nice = getpriority_process(Some(tid)).unwrap_or(0) + i32::from(levels);
        if let Err(e) = setpriority_process(Some(tid), nice.min(19)) {
            warn!("cannot lower the priority of a search worker ({e}); it runs at the daemon's priority");
        }
    }
    #[cfg(not(target_os = "linux"))]
    debug!("worker priority is left as is on this system");
}
