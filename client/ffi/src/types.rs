//! The plain C structs of the API (parameters, rendezvous request, answer, map
//! description), their codes, and their conversions to and from the Rust client's
//! types.

use crate::status::{
    DYFOS_STATUS_INVALID_ALGORITHM, DYFOS_STATUS_INVALID_BELIEF, DYFOS_STATUS_MALFORMED_DELTA,
    DYFOS_STATUS_NULL_PARAMETER, Failure,
};
use dyfos_shared::answer::{Algorithm, Answer, EvalStats, StopReason};
use dyfos_shared::math::{Matrix3, Point3, UnitQuaternion, canonical_xyzw, rows3};
use dyfos_shared::params::Params;
use dyfos_shared::posterior::Belief;
use dyfos_shared::sensor::SensorState;
use dyfos_shared::wire::map::MapInfo;
use dyfos_shared::wire::rendezvous::{RendezvousRequest, WireParams};
use dyfos_shared::world::MapDelta;
use std::ffi::{CStr, c_char};
use std::time::Duration;

/// `expected_version` of `dyfos_client_apply` and `dyfos_client_delete_map` that
/// accepts any map version.
pub const DYFOS_ANY_VERSION: u64 = u64::MAX;

/// Most delta records one `dyfos_client_apply` batch may carry (more is
/// `DYFOS_STATUS_OVER_CAPACITY`, nothing sent). A delta is one record, except
/// `SetVoxels` (1 + one per cell) and `SetVoxelBlocks` (1 + one per block).
pub const DYFOS_MAX_BATCH_RECORDS: u32 = 4096u32;

/// Most delta records a rendezvous request may carry in `deltas_json` (counted as
/// for `DYFOS_MAX_BATCH_RECORDS`; more is `DYFOS_STATUS_OVER_CAPACITY`, nothing sent):
/// apply larger batches with `dyfos_client_apply` first.
pub const DYFOS_MAX_INLINE_RECORDS: u32 = 1024u32;

/// Most maps one daemon holds: a `dyfos_map_info` array of this many entries holds
/// every map `dyfos_client_list_maps` describes.
pub const DYFOS_MAX_MAPS: u32 = 256u32;

/// Differential evolution with a final local polish (the DyFOS optimizer).
pub const DYFOS_ALGORITHM_DYFOS: u32 = 0u32;
/// Differential evolution exactly as SciPy's defaults, no polish (the paper's).
pub const DYFOS_ALGORITHM_DYFOS_SCIPY: u32 = 1u32;
/// Exhaustive grid on all of the daemon's workers.
pub const DYFOS_ALGORITHM_BRUTE: u32 = 2u32;
/// Uniform samples until the first feasible one.
pub const DYFOS_ALGORITHM_RANDOM: u32 = 3u32;
/// Rover in the image centre, uniform ρ and yaw until the first feasible one.
pub const DYFOS_ALGORITHM_CENTER: u32 = 4u32;

/// `dyfos_params.model`: the paper's isotropic linear SDSMM (the default).
pub const DYFOS_MODEL_PAPER: u32 = 0u32;
/// `dyfos_params.model`: `paper`'s variance stretched along the line of sight.
pub const DYFOS_MODEL_ANISOTROPIC: u32 = 1u32;
/// `dyfos_params.model`: the trained network (the daemon needs its weights).
pub const DYFOS_MODEL_LEARNED: u32 = 2u32;

/// `dyfos_answer.stop`: the search ran to its natural end.
pub const DYFOS_STOP_FINISHED: u32 = 0u32;
/// `dyfos_answer.stop`: differential evolution hit its generation cap.
pub const DYFOS_STOP_MAX_GENERATIONS: u32 = 1u32;
/// `dyfos_answer.stop`: the request's evaluation budget ran out.
pub const DYFOS_STOP_BUDGET: u32 = 2u32;
/// `dyfos_answer.stop`: the deadline passed; the answer is the best found so far.
pub const DYFOS_STOP_DEADLINE: u32 = 3u32;
/// `dyfos_answer.stop`: the search was abandoned (never in an answer the daemon sends).
pub const DYFOS_STOP_ABANDONED: u32 = 4u32;

