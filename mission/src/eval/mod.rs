//! Evaluation of a mission: record the ground truth and the rover's estimate from
//! their topics, compute the absolute position error (APE, paper Table I) and draw
//! the run (paper Fig. 5); keep it as an MCAP file that Foxglove opens as is or
//! that ROS 2 plays as a bag ([`McapMission`], [`McapProfile`]; modules
//! [`foxglove`] and [`ros2`]).
//!
//! The APE is taken over every recorded sample — the estimate and the truth with
//! the same sample number, i.e. the same instant — as `|est_xy − true_xy|`, like
//! `evo_ape` with translation only. Samples come every 5 control ticks while
//! driving (4 Hz of simulated time), at each arrival and after each update, so the
//! error between rendezvous counts as much as the error at them.
//!
//! ```
//! use dyfos_mission::eval::ApeStats;
//!
//! let ape = ApeStats::from_errors(&[0.03, 0.04, 0.05, 0.12]).unwrap();
//! assert!((ape.mean - 0.06).abs() < 1e-12);
//! assert!((ape.median - 0.045).abs() < 1e-12);
//! assert_eq!(ape.max, 0.12);
//! ```

pub mod foxglove;
pub mod mission_mcap;
mod recorder;
pub mod ros2;
mod svg;

pub use mission_mcap::{AnswerRecord, McapMission, McapProfile, McapWriteError};
pub use recorder::{MissionTrace, Recorder};
pub use svg::render_svg;

/// Statistics of the absolute position error, m.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct ApeStats {
    /// Root mean square.
    pub rmse: f64,
    /// Median.
    pub median: f64,
    /// Mean.
    pub mean: f64,
    /// Population standard deviation.
    pub std: f64,
    /// Largest.
    pub max: f64,
    /// Number of samples.
    pub count: usize,
}

impl ApeStats {
    /// The statistics of `errors` (m); `None` for no samples.
    pub fn from_errors(errors: &[f64]) -> Option<Self> {
        if errors.is_empty() {
            return None;
        }
        let n = errors.len() as f64;
        let mean = errors.iter().sum::<f64>() / n;
        let rmse = (errors.iter().map(|e| e * e).sum::<f64>() / n).sqrt();
        let std = (errors.iter().map(|e| (e - mean).powi(2)).sum::<f64>() / n).sqrt();
        let mut sorted = errors.to_vec();
        sorted.sort_by(f64::total_cmp);
        let mid = sorted.len() / 2;
        let median = if sorted.len().is_multiple_of(2) { (sorted[mid - 1] + sorted[mid]) / 2.0 } else { sorted[mid] };
        Some(ApeStats { rmse, median, mean, std, max: sorted[sorted.len() - 1], count: errors.len() })
    }

    /// `[rmse, median, mean, std, max]` in centimetres, the rows of paper Table I.
    pub fn centimetres(&self) -> [f64; 5] {
        [self.rmse, self.median, self.mean, self.std, self.max].map(|v| v * 100.0)
    }
}

/// Mean and population standard deviation of `values`.
pub fn mean_std(values: &[f64]) -> (f64, f64) {
    if values.is_empty() {
        return (f64::NAN, f64::NAN);
    }
    let n = values.len() as f64;
    let mean = values.iter().sum::<f64>() / n;
    (mean, (values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n).sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn statistics_of_a_known_sample() {
        let a = ApeStats::from_errors(&[0.1, 0.2, 0.3]).unwrap();
        assert!((a.rmse - (0.14f64 / 3.0).sqrt()).abs() < 1e-12);
        assert_eq!(a.median, 0.2);
        assert!((a.std - (0.02f64 / 3.0).sqrt()).abs() < 1e-12);
        assert_eq!(a.count, 3);
        assert!(ApeStats::from_errors(&[]).is_none());
        assert_eq!(mean_std(&[1.0, 3.0]), (2.0, 1.0));
    }
}
