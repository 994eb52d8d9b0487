//! Scenario files (SPEC §11): one JSON document describes one query.
//!
//! Parsing is strict: unknown fields, non-finite numbers, duplicate obstacle ids, a
//! covariance that is not symmetric positive definite and out-of-range parameters
//! are all errors that name the field, e.g. `params.rho_min = 7 must be < rho_max = 6`.
//!
//! ```
//! use dyfos_shared::scenario::Scenario;
//!
//! let json = r#"{"bounds": [-10, -10, 10, 10], "sun": {"elevation": 0.7, "azimuth": 2.1},
//!   "obstacles": [], "rover": {"mean": [0, 0, 0.3], "cov": [[0.2, 0, 0], [0, 0.1, 0], [0, 0, 0.05]]},
//!   "params": {"rho_mim": 2.0}}"#;
//! let err = Scenario::from_json(json).unwrap_err().to_string();
//! assert!(err.starts_with("params: unknown field `rho_mim`"), "{err}");
//! assert!(err.contains("did you mean `rho_min`?"), "{err}");
//! ```

use crate::map_json::{RawObstacle, RawSun, RawVoxels, world_of};
use crate::math::{Point3, rows3};
use crate::params::{ParamValue, Params};
use crate::posterior::Belief;
use crate::world::{VoxelGrid, World};
use serde::{Deserialize, Deserializer, Serialize};

/// A validated scenario: the world, the rendezvous belief and the parameters.
#[derive(Debug, Clone, PartialEq)]
pub struct Scenario {
    /// The environment model M, at version 0.
    pub world: World,
    /// The a priori rover belief at the rendezvous.
    pub belief: Belief,
    /// Parameters, SPEC defaults overridden by the file's `params`.
    pub params: Params,
}

/// A scenario that cannot be used, with the path of the field at fault.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ScenarioError {
    /// Not JSON, or not of the scenario's shape (unknown field, wrong type, missing field).
    #[error("{}{message} (line {line}, column {column})", path_prefix(path))]
    Malformed {
        /// Dotted path of the field, e.g. `params.rho_min` (empty at top level).
        path: String,
        /// serde's message, with a suggestion for misspelt fields.
        message: String,
        /// 1-based line.
        line: usize,
        /// 1-based column.
        column: usize,
    },
    /// Well-formed, but a value is out of range or inconsistent.
    #[error("{path}{}{message}", if message.starts_with("= ") { " " } else { ": " })]
    Invalid {
        /// Dotted path of the field.
        path: String,
        /// What is wrong and what would be right.
        message: String,
    },
}

fn path_prefix(path: &str) -> String {
    if path.is_empty() || path == "." { String::new() } else { format!("{path}: ") }
}

impl ScenarioError {
    /// The path of the field at fault.
    pub fn path(&self) -> &str {
        match self {
            ScenarioError::Malformed { path, .. } | ScenarioError::Invalid { path, .. } => path,
        }
    }

    pub(crate) fn invalid(path: impl Into<String>, message: impl ToString) -> Self {
        ScenarioError::Invalid { path: path.into(), message: message.to_string() }
    }
}

/// A record that must be written as a JSON object (SPEC §11). serde's derived
/// structs also accept their fields in order as a JSON array (`"sun": [0.7, 2.1]`);
/// this wrapper asks the parser for an object only, so an array, like `null`, is
/// "invalid type: sequence, expected a JSON object". Other documents built on
/// scenarios (the mission files of `dyfos-rover`) use it for their records too.
#[derive(Debug)]
pub struct Object<T>(pub T);

impl<'de, T: Deserialize<'de>> Deserialize<'de> for Object<T> {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct ObjectVisitor<T>(std::marker::PhantomData<T>);
        impl<'de, T: Deserialize<'de>> serde::de::Visitor<'de> for ObjectVisitor<T> {
            type Value = T;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("a JSON object")
            }
            fn visit_map<A: serde::de::MapAccess<'de>>(self, map: A) -> Result<T, A::Error> {
                T::deserialize(serde::de::value::MapAccessDeserializer::new(map))
            }
        }
        d.deserialize_map(ObjectVisitor(std::marker::PhantomData)).map(Object)
    }
}