/// `dyfos_params.set` bit of `rover_radius`.
pub const DYFOS_PARAM_ROVER_RADIUS: u32 = 1u32 << 0;
/// `dyfos_params.set` bit of `marker_size`.
pub const DYFOS_PARAM_MARKER_SIZE: u32 = 1u32 << 1;
/// `dyfos_params.set` bit of `marker_height`.
pub const DYFOS_PARAM_MARKER_HEIGHT: u32 = 1u32 << 2;
/// `dyfos_params.set` bit of `viewer_radius`.
pub const DYFOS_PARAM_VIEWER_RADIUS: u32 = 1u32 << 3;
/// `dyfos_params.set` bit of `safety_margin`.
pub const DYFOS_PARAM_SAFETY_MARGIN: u32 = 1u32 << 4;
/// `dyfos_params.set` bit of `z_min`.
pub const DYFOS_PARAM_Z_MIN: u32 = 1u32 << 5;
/// `dyfos_params.set` bit of `z_max`.
pub const DYFOS_PARAM_Z_MAX: u32 = 1u32 << 6;
/// `dyfos_params.set` bit of `camera_pitch`.
pub const DYFOS_PARAM_CAMERA_PITCH: u32 = 1u32 << 7;
/// `dyfos_params.set` bit of `t_vs`.
pub const DYFOS_PARAM_T_VS: u32 = 1u32 << 8;
/// `dyfos_params.set` bit of `f_h`.
pub const DYFOS_PARAM_F_H: u32 = 1u32 << 9;
/// `dyfos_params.set` bit of `f_v`.
pub const DYFOS_PARAM_F_V: u32 = 1u32 << 10;
/// `dyfos_params.set` bit of `rho_min`.
pub const DYFOS_PARAM_RHO_MIN: u32 = 1u32 << 11;
/// `dyfos_params.set` bit of `rho_max`.
pub const DYFOS_PARAM_RHO_MAX: u32 = 1u32 << 12;
/// `dyfos_params.set` bit of `kappa`.
pub const DYFOS_PARAM_KAPPA: u32 = 1u32 << 13;
/// `dyfos_params.set` bit of `lambda`.
pub const DYFOS_PARAM_LAMBDA: u32 = 1u32 << 14;
/// `dyfos_params.set` bit of `perimeter_points`.
pub const DYFOS_PARAM_PERIMETER_POINTS: u32 = 1u32 << 15;
/// `dyfos_params.set` bit of `model`.
pub const DYFOS_PARAM_MODEL: u32 = 1u32 << 16;
/// `dyfos_params.set` with every field given.
pub const DYFOS_PARAMS_ALL_SET: u32 = (1u32 << 17) - 1;

/// Every parameter of SPEC §11 (units as there: metres, radians). `set` says which
/// fields are given: bit `DYFOS_PARAM_<NAME>` set means the field is used, clear
/// means the SPEC default is used and the field is ignored. So a request whose
/// `set` is 0 uses every default, and overriding one parameter is
/// `p.lambda = 2.0; p.set |= DYFOS_PARAM_LAMBDA;`. `dyfos_params_init` fills the
/// fields with the defaults (so they can be read) and clears `set`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct dyfos_params {
    /// Rover footprint radius, m.
    pub rover_radius: f64,
    /// Marker side, m.
    pub marker_size: f64,
    /// Marker height above ground, m.
    pub marker_height: f64,
    /// Viewer body radius, m.
    pub viewer_radius: f64,
    /// Extra clearance for the collision rays, m.
    pub safety_margin: f64,
    /// Lowest viewer altitude, m.
    pub z_min: f64,
    /// Highest viewer altitude, m.
    pub z_max: f64,
    /// Downward camera pitch, rad.
    pub camera_pitch: f64,
    /// Camera offset in the viewer frame, m.
    pub t_vs: [f64; 3],
    /// Horizontal field of view, rad.
    pub f_h: f64,
    /// Vertical field of view, rad.
    pub f_v: f64,
    /// Least sensor-to-marker distance, m.
    pub rho_min: f64,
    /// Greatest sensor-to-marker distance, m.
    pub rho_max: f64,
    /// SDSMM noise scale.
    pub kappa: f64,
    /// SDSMM anisotropy.
    pub lambda: f64,
    /// Target points on the footprint circle besides the marker centre.
    pub perimeter_points: u32,
    /// One of `DYFOS_MODEL_*`.
    pub model: u32,
    /// Which fields are given: `DYFOS_PARAM_*` bits; a clear bit means the SPEC default.
    pub set: u32,
}

