//! Rover ↔ viewer payloads of the simulated mission (SPEC §9, paper Fig. 2).
//!
//! Four publish-subscribe topics under the service prefix and a mission name
//! ([`topic_name`]):
//!
//! | topic | from → to | payload |
//! |---|---|---|
//! | `mission/<name>/rendezvous` | rover → viewer | [`RendezvousStateMsg`]: the a priori belief at the next waypoint, or "finished" |
//! | `mission/<name>/measurement` | viewer → rover (and evaluation) | [`MeasurementMsg`]: the measured position and R, or why there is none |
//! | `mission/<name>/estimate` | rover → evaluation | [`EstimateMsg`]: the rover's EKF belief over time |
//! | `sim/<name>/truth` | simulator → simulated camera and evaluation only | [`TrueStateMsg`]: the rover's true pose |
//! | `mission/<name>/evaluation` | evaluation → rover | [`EvaluationAckMsg`]: "I have every sample up to this one" |
//! | `mission/<name>/rover_presence` | rover → viewer | [`PresenceMsg`]: the rover's heartbeat |
//! | `mission/<name>/viewer_presence` | viewer → rover | [`PresenceMsg`]: the viewer's heartbeat |
//! | `mission/<name>/rover_ack` | rover → viewer | [`AckMsg`]: "I have your measurement of step k" |
//! | `mission/<name>/viewer_ack` | viewer → rover | [`AckMsg`]: "I have your rendezvous (or finish) of step k" |
//!
//! Presence is a heartbeat, not a count of attached ports (a cross-host link's
//! ports count too): each process publishes a [`PresenceMsg`] every
//! [`HEARTBEAT_PERIOD`], and a peer silent for longer than its presence timeout is
//! gone. Whatever one side waits for (a rendezvous, the finish, a measurement) is
//! re-sent every [`RESEND_INTERVAL`] until the other side acknowledges it by
//! (step, kind) with an [`AckMsg`]; receivers are idempotent by step, so a
//! duplicate is acknowledged again and otherwise ignored.
//!
//! A publisher's samples reach a subscriber only if the subscriber connected while
//! the publisher was alive; a rover that finishes in milliseconds could exit before
//! a busy evaluation ever connected. So a rover with estimate readers waits (a
//! bounded time) at the end for their acknowledgement of its last sample.
//!
//! Payloads are `#[repr(C)]`, plain numbers only, with a stable `#[type_name]` so
//! that other languages can join. Tags and codes are integers and every message is
//! decoded with `TryFrom` into a validated type before use: a peer can write any bits.
//!
//! ```
//! use dyfos_shared::wire::mission::{Phase, TrueState, TrueStateMsg};
//!
//! let msg = TrueStateMsg::from(&TrueState { sample: 7, step: 2, phase: Phase::AtWaypoint, sim_time: 3.5, pose: [1.0, 2.0, 0.5] });
//! assert_eq!(msg.phase, 1);
//! assert_eq!(TrueState::try_from(&msg).unwrap().pose, [1.0, 2.0, 0.5]);
//! let bad = TrueStateMsg { phase: 9, ..msg };
//! assert!(TrueState::try_from(&bad).is_err());
//! ```
#![allow(unsafe_code)] // SAFETY: only `#[derive(ZeroCopySend)]` below, on `#[repr(C)]` structs of plain numbers.

use crate::limits::MAX_COORDINATE;
use crate::math::{Cov2, CovarianceError};
use crate::posterior::{Belief, BeliefError};
use iceoryx2::prelude::ZeroCopySend;

/// The full service name of a mission topic: `<prefix><group>/<mission>/<topic>`,
/// e.g. `dyfos/mission/demo-dyfos/rendezvous`. `group` is `mission` for the robots'
/// own topics and `sim` for simulation-only ones (ground truth).
pub fn topic_name(prefix: &str, group: &str, mission: &str, topic: &str) -> String {
    format!("{prefix}{group}/{mission}/{topic}")
}

