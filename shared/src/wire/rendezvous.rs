//! The rendezvous service (`<prefix>rendezvous`): where should the viewer's camera
//! be to localize the rover at the rendezvous (SPEC §2, §8)?
//!
//! The request is a [`RendezvousRequestHeader`] (the iceoryx2 request user header)
//! plus a slice of inline [`WireDelta`] records that are applied to the map, all or
//! none, before the search. The reply is one [`RendezvousReply`] carrying the full
//! answer of `dyfos solve`, or an error code.
//!
//! *Interpretations:* the expected version is checked against the map *before* the
//! inline deltas; the answer's `map_version` is the version searched (after them).
//! Inline deltas describe the world, so once valid they are committed before the
//! search and stay applied whatever the search finds: a reply of `no_feasible_pose`,
//! `deadline_exceeded` or `internal_error` to a request that carried deltas means
//! they *were* applied, and its `map_version` is the version they produced. Every
//! other error is given before the deltas are applied (all or none), changes
//! nothing, and carries the map's version as it is.
//! The deadline is relative, counted from the moment the daemon receives the
//! request (queueing included): processes share no clock on the wire.
//!
//! ```
//! use dyfos_shared::prelude::*;
//! use dyfos_shared::wire::rendezvous::{Mode, RendezvousRequest};
//!
//! let belief = Belief::new([0.0, 0.0, 0.3], [[0.2, 0.05, 0.0], [0.05, 0.1, 0.0], [0.0, 0.0, 0.05]]).unwrap();
//! let request = RendezvousRequest { seed: 7, ..RendezvousRequest::new(1, belief) };
//! let header = request.header(Mode::Solve, 42, [0, 0]);
//! let (decoded, mode) = RendezvousRequest::decode(&header, &request.records()).unwrap();
//! assert_eq!((decoded, mode), (request, Mode::Solve));
//! let mut bad = header;
//! bad.cov[0][0] = f64::NAN;
//! assert_eq!(RendezvousRequest::decode(&bad, &[]).unwrap_err().status.name(), "invalid_belief");
//! ```

use super::map::{MapId, WireDelta, decode_batch, encode_deltas};
use super::{ANY_VERSION, Detail, Rejection, Status};
use crate::answer::{Algorithm, Answer, EvalStats, StopReason};
use crate::codes::codes;
use crate::limits::{MAX_DEADLINE_MICROS, MAX_INLINE_DELTAS};
use crate::math::{Matrix3, Point3, UnitQuaternion};
use crate::params::{ParamValue, Params};
use crate::posterior::Belief;
use crate::world::MapDelta;
use iceoryx2::prelude::ZeroCopySend;
use std::time::Duration;

codes! {
    /// What the daemon does with a valid request; the code is the header's `mode`.
    pub enum Mode("mode") {
        /// Search and answer.
        Solve = 0, "solve";
        /// Validate everything (map, version, belief, parameters, inline deltas on a
        /// copy of the map) and answer at once without searching or changing the map:
        /// the round-trip floor, for latency benchmarks and health checks.
        Check = 1, "check";
    }
}