macro_rules! c_params {
    ($($(#[doc = $doc:literal])* #[wire($slot:literal)] $name:ident: $ty:ty = $default:expr,)*) => {
        impl From<&dyfos_params> for WireParams {
            fn from(p: &dyfos_params) -> Self {
                WireParams { $($name: p.$name,)* set: p.set, reserved: 0 }
            }
        }

        impl dyfos_params {
            /// `params`' values with the given `set` bits.
            pub(crate) fn from_params(params: &Params, set: u32) -> Self {
                let w = WireParams::from(params);
                dyfos_params { $($name: w.$name,)* set }
            }
        }
    };
}

dyfos_shared::spec_params!(c_params);

impl dyfos_params {
    /// Decodes and validates (SPEC §11 ranges); unset fields take the default.
    pub(crate) fn to_params(self) -> Result<Params, Failure> {
        if self.set == 0 {
            // What `Params::try_from` gives for no field set, without its checks.
            return Ok(Params::default());
        }
        Params::try_from(&WireParams::from(&self)).map_err(Failure::from)
    }
}

/// A rendezvous query (SPEC §8): where should the viewer's camera be to localize
/// the rover on map `map`, whose a priori belief is `mean`/`cov`?
///
/// Every field's zero is its default: a request zeroed with `= {0}` or `memset`
/// asks for any map version, algorithm dyfos, seed 0, no budget, deadline or
/// deltas, every parameter at its SPEC default. So `dyfos_rendezvous_request r =
/// {0};` (or `dyfos_rendezvous_request_init(&r)`, the same request with the
/// parameter fields readable), then set `map`, `mean`, `cov` and whatever else differs.
#[repr(C)]
#[derive(Debug, Clone, Copy)]
pub struct dyfos_rendezvous_request {
    /// The map to search.
    pub map: u64,
    /// 1: the map must be at `expected_version` before `deltas_json` (else
    /// `DYFOS_STATUS_MAP_VERSION_MISMATCH`, nothing applied); 0: any version, and
    /// `expected_version` is ignored. Other values are `DYFOS_STATUS_INVALID_ARGUMENT`.
    pub has_expected_version: u32,
    /// The version the map must have before `deltas_json`, when
    /// `has_expected_version` is 1. The version counts deltas, not batches: each
    /// delta applied adds 1 (a voxel run with its cells is one delta).
    pub expected_version: u64,
    /// Belief mean (x, y, θ): m, m, rad.
    pub mean: [f64; 3],
    /// Belief covariance Σ⁻, rows; symmetric positive definite.
    pub cov: [[f64; 3]; 3],
    /// One of `DYFOS_ALGORITHM_*`.
    pub algorithm: u32,
    /// Seed of the search's random stream: the same request and seed give the same
    /// answer, bit for bit.
    pub seed: u64,
    /// Most candidates to evaluate; 0 for the algorithm's own limits.
    pub budget: u64,
    /// Time the daemon has from receipt to answer, µs; 0 for none. When it passes
    /// the answer is the best pose so far (`stop` = `DYFOS_STOP_DEADLINE`), or
    /// `DYFOS_STATUS_DEADLINE_EXCEEDED` if none was feasible yet.
    pub deadline_micros: u64,
    /// Parameters; fields whose `set` bit is clear take the SPEC default.
    pub params: dyfos_params,
    /// Map deltas applied (all or none) before the search, as a JSON array in the
    /// format of `dyfos map apply` files; NULL for none. Borrowed for the call only.
    /// At most `DYFOS_MAX_INLINE_RECORDS` records. Once valid they are committed to
    /// the map before the search and stay applied whatever it finds; each adds 1 to
    /// the map's version.
    pub deltas_json: *const c_char,
}

impl dyfos_rendezvous_request {
    /// The defaults `dyfos_rendezvous_request_init` writes: a zeroed request but for
    /// the parameter fields, which hold their defaults (with `set` 0, as zeros would
    /// mean the same). The belief is zero, to be set: a zero covariance is
    /// `DYFOS_STATUS_INVALID_BELIEF`.
    pub(crate) fn defaults() -> Self {
        dyfos_rendezvous_request {
            map: 0,
            has_expected_version: 0,
            expected_version: 0,
            mean: [0.0; 3],
            cov: [[0.0; 3]; 3],
            algorithm: DYFOS_ALGORITHM_DYFOS,
            seed: 0,
            budget: 0,
            deadline_micros: 0,
            params: dyfos_params::from_params(&Params::default(), 0),
            deltas_json: std::ptr::null(),
        }
    }

    /// The Rust client's request. Checks what the client needs valid (belief,
    /// algorithm, parameters) with the codes the daemon would use.
    ///
    /// # Safety
    /// `self.deltas_json` is NULL or a NUL-terminated string valid for the call.
    pub(crate) unsafe fn decode(&self) -> Result<RendezvousRequest, Failure> {
        let belief = Belief::new(self.mean, self.cov)
            .map_err(|e| Failure::new(DYFOS_STATUS_INVALID_BELIEF, format!("belief: {e}")))?;
        let algorithm = Algorithm::try_from(self.algorithm).map_err(|e| {
            Failure::new(
                DYFOS_STATUS_INVALID_ALGORITHM,
                format!("algorithm = {} is not an algorithm ({})", e.value, Algorithm::listing()),
            )
        })?;
        let params = self.params.to_params()?;
        let expected_version = match self.has_expected_version {
            0 => None,
            1 => Some(self.expected_version),
            flag => {
                return Err(Failure::invalid(format!(
                    "has_expected_version = {flag} must be 0 (any version) or 1 (the map must be at expected_version)"
                )));
            }
        };
        let deltas = if self.deltas_json.is_null() {
            Vec::new()
        } else {
            // SAFETY: non-null, and the caller promises a NUL-terminated string.
            let text = unsafe { crate::text(self.deltas_json, "deltas_json")? };
            deltas_from_json(text)?
        };
        Ok(RendezvousRequest {
            map: self.map,
            expected_version,
            belief,
            deltas,
            algorithm,
            seed: self.seed,
            budget: (self.budget != 0).then_some(self.budget),
            deadline: (self.deadline_micros != 0).then(|| Duration::from_micros(self.deadline_micros)),
            params,
        })
    }
}

/// Map deltas from a JSON array (the `dyfos map apply` file format, `docs/deltas.md`);
/// the message names the field and shows a valid example of the kind at fault.
pub(crate) fn deltas_from_json(text: &str) -> Result<Vec<MapDelta>, Failure> {
    dyfos_shared::map_json::deltas_from_json(text)
        .map_err(|e| Failure::new(DYFOS_STATUS_MALFORMED_DELTA, e.to_string()))
}

/// Candidates evaluated, split by the first constraint that rejected them.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct dyfos_evaluations {
    /// Every candidate evaluated.
    pub total: u64,
    /// Rejected: viewer outside the bounds or the altitude limits.
    pub workspace: u64,
    /// Rejected: viewer too close to an obstacle.
    pub collision: u64,
    /// Rejected: the line of sight to the rover is blocked.
    pub occlusion: u64,
}

/// The optimal sensor state found (SPEC §8), every field `dyfos solve` prints.
/// `dyfos_answer_to_json` gives the same JSON text.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct dyfos_answer {
    /// The algorithm that found it, one of `DYFOS_ALGORITHM_*`.
    pub algorithm: u32,
    /// Why the search stopped, one of `DYFOS_STOP_*`; `DYFOS_STOP_DEADLINE` means
    /// the best pose found in time, not converged.
    pub stop: u32,
    /// The map version searched: the version the request found, plus one for each
    /// of its deltas (the version counts deltas, not batches).
    pub map_version: u64,
    /// The candidate x = (ρ, ψ, φ, ψ_v): m, rad, rad, rad.
    pub x: [f64; 4],
    /// E = ln det Σ⁺.
    pub cost: f64,
    /// Sensor position p_s, m.
    pub sensor_position: [f64; 3],
    /// Sensor orientation R_ws as a quaternion (x, y, z, w), w ≥ 0.
    pub sensor_quaternion: [f64; 4],
    /// Viewer position p_v, m.
    pub viewer_position: [f64; 3],
    /// Viewer yaw ψ_v, rad.
    pub viewer_yaw: f64,
    /// Predicted measurement noise R, rows.
    pub r: [[f64; 2]; 2],
    /// Predicted posterior Σ⁺, rows.
    pub posterior: [[f64; 3]; 3],
    /// Evaluation counts.
    pub evaluations: dyfos_evaluations,
    /// The search's compute time, µs.
    pub micros: u64,
}