/// Topic of [`RendezvousStateMsg`] (group `mission`).
pub const RENDEZVOUS_TOPIC: &str = "rendezvous";
/// Topic of [`MeasurementMsg`] (group `mission`).
pub const MEASUREMENT_TOPIC: &str = "measurement";
/// Topic of [`EstimateMsg`] (group `mission`).
pub const ESTIMATE_TOPIC: &str = "estimate";
/// Topic of [`TrueStateMsg`] (group `sim`): simulation only.
pub const TRUTH_TOPIC: &str = "truth";
/// Topic of [`EvaluationAckMsg`] (group `mission`).
pub const EVALUATION_TOPIC: &str = "evaluation";

/// Topic of the rover's [`PresenceMsg`] heartbeats (group `mission`).
pub const ROVER_PRESENCE_TOPIC: &str = "rover_presence";
/// Topic of the viewer's [`PresenceMsg`] heartbeats (group `mission`).
pub const VIEWER_PRESENCE_TOPIC: &str = "viewer_presence";
/// Topic of the rover's [`AckMsg`]s (of measurements; group `mission`).
pub const ROVER_ACK_TOPIC: &str = "rover_ack";
/// Topic of the viewer's [`AckMsg`]s (of rendezvous states; group `mission`).
pub const VIEWER_ACK_TOPIC: &str = "viewer_ack";

/// How often each mission process publishes its heartbeat.
pub const HEARTBEAT_PERIOD: std::time::Duration = std::time::Duration::from_millis(100);
/// How often an unacknowledged rendezvous, finish or measurement is sent again.
pub const RESEND_INTERVAL: std::time::Duration = std::time::Duration::from_millis(250);

/// A heartbeat: process `instance` (random per process start) is alive and at
/// waypoint `step`. Any value is acceptable.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ZeroCopySend, serde::Serialize, serde::Deserialize)]
#[type_name("dyfos::mission::Presence")]
#[repr(C)]
pub struct PresenceMsg {
    /// Random number drawn at the process's start: a new one means a restarted peer.
    pub instance: u64,
    /// The waypoint the process is at or working on (0 before the first).
    pub step: u32,
    /// Explicit padding (always 0).
    pub reserved: u32,
}

/// What an [`AckMsg`] acknowledges.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum AckKind {
    /// The rendezvous state of `step` (viewer → rover).
    Rendezvous,
    /// The rover's "finished" (viewer → rover).
    Finished,
    /// The measurement of `step` (rover → viewer).
    Measurement,
}

impl AckKind {
    /// The wire code.
    pub fn code(self) -> u32 {
        match self {
            AckKind::Rendezvous => 0,
            AckKind::Finished => 1,
            AckKind::Measurement => 2,
        }
    }
}

/// Wire form of [`Ack`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, ZeroCopySend, serde::Serialize, serde::Deserialize)]
#[type_name("dyfos::mission::Ack")]
#[repr(C)]
pub struct AckMsg {
    /// The acknowledging process's [`PresenceMsg::instance`].
    pub instance: u64,
    /// The step acknowledged.
    pub step: u32,
    /// [`AckKind`] code.
    pub kind: u32,
}

/// "Process `instance` holds your message of `kind` for `step`."
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Ack {
    /// The acknowledging process.
    pub instance: u64,
    /// The step.
    pub step: u32,
    /// What is acknowledged.
    pub kind: AckKind,
}

impl From<&Ack> for AckMsg {
    fn from(a: &Ack) -> Self {
        AckMsg { instance: a.instance, step: a.step, kind: a.kind.code() }
    }
}

impl TryFrom<&AckMsg> for Ack {
    type Error = MissionDecodeError;
    fn try_from(m: &AckMsg) -> Result<Self, Self::Error> {
        let kind = match m.kind {
            0 => AckKind::Rendezvous,
            1 => AckKind::Finished,
            2 => AckKind::Measurement,
            value => return Err(MissionDecodeError::UnknownCode { field: "kind", value }),
        };
        Ok(Ack { instance: m.instance, step: m.step, kind })
    }
}

