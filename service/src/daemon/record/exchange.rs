//! A rendezvous query as recorded (`/dyfosd/rendezvous`): the decoded request and
//! the reply, in JSON that rebuilds both bit for bit.

use super::format::params_to_json;
use dyfos_shared::answer::{Algorithm, StopReason};
use dyfos_shared::posterior::Belief;
use dyfos_shared::wire::Status;
use dyfos_shared::wire::map::MapId;
use dyfos_shared::wire::rendezvous::{RendezvousReply, RendezvousRequest};
use dyfos_shared::world::MapDelta;
use serde::{Deserialize, Serialize};
use std::time::Duration;

/// A rendezvous request as recorded: the decoded, validated request.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct RecordedRequest {
    /// The map searched.
    pub map: MapId,
    /// The version the request expected before its deltas.
    pub expected_version: Option<u64>,
    /// The belief.
    pub belief: RecordedBelief,
    /// Inline deltas (applied before the search).
    #[serde(deserialize_with = "recorded_deltas")]
    pub deltas: Vec<MapDelta>,
    /// The algorithm's name.
    pub algorithm: String,
    /// The seed.
    pub seed: u64,
    /// The evaluation budget.
    pub budget: Option<u64>,
    /// The deadline from receipt, ns.
    pub deadline_ns: Option<u64>,
    /// Every parameter, SPEC §11 names.
    pub params: serde_json::Value,
}

/// A belief as recorded.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct RecordedBelief {
    /// Mean (x, y, θ).
    pub mean: [f64; 3],
    /// Covariance, rows.
    pub cov: [[f64; 3]; 3],
}

/// Why a recorded request cannot be rebuilt.
#[derive(Debug, thiserror::Error)]
pub enum RebuildError {
    /// A field is invalid.
    #[error("recorded request: {0}")]
    Invalid(String),
}

impl RecordedRequest {
    /// The request as recorded.
    pub fn of(r: &RendezvousRequest) -> Self {
        RecordedRequest {
            map: r.map,
            expected_version: r.expected_version,
            belief: RecordedBelief { mean: r.belief.mean.into(), cov: r.belief.cov.to_rows() },
            deltas: r.deltas.clone(),
            algorithm: r.algorithm.name().to_string(),
            seed: r.seed,
            budget: r.budget,
            deadline_ns: r.deadline.map(|d| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX)),
            params: params_to_json(&r.params),
        }
    }

    /// The request again, with `params` (SPEC §11 names) for the recorded ones.
    pub fn rebuild_with(&self, params: &serde_json::Value) -> Result<RendezvousRequest, RebuildError> {
        let bad = |e: &dyn std::fmt::Display| RebuildError::Invalid(e.to_string());
        let belief = Belief::new(self.belief.mean, self.belief.cov).map_err(|e| bad(&e))?;
        let algorithm = Algorithm::from_name(&self.algorithm)
            .ok_or_else(|| RebuildError::Invalid(format!("unknown algorithm `{}`", self.algorithm)))?;
        let params = dyfos_shared::scenario::params_from_json(&params.to_string()).map_err(|e| bad(&e))?;
        Ok(RendezvousRequest {
            map: self.map,
            expected_version: self.expected_version,
            belief,
            deltas: self.deltas.clone(),
            algorithm,
            seed: self.seed,
            budget: self.budget,
            deadline: self.deadline_ns.map(Duration::from_nanos),
            params,
        })
    }

    /// The request again, as the daemon decoded it.
    pub fn rebuild(&self) -> Result<RendezvousRequest, RebuildError> {
        self.rebuild_with(&self.params)
    }
}

