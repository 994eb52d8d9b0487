//! The evaluation's listener: ground truth, estimates and measurements of one
//! mission, as they are published.

use super::ApeStats;
use crate::mission::topics::{Inbox, MAX_BUFFER, Outbox, TopicOpenError, Topics, TopicsConfig};
use crate::rover::{MISSION, SIM};
use dyfos_shared::wire::mission::{
    ESTIMATE_TOPIC, EVALUATION_TOPIC, Estimate, EstimateMsg, EvaluationAckMsg, MEASUREMENT_TOPIC, Measurement,
    MeasurementMsg, Phase, TRUTH_TOPIC, TrueState, TrueStateMsg,
};
use std::collections::BTreeMap;
use std::time::Duration;

/// Everything recorded of one mission.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct MissionTrace {
    /// Ground-truth samples, in arrival order.
    pub truth: Vec<TrueState>,
    /// The rover's estimates, in arrival order.
    pub estimates: Vec<Estimate>,
    /// The viewer's measurements (and non-measurements), in arrival order, one per
    /// step (repeats are dropped).
    pub measurements: Vec<Measurement>,
    /// Messages that failed to decode.
    pub malformed: usize,
}

impl MissionTrace {
    /// Truth and estimate of the same instant, by sample number (samples missing on
    /// either side are left out).
    pub fn pairs(&self) -> Vec<(TrueState, Estimate)> {
        let truth: BTreeMap<u64, TrueState> = self.truth.iter().map(|t| (t.sample, *t)).collect();
        let mut pairs: Vec<_> = self.estimates.iter().filter_map(|e| truth.get(&e.sample).map(|t| (*t, *e))).collect();
        pairs.sort_by_key(|(t, _)| t.sample);
        pairs
    }

    /// The absolute position error of every paired sample, m.
    pub fn errors(&self) -> Vec<f64> {
        self.pairs().iter().map(|(t, e)| (e.belief.mean.x - t.pose[0]).hypot(e.belief.mean.y - t.pose[1])).collect()
    }

    /// APE statistics of the samples taken right after an update: how good the
    /// fused measurements were, without the drift between rendezvous.
    pub fn ape_after_updates(&self) -> Option<ApeStats> {
        let errors: Vec<f64> = self
            .pairs()
            .iter()
            .filter(|(_, e)| e.updated)
            .map(|(t, e)| (e.belief.mean.x - t.pose[0]).hypot(e.belief.mean.y - t.pose[1]))
            .collect();
        ApeStats::from_errors(&errors)
    }

    /// APE statistics over every paired sample.
    pub fn ape(&self) -> Option<ApeStats> {
        ApeStats::from_errors(&self.errors())
    }

    /// Whether the rover reported reaching its goal.
    pub fn finished(&self) -> bool {
        self.estimates.iter().any(|e| e.phase == Phase::Finished)
    }

    /// The waypoint the rover is at or heading for, as last reported.
    pub fn step(&self) -> u32 {
        self.estimates.last().map_or(0, |e| e.step)
    }

    /// How many estimates follow an update with a measurement.
    pub fn updates(&self) -> usize {
        self.estimates.iter().filter(|e| e.updated).count()
    }
}

/// Subscribes to a mission's ground truth, estimates and measurements. Open it
/// before the rover starts: what was published before is not replayed. Once it
/// holds the rover's final sample it acknowledges it, which lets the rover exit.
pub struct Recorder {
    _topics: Topics,
    truth: Inbox<TrueStateMsg>,
    estimate: Inbox<EstimateMsg>,
    measurement: Inbox<MeasurementMsg>,
    ack: Outbox<EvaluationAckMsg>,
    acked: bool,
    trace: MissionTrace,
}

impl std::fmt::Debug for Recorder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Recorder").field("samples", &self.trace.estimates.len()).finish()
    }
}