/// The evaluation's acknowledgement: it holds every truth and estimate sample up
/// to and including `sample`. Any value is acceptable, so there is nothing to decode.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ZeroCopySend, serde::Serialize, serde::Deserialize)]
#[type_name("dyfos::mission::EvaluationAck")]
#[repr(C)]
pub struct EvaluationAckMsg {
    /// The last sample number received.
    pub sample: u64,
}

/// A message that cannot be used, and why.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MissionDecodeError {
    /// An integer tag or code outside its set.
    #[error("{field} = {value} is not a known code")]
    UnknownCode {
        /// The field.
        field: &'static str,
        /// The value found.
        value: u32,
    },
    /// A number that is NaN, infinite or absurdly large.
    #[error("{field} = {value} must be a finite number within ±1e6")]
    NotFinite {
        /// The field.
        field: &'static str,
        /// The value found.
        value: f64,
    },
    /// The belief is not valid.
    #[error("belief: {0}")]
    Belief(#[from] BeliefError),
    /// The measurement covariance is not SPD.
    #[error("measurement covariance R: {0}")]
    Covariance(#[from] CovarianceError),
}

fn finite(field: &'static str, values: &[f64]) -> Result<(), MissionDecodeError> {
    match values.iter().find(|v| !(v.is_finite() && v.abs() <= MAX_COORDINATE)) {
        Some(value) => Err(MissionDecodeError::NotFinite { field, value: *value }),
        None => Ok(()),
    }
}

/// Where the rover is in its mission loop.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Phase {
    /// Driving towards waypoint `step`.
    Driving,
    /// Standing at waypoint `step`, waiting for the measurement.
    AtWaypoint,
    /// At the goal; the mission is over.
    Finished,
}

impl Phase {
    fn code(self) -> u32 {
        match self {
            Phase::Driving => 0,
            Phase::AtWaypoint => 1,
            Phase::Finished => 2,
        }
    }
}

impl TryFrom<u32> for Phase {
    type Error = MissionDecodeError;
    fn try_from(value: u32) -> Result<Self, Self::Error> {
        match value {
            0 => Ok(Phase::Driving),
            1 => Ok(Phase::AtWaypoint),
            2 => Ok(Phase::Finished),
            _ => Err(MissionDecodeError::UnknownCode { field: "phase", value }),
        }
    }
}

// ---------------------------------------------------------------------------------
// Rendezvous state: rover → viewer.

/// Wire form of [`RendezvousState`].
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend, serde::Serialize, serde::Deserialize)]
#[type_name("dyfos::mission::RendezvousState")]
#[repr(C)]
pub struct RendezvousStateMsg {
    /// Waypoint index the rover is heading for (1-based; 0 is the start).
    pub step: u32,
    /// 0 = rendezvous at `step`, 1 = mission finished (the rover is at the goal).
    pub kind: u32,
    /// Simulated time of sending, s.
    pub sim_time: f64,
    /// Belief mean (x, y, θ) at the rendezvous.
    pub mean: [f64; 3],
    /// Belief covariance Σ⁻, rows.
    pub cov: [[f64; 3]; 3],
}

/// What the rover tells the viewer.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum RendezvousState {
    /// "I will be at waypoint `step` with this a priori belief": find a pose and measure me.
    Rendezvous {
        /// Waypoint index (1-based).
        step: u32,
        /// Simulated time of sending, s.
        sim_time: f64,
        /// The rendezvous belief, propagated to the waypoint.
        belief: Belief,
    },
    /// The rover reached its goal after `step` waypoints; the viewer may stop.
    Finished {
        /// The last waypoint index.
        step: u32,
        /// Simulated time of sending, s.
        sim_time: f64,
    },
}

