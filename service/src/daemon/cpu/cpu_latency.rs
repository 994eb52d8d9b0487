//! How fast an idle core wakes while traffic is steady: a CPU latency request
//! (Linux PM QoS, `/dev/cpu_dma_latency`) held only then, so that a cheap request
//! after a short pause is not charged an idle core's wake-up.
//!
//! A request that finds the IPC thread asleep wakes it on a core that is idle, and
//! an idle core sleeps in a power state it takes time to leave (on a virtual
//! machine the halt goes through the host; on bare metal, a deep C-state). At 0 µs
//! the idle loop polls instead and a wake-up needs no interrupt at all
//! (`bench/RESULTS.md`, "What a wake-up costs"). Polling idle cores cost power, so
//! the request is held only while requests arrive steadily (when the IPC thread
//! polls anyway) and released [`CpuLatency::RELEASE_AFTER`] after the last one. The
//! kernel drops it when the file closes, so a daemon that dies leaves nothing behind.

use std::io::Write;
use std::path::Path;
use std::time::{Duration, Instant};
use tracing::{debug, info};

/// The CPU latency request of the daemon.
#[derive(Debug)]
pub(crate) struct CpuLatency {
    /// The open request (`None`: off, or the system refused it).
    file: Option<std::fs::File>,
    /// The latency asked for while held, µs (at most `NONE_US`).
    target_us: i32,
    held: bool,
    /// Whether the first hold was logged.
    logged: bool,
}

impl CpuLatency {
    /// The kernel's device for CPU latency requests.
    pub(crate) const DEVICE: &'static str = "/dev/cpu_dma_latency";

    /// How long after the last request the hold ends: longer than any gap of
    /// steady traffic (at 500/s a Poisson gap passes 50 ms once in 10¹⁰).
    pub(crate) const RELEASE_AFTER: Duration = Duration::from_millis(50);

    /// The kernel's value for "no constraint" (`PM_QOS_CPU_LATENCY_DEFAULT_VALUE`,
    /// 2 000 s): what a released request says.
    const NONE_US: i32 = 2_000_000_000;

    /// Opens a request at `device` for `target_us` (`None`: off). The request asks
    /// for nothing until [`hold`](Self::hold). Where it may not be opened (it needs
    /// root), says so once and works without it.
    pub(crate) fn open(target_us: Option<u32>, device: &Path) -> CpuLatency {
        let target_us = target_us.map_or(Self::NONE_US, |us| i32::try_from(us).unwrap_or(Self::NONE_US));
        let mut me = CpuLatency { file: None, target_us, held: false, logged: false };
        if target_us == Self::NONE_US {
            return me;
        }
        match std::fs::OpenOptions::new().write(true).open(device) {
            // Ask for nothing yet; a device that takes no value is dropped here.
            Ok(f) => {
                me.file = Some(f);
                me.write(Self::NONE_US);
            }
            Err(e) => info!(
                "cannot open {} ({e}): idle cores wake as the kernel decides (tens of µs more for a request after a pause); it needs root (see docs/daemon.md, Priorities)",
                device.display()
            ),
        }
        me
    }

    /// Whether the request is held now.
    #[cfg(test)]
    pub(crate) fn is_held(&self) -> bool {
        self.held
    }

    /// Traffic is steady: ask that idle cores wake within the target.
    pub(crate) fn hold(&mut self) {
        if self.held {
            return;
        }
        if self.write(self.target_us) {
            self.held = true;
            if self.logged {
                debug!(target_us = self.target_us, "CPU latency request held: traffic is steady");
            } else {
                self.logged = true;
                info!(
                    target_us = self.target_us,
                    "traffic is steady: idle cores are asked to wake within {} µs (PM QoS) until {:?} without requests; `scheduling.cpu_latency_us = \"off\"` turns this off",
                    self.target_us,
                    Self::RELEASE_AFTER
                );
            }
        }
    }

    /// Ends the hold if the last request came [`RELEASE_AFTER`](Self::RELEASE_AFTER)
    /// or longer before `now`; else, how long until it would.
    pub(crate) fn release_if_quiet(&mut self, last_request: Instant, now: Instant) -> Option<Duration> {
        if !self.held {
            return None;
        }
        let quiet = now.saturating_duration_since(last_request);
        if quiet < Self::RELEASE_AFTER {
            return Some(Self::RELEASE_AFTER - quiet);
        }
        if self.write(Self::NONE_US) {
            self.held = false;
            debug!("CPU latency request released: no request for {quiet:?}");
        }
        None
    }

    /// Writes `value` (µs) to the request; on failure drops it for good.
    fn write(&mut self, value: i32) -> bool {
        let Some(f) = self.file.as_mut() else { return false };
        match f.write_all(&value.to_ne_bytes()) {
            Ok(()) => true,
            Err(e) => {
                info!("the CPU latency request failed ({e}); idle cores wake as the kernel decides from now on");
                self.file = None;
                self.held = false;
                false
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use dyfos_process::scratch::Scratch;

    /// An empty file standing in for the device, in a directory of its own.
    fn fake_device(test: &str) -> (Scratch, std::path::PathBuf) {
        let dir = Scratch::new(&format!("cpu-latency-{test}"));
        let dev = dir.0.join("cpu_dma_latency");
        std::fs::write(&dev, b"").unwrap();
        (dir, dev)
    }

    /// The values the request was given, in order, from a file standing in for the
    /// device.
    fn written(path: &Path) -> Vec<i32> {
        std::fs::read(path).unwrap().chunks_exact(4).map(|c| i32::from_ne_bytes(c.try_into().unwrap())).collect()
    }

    #[test]
    fn the_request_is_held_once_and_released_after_a_quiet_time() {
        let (_dir, dev) = fake_device("held");
        let mut q = CpuLatency::open(Some(0), &dev);
        assert_eq!(written(&dev), [CpuLatency::NONE_US]);
        q.hold();
        q.hold();
        assert!(q.is_held());
        assert_eq!(written(&dev), [CpuLatency::NONE_US, 0]);
        let t = Instant::now();
        // Not quiet long enough: still held, and says how long until release.
        let left = q.release_if_quiet(t, t + Duration::from_millis(20));
        assert_eq!(left, Some(CpuLatency::RELEASE_AFTER - Duration::from_millis(20)));
        assert!(q.is_held());
        assert_eq!(q.release_if_quiet(t, t + CpuLatency::RELEASE_AFTER), None);
        assert!(!q.is_held());
        assert_eq!(written(&dev), [CpuLatency::NONE_US, 0, CpuLatency::NONE_US]);
        // Traffic again: held again, at the target asked for.
        q.hold();
        assert_eq!(written(&dev), [CpuLatency::NONE_US, 0, CpuLatency::NONE_US, 0]);
    }

    #[test]
    fn off_or_refused_it_asks_nothing() {
        let (dir, dev) = fake_device("off");
        let mut off = CpuLatency::open(None, &dev);
        off.hold();
        assert!(!off.is_held());
        assert!(written(&dev).is_empty());
        let mut refused = CpuLatency::open(Some(0), &dir.0.join("missing").join("device"));
        refused.hold();
        assert!(!refused.is_held());
    }
}