impl Recorder {
    /// Subscribes to the mission `config.mission`.
    pub fn open(config: &TopicsConfig) -> Result<Self, TopicOpenError> {
        let topics = Topics::open(config)?;
        Ok(Recorder {
            truth: topics.inbox(SIM, TRUTH_TOPIC, MAX_BUFFER)?,
            estimate: topics.inbox(MISSION, ESTIMATE_TOPIC, MAX_BUFFER)?,
            measurement: topics.inbox(MISSION, MEASUREMENT_TOPIC, 256)?,
            ack: topics.outbox(MISSION, EVALUATION_TOPIC)?,
            acked: false,
            _topics: topics,
            trace: MissionTrace::default(),
        })
    }

    /// Takes in everything published since the last poll; returns how many
    /// messages arrived.
    pub fn poll(&mut self) -> usize {
        let mut n = 0;
        for m in self.truth.drain() {
            n += 1;
            match TrueState::try_from(&m) {
                Ok(t) => self.trace.truth.push(t),
                Err(_) => self.trace.malformed += 1,
            }
        }
        for m in self.estimate.drain() {
            n += 1;
            match Estimate::try_from(&m) {
                Ok(e) => self.trace.estimates.push(e),
                Err(_) => self.trace.malformed += 1,
            }
        }
        for m in self.measurement.drain() {
            n += 1;
            match Measurement::try_from(&m) {
                // A measurement is re-sent until the rover acknowledges it: keep the
                // first of each step.
                Ok(x) if self.trace.measurements.iter().any(|m| m.step == x.step) => {}
                Ok(x) => self.trace.measurements.push(x),
                Err(_) => self.trace.malformed += 1,
            }
        }
        if !self.acked
            && let Some(last) = self.trace.estimates.iter().find(|e| e.phase == Phase::Finished)
            && self.trace.truth.iter().any(|t| t.sample == last.sample)
        {
            self.acked = true;
            if let Err(e) = self.ack.send(EvaluationAckMsg { sample: last.sample }) {
                tracing::warn!("cannot acknowledge the rover's last sample: {e}");
            }
        }
        n
    }

    /// Sleeps until the rover publishes an estimate, at most `timeout`.
    pub fn wait(&self, timeout: Duration) {
        self.estimate.wait(timeout);
    }

    /// What has been recorded so far.
    pub fn trace(&self) -> &MissionTrace {
        &self.trace
    }

    /// Takes in what is left and returns the whole trace.
    pub fn finish(mut self) -> MissionTrace {
        self.poll();
        self.trace
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use dyfos_shared::posterior::Belief;

    #[test]
    fn samples_pair_by_number_and_updates_are_singled_out() {
        let mut trace = MissionTrace::default();
        let b = Belief::new([0.0; 3], [[0.01, 0.0, 0.0], [0.0, 0.01, 0.0], [0.0, 0.0, 0.01]]).unwrap();
        for i in 0..4u64 {
            // Truth for samples 0..=2 only, arriving out of order.
            if i < 3 {
                let pose = [i as f64, 0.0, 0.0];
                trace.truth.insert(0, TrueState { sample: 2 - i, step: 1, phase: Phase::Driving, sim_time: 0.0, pose });
            }
            let belief = Belief { mean: nalgebra::Vector3::new(i as f64, 0.1 * i as f64, 0.0), ..b };
            let phase = if i == 3 { Phase::Finished } else { Phase::Driving };
            trace.estimates.push(Estimate { sample: i, step: 1, phase, updated: i == 1, sim_time: 0.0, belief });
        }
        // Truth sample k has x = 2 − k; estimate k has (k, 0.1k).
        let pairs = trace.pairs();
        assert_eq!(pairs.iter().map(|(t, _)| t.sample).collect::<Vec<_>>(), [0, 1, 2]);
        let errors = trace.errors();
        assert!((errors[0] - 2.0).abs() < 1e-12 && (errors[1] - 0.1).abs() < 1e-12);
        assert!((errors[2] - 2.0f64.hypot(0.2)).abs() < 1e-12);
        assert_eq!(trace.ape().unwrap().count, 3);
        let after = trace.ape_after_updates().unwrap();
        assert_eq!(after.count, 1);
        assert!((after.max - 0.1).abs() < 1e-12);
        assert!(trace.finished() && trace.updates() == 1 && trace.step() == 1);
    }
}