impl From<&RendezvousState> for RendezvousStateMsg {
    fn from(s: &RendezvousState) -> Self {
        match s {
            RendezvousState::Rendezvous { step, sim_time, belief } => RendezvousStateMsg {
                step: *step,
                kind: 0,
                sim_time: *sim_time,
                mean: belief.mean.into(),
                cov: belief.cov.to_rows(),
            },
            RendezvousState::Finished { step, sim_time } => {
                RendezvousStateMsg { step: *step, kind: 1, sim_time: *sim_time, mean: [0.0; 3], cov: [[0.0; 3]; 3] }
            }
        }
    }
}

impl TryFrom<&RendezvousStateMsg> for RendezvousState {
    type Error = MissionDecodeError;
    fn try_from(m: &RendezvousStateMsg) -> Result<Self, Self::Error> {
        finite("sim_time", &[m.sim_time])?;
        match m.kind {
            0 => Ok(RendezvousState::Rendezvous {
                step: m.step,
                sim_time: m.sim_time,
                belief: Belief::new(m.mean, m.cov)?,
            }),
            1 => Ok(RendezvousState::Finished { step: m.step, sim_time: m.sim_time }),
            value => Err(MissionDecodeError::UnknownCode { field: "kind", value }),
        }
    }
}

// ---------------------------------------------------------------------------------
// Measurement: viewer → rover.

/// Why the viewer has no measurement for a step.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum NoMeasurement {
    /// The rover is outside the camera's field of view.
    OutOfView,
    /// The rover is outside the detection range [ρ_min, ρ_max].
    OutOfRange,
    /// An obstacle blocks the line of sight to the marker.
    Occluded,
    /// The daemon found no feasible sensor pose for the rendezvous belief.
    NoFeasiblePose,
    /// The daemon could not be asked (down, timed out, or refused the request).
    DaemonUnavailable,
    /// The rover had left the waypoint before the viewer could look.
    RoverLeft,
}

impl NoMeasurement {
    fn code(self) -> u32 {
        match self {
            NoMeasurement::OutOfView => 1,
            NoMeasurement::OutOfRange => 2,
            NoMeasurement::Occluded => 3,
            NoMeasurement::NoFeasiblePose => 4,
            NoMeasurement::DaemonUnavailable => 5,
            NoMeasurement::RoverLeft => 6,
        }
    }

    /// A short snake_case name for logs.
    pub fn name(self) -> &'static str {
        match self {
            NoMeasurement::OutOfView => "out_of_view",
            NoMeasurement::OutOfRange => "out_of_range",
            NoMeasurement::Occluded => "occluded",
            NoMeasurement::NoFeasiblePose => "no_feasible_pose",
            NoMeasurement::DaemonUnavailable => "daemon_unavailable",
            NoMeasurement::RoverLeft => "rover_left",
        }
    }
}

/// Wire form of [`Measurement`].
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend, serde::Serialize, serde::Deserialize)]
#[type_name("dyfos::mission::Measurement")]
#[repr(C)]
pub struct MeasurementMsg {
    /// The waypoint index this answers.
    pub step: u32,
    /// 0 = observed; otherwise the [`NoMeasurement`] code (1..=6).
    pub status: u32,
    /// Simulated time of the observation, s.
    pub sim_time: f64,
    /// Measured rover (x, y), m (status 0 only).
    pub position: [f64; 2],
    /// Measurement covariance R, rows, m² (status 0 only).
    pub r: [[f64; 2]; 2],
    /// 1 when `viewer_position`/`viewer_yaw` hold the pose the viewer observed from.
    pub has_viewer_pose: u32,
    /// Viewer position p_v, m.
    pub viewer_position: [f64; 3],
    /// Viewer yaw ψ_v, rad.
    pub viewer_yaw: f64,
    /// The daemon's predicted cost E = ln det Σ⁺ for the pose (NaN when none).
    pub predicted_cost: f64,
}