/// Every parameter of SPEC §11, as plain numbers. `model`: 0 paper, 1 anisotropic,
/// 2 learned.
///
/// `set` says which fields the request gives: bit `i` (see [`WireParams::FIELDS`],
/// in field order) set means field `i` is used, clear means the SPEC default is used
/// and the field's bits are ignored. So an all-zero `WireParams` asks for every SPEC
/// default, and a client in any language overrides one parameter without knowing the
/// others' values. Bits above [`WireParams::ALL_SET`] and a non-zero `reserved` are
/// `invalid_params`.
///
/// ```
/// use dyfos_shared::params::Params;
/// use dyfos_shared::wire::rendezvous::WireParams;
///
/// let only_lambda = WireParams { lambda: 2.0, set: WireParams::bit("lambda").unwrap(), ..WireParams::default() };
/// let params = Params::try_from(&only_lambda).unwrap();
/// assert_eq!(params, Params { lambda: 2.0, ..Params::default() });
/// assert_eq!(Params::try_from(&WireParams::default()).unwrap(), Params::default());
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend)]
#[type_name("dyfos::WireParams")]
#[repr(C)]
pub struct WireParams {
    /// `rover_radius`, m.
    pub rover_radius: f64,
    /// `marker_size`, m.
    pub marker_size: f64,
    /// `marker_height`, m.
    pub marker_height: f64,
    /// `viewer_radius`, m.
    pub viewer_radius: f64,
    /// `safety_margin`, m.
    pub safety_margin: f64,
    /// `z_min`, m.
    pub z_min: f64,
    /// `z_max`, m.
    pub z_max: f64,
    /// `camera_pitch`, rad.
    pub camera_pitch: f64,
    /// `t_vs`, m.
    pub t_vs: [f64; 3],
    /// `f_h`, rad.
    pub f_h: f64,
    /// `f_v`, rad.
    pub f_v: f64,
    /// `rho_min`, m.
    pub rho_min: f64,
    /// `rho_max`, m.
    pub rho_max: f64,
    /// `kappa`.
    pub kappa: f64,
    /// `lambda`.
    pub lambda: f64,
    /// `perimeter_points`.
    pub perimeter_points: u32,
    /// 0 paper, 1 anisotropic, 2 learned.
    pub model: u32,
    /// Which fields are given, one bit per field in [`WireParams::FIELDS`] order;
    /// a clear bit means the SPEC default.
    pub set: u32,
    /// Must be 0.
    pub reserved: u32,
}

macro_rules! wire_params {
    ($($(#[doc = $doc:literal])* #[wire($slot:literal)] $name:ident: $ty:ty = $default:expr,)*) => {
        impl WireParams {
            /// The fields' SPEC §11 names, in field order: bit `i` of `set` is `FIELDS[i]`.
            pub const FIELDS: [&'static str; [$(stringify!($name)),*].len()] = {
                let mut fields = [""; [$(stringify!($name)),*].len()];
                $(fields[$slot] = stringify!($name);)*
                fields
            };
        }

        // The struct above is the one place that restates the parameters (its
        // layout is the ABI): its fields must be in `#[wire(i)]` order.
        const _: () = {
            let mut offsets = [0usize; WireParams::FIELDS.len()];
            $(offsets[$slot] = std::mem::offset_of!(WireParams, $name);)*
            let mut i = 1;
            while i < offsets.len() {
                assert!(offsets[i - 1] < offsets[i], "WireParams's fields are not in #[wire(i)] order");
                i += 1;
            }
        };

        impl From<&Params> for WireParams {
            fn from(p: &Params) -> Self {
                WireParams { $($name: ParamValue::to_wire(p.$name),)* set: WireParams::ALL_SET, reserved: 0 }
            }
        }

        impl TryFrom<&WireParams> for Params {
            type Error = Rejection;

            /// Decodes and validates (SPEC §11 ranges): `invalid_params` names the field.
            /// Fields whose `set` bit is clear take the SPEC default.
            fn try_from(w: &WireParams) -> Result<Self, Rejection> {
                if w.set & !WireParams::ALL_SET != 0 || w.reserved != 0 {
                    return Err(Rejection::new(
                        Status::InvalidParams,
                        format!(
                            "params.set = {:#x} has bits above {:#x}, or params.reserved = {} is not 0",
                            w.set,
                            WireParams::ALL_SET,
                            w.reserved
                        ),
                    ));
                }
                // Unset fields take their default before anything is decoded, so their
                // bits (whatever a peer left there) are never looked at.
                let d = WireParams::from(&Params::default());
                let given = |name: &str| w.set & WireParams::bit(name).unwrap_or(0) != 0;
                let invalid = |message: String| Rejection::new(Status::InvalidParams, message);
                let p = Params {
                    $($name: ParamValue::from_wire(
                        concat!("params.", stringify!($name)),
                        if given(stringify!($name)) { w.$name } else { d.$name },
                    )
                    .map_err(invalid)?,)*
                };
                // A pair out of order names the field the request gave, not a default.
                p.validate_given(given).map_err(|e| invalid(format!("params.{e}")))?;
                Ok(p)
            }
        }
    };
}

crate::spec_params!(wire_params);

impl WireParams {
    /// `set` with every field given.
    pub const ALL_SET: u32 = (1 << Self::FIELDS.len()) - 1;

    /// The `set` bit of the field named `name` (SPEC §11 name), if there is one.
    pub fn bit(name: &str) -> Option<u32> {
        Self::FIELDS.iter().position(|f| *f == name).map(|i| 1 << i)
    }
}

/// The fixed part of a rendezvous request (the iceoryx2 request user header).
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend)]
#[type_name("dyfos::RendezvousRequestHeader")]
#[repr(C)]
pub struct RendezvousRequestHeader {
    /// The client's id for this request, echoed in the reply.
    pub request_id: u64,
    /// The map to search.
    pub map_id: u64,
    /// The version the map must have (before the inline deltas), or [`ANY_VERSION`].
    pub expected_version: u64,
    /// Seed of the search's random stream.
    pub seed: u64,
    /// Most candidates to evaluate; 0 for the algorithm's own limits.
    pub budget: u64,
    /// Deadline in µs after the daemon receives the request; 0 for none.
    pub deadline_micros: u64,
    /// Belief mean (x, y, θ).
    pub mean: [f64; 3],
    /// Belief covariance Σ⁻, rows.
    pub cov: [[f64; 3]; 3],
    /// Parameters.
    pub params: WireParams,
    /// 0 dyfos, 1 dyfos-scipy, 2 brute, 3 random, 4 center ([`Algorithm::ALL`] order).
    pub algorithm: u32,
    /// 0 solve, 1 check ([`Mode`]).
    pub mode: u32,
    /// The client's reply listener id ([`super::split_u128`]).
    pub reply_to: [u64; 2],
}