macro_rules! recorded_reply {
    ($($(#[doc = $doc:literal])* $name:ident: $ty:ty,)*) => {
        /// A rendezvous reply as recorded (and as `dyfos replay` compares it): the
        /// codes by name, the answer's fields as the wire carries them.
        #[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
        pub struct RecordedReply {
            /// The status name (`ok`, `no_feasible_pose`, …).
            pub status: String,
            /// The algorithm's name.
            pub algorithm: String,
            /// Why the search stopped.
            pub stop: String,
            $($(#[doc = $doc])* pub $name: $ty,)*
            /// The failing delta's index, if any.
            pub error_index: Option<u64>,
            /// The detail text of an error.
            pub message: String,
        }

        impl RecordedReply {
            /// The reply as sent.
            pub fn of(r: &RendezvousReply) -> Self {
                RecordedReply {
                    status: Status::try_from(r.status).map_or_else(|_| format!("status_{}", r.status), |s| s.name().into()),
                    algorithm: Algorithm::try_from(r.algorithm).map_or("?", Algorithm::name).to_string(),
                    stop: StopReason::try_from(r.stop).map_or("?", StopReason::name).to_string(),
                    $($name: r.$name,)*
                    error_index: (r.error_index != u64::MAX).then_some(r.error_index),
                    message: if r.status == Status::Ok as u32 { String::new() } else { r.detail.text() },
                }
            }
        }
    };
}

dyfos_shared::reply_answer_fields!(recorded_reply);

impl RecordedReply {
    /// Every floating-point number of the reply.
    fn floats(&self) -> impl Iterator<Item = f64> + '_ {
        self.x
            .iter()
            .chain(std::iter::once(&self.cost))
            .chain(&self.sensor_position)
            .chain(&self.sensor_quaternion)
            .chain(&self.viewer_position)
            .chain(std::iter::once(&self.viewer_yaw))
            .chain(self.r.iter().flatten())
            .chain(self.posterior.iter().flatten())
            .copied()
    }

    /// Whether `other` is the same answer bit for bit (every number compared by its
    /// bits; the timings `micros` and `daemon_micros` left out).
    pub fn identical(&self, other: &RecordedReply) -> bool {
        self.status == other.status
            && self.algorithm == other.algorithm
            && self.stop == other.stop
            && self.map_version == other.map_version
            && self.evaluations == other.evaluations
            && self.error_index == other.error_index
            && self.message == other.message
            && self.floats().map(f64::to_bits).eq(other.floats().map(f64::to_bits))
    }
}

/// A `/dyfosd/rendezvous` message, serialized straight from its parts.
#[derive(Serialize)]
pub(super) struct RendezvousMessage {
    pub(super) mode: &'static str,
    pub(super) request_id: u64,
    pub(super) received_ns: u64,
    pub(super) replied_ns: u64,
    pub(super) request: RecordedRequest,
    pub(super) reply: RecordedReply,
}

/// Deltas as recorded: in the spelling of `docs/deltas.md`, or in serde's derived
/// one that recordings made before it hold, so that those still replay.
pub(super) fn recorded_deltas<'de, D: serde::Deserializer<'de>>(d: D) -> Result<Vec<MapDelta>, D::Error> {
    Vec::<serde_json::Value>::deserialize(d)?
        .into_iter()
        .map(|v| dyfos_shared::map_json::recorded_delta_from_value(v).map_err(serde::de::Error::custom))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use dyfos_shared::params::{ModelKind, Params};
    use dyfos_shared::world::{Obstacle, VerticalCylinder};

    /// Awkward numbers: no short decimal form, the smallest subnormal, -0.
    fn awkward() -> RendezvousRequest {
        let cov = [[0.1 + 0.2, 1e-3 / 3.0, 0.0], [1e-3 / 3.0, std::f64::consts::PI / 10.0, 0.0], [0.0, 0.0, 0.05]];
        let belief = Belief::new([1.0 / 3.0, -0.0, 2.0f64.sqrt()], cov).unwrap();
        let params = Params {
            rho_max: 6.0 + f64::EPSILON * 4.0,
            camera_pitch: 0.7f64.to_radians(),
            lambda: f64::from_bits(0x4008_0000_0000_0001),
            model: ModelKind::Anisotropic,
            ..Params::default()
        };
        let obstacle = Obstacle::Cylinder(VerticalCylinder {
            center: nalgebra::Point2::new(0.1 + 0.7, 5e-324),
            radius: 1.0 / 7.0,
            height: 2.5,
        });
        RendezvousRequest {
            expected_version: Some(3),
            deltas: vec![MapDelta::UpsertObstacle { id: 4, obstacle }],
            algorithm: Algorithm::DyfosScipy,
            seed: u64::MAX - 1,
            budget: Some(1234),
            deadline: Some(Duration::from_nanos(1_234_567_891)),
            params,
            ..RendezvousRequest::new(9, belief)
        }
    }

    #[test]
    fn a_recorded_request_is_rebuilt_bit_for_bit() {
        let request = awkward();
        let text = serde_json::to_string(&RecordedRequest::of(&request)).unwrap();
        let back: RecordedRequest = serde_json::from_str(&text).unwrap();
        let rebuilt = back.rebuild().unwrap();
        // `{:?}` prints every f64 in the shortest form that parses to the same bits
        // (-0.0 included): equal texts are equal bits.
        assert_eq!(format!("{rebuilt:?}"), format!("{request:?}"));
        assert_eq!(rebuilt.belief.mean.y.to_bits(), (-0.0f64).to_bits());
        assert_eq!(rebuilt.params.lambda.to_bits(), request.params.lambda.to_bits());
        // A changed parameter is seen.
        let mut params = back.params.clone();
        params["rho_max"] = serde_json::json!(5.0);
        assert_eq!(back.rebuild_with(&params).unwrap().params.rho_max, 5.0);
    }

    #[test]
    fn replies_are_compared_by_their_bits() {
        let answer = RendezvousReply { x: [1.0, 0.5, -0.25, 0.0], cost: -3.5, ..RendezvousReply::checked(1, 2) };
        let a = RecordedReply::of(&answer);
        let back: RecordedReply = serde_json::from_str(&serde_json::to_string(&a).unwrap()).unwrap();
        assert!(a.identical(&back));
        let timing = RecordedReply { micros: 99, daemon_micros: 7, ..a.clone() };
        assert!(a.identical(&timing), "timings are not compared");
        let signed_zero = RecordedReply { x: [1.0, 0.5, -0.25, -0.0], ..a.clone() };
        assert!(!a.identical(&signed_zero), "-0 and 0 differ in their bits");
        let next = RecordedReply { cost: f64::from_bits((-3.5f64).to_bits() + 1), ..a.clone() };
        assert!(!a.identical(&next));
    }
}