impl<T> std::ops::Deref for Object<T> {
    type Target = T;
    fn deref(&self) -> &T {
        &self.0
    }
}

impl<T: Serialize> Serialize for Object<T> {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        self.0.serialize(s)
    }
}

/// Deserializes a field that may be absent but, if present, must not be `null`.
pub(crate) fn present<'de, D: Deserializer<'de>, T: Deserialize<'de>>(d: D) -> Result<Option<T>, D::Error> {
    T::deserialize(d).map(Some)
}

#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawScenario {
    bounds: [f64; 4],
    sun: Object<RawSun>,
    obstacles: Vec<Object<RawObstacle>>,
    rover: Object<RawRover>,
    #[serde(default, deserialize_with = "present", skip_serializing_if = "Option::is_none")]
    params: Option<Object<RawParams>>,
    #[serde(default, deserialize_with = "present", skip_serializing_if = "Option::is_none")]
    voxels: Option<Object<RawVoxels>>,
    #[serde(default, deserialize_with = "present", skip_serializing_if = "Option::is_none")]
    octomap: Option<Object<RawOctomap>>,
}

#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawOctomap {
    file: String,
    #[serde(default, deserialize_with = "present", skip_serializing_if = "Option::is_none")]
    origin: Option<[f64; 3]>,
}

#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawRover {
    mean: [f64; 3],
    cov: [[f64; 3]; 3],
}