/// A rendezvous query, validated.
#[derive(Debug, Clone, PartialEq)]
pub struct RendezvousRequest {
    /// The map to search.
    pub map: MapId,
    /// The version the map must have before `deltas`; `None` accepts any.
    pub expected_version: Option<u64>,
    /// The rover's a priori belief at the rendezvous (SPEC §2).
    pub belief: Belief,
    /// Deltas applied to the map, all or none, before the search (a newly seen
    /// obstacle, a moved sun). They change the stored map, and stay applied even
    /// if the search then finds no pose or runs out of time.
    pub deltas: Vec<MapDelta>,
    /// The search algorithm.
    pub algorithm: Algorithm,
    /// Seed: the same request and seed give the same answer, bit for bit.
    pub seed: u64,
    /// Most candidates to evaluate; `None` for the algorithm's own limits. On the
    /// wire 0 means `None`, so `Some(0)` cannot be sent (the client refuses it).
    pub budget: Option<u64>,
    /// Time allowed from receipt to answer; when it passes the daemon answers with
    /// the best feasible pose so far (`stop = deadline`) or `deadline_exceeded`.
    pub deadline: Option<Duration>,
    /// Parameters (SPEC defaults unless overridden).
    pub params: Params,
}

impl RendezvousRequest {
    /// A `dyfos` query of `map` for `belief`, seed 0, any version, SPEC parameters,
    /// no deltas, no budget or deadline.
    pub fn new(map: MapId, belief: Belief) -> Self {
        RendezvousRequest {
            map,
            expected_version: None,
            belief,
            deltas: Vec::new(),
            algorithm: Algorithm::Dyfos,
            seed: 0,
            budget: None,
            deadline: None,
            params: Params::default(),
        }
    }

    /// The header to send.
    pub fn header(&self, mode: Mode, request_id: u64, reply_to: [u64; 2]) -> RendezvousRequestHeader {
        RendezvousRequestHeader {
            request_id,
            map_id: self.map,
            expected_version: self.expected_version.unwrap_or(ANY_VERSION),
            seed: self.seed,
            budget: self.budget.unwrap_or(0),
            deadline_micros: self.deadline.map_or(0, |d| u64::try_from(d.as_micros()).unwrap_or(u64::MAX).max(1)),
            mean: self.belief.mean.into(),
            cov: self.belief.cov.to_rows(),
            params: WireParams::from(&self.params),
            algorithm: self.algorithm.code(),
            mode: mode.code(),
            reply_to,
        }
    }

    /// The inline delta records to send.
    pub fn records(&self) -> Vec<WireDelta> {
        encode_deltas(&self.deltas)
    }

