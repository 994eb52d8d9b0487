//! A child process that cannot outlive its owner: killed (SIGKILL) and reaped when
//! dropped, unless it already exited. What tests, benchmarks and the demo hold
//! their daemons and robots in.
//!
//! ```
//! use dyfos_process::child::KillOnDrop;
//! use std::time::Duration;
//!
//! let mut sleeper = KillOnDrop::spawn(std::process::Command::new("sleep").arg("60")).unwrap();
//! assert!(sleeper.is_running());
//! assert!(sleeper.terminate(Duration::from_secs(5)).is_some_and(|s| !s.success()));
//! assert!(!sleeper.is_running());
//! ```

use std::process::{Child, Command, ExitStatus};
use std::time::{Duration, Instant};

/// A child process, killed and reaped on drop. Once it is seen to exit (by
/// [`try_wait`](Self::try_wait), [`wait_timeout`](Self::wait_timeout),
/// [`terminate`](Self::terminate) or [`kill`](Self::kill)) it is reaped and
/// forgotten: its pid is never signalled again, as it may belong to another process.
#[derive(Debug)]
pub struct KillOnDrop(Option<Child>);

impl KillOnDrop {
    /// Takes ownership of `child`.
    pub fn new(child: Child) -> Self {
        KillOnDrop(Some(child))
    }

    /// Spawns `command`.
    pub fn spawn(command: &mut Command) -> std::io::Result<Self> {
        command.spawn().map(KillOnDrop::new)
    }

    /// The process id (0 once it exited).
    pub fn id(&self) -> u32 {
        self.0.as_ref().map_or(0, Child::id)
    }

    /// The child, until it exited (for its pipes).
    pub fn child_mut(&mut self) -> Option<&mut Child> {
        self.0.as_mut()
    }

    /// Its exit status if it has exited (reaped then), `None` while it runs.
    pub fn try_wait(&mut self) -> Option<ExitStatus> {
        let status = self.0.as_mut().and_then(|c| c.try_wait().ok().flatten())?;
        self.0 = None;
        Some(status)
    }

    /// Whether it has not exited.
    pub fn is_running(&mut self) -> bool {
        self.0.is_some() && self.try_wait().is_none()
    }

    /// Waits up to `limit` for it to exit; `None` if it still runs (or was already reaped).
    pub fn wait_timeout(&mut self, limit: Duration) -> Option<ExitStatus> {
        let start = Instant::now();
        loop {
            self.0.as_ref()?;
            if let Some(status) = self.try_wait() {
                return Some(status);
            }
            if start.elapsed() >= limit {
                return None;
            }
            std::thread::sleep(Duration::from_millis(5));
        }
    }

    /// SIGTERM, then up to `grace` for it to exit, then SIGKILL. The exit status
    /// if it exited within `grace`, `None` if it had to be killed (or was already reaped).
    pub fn terminate(&mut self, grace: Duration) -> Option<ExitStatus> {
        crate::shutdown::terminate(self.0.as_ref()?.id());
        let status = self.wait_timeout(grace);
        if status.is_none() {
            self.kill();
        }
        status
    }

    /// SIGKILL, and reap.
    pub fn kill(&mut self) {
        if let Some(mut c) = self.0.take() {
            let _ = c.kill();
            let _ = c.wait();
        }
    }
}

impl Drop for KillOnDrop {
    fn drop(&mut self) {
        self.kill();
    }
}