/// One map the daemon holds, as `dyfos_client_list_maps` describes it.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct dyfos_map_info {
    /// The map's id.
    pub map: u64,
    /// Its version (the version counts deltas, not batches).
    pub version: u64,
    /// Its bounds: x_min, y_min, x_max, y_max, m.
    pub bounds: [f64; 4],
    /// Its sun's elevation, rad.
    pub sun_elevation: f64,
    /// Its sun's azimuth, rad.
    pub sun_azimuth: f64,
    /// Its generation, a number the daemon picks when the map is made (created,
    /// uploaded, or loaded at start): a map deleted and made again under its id,
    /// back at version 0, has another one.
    pub generation: u32,
}

impl From<&MapInfo> for dyfos_map_info {
    fn from(m: &MapInfo) -> Self {
        dyfos_map_info {
            map: m.id,
            version: m.version,
            bounds: m.bounds.to_array(),
            sun_elevation: m.sun.elevation,
            sun_azimuth: m.sun.azimuth,
            generation: m.generation,
        }
    }
}

impl From<&Answer> for dyfos_answer {
    fn from(a: &Answer) -> Self {
        let e = a.evaluations;
        dyfos_answer {
            algorithm: a.algorithm.code(),
            stop: a.stop.code(),
            map_version: a.map_version,
            x: a.x.to_array(),
            cost: a.cost,
            sensor_position: a.sensor_position.coords.into(),
            sensor_quaternion: canonical_xyzw(&a.sensor_orientation),
            viewer_position: a.viewer_position.coords.into(),
            viewer_yaw: a.viewer_yaw,
            r: a.r,
            posterior: rows3(&a.posterior),
            evaluations: dyfos_evaluations {
                total: e.total,
                workspace: e.workspace,
                collision: e.collision,
                occlusion: e.occlusion,
            },
            micros: a.micros,
        }
    }
}