    /// Decodes and validates every field; the map-dependent checks (id, version,
    /// deltas applying cleanly) are the daemon's.
    pub fn decode(h: &RendezvousRequestHeader, records: &[WireDelta]) -> Result<(Self, Mode), Rejection> {
        let mode = Mode::try_from(h.mode).map_err(|e| {
            let codes: Vec<String> = Mode::ALL.iter().map(|m| format!("{} ({m})", m.code())).collect();
            Rejection::new(Status::MalformedRequest, format!("mode = {} must be {}", e.value, codes.join(" or ")))
        })?;
        let algorithm = Algorithm::try_from(h.algorithm).map_err(|e| {
            Rejection::new(
                Status::InvalidAlgorithm,
                format!("algorithm = {} is not an algorithm ({})", e.value, Algorithm::listing()),
            )
        })?;
        let belief =
            Belief::new(h.mean, h.cov).map_err(|e| Rejection::new(Status::InvalidBelief, format!("belief: {e}")))?;
        // `learned` decodes like any model; whether the daemon has weights for it is
        // the daemon's check (it refuses it with `unsupported_model` if not).
        let params = Params::try_from(&h.params)?;
        if h.deadline_micros > MAX_DEADLINE_MICROS {
            return Err(Rejection::new(
                Status::InvalidDeadline,
                format!("deadline = {} µs exceeds the limit of {MAX_DEADLINE_MICROS} µs (one hour)", h.deadline_micros),
            ));
        }
        Rejection::at_most(
            records.len(),
            MAX_INLINE_DELTAS,
            "inline delta records",
            "; send large changes to the map service first",
        )?;
        let deltas = decode_batch(records)?;
        let request = RendezvousRequest {
            map: h.map_id,
            expected_version: (h.expected_version != ANY_VERSION).then_some(h.expected_version),
            belief,
            deltas,
            algorithm,
            seed: h.seed,
            budget: (h.budget != 0).then_some(h.budget),
            deadline: (h.deadline_micros != 0).then(|| Duration::from_micros(h.deadline_micros)),
            params,
        };
        Ok((request, mode))
    }
}

/// Calls macro `$callback` with the fields of a rendezvous reply that carry the
/// answer as the wire has it (the map version, the numbers, the counts and the
/// timings), written once here with their documentation, in wire order.
///
/// [`RendezvousReply`] is generated from it, and so is the daemon's recording of a
/// reply, which keeps these fields as they are and spells the codes out.
#[macro_export]
macro_rules! reply_answer_fields {
    ($callback:ident) => {
        $callback! {
            /// On success, the map version searched (or checked), after the inline deltas.
            /// On error, the version as the request left the map: after its inline deltas
            /// when they were applied before the search failed (`no_feasible_pose`,
            /// `deadline_exceeded`, `internal_error`), else the version the map had when
            /// the request was refused (nothing changed); `ANY_VERSION` if no map has the id.
            map_version: u64,
            /// x = (ρ, ψ, φ, ψ_v).
            x: [f64; 4],
            /// E = ln det Σ⁺.
            cost: f64,
            /// p_s.
            sensor_position: [f64; 3],
            /// R_ws as a quaternion (x, y, z, w), w ≥ 0 (SPEC §3).
            sensor_quaternion: [f64; 4],
            /// p_v.
            viewer_position: [f64; 3],
            /// ψ_v.
            viewer_yaw: f64,
            /// R, rows.
            r: [[f64; 2]; 2],
            /// Σ⁺, rows.
            posterior: [[f64; 3]; 3],
            /// Evaluations: total, workspace, collision, occlusion.
            evaluations: [u64; 4],
            /// Search time, µs.
            micros: u64,
            /// Time from receipt to reply in the daemon, µs (queueing included).
            daemon_micros: u64,
        }
    };
}