/// The viewer's pose when it observed.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ViewerPose {
    /// Position p_v, m.
    pub position: [f64; 3],
    /// Yaw ψ_v, rad.
    pub yaw: f64,
}

/// What the viewer saw at one rendezvous.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Observation {
    /// The rover was seen: its measured (x, y) and the noise covariance R.
    Observed {
        /// Measured (x, y), m.
        position: [f64; 2],
        /// R, m².
        r: Cov2,
    },
    /// No measurement, and why.
    NotObserved(NoMeasurement),
}

/// The viewer's answer to one rendezvous state.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Measurement {
    /// The waypoint index this answers.
    pub step: u32,
    /// Simulated time of the observation, s.
    pub sim_time: f64,
    /// The measurement or why there is none.
    pub observation: Observation,
    /// Where the viewer was, if it got to a pose.
    pub viewer: Option<ViewerPose>,
    /// The daemon's predicted E for the pose, if it answered.
    pub predicted_cost: Option<f64>,
}

impl From<&Measurement> for MeasurementMsg {
    fn from(m: &Measurement) -> Self {
        let (status, position, r) = match &m.observation {
            Observation::Observed { position, r } => (0, *position, r.to_rows()),
            Observation::NotObserved(why) => (why.code(), [0.0; 2], [[0.0; 2]; 2]),
        };
        let (has_viewer_pose, viewer_position, viewer_yaw) = match m.viewer {
            Some(v) => (1, v.position, v.yaw),
            None => (0, [0.0; 3], 0.0),
        };
        MeasurementMsg {
            step: m.step,
            status,
            sim_time: m.sim_time,
            position,
            r,
            has_viewer_pose,
            viewer_position,
            viewer_yaw,
            predicted_cost: m.predicted_cost.unwrap_or(f64::NAN),
        }
    }
}

impl TryFrom<&MeasurementMsg> for Measurement {
    type Error = MissionDecodeError;
    fn try_from(m: &MeasurementMsg) -> Result<Self, Self::Error> {
        finite("sim_time", &[m.sim_time])?;
        let observation = match m.status {
            0 => {
                finite("position", &m.position)?;
                Observation::Observed { position: m.position, r: Cov2::from_rows(&m.r)? }
            }
            1 => Observation::NotObserved(NoMeasurement::OutOfView),
            2 => Observation::NotObserved(NoMeasurement::OutOfRange),
            3 => Observation::NotObserved(NoMeasurement::Occluded),
            4 => Observation::NotObserved(NoMeasurement::NoFeasiblePose),
            5 => Observation::NotObserved(NoMeasurement::DaemonUnavailable),
            6 => Observation::NotObserved(NoMeasurement::RoverLeft),
            value => return Err(MissionDecodeError::UnknownCode { field: "status", value }),
        };
        let viewer = match m.has_viewer_pose {
            0 => None,
            1 => {
                finite("viewer_position", &m.viewer_position)?;
                finite("viewer_yaw", &[m.viewer_yaw])?;
                Some(ViewerPose { position: m.viewer_position, yaw: m.viewer_yaw })
            }
            value => return Err(MissionDecodeError::UnknownCode { field: "has_viewer_pose", value }),
        };
        let predicted_cost = if m.predicted_cost.is_nan() {
            None
        } else {
            finite("predicted_cost", &[m.predicted_cost])?;
            Some(m.predicted_cost)
        };
        Ok(Measurement { step: m.step, sim_time: m.sim_time, observation, viewer, predicted_cost })
    }
}

// ---------------------------------------------------------------------------------
// Estimate: rover → evaluation.

/// Wire form of [`Estimate`].
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend, serde::Serialize, serde::Deserialize)]
#[type_name("dyfos::mission::Estimate")]
#[repr(C)]
pub struct EstimateMsg {
    /// Sample number; the truth sample with the same number is the same instant.
    pub sample: u64,
    /// Waypoint index the rover is heading for or standing at.
    pub step: u32,
    /// [`Phase`] code.
    pub phase: u32,
    /// 1 when this sample follows an EKF update with a measurement.
    pub updated: u32,
    /// Explicit padding (always 0).
    pub reserved: u32,
    /// Simulated time, s.
    pub sim_time: f64,
    /// EKF mean (x, y, θ).
    pub mean: [f64; 3],
    /// EKF covariance, rows.
    pub cov: [[f64; 3]; 3],
}