impl dyfos_answer {
    /// Rebuilds the answer (for its JSON); codes written by the caller are checked.
    pub(crate) fn decode(&self) -> Result<Answer, Failure> {
        let a = self;
        let algorithm = Algorithm::try_from(a.algorithm)
            .map_err(|e| Failure::invalid(format!("answer.algorithm = {} is not an algorithm", e.value)))?;
        let stop = StopReason::try_from(a.stop)
            .map_err(|e| Failure::invalid(format!("answer.stop = {} is not a stop reason", e.value)))?;
        let [i, j, k, w] = a.sensor_quaternion;
        let e = a.evaluations;
        Ok(Answer {
            algorithm,
            // Not `from_array`: re-wrapping the yaw could change its last bit.
            x: SensorState { rho: a.x[0], psi: a.x[1], phi: a.x[2], yaw: a.x[3] },
            cost: a.cost,
            sensor_position: Point3::from(a.sensor_position),
            sensor_orientation: UnitQuaternion::new_unchecked(nalgebra_quaternion(w, i, j, k)),
            viewer_position: Point3::from(a.viewer_position),
            viewer_yaw: a.viewer_yaw,
            r: a.r,
            posterior: Matrix3::from_fn(|r, c| a.posterior[r][c]),
            evaluations: EvalStats {
                total: e.total,
                workspace: e.workspace,
                collision: e.collision,
                occlusion: e.occlusion,
            },
            micros: a.micros,
            map_version: a.map_version,
            stop,
        })
    }
}

fn nalgebra_quaternion(w: f64, i: f64, j: f64, k: f64) -> dyfos_shared::prelude::na::Quaternion<f64> {
    dyfos_shared::prelude::na::Quaternion::new(w, i, j, k)
}

/// A required input pointer, or the null-parameter failure naming it.
///
/// # Safety
/// `ptr` is NULL or points to a valid, initialised `T` for `'a`.
pub(crate) unsafe fn required<'a, T>(ptr: *const T, what: &str) -> Result<&'a T, Failure> {
    // SAFETY: as the caller promises.
    unsafe { ptr.as_ref() }.ok_or_else(|| Failure::null(what))
}

