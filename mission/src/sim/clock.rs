//! Simulated time, paced against the wall clock.

use std::time::{Duration, Instant};

/// Simulated seconds, paced so that they pass `scale` times faster than wall time,
/// or as fast as the computer allows (`scale = None`). The physics never reads the
/// wall clock: it advances in fixed ticks, so runs are reproducible at any pace.
#[derive(Debug, Clone)]
pub struct SimClock {
    scale: Option<f64>,
    origin: Instant,
    now: f64,
}

/// Longest single sleep, so that a stop request is noticed quickly.
const SLICE: Duration = Duration::from_millis(50);

impl SimClock {
    /// A clock at simulated time 0. `scale` must be positive when given.
    pub fn new(scale: Option<f64>) -> Self {
        debug_assert!(scale.is_none_or(|s| s > 0.0 && s.is_finite()));
        SimClock { scale, origin: Instant::now(), now: 0.0 }
    }

    /// The simulated time, s.
    pub fn now(&self) -> f64 {
        self.now
    }

    /// Simulated seconds per wall second (`None`: unpaced).
    pub fn scale(&self) -> Option<f64> {
        self.scale
    }

    /// Advances to simulated time `t` (never backwards), sleeping until the wall
    /// clock catches up. Returns `false`, early, when `stop()` turns true.
    pub fn advance_to(&mut self, t: f64, stop: &impl Fn() -> bool) -> bool {
        self.now = self.now.max(t);
        let Some(scale) = self.scale else {
            return !stop();
        };
        let due = self.origin + Duration::from_secs_f64(self.now / scale);
        loop {
            if stop() {
                return false;
            }
            let left = due.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return true;
            }
            std::thread::sleep(left.min(SLICE));
        }
    }

    /// Brings simulated time up to the wall clock, after waiting for a message
    /// (unpaced clocks do not move).
    pub fn catch_up(&mut self) {
        if let Some(scale) = self.scale {
            self.now = self.now.max(self.origin.elapsed().as_secs_f64() * scale);
        }
    }

    /// The wall time that `sim_seconds` take at this pace (zero when unpaced).
    pub fn wall(&self, sim_seconds: f64) -> Duration {
        match self.scale {
            Some(s) => Duration::from_secs_f64((sim_seconds / s).max(0.0)),
            None => Duration::ZERO,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unpaced_clock_jumps_and_paced_clock_sleeps() {
        let mut c = SimClock::new(None);
        assert!(c.advance_to(1000.0, &|| false));
        assert_eq!(c.now(), 1000.0);
        assert!(c.advance_to(5.0, &|| false));
        assert_eq!(c.now(), 1000.0, "never backwards");
        assert!(!c.advance_to(2000.0, &|| true));

        let mut p = SimClock::new(Some(100.0));
        let start = Instant::now();
        assert!(p.advance_to(2.0, &|| false)); // 20 ms of wall time
        assert!(start.elapsed() >= Duration::from_millis(19));
        assert_eq!(p.wall(1.0), Duration::from_millis(10));
    }
}