macro_rules! raw_params {
    ($($(#[doc = $doc:literal])* #[wire($slot:literal)] $name:ident: $ty:ty = $default:expr,)*) => {
        /// A `params` object: every field optional.
        #[derive(Debug, Default, Serialize, Deserialize)]
        #[serde(deny_unknown_fields)]
        struct RawParams {
            $(
                #[serde(default, deserialize_with = "present", skip_serializing_if = "Option::is_none")]
                $name: Option<<$ty as ParamValue>::File>,
            )*
        }

        impl RawParams {
            /// The parameters given, SPEC defaults for the others.
            fn resolve(&self) -> Params {
                let d = Params::default();
                Params { $($name: self.$name.map_or(d.$name, ParamValue::from_file),)* }
            }

            /// Every parameter written out (files written by us are explicit).
            fn explicit(p: &Params) -> Self {
                RawParams { $($name: Some(p.$name.to_file()),)* }
            }
        }
    };
}

crate::spec_params!(raw_params);

/// Every parameter as a `params` object, as scenario files and recordings spell it
/// ([`params_from_json`] reads it back, bit for bit).
pub fn params_to_json(p: &Params) -> serde_json::Value {
    serde_json::to_value(RawParams::explicit(p)).expect("numbers and names always serialize")
}

/// Edit distance, for "did you mean" suggestions.
fn levenshtein(a: &str, b: &str) -> usize {
    let b: Vec<char> = b.chars().collect();
    let mut row: Vec<usize> = (0..=b.len()).collect();
    for (i, ca) in a.chars().enumerate() {
        let mut prev = row[0];
        row[0] = i + 1;
        for (j, cb) in b.iter().enumerate() {
            let cur = row[j + 1];
            row[j + 1] = (prev + usize::from(ca != *cb)).min(row[j] + 1).min(cur + 1);
            prev = cur;
        }
    }
    row[b.len()]
}

/// Appends "did you mean `x`?" to serde's unknown-field and unknown-variant
/// messages. Names are compared without case and underscores, so that
/// `SetSun` finds `set_sun`.
pub fn suggest(message: String) -> String {
    let Some(rest) = message.strip_prefix("unknown field `").or_else(|| message.strip_prefix("unknown variant `"))
    else {
        return message;
    };
    let Some((field, expected)) = rest.split_once('`') else {
        return message;
    };
    let plain = |name: &str| name.to_lowercase().replace('_', "");
    let best = expected
        .split('`')
        .skip(1)
        .step_by(2)
        .map(|c| (levenshtein(&plain(field), &plain(c)), c))
        .min()
        .filter(|(d, c)| *d <= 2.max(c.len() / 3));
    match best {
        Some((_, c)) => format!("{message} (did you mean `{c}`?)"),
        None => message,
    }
}

fn inner_is_unknown_field(e: &serde_path_to_error::Error<serde_json::Error>) -> bool {
    e.inner().to_string().starts_with("unknown field")
}

/// A parse error of the field at `path`, with serde_json's position.
fn malformed(path: String, inner: serde_json::Error) -> ScenarioError {
    let (line, column) = (inner.line(), inner.column());
    // serde_json appends " at line L column C"; we print those ourselves.
    let text = inner.to_string();
    let message = match text.rfind(" at line ") {
        Some(i) => text[..i].to_string(),
        None => text,
    };
    ScenarioError::Malformed { path, message: suggest(message), line, column }
}

/// Parses exactly one JSON value of type `T` (white space around it allowed,
/// nothing after it); errors name the field, under `root` (`params.rho_min`,
/// `deltas[2].set_sun`).
pub(crate) fn parse_json<T: serde::de::DeserializeOwned>(json: &str, root: &str) -> Result<T, ScenarioError> {
    let de = &mut serde_json::Deserializer::from_str(json);
    let value: T = serde_path_to_error::deserialize(&mut *de).map_err(|e| {
        let mut path = e.path().to_string();
        if inner_is_unknown_field(&e) {
            // The path ends in the unknown name itself; report its parent.
            path = path.rsplit_once('.').map(|(parent, _)| parent.to_string()).unwrap_or_default();
        }
        let path = match path.as_str() {
            _ if root.is_empty() => path,
            "." | "" => root.to_string(),
            p if p.starts_with('[') => format!("{root}{p}"),
            p => format!("{root}.{p}"),
        };
        malformed(path, e.into_inner())
    })?;
    de.end().map_err(|e| malformed(root.to_string(), e))?;
    Ok(value)
}

/// As [`parse_json`], for a document that must be a JSON object.
fn parse_object<T: serde::de::DeserializeOwned>(json: &str, root: &str) -> Result<T, ScenarioError> {
    parse_json::<Object<T>>(json, root).map(|o| o.0)
}

/// Parses a scenario's `params` object on its own (SPEC §11 names, every field
/// optional, the rest SPEC defaults), validated: what bindings take for "params as
/// a dict". Errors name the field as in a scenario, e.g. `params.rho_min`.
///
/// ```
/// use dyfos_shared::params::Params;
/// use dyfos_shared::scenario::params_from_json;
///
/// assert_eq!(params_from_json(r#"{"lambda": 2.0}"#).unwrap(), Params { lambda: 2.0, ..Params::default() });
/// assert_eq!(params_from_json("{}").unwrap(), Params::default());
/// assert!(params_from_json(r#"{"rho_mim": 2}"#).unwrap_err().to_string().contains("rho_min"));
/// ```
pub fn params_from_json(json: &str) -> Result<Params, ScenarioError> {
    let raw: RawParams = parse_object(json, "params")?;
    let params = raw.resolve();
    params
        .validate()
        .map_err(|e| ScenarioError::invalid(format!("params.{}", e.field), format!("= {} {}", e.value, e.rule)))?;
    Ok(params)
}

impl Scenario {
    /// Parses and validates a scenario document: exactly one JSON object, white
    /// space around it allowed, nothing else after it. A scenario with an `octomap`
    /// names a file, which this cannot read: use [`Scenario::from_json_with_files`].
    pub fn from_json(json: &str) -> Result<Self, ScenarioError> {
        Self::from_json_with_files(json, |path| {
            Err(format!(
                "cannot read `{path}`: this scenario was not read from a file; load it with its path (dyfos does)"
            ))
        })
    }

    /// As [`Scenario::from_json`], with `read_file` giving the bytes of the files the
    /// scenario names (its `octomap.file`, as written; the caller resolves a relative
    /// path against the scenario's folder, SPEC §11).
    ///
    /// *Interpretation (SPEC §1, §11):* the OctoMap's occupied cells become the
    /// world's voxel grid, of the file's resolution, with `octomap.origin` (default
    /// 0, 0, 0) as the minimum corner of cell (0, 0, 0); at most
    /// [`crate::limits::MAX_OCCUPIED_VOXELS`] cells, else an error naming the count.
    pub fn from_json_with_files(
        json: &str,
        read_file: impl FnOnce(&str) -> Result<Vec<u8>, String>,
    ) -> Result<Self, ScenarioError> {
        let raw: RawScenario = parse_object(json, "")?;
        let octomap = match &raw.octomap {
            None => None,
            Some(_) if raw.voxels.is_some() => {
                return Err(ScenarioError::invalid("octomap", "a scenario carries `voxels` or `octomap`, not both"));
            }
            Some(o) => {
                let bytes = read_file(&o.file).map_err(|e| ScenarioError::invalid("octomap.file", e))?;
                let map = crate::world::octomap::Octomap::from_bt(&bytes)
                    .map_err(|e| ScenarioError::invalid("octomap.file", format!("{}: {e}", o.file)))?;
                let origin = o.origin.unwrap_or([0.0; 3]);
                Some(map.to_voxels(Point3::from(origin)).map_err(|e| ScenarioError::invalid("octomap", e))?)
            }
        };
        Self::from_raw(raw, octomap)
    }

    fn from_raw(raw: RawScenario, octomap: Option<VoxelGrid>) -> Result<Self, ScenarioError> {
        let world = world_of(0, raw.bounds, &raw.sun, &raw.obstacles, raw.voxels.as_deref(), octomap)?;
        let belief = Belief::new(raw.rover.mean, raw.rover.cov).map_err(|e| match e {
            crate::posterior::BeliefError::Mean { index, value } => {
                ScenarioError::invalid(format!("rover.mean[{index}]"), format!("= {value} must be a finite number"))
            }
            crate::posterior::BeliefError::Covariance(c) => {
                ScenarioError::invalid("rover.cov", format!("{c}: need a symmetric positive definite matrix"))
            }
        })?;
        let params = raw.params.as_ref().map(|p| p.resolve()).unwrap_or_default();
        params
            .validate()
            .map_err(|e| ScenarioError::invalid(format!("params.{}", e.field), format!("= {} {}", e.value, e.rule)))?;
        Ok(Scenario { world, belief, params })
    }

    /// The scenario as a JSON document that [`Scenario::from_json`] reads back to an
    /// equal scenario; every parameter is written out.
    pub fn to_json(&self) -> String {
        let w = &self.world;
        let raw = RawScenario {
            bounds: w.bounds().to_array(),
            sun: Object(RawSun::of(w.sun())),
            obstacles: w.obstacles().iter().map(|(id, o)| Object(RawObstacle::of(*id, o))).collect(),
            rover: Object(RawRover { mean: self.belief.mean.into(), cov: rows3(self.belief.cov.matrix()) }),
            params: Some(Object(RawParams::explicit(&self.params))),
            voxels: w.voxels().map(|v| Object(RawVoxels::of(v))),
            octomap: None,
        };
        serde_json::to_string_pretty(&raw).expect("scenario serializes")
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::params::ModelKind;

    const GOOD: &str = r#"{
      "bounds": [-10.0, -10.0, 10.0, 10.0],
      "sun": {"elevation": 0.7, "azimuth": 2.1},
      "obstacles": [
        {"id": 1, "cylinder": {"x": 2.0, "y": 1.0, "radius": 0.5, "height": 10.0}},
        {"id": 2, "box": {"min": [4.0, 4.0, 0.0], "max": [5.0, 6.0, 3.0]}}
      ],
      "rover": {"mean": [0.0, 0.0, 0.3],
                "cov": [[0.2, 0.05, 0.0], [0.05, 0.1, 0.0], [0.0, 0.0, 0.05]]},
      "params": {"model": "paper"}
    }"#;

    fn with(from: &str, to: &str) -> Result<Scenario, ScenarioError> {
        assert!(GOOD.contains(from), "test edit `{from}` does not apply");
        Scenario::from_json(&GOOD.replacen(from, to, 1))
    }

    #[test]
    fn spec_example_parses() {
        let s = Scenario::from_json(GOOD).unwrap();
        assert_eq!(s.world.obstacles().len(), 2);
        assert_eq!(s.params.model, ModelKind::Paper);
        assert_eq!(s.belief.mean.z, 0.3);
    }

    #[test]
    fn round_trips_through_json() {
        let s = with("\"params\": {\"model\": \"paper\"}", r#""params": {"model": "anisotropic", "lambda": 2.0}, "voxels": {"resolution": 0.1, "origin": [0, 0, 0], "occupied": [[1, 2, 3]]}"#).unwrap();
        assert_eq!(Scenario::from_json(&s.to_json()).unwrap(), s);
    }

    /// Each bad edit of the SPEC example, and the path its error must name.
    #[test]
    fn every_validation_error_names_its_field() {
        let cases = [
            ("\"sun\"", "\"sunn\"", ""),
            ("\"model\": \"paper\"", "\"model\": \"paper\", \"rho_mim\": 1", "params"),
            ("\"model\": \"paper\"", "\"model\": \"neural\"", "params.model"),
            ("\"model\": \"paper\"", "\"perimeter_points\": 8.0", "params.perimeter_points"),
            ("\"model\": \"paper\"", "\"perimeter_points\": -1", "params.perimeter_points"),
            ("\"model\": \"paper\"", "\"perimeter_points\": 4097", "params.perimeter_points"),
            ("\"model\": \"paper\"", "\"rho_min\": 7", "params.rho_min"),
            ("\"model\": \"paper\"", "\"f_h\": 3.2", "params.f_h"),
            ("\"model\": \"paper\"", "\"kappa\": 0", "params.kappa"),
            ("\"model\": \"paper\"", "\"lambda\": -1", "params.lambda"),
            ("\"model\": \"paper\"", "\"z_min\": 9", "params.z_max"),
            ("\"model\": \"paper\"", "\"camera_pitch\": 2", "params.camera_pitch"),
            ("\"model\": \"paper\"", "\"marker_height\": -0.1", "params.marker_height"),
            ("\"model\": \"paper\"", "\"rover_radius\": 0", "params.rover_radius"),
            ("\"params\": {\"model\": \"paper\"}", "\"params\": null", "params"),
            ("\"params\": {\"model\": \"paper\"}", "\"params\": 3", "params"),
            ("\"radius\": 0.5", "\"radius\": -0.5", "obstacles[0].cylinder"),
            ("\"height\": 10.0", "\"height\": 0", "obstacles[0].cylinder"),
            ("\"max\": [5.0, 6.0, 3.0]", "\"max\": [5.0, 6.0, 0.0]", "obstacles[1].box"),
            ("{\"id\": 2, \"box\"", "{\"id\": 1, \"box\"", "obstacles[1].id"),
            ("\"cylinder\": {\"x\": 2.0", "\"cone\": {\"x\": 2.0", "obstacles[0]"),
            ("[-10.0, -10.0, 10.0, 10.0]", "[10.0, -10.0, -10.0, 10.0]", "bounds"),
            ("[-10.0, -10.0, 10.0, 10.0]", "[-10.0, -10.0, 1e999, 10.0]", "bounds[2]"),
            ("\"elevation\": 0.7", "\"elevation\": 1.7", "sun.elevation"),
            ("[0.05, 0.1, 0.0]", "[0.06, 0.1, 0.0]", "rover.cov"),
            ("[0.0, 0.0, 0.05]]", "[0.0, 0.0, -0.05]]", "rover.cov"),
            ("\"mean\": [0.0, 0.0, 0.3]", "\"mean\": [0.0, NaN, 0.3]", "rover.mean[1]"),
            (
                "\"params\": {\"model\": \"paper\"}",
                "\"voxels\": {\"resolution\": 0, \"origin\": [0,0,0], \"occupied\": []}",
                "voxels",
            ),
        ];
        for (from, to, path) in cases {
            let err = with(from, to).unwrap_err();
            assert_eq!(err.path(), path, "`{to}` gave `{err}`");
            assert!(!err.to_string().is_empty());
        }
        assert!(matches!(Scenario::from_json("{"), Err(ScenarioError::Malformed { .. })));
        assert!(matches!(Scenario::from_json("[]"), Err(ScenarioError::Malformed { .. })));
    }

    /// SPEC §11: `params` and `voxels` are objects if present, and so is every other
    /// record. serde's derived structs would also take the fields in order as a JSON
    /// array (`"sun": [0.7, 2.1]`); that is not a scenario.
    #[test]
    fn records_written_as_arrays_are_rejected() {
        let cases = [
            ("\"params\": {\"model\": \"paper\"}", "\"params\": []", "params"),
            ("\"params\": {\"model\": \"paper\"}", "\"voxels\": [0.5, [0, 0, 0], [[1, 2, 3]]]", "voxels"),
            ("{\"elevation\": 0.7, \"azimuth\": 2.1}", "[0.7, 2.1]", "sun"),
            (
                "{\"x\": 2.0, \"y\": 1.0, \"radius\": 0.5, \"height\": 10.0}",
                "[2.0, 1.0, 0.5, 10.0]",
                "obstacles[0].cylinder",
            ),
            (
                "{\"min\": [4.0, 4.0, 0.0], \"max\": [5.0, 6.0, 3.0]}",
                "[[4.0, 4.0, 0.0], [5.0, 6.0, 3.0]]",
                "obstacles[1].box",
            ),
            ("{\"id\": 2, \"box\": {\"min\": [4.0, 4.0, 0.0], \"max\": [5.0, 6.0, 3.0]}}", "[2]", "obstacles[1]"),
            (
                "\"rover\": {\"mean\"",
                "\"rover\": [[0, 0, 0], [[1, 0, 0], [0, 1, 0], [0, 0, 1]]], \"unused\": {\"mean\"",
                "rover",
            ),
        ];
        for (from, to, path) in cases {
            let err = with(from, to).unwrap_err();
            assert!(matches!(err, ScenarioError::Malformed { .. }), "`{to}` gave `{err}`");
            assert_eq!(err.path(), path, "`{to}` gave `{err}`");
            assert!(err.to_string().contains("expected a JSON object"), "`{to}` gave `{err}`");
        }
        let positional = r#"[[-10, -10, 10, 10], {"elevation": 0.7, "azimuth": 2.1}, [],
            {"mean": [0, 0, 0.3], "cov": [[0.2, 0, 0], [0, 0.1, 0], [0, 0, 0.05]]}]"#;
        assert!(Scenario::from_json(positional).is_err());
    }

    /// One JSON document: anything but white space after it is an error.
    #[test]
    fn trailing_characters_are_rejected() {
        assert!(Scenario::from_json(&format!("{GOOD} \n\t")).is_ok());
        for tail in ["x", "{}", ",", "]"] {
            let err = Scenario::from_json(&format!("{GOOD} {tail}")).unwrap_err();
            assert!(matches!(err, ScenarioError::Malformed { .. }), "`{tail}` gave `{err}`");
            assert!(err.to_string().contains("trailing characters"), "{err}");
        }
    }

    #[test]
    fn messages_say_what_to_do() {
        let err = with("\"model\": \"paper\"", "\"rho_min\": 7").unwrap_err();
        assert_eq!(err.to_string(), "params.rho_min = 7 must be < rho_max = 6");
        let err = with("\"model\": \"paper\"", "\"kapa\": 2").unwrap_err();
        assert!(err.to_string().contains("did you mean `kappa`?"), "{err}");
    }
}