/// The rover's belief at one instant.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Estimate {
    /// Sample number (matches [`TrueState::sample`]).
    pub sample: u64,
    /// Waypoint index.
    pub step: u32,
    /// Mission phase.
    pub phase: Phase,
    /// Whether this sample follows an EKF update with a measurement.
    pub updated: bool,
    /// Simulated time, s.
    pub sim_time: f64,
    /// The belief.
    pub belief: Belief,
}

impl From<&Estimate> for EstimateMsg {
    fn from(e: &Estimate) -> Self {
        EstimateMsg {
            sample: e.sample,
            step: e.step,
            phase: e.phase.code(),
            updated: u32::from(e.updated),
            reserved: 0,
            sim_time: e.sim_time,
            mean: e.belief.mean.into(),
            cov: e.belief.cov.to_rows(),
        }
    }
}

impl TryFrom<&EstimateMsg> for Estimate {
    type Error = MissionDecodeError;
    fn try_from(m: &EstimateMsg) -> Result<Self, Self::Error> {
        finite("sim_time", &[m.sim_time])?;
        let updated = match m.updated {
            0 => false,
            1 => true,
            value => return Err(MissionDecodeError::UnknownCode { field: "updated", value }),
        };
        Ok(Estimate {
            sample: m.sample,
            step: m.step,
            phase: Phase::try_from(m.phase)?,
            updated,
            sim_time: m.sim_time,
            belief: Belief::new(m.mean, m.cov)?,
        })
    }
}

// ---------------------------------------------------------------------------------
// Truth: simulator → camera and evaluation.

/// Wire form of [`TrueState`].
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend, serde::Serialize, serde::Deserialize)]
#[type_name("dyfos::sim::TrueState")]
#[repr(C)]
pub struct TrueStateMsg {
    /// Sample number (matches [`EstimateMsg::sample`]).
    pub sample: u64,
    /// Waypoint index the rover is heading for or standing at.
    pub step: u32,
    /// [`Phase`] code.
    pub phase: u32,
    /// Simulated time, s.
    pub sim_time: f64,
    /// True pose (x, y, θ).
    pub pose: [f64; 3],
}

/// The rover's true pose at one instant: simulation ground truth, never seen by the
/// rover's filter.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrueState {
    /// Sample number.
    pub sample: u64,
    /// Waypoint index.
    pub step: u32,
    /// Mission phase.
    pub phase: Phase,
    /// Simulated time, s.
    pub sim_time: f64,
    /// (x, y, θ).
    pub pose: [f64; 3],
}

impl From<&TrueState> for TrueStateMsg {
    fn from(t: &TrueState) -> Self {
        TrueStateMsg { sample: t.sample, step: t.step, phase: t.phase.code(), sim_time: t.sim_time, pose: t.pose }
    }
}