/// Fails naming `what` if the output pointer `ptr` is NULL (checked before any work).
pub(crate) fn non_null<T>(ptr: *mut T, what: &str) -> Result<(), Failure> {
    if ptr.is_null() {
        return Err(Failure {
            code: DYFOS_STATUS_NULL_PARAMETER,
            message: format!("output `{what}` is NULL; pass where to write it"),
        });
    }
    Ok(())
}

/// Writes `value` through a required output pointer, or fails naming it.
///
/// # Safety
/// `ptr` is NULL or points to memory writable as one `T` (initialised or not).
pub(crate) unsafe fn write<T>(ptr: *mut T, what: &str, value: T) -> Result<(), Failure> {
    non_null(ptr, what)?;
    // SAFETY: non-null and writable, as the caller promises; `write` does not read
    // or drop the old (possibly uninitialised) value.
    unsafe { ptr.write(value) };
    Ok(())
}

/// Writes `value` through an optional output pointer (NULL: not wanted).
///
/// # Safety
/// `ptr` is NULL or points to memory writable as one `T` (initialised or not).
pub(crate) unsafe fn write_optional<T>(ptr: *mut T, value: T) {
    if !ptr.is_null() {
        // SAFETY: non-null and writable, as the caller promises.
        unsafe { ptr.write(value) };
    }
}

/// Reads a NUL-terminated string argument.
///
/// # Safety
/// `ptr` is NULL or points to a NUL-terminated string valid for `'a`.
pub(crate) unsafe fn c_str<'a>(ptr: *const c_char) -> Option<&'a CStr> {
    // SAFETY: as the caller promises.
    (!ptr.is_null()).then(|| unsafe { CStr::from_ptr(ptr) })
}

#[cfg(test)]
mod tests {
    use super::*;
    use dyfos_shared::params::ModelKind;

    /// The `#define PREFIX<NAME> <code>u` lines of the header (which the header test
    /// keeps equal to cbindgen's output of this file's constants).
    fn header_codes(prefix: &str) -> Vec<(String, u32)> {
        let header = include_str!("../include/dyfos.h");
        let mut out: Vec<(String, u32)> = header
            .lines()
            .filter_map(|l| l.strip_prefix("#define ")?.strip_prefix(prefix))
            .filter_map(|rest| {
                let (name, code) = rest.split_once(' ')?;
                Some((name.to_string(), code.trim_end_matches('u').parse().ok()?))
            })
            .collect();
        out.sort_by_key(|(_, code)| *code);
        out
    }

    /// Each C constant is its set's wire code, named after it; none is missing or extra.
    #[test]
    fn c_codes_are_the_wire_codes() {
        fn c_names(names: &[&str]) -> Vec<String> {
            names.iter().map(|n| n.to_uppercase().replace('-', "_")).collect()
        }
        let sets: [(&str, Vec<String>, Vec<u32>); 3] = [
            ("DYFOS_ALGORITHM_", c_names(Algorithm::NAMES), Algorithm::ALL.map(Algorithm::code).to_vec()),
            ("DYFOS_MODEL_", c_names(ModelKind::NAMES), ModelKind::ALL.map(ModelKind::code).to_vec()),
            ("DYFOS_STOP_", c_names(StopReason::NAMES), StopReason::ALL.map(StopReason::code).to_vec()),
        ];
        for (prefix, names, codes) in sets {
            let expected: Vec<(String, u32)> = names.into_iter().zip(codes).collect();
            assert_eq!(header_codes(prefix), expected, "{prefix}*");
        }
    }