macro_rules! rendezvous_reply {
    ($($(#[doc = $doc:literal])* $name:ident: $ty:ty,)*) => {
        /// The reply: a status and, on success, the whole answer.
        #[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend)]
        #[type_name("dyfos::RendezvousReply")]
        #[repr(C)]
        pub struct RendezvousReply {
            /// A [`Status`] code.
            pub status: u32,
            /// [`Algorithm::ALL`] index of the algorithm used.
            pub algorithm: u32,
            /// Why the search stopped: 0 finished, 1 max generations, 2 budget, 3 deadline,
            /// 4 abandoned (never sent by `dyfosd`, which does not reply to a client that left).
            pub stop: u32,
            /// 0 solve, 1 check.
            pub mode: u32,
            /// The request's id.
            pub request_id: u64,
            $($(#[doc = $doc])* pub $name: $ty,)*
            /// For delta errors, the failing delta's index, else `u64::MAX`.
            pub error_index: u64,
            /// What went wrong, for people.
            pub detail: Detail,
        }
    };
}

crate::reply_answer_fields!(rendezvous_reply);

/// The outcome of a check-mode request: everything validated, nothing searched.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RendezvousCheck {
    /// The version the query would have searched (after the inline deltas).
    pub map_version: u64,
}

impl RendezvousReply {
    /// A success reply carrying `answer`.
    pub fn answer(request_id: u64, answer: &Answer) -> Self {
        let q = answer.sensor_orientation.coords; // (i, j, k, w)
        let e = answer.evaluations;
        RendezvousReply {
            status: Status::Ok as u32,
            algorithm: answer.algorithm.code(),
            stop: answer.stop.code(),
            mode: Mode::Solve.code(),
            request_id,
            map_version: answer.map_version,
            x: answer.x.to_array(),
            cost: answer.cost,
            sensor_position: answer.sensor_position.coords.into(),
            sensor_quaternion: [q.x, q.y, q.z, q.w],
            viewer_position: answer.viewer_position.coords.into(),
            viewer_yaw: answer.viewer_yaw,
            r: answer.r,
            posterior: crate::math::rows3(&answer.posterior),
            evaluations: [e.total, e.workspace, e.collision, e.occlusion],
            micros: answer.micros,
            daemon_micros: 0,
            error_index: u64::MAX,
            detail: Detail::default(),
        }
    }

    /// A success reply to a check-mode request.
    pub fn checked(request_id: u64, map_version: u64) -> Self {
        RendezvousReply {
            status: Status::Ok as u32,
            mode: Mode::Check.code(),
            request_id,
            map_version,
            error_index: u64::MAX,
            ..Default::default()
        }
    }

    /// An error reply; `map_version` is the rejection's, or [`ANY_VERSION`] (`u64::MAX`)
    /// for none.
    pub fn rejected(request_id: u64, rejection: &Rejection) -> Self {
        RendezvousReply {
            status: rejection.status as u32,
            request_id,
            map_version: rejection.map_version.unwrap_or(ANY_VERSION),
            error_index: rejection.wire_index(),
            detail: Detail::new(&rejection.message),
            ..Default::default()
        }
    }

    /// The rejection an error reply carries, with its map version.
    fn rejection(&self) -> Rejection {
        let map_version = (self.map_version != ANY_VERSION).then_some(self.map_version);
        Rejection { map_version, ..Rejection::from_wire(self.status, &self.detail, self.error_index) }
    }

    /// Decodes a solve reply: the answer, or the daemon's rejection. Tags from the
    /// wire are checked, never trusted.
    pub fn decode_answer(&self) -> Result<Answer, Rejection> {
        if self.status != Status::Ok as u32 {
            return Err(self.rejection());
        }
        let bad = |what: String| Rejection::new(Status::MalformedRequest, format!("malformed reply: {what}"));
        let algorithm = Algorithm::try_from(self.algorithm).map_err(|e| bad(format!("algorithm = {}", e.value)))?;
        let stop = StopReason::try_from(self.stop).map_err(|e| bad(format!("stop = {}", e.value)))?;
        let [i, j, k, w] = self.sensor_quaternion;
        let e = self.evaluations;
        Ok(Answer {
            algorithm,
            // Not `from_array`: re-wrapping the yaw could change its last bit.
            x: crate::sensor::SensorState { rho: self.x[0], psi: self.x[1], phi: self.x[2], yaw: self.x[3] },
            cost: self.cost,
            sensor_position: Point3::from(self.sensor_position),
            sensor_orientation: UnitQuaternion::new_unchecked(nalgebra::Quaternion::new(w, i, j, k)),
            viewer_position: Point3::from(self.viewer_position),
            viewer_yaw: self.viewer_yaw,
            r: self.r,
            posterior: Matrix3::from_fn(|r, c| self.posterior[r][c]),
            evaluations: EvalStats { total: e[0], workspace: e[1], collision: e[2], occlusion: e[3] },
            micros: self.micros,
            map_version: self.map_version,
            stop,
        })
    }

    /// Decodes a check reply.
    pub fn decode_check(&self) -> Result<RendezvousCheck, Rejection> {
        if self.status != Status::Ok as u32 {
            return Err(self.rejection());
        }
        Ok(RendezvousCheck { map_version: self.map_version })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::Vector3;
    use crate::params::ModelKind;
    use crate::world::Sun;

    fn request() -> RendezvousRequest {
        let belief = Belief::new([1.0, 2.0, 0.3], [[0.2, 0.05, 0.0], [0.05, 0.1, 0.0], [0.0, 0.0, 0.05]]).unwrap();
        RendezvousRequest {
            expected_version: Some(3),
            deltas: vec![MapDelta::SetSun(Sun::new(0.2, 0.1).unwrap())],
            algorithm: Algorithm::Center,
            seed: 11,
            budget: Some(500),
            deadline: Some(Duration::from_millis(250)),
            params: Params { lambda: 2.0, model: ModelKind::Anisotropic, ..Params::default() },
            ..RendezvousRequest::new(9, belief)
        }
    }

    #[test]
    fn every_field_round_trips() {
        let r = request();
        let h = r.header(Mode::Check, 5, [7, 8]);
        assert_eq!(RendezvousRequest::decode(&h, &r.records()).unwrap(), (r, Mode::Check));
    }

    #[test]
    fn every_bad_field_has_its_code() {
        let r = request();
        let h = r.header(Mode::Solve, 5, [7, 8]);
        let status = |h: RendezvousRequestHeader| RendezvousRequest::decode(&h, &[]).unwrap_err().status;
        let mut cov = h.cov;
        cov[0][1] = 0.3;
        let mut not_spd = h.cov;
        not_spd[2][2] = -1.0;
        let cases = [
            (RendezvousRequestHeader { mode: 2, ..h }, Status::MalformedRequest),
            (RendezvousRequestHeader { algorithm: 5, ..h }, Status::InvalidAlgorithm),
            (RendezvousRequestHeader { mean: [f64::INFINITY, 0.0, 0.0], ..h }, Status::InvalidBelief),
            (RendezvousRequestHeader { cov, ..h }, Status::InvalidBelief),
            (RendezvousRequestHeader { cov: not_spd, ..h }, Status::InvalidBelief),
            (RendezvousRequestHeader { params: WireParams { rho_min: 9.0, ..h.params }, ..h }, Status::InvalidParams),
            (
                RendezvousRequestHeader { params: WireParams { kappa: f64::NAN, ..h.params }, ..h },
                Status::InvalidParams,
            ),
            (RendezvousRequestHeader { params: WireParams { model: 3, ..h.params }, ..h }, Status::InvalidParams),
            (RendezvousRequestHeader { deadline_micros: MAX_DEADLINE_MICROS + 1, ..h }, Status::InvalidDeadline),
        ];
        for (bad, expected) in cases {
            assert_eq!(status(bad), expected, "{bad:?}");
        }
        let learned = RendezvousRequestHeader { params: WireParams { model: 2, ..h.params }, ..h };
        assert_eq!(RendezvousRequest::decode(&learned, &[]).unwrap().0.params.model, ModelKind::Learned);
        let too_many =
            vec![WireDelta { tag: super::super::map::tag::CLEAR, ..Default::default() }; MAX_INLINE_DELTAS + 1];
        assert_eq!(RendezvousRequest::decode(&h, &too_many).unwrap_err().status, Status::OverCapacity);
    }

    #[test]
    fn params_left_unset_take_the_spec_default() {
        let default = Params::default();
        // Zeroed (as a C or Python client allocates it): every default.
        assert_eq!(Params::try_from(&WireParams::default()).unwrap(), default);
        // Unset fields are ignored whatever their bits, even NaN.
        let garbage = WireParams { kappa: f64::NAN, model: 99, rho_min: -1.0, ..WireParams::default() };
        assert_eq!(Params::try_from(&garbage).unwrap(), default);
        // Each field alone: given, it is used; every name in FIELDS names a field.
        let changed = Params {
            rover_radius: 0.5,
            perimeter_points: 4,
            marker_size: 0.3,
            marker_height: 0.25,
            viewer_radius: 0.3,
            safety_margin: 0.2,
            z_min: 0.6,
            z_max: 7.0,
            camera_pitch: 0.5,
            t_vs: Vector3::new(0.2, 0.0, -0.1),
            f_h: 1.0,
            f_v: 0.6,
            rho_min: 1.5,
            rho_max: 5.0,
            kappa: 2.0,
            lambda: 2.5,
            model: ModelKind::Anisotropic,
        };
        let full = WireParams::from(&changed);
        for name in WireParams::FIELDS {
            let one = WireParams { set: WireParams::bit(name).unwrap(), ..full };
            let decoded = Params::try_from(&one).unwrap();
            assert_ne!(decoded, default, "{name} is not decoded");
        }
        assert_eq!(Params::try_from(&full).unwrap(), changed);
        for bad in [WireParams { set: 1 << 17, ..full }, WireParams { reserved: 1, ..full }] {
            assert_eq!(Params::try_from(&bad).unwrap_err().status, Status::InvalidParams);
        }
    }

    /// Regression: `z_min` = 9 given alone was reported as `z_max`, a field the
    /// request never set.
    #[test]
    fn a_pair_out_of_order_names_the_field_the_request_gave() {
        let only = |name: &str, v: f64| {
            let mut w = WireParams { set: WireParams::bit(name).unwrap(), ..WireParams::default() };
            match name {
                "z_min" => w.z_min = v,
                "z_max" => w.z_max = v,
                "rho_min" => w.rho_min = v,
                _ => w.rho_max = v,
            }
            Params::try_from(&w).unwrap_err().message
        };
        assert!(only("z_min", 9.0).starts_with("params.z_min = 9 must be < z_max = 8"), "{}", only("z_min", 9.0));
        assert!(only("z_max", 0.2).starts_with("params.z_max = 0.2 must be > z_min = 0.5"), "{}", only("z_max", 0.2));
        assert!(
            only("rho_max", 0.5).starts_with("params.rho_max = 0.5 must be > rho_min = 1"),
            "{}",
            only("rho_max", 0.5)
        );
        assert!(
            only("rho_min", 7.0).starts_with("params.rho_min = 7 must be < rho_max = 6"),
            "{}",
            only("rho_min", 7.0)
        );
        // Both given: the documented choice, as for a scenario file.
        let both = WireParams {
            z_min: 9.0,
            z_max: 8.0,
            set: WireParams::bit("z_min").unwrap() | WireParams::bit("z_max").unwrap(),
            ..WireParams::default()
        };
        assert!(Params::try_from(&both).unwrap_err().message.starts_with("params.z_max"));
    }

    #[test]
    fn replies_round_trip_and_reject_bad_tags() {
        let rejection =
            Rejection { map_version: Some(6), ..Rejection::at_delta(Status::InvalidDelta, "delta #2: no", 2) };
        assert_eq!(RendezvousReply::rejected(1, &rejection).decode_answer().unwrap_err(), rejection);
        let ok = RendezvousReply { stop: 3, algorithm: 2, ..RendezvousReply::checked(1, 4) };
        let answer = ok.decode_answer().unwrap();
        assert_eq!((answer.algorithm, answer.stop), (Algorithm::Brute, StopReason::Deadline));
        assert_eq!(RendezvousReply { stop: 4, ..ok }.decode_answer().unwrap().stop, StopReason::Abandoned);
        assert!(RendezvousReply { stop: 5, ..ok }.decode_answer().is_err());
        assert!(RendezvousReply { algorithm: 99, ..ok }.decode_answer().is_err());
        let unknown = RendezvousReply { status: 999, ..ok }.decode_answer().unwrap_err();
        assert_eq!(unknown.status, Status::MalformedRequest);
    }
}