impl TryFrom<&TrueStateMsg> for TrueState {
    type Error = MissionDecodeError;
    fn try_from(m: &TrueStateMsg) -> Result<Self, Self::Error> {
        finite("sim_time", &[m.sim_time])?;
        finite("pose", &m.pose)?;
        Ok(TrueState {
            sample: m.sample,
            step: m.step,
            phase: Phase::try_from(m.phase)?,
            sim_time: m.sim_time,
            pose: m.pose,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn belief() -> Belief {
        Belief::new([1.0, 2.0, 0.3], [[0.2, 0.05, 0.0], [0.05, 0.1, 0.0], [0.0, 0.0, 0.05]]).unwrap()
    }

    #[test]
    fn every_message_round_trips() {
        for s in [
            RendezvousState::Rendezvous { step: 3, sim_time: 12.5, belief: belief() },
            RendezvousState::Finished { step: 10, sim_time: 80.0 },
        ] {
            assert_eq!(RendezvousState::try_from(&RendezvousStateMsg::from(&s)).unwrap(), s);
        }
        let r = Cov2::from_rows(&[[0.01, 0.002], [0.002, 0.02]]).unwrap();
        for m in [
            Measurement {
                step: 2,
                sim_time: 9.0,
                observation: Observation::Observed { position: [1.0, -2.0], r },
                viewer: Some(ViewerPose { position: [0.0, 1.0, 3.0], yaw: -1.0 }),
                predicted_cost: Some(-12.0),
            },
            Measurement {
                step: 4,
                sim_time: 19.0,
                observation: Observation::NotObserved(NoMeasurement::Occluded),
                viewer: None,
                predicted_cost: None,
            },
        ] {
            assert_eq!(Measurement::try_from(&MeasurementMsg::from(&m)).unwrap(), m);
        }
        for code in 1..=6 {
            let msg = MeasurementMsg {
                status: code,
                ..MeasurementMsg::from(&Measurement {
                    step: 1,
                    sim_time: 0.0,
                    observation: Observation::NotObserved(NoMeasurement::OutOfView),
                    viewer: None,
                    predicted_cost: None,
                })
            };
            let Observation::NotObserved(why) = Measurement::try_from(&msg).unwrap().observation else {
                panic!("code {code} decoded as observed");
            };
            assert_eq!(why.code(), code);
        }
        let e = Estimate { sample: 5, step: 1, phase: Phase::Driving, updated: true, sim_time: 1.0, belief: belief() };
        assert_eq!(Estimate::try_from(&EstimateMsg::from(&e)).unwrap(), e);
    }

    #[test]
    fn hostile_bits_are_rejected() {
        let ok = RendezvousStateMsg::from(&RendezvousState::Rendezvous { step: 1, sim_time: 0.0, belief: belief() });
        assert!(matches!(
            RendezvousState::try_from(&RendezvousStateMsg { kind: 7, ..ok }),
            Err(MissionDecodeError::UnknownCode { field: "kind", value: 7 })
        ));
        let mut nan = ok;
        nan.mean[1] = f64::NAN;
        assert!(matches!(RendezvousState::try_from(&nan), Err(MissionDecodeError::Belief(_))));
        let mut not_spd = ok;
        not_spd.cov[2][2] = -1.0;
        assert!(RendezvousState::try_from(&not_spd).is_err());

        let m = MeasurementMsg::from(&Measurement {
            step: 1,
            sim_time: 0.0,
            observation: Observation::Observed {
                position: [0.0, 0.0],
                r: Cov2::from_rows(&[[0.01, 0.0], [0.0, 0.01]]).unwrap(),
            },
            viewer: None,
            predicted_cost: None,
        });
        assert!(Measurement::try_from(&MeasurementMsg { status: 99, ..m }).is_err());
        assert!(Measurement::try_from(&MeasurementMsg { r: [[0.0, 1.0], [1.0, 0.0]], ..m }).is_err());
        assert!(Measurement::try_from(&MeasurementMsg { position: [f64::INFINITY, 0.0], ..m }).is_err());
        assert!(Measurement::try_from(&MeasurementMsg { has_viewer_pose: 2, ..m }).is_err());
        let t = TrueStateMsg { sample: 0, step: 0, phase: 0, sim_time: 0.0, pose: [0.0, f64::NAN, 0.0] };
        assert!(TrueState::try_from(&t).is_err());
        let e = EstimateMsg::from(&Estimate {
            sample: 0,
            step: 0,
            phase: Phase::Finished,
            updated: false,
            sim_time: 0.0,
            belief: belief(),
        });
        assert!(Estimate::try_from(&EstimateMsg { updated: 3, ..e }).is_err());
    }
}