    /// The C header spells the parameters out (cbindgen cannot see through the
    /// list's macro): `dyfos_params`' fields, the `DYFOS_PARAM_*` bits and the C++
    /// accessors are each the list's, in its wire order.
    #[test]
    fn c_and_cpp_params_follow_wire_params_fields() {
        let header = include_str!("../include/dyfos.h");
        let bits: Vec<String> = header
            .lines()
            .filter_map(|l| l.strip_prefix("#define DYFOS_PARAM_"))
            .map(|l| l.split_whitespace().collect::<Vec<_>>().join(" "))
            .collect();
        let expected: Vec<String> =
            WireParams::FIELDS.iter().enumerate().map(|(i, f)| format!("{} (1u << {i})", f.to_uppercase())).collect();
        assert_eq!(bits, expected);
        assert_eq!(DYFOS_PARAMS_ALL_SET, WireParams::ALL_SET);

        let body = header.split("typedef struct dyfos_params {").nth(1).and_then(|b| b.split("} dyfos_params;").next());
        let fields: Vec<&str> = body
            .expect("dyfos_params in dyfos.h")
            .lines()
            .map(str::trim)
            .filter(|l| !l.is_empty() && !l.starts_with('/') && !l.starts_with('*'))
            .filter_map(|l| l.trim_end_matches(';').split_whitespace().last())
            .map(|f| f.split('[').next().unwrap_or(f))
            .collect();
        let mut expected: Vec<&str> = WireParams::FIELDS.to_vec();
        expected.push("set");
        assert_eq!(fields, expected, "dyfos_params' fields in dyfos.h");

        let cpp = include_str!("../include/dyfos.hpp");
        for field in WireParams::FIELDS {
            let bit = format!("DYFOS_PARAM_{}", field.to_uppercase());
            assert!(
                cpp.contains(&format!("DYFOS_HPP_FIELD({field}, ")) || cpp.contains(&format!("Params& {field}(")),
                "dyfos.hpp has no setter for {field}"
            );
            assert!(cpp.contains(&bit), "dyfos.hpp does not use {bit}");
        }
    }

    #[test]
    fn params_round_trip_through_the_c_struct() {
        let changed = Params { lambda: 2.5, rho_min: 1.5, ..Params::default() };
        let all = dyfos_params::from_params(&changed, DYFOS_PARAMS_ALL_SET);
        assert_eq!(all.to_params().unwrap(), changed);
        // Bits clear: the defaults, whatever the fields hold.
        assert_eq!(dyfos_params { kappa: f64::NAN, ..all }.with_set(0).to_params().unwrap(), Params::default());
        let lambda_only = all.with_set(DYFOS_PARAM_LAMBDA);
        assert_eq!(lambda_only.to_params().unwrap(), Params { lambda: 2.5, ..Params::default() });
        let bad = dyfos_params { rho_min: 9.0, ..all };
        assert_eq!(bad.to_params().unwrap_err().code, crate::status::DYFOS_STATUS_INVALID_PARAMS);
        let bad_bits = all.with_set(1 << 17);
        assert_eq!(bad_bits.to_params().unwrap_err().code, crate::status::DYFOS_STATUS_INVALID_PARAMS);
    }

    impl dyfos_params {
        fn with_set(self, set: u32) -> Self {
            dyfos_params { set, ..self }
        }
    }

    #[test]
    fn answers_round_trip_through_the_c_struct_bit_for_bit() {
        let answer = Answer {
            algorithm: Algorithm::Brute,
            x: SensorState { rho: 3.25, psi: 0.1, phi: -2.0, yaw: 1.0e-9 },
            cost: -7.123456789,
            sensor_position: Point3::new(1.0, 2.0, 3.0),
            sensor_orientation: UnitQuaternion::from_euler_angles(0.1, 0.2, 2.9),
            viewer_position: Point3::new(1.5, 2.5, 3.5),
            viewer_yaw: 2.9,
            r: [[0.1, 0.01], [0.01, 0.2]],
            posterior: Matrix3::new(0.1, 0.0, 0.0, 0.0, 0.2, 0.0, 0.0, 0.0, 0.3),
            evaluations: EvalStats { total: 10, workspace: 1, collision: 2, occlusion: 3 },
            micros: 99,
            map_version: 4,
            stop: StopReason::Deadline,
        };
        let c = dyfos_answer::from(&answer);
        assert_eq!(c.algorithm, DYFOS_ALGORITHM_BRUTE);
        assert_eq!(c.stop, DYFOS_STOP_DEADLINE);
        let back = c.decode().unwrap();
        assert_eq!(back.to_json(), answer.to_json());
        assert!(dyfos_answer { stop: 5, ..c }.decode().is_err());
        assert!(dyfos_answer { algorithm: 5, ..c }.decode().is_err());
    }

    #[test]
    fn a_default_request_needs_a_belief() {
        let r = dyfos_rendezvous_request::defaults();
        // SAFETY: no deltas pointer.
        let err = unsafe { r.decode() }.unwrap_err();
        assert_eq!(err.code, DYFOS_STATUS_INVALID_BELIEF);
        let good = dyfos_rendezvous_request {
            mean: [0.0, 0.0, 0.3],
            cov: [[0.2, 0.0, 0.0], [0.0, 0.1, 0.0], [0.0, 0.0, 0.05]],
            ..r
        };
        // SAFETY: no deltas pointer.
        let request = unsafe { good.decode() }.unwrap();
        assert_eq!(
            (request.params, request.algorithm, request.expected_version),
            (Params::default(), Algorithm::Dyfos, None)
        );
        let bad_algorithm = dyfos_rendezvous_request { algorithm: 5, ..good };
        // SAFETY: no deltas pointer.
        assert_eq!(unsafe { bad_algorithm.decode() }.unwrap_err().code, DYFOS_STATUS_INVALID_ALGORITHM);
    }

    /// The request the zeroed belief-set struct decodes to.
    fn decoded(r: dyfos_rendezvous_request) -> Result<RendezvousRequest, Failure> {
        let with_belief = dyfos_rendezvous_request {
            mean: [0.0, 0.0, 0.3],
            cov: [[0.2, 0.0, 0.0], [0.0, 0.1, 0.0], [0.0, 0.0, 0.05]],
            map: 7,
            ..r
        };
        // SAFETY: `deltas_json` is NULL or a C string literal.
        unsafe { with_belief.decode() }
    }

    #[test]
    fn a_zeroed_request_is_the_default_request_and_asks_for_any_version() {
        // SAFETY: every field is a number or a raw pointer, for which zero is valid.
        let zeroed: dyfos_rendezvous_request = unsafe { std::mem::zeroed() };
        let from_zero = decoded(zeroed).unwrap();
        assert_eq!(from_zero.expected_version, None);
        assert_eq!(from_zero, decoded(dyfos_rendezvous_request::defaults()).unwrap());
        let at_zero = decoded(dyfos_rendezvous_request { has_expected_version: 1, ..zeroed }).unwrap();
        assert_eq!(at_zero.expected_version, Some(0));
        let at_five =
            decoded(dyfos_rendezvous_request { has_expected_version: 1, expected_version: 5, ..zeroed }).unwrap();
        assert_eq!(at_five.expected_version, Some(5));
        let ignored = decoded(dyfos_rendezvous_request { expected_version: 5, ..zeroed }).unwrap();
        assert_eq!(ignored.expected_version, None);
        let bad_flag = decoded(dyfos_rendezvous_request { has_expected_version: 2, ..zeroed });
        assert_eq!(bad_flag.unwrap_err().code, crate::status::DYFOS_STATUS_INVALID_ARGUMENT);
    }

    #[test]
    fn deltas_json_that_does_not_parse_is_a_malformed_delta() {
        for text in [c"[not json", c"{}", c"[{\"Teleport\": {}}]"] {
            let r = dyfos_rendezvous_request { deltas_json: text.as_ptr(), ..dyfos_rendezvous_request::defaults() };
            let failure = decoded(r).unwrap_err();
            assert_eq!(failure.code, DYFOS_STATUS_MALFORMED_DELTA, "{text:?}: {}", failure.message);
        }
        let good = dyfos_rendezvous_request {
            deltas_json: c"[{\"clear\": {}}]".as_ptr(),
            ..dyfos_rendezvous_request::defaults()
        };
        assert_eq!(decoded(good).unwrap().deltas, vec![MapDelta::Clear]);
    }

    #[test]
    fn the_batch_limits_are_the_clients() {
        use dyfos_shared::limits::{MAX_DELTAS_PER_MESSAGE, MAX_INLINE_DELTAS};
        assert_eq!(DYFOS_MAX_BATCH_RECORDS as usize, MAX_DELTAS_PER_MESSAGE);
        assert_eq!(DYFOS_MAX_INLINE_RECORDS as usize, MAX_INLINE_DELTAS);
        assert_eq!(DYFOS_MAX_MAPS as usize, dyfos_shared::limits::MAX_MAPS);
    }
}
