//! The one JSON spelling of a map and of its changes (SPEC §11, `docs/deltas.md`).
//!
//! An obstacle, the voxels, the sun and the bounds are written as a scenario file
//! writes them, wherever they appear: in scenarios, in map deltas (`dyfos map apply`
//! files, Python's and C's `apply`, a query's inline deltas, the daemon's
//! recordings) and in snapshots (`dyfos map snapshot`, which this module also reads
//! back). A delta is an object with one key, its kind in snake case, whose value is
//! the scenario's record of the thing it sets:
//!
//! ```json
//! {"upsert_obstacle": {"id": 1, "cylinder": {"x": 2.0, "y": 1.0, "radius": 0.5, "height": 10.0}}}
//! {"upsert_obstacle": {"id": 2, "box": {"min": [4.0, 4.0, 0.0], "max": [5.0, 6.0, 3.0]}}}
//! {"remove_obstacle": {"id": 2}}
//! {"set_voxels": {"resolution": 0.1, "origin": [0.0, 0.0, 0.0], "occupied": [[1, 2, 3], [1, 2, 4]]}}
//! {"set_voxels": {"resolution": 0.1, "origin": [0.0, 0.0, 0.0], "free": [[1, 2, 3]]}}
//! {"set_voxel_blocks": {"resolution": 0.1, "origin": [0.0, 0.0, 0.0], "occupied": [{"min": [0, 0, 0], "mask": 7}]}}
//! {"set_sun": {"elevation": 0.5, "azimuth": 1.0}}
//! {"set_bounds": [-20.0, -20.0, 20.0, 20.0]}
//! {"clear": {}}
//! ```
//!
//! A scenario's `voxels` object is a valid `set_voxels` value, and a snapshot's
//! fields other than `map` and `version` are a scenario's map fields.
//!
//! *Interpretation (SPEC §1, §11):* the kinds are SPEC §1's deltas (upsert obstacle,
//! remove obstacle, set voxels occupied or free, set sun, set bounds, clear), plus
//! `set_voxel_blocks`, the compact form of `set_voxels` the daemon uploads and records
//! in; they are read as strictly as a scenario (unknown fields, `null` and records
//! written as arrays are errors), and their values are checked by the map they are
//! applied to, with SPEC §11's ranges.
//!
//! [`MapDelta`]'s serde form is this spelling in human-readable formats (JSON), so
//! every `serde_json` user writes and reads it; compact binary formats (the daemon's
//! map store, bincode) keep the derived layout stored maps were written in.
//!
//! ```
//! use dyfos_shared::map_json::deltas_from_json;
//! use dyfos_shared::world::{MapDelta, Sun};
//!
//! let deltas = deltas_from_json(r#"[{"remove_obstacle": {"id": 3}}, {"set_sun": {"elevation": 0.5, "azimuth": 1.0}}]"#).unwrap();
//! assert_eq!(deltas, [MapDelta::RemoveObstacle { id: 3 }, MapDelta::SetSun(Sun { elevation: 0.5, azimuth: 1.0 })]);
//!
//! let err = deltas_from_json(r#"[{"upsert_obstacle": {"id": 1, "cylinder": {"x": 0, "y": 0, "radius": 1, "heigth": 2}}}]"#)
//!     .unwrap_err()
//!     .to_string();
//! assert!(err.starts_with("deltas[0].upsert_obstacle.cylinder: unknown field `heigth`"), "{err}");
//! assert!(err.contains("did you mean `height`?"), "{err}");
//! assert!(err.contains(r#"a valid upsert_obstacle: {"upsert_obstacle": {"id": 1, "cylinder""#), "{err}");
//! ```

use crate::limits::MAX_OBSTACLES;
use crate::math::{Point2, Point3};
use crate::scenario::{Object, ScenarioError, parse_json, present};
use crate::wire::map::MapId;
use crate::world::{
    AxisBox, Bounds, CellIndex, MapDelta, Obstacle, Sun, VerticalCylinder, VoxelBlock, VoxelError, VoxelGrid, World,
};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

// The records of SPEC §11, shared by scenarios, deltas and snapshots.

/// `sun`: `{"elevation": el, "azimuth": az}`.
#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawSun {
    pub(crate) elevation: f64,
    pub(crate) azimuth: f64,
}

impl RawSun {
    pub(crate) fn of(sun: &Sun) -> Self {
        RawSun { elevation: sun.elevation, azimuth: sun.azimuth }
    }
}

/// One obstacle: `{"id": 1, "cylinder": {…}}` or `{"id": 2, "box": {…}}`.
#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawObstacle {
    pub(crate) id: u32,
    #[serde(default, deserialize_with = "present", skip_serializing_if = "Option::is_none")]
    cylinder: Option<Object<RawCylinder>>,
    #[serde(rename = "box", default, deserialize_with = "present", skip_serializing_if = "Option::is_none")]
    box_: Option<Object<RawBox>>,
}

#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawCylinder {
    x: f64,
    y: f64,
    radius: f64,
    height: f64,
}

#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawBox {
    min: [f64; 3],
    max: [f64; 3],
}

impl RawObstacle {
    pub(crate) fn of(id: u32, obstacle: &Obstacle) -> Self {
        match obstacle {
            Obstacle::Cylinder(c) => RawObstacle {
                id,
                cylinder: Some(Object(RawCylinder {
                    x: c.center.x,
                    y: c.center.y,
                    radius: c.radius,
                    height: c.height,
                })),
                box_: None,
            },
            Obstacle::Box(b) => RawObstacle {
                id,
                cylinder: None,
                box_: Some(Object(RawBox { min: b.min.coords.into(), max: b.max.coords.into() })),
            },
        }
    }

    /// The geometry, not validated, with the name of its field.
    pub(crate) fn geometry(&self) -> Result<(&'static str, Obstacle), &'static str> {
        match (&self.cylinder, &self.box_) {
            (Some(c), None) => Ok((
                "cylinder",
                Obstacle::Cylinder(VerticalCylinder {
                    center: Point2::new(c.x, c.y),
                    radius: c.radius,
                    height: c.height,
                }),
            )),
            (None, Some(b)) => {
                Ok(("box", Obstacle::Box(AxisBox { min: Point3::from(b.min), max: Point3::from(b.max) })))
            }
            _ => Err("needs exactly one of `cylinder` or `box`"),
        }
    }
}

/// `voxels`: `{"resolution": r, "origin": [x, y, z], "occupied": [[i, j, k], …]}`.
#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawVoxels {
    resolution: f64,
    origin: [f64; 3],
    occupied: Vec<CellIndex>,
}

impl RawVoxels {
    pub(crate) fn of(grid: &VoxelGrid) -> Self {
        RawVoxels { resolution: grid.resolution(), origin: grid.origin().coords.into(), occupied: grid.cells_sorted() }
    }

    pub(crate) fn grid(&self) -> Result<VoxelGrid, VoxelError> {
        VoxelGrid::new(self.resolution, Point3::from(self.origin), self.occupied.iter().copied())
    }
}

/// The world of a scenario's or a snapshot's map fields, validated; errors name the
/// field (`bounds`, `sun.elevation`, `obstacles[3].cylinder`, `voxels`). `voxels`
/// wins over `otherwise` (a scenario's OctoMap, read by the caller).
pub(crate) fn world_of(
    version: u64,
    bounds: [f64; 4],
    sun: &RawSun,
    obstacles: &[Object<RawObstacle>],
    voxels: Option<&RawVoxels>,
    otherwise: Option<VoxelGrid>,
) -> Result<World, ScenarioError> {
    let bounds = Bounds::new(bounds).map_err(|e| ScenarioError::invalid("bounds", e.problem))?;
    let sun = Sun::new(sun.elevation, sun.azimuth)
        .map_err(|e| ScenarioError::invalid(format!("sun.{}", e.field), format!("= {} {}", e.value, e.rule)))?;
    if obstacles.len() > MAX_OBSTACLES {
        return Err(ScenarioError::invalid(
            "obstacles",
            format!("{} obstacles exceed the limit of {MAX_OBSTACLES}", obstacles.len()),
        ));
    }
    let mut first_index: BTreeMap<u32, usize> = BTreeMap::new();
    let mut solids = Vec::with_capacity(obstacles.len());
    for (i, o) in obstacles.iter().enumerate() {
        let (kind, obstacle) = o.geometry().map_err(|e| ScenarioError::invalid(format!("obstacles[{i}]"), e))?;
        obstacle.validate().map_err(|e| ScenarioError::invalid(format!("obstacles[{i}].{kind}"), e))?;
        if let Some(j) = first_index.insert(o.id, i) {
            return Err(ScenarioError::invalid(
                format!("obstacles[{i}].id"),
                format!("duplicate obstacle id {} (also obstacles[{j}])", o.id),
            ));
        }
        solids.push((o.id, obstacle));
    }
    let voxels = match voxels {
        None => otherwise,
        Some(v) => Some(v.grid().map_err(|e| ScenarioError::invalid("voxels", e))?),
    };
    World::new(version, bounds, sun, solids, voxels).map_err(|e| ScenarioError::invalid("obstacles", e))
}

// Snapshots.

/// A map as `dyfos map snapshot` prints it: a scenario's map fields, after the map
/// id and version.
#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawMap {
    #[serde(default, deserialize_with = "present", skip_serializing_if = "Option::is_none")]
    map: Option<MapId>,
    #[serde(default, deserialize_with = "present", skip_serializing_if = "Option::is_none")]
    version: Option<u64>,
    bounds: [f64; 4],
    sun: Object<RawSun>,
    obstacles: Vec<Object<RawObstacle>>,
    #[serde(default, deserialize_with = "present", skip_serializing_if = "Option::is_none")]
    voxels: Option<Object<RawVoxels>>,
}

/// The map as JSON: `map` (if given), `version`, then the scenario's `bounds`,
/// `sun`, `obstacles` and `voxels` (if any, every occupied cell listed). What
/// `dyfos map snapshot`, Python's `snapshot` and C's `dyfos_client_snapshot` give;
/// [`map_from_json`] reads it back.
pub fn map_to_json(map: Option<MapId>, world: &World) -> serde_json::Value {
    let raw = RawMap {
        map,
        version: Some(world.version()),
        bounds: world.bounds().to_array(),
        sun: Object(RawSun::of(world.sun())),
        obstacles: world.obstacles().iter().map(|(id, o)| Object(RawObstacle::of(*id, o))).collect(),
        voxels: world.voxels().map(|v| Object(RawVoxels::of(v))),
    };
    serde_json::to_value(raw).expect("a map serializes")
}

/// Reads a map written as [`map_to_json`] writes it, validated as a scenario's map
/// fields are (SPEC §11); `map` and `version` may be left out (a scenario's map
/// fields alone read as version 0). Returns the map id, if written, and the map.
///
/// ```
/// use dyfos_shared::map_json::{map_from_json, map_to_json};
///
/// let text = r#"{"map": 7, "version": 3, "bounds": [-10, -10, 10, 10], "sun": {"elevation": 0.7, "azimuth": 2.1},
///   "obstacles": [{"id": 1, "cylinder": {"x": 2, "y": 1, "radius": 0.5, "height": 10}}]}"#;
/// let (map, world) = map_from_json(text).unwrap();
/// assert_eq!((map, world.version(), world.obstacles().len()), (Some(7), 3, 1));
/// assert_eq!(map_from_json(&map_to_json(map, &world).to_string()).unwrap(), (map, world));
/// ```
pub fn map_from_json(json: &str) -> Result<(Option<MapId>, World), ScenarioError> {
    let raw: RawMap = parse_json::<Object<RawMap>>(json, "")?.0;
    let world = world_of(raw.version.unwrap_or(0), raw.bounds, &raw.sun, &raw.obstacles, raw.voxels.as_deref(), None)?;
    Ok((raw.map, world))
}

/// The map of a document that is either a scenario (it has a `rover`; an
/// `octomap.file` is read with `read_file`, as [`crate::scenario::Scenario::from_json_with_files`]
/// does) or a map as [`map_to_json`] writes it (any other object): what `dyfos map
/// upload` and Python's `upload_scenario` take, so a snapshot uploads as it is.
pub fn world_from_json_with_files(
    json: &str,
    read_file: impl FnOnce(&str) -> Result<Vec<u8>, String>,
) -> Result<World, ScenarioError> {
    #[derive(Deserialize)]
    struct Probe {
        #[serde(default)]
        rover: Option<serde::de::IgnoredAny>,
    }
    // Anything that is not an object with `rover` but is not a map either gets the
    // scenario's error, which names what a scenario needs.
    let is_map =
        serde_json::from_str::<Probe>(json).is_ok_and(|p| p.rover.is_none()) && json.trim_start().starts_with('{');
    if !is_map {
        return crate::scenario::Scenario::from_json_with_files(json, read_file).map(|s| s.world);
    }
    map_from_json(json).map(|(_, world)| world).map_err(|e| match e {
        ScenarioError::Malformed { path, message, line, column } if path.is_empty() => ScenarioError::Malformed {
            path,
            message: format!("{message}; without `rover` this is read as a map, not a scenario"),
            line,
            column,
        },
        e => e,
    })
}

// Deltas.

/// Every delta kind with a valid example of it, as error messages and
/// `docs/deltas.md` show them.
pub const DELTA_EXAMPLES: [(&str, &str); 7] = [
    (
        "upsert_obstacle",
        r#"{"upsert_obstacle": {"id": 1, "cylinder": {"x": 2.0, "y": 1.0, "radius": 0.5, "height": 10.0}}} or {"upsert_obstacle": {"id": 2, "box": {"min": [4.0, 4.0, 0.0], "max": [5.0, 6.0, 3.0]}}}"#,
    ),
    ("remove_obstacle", r#"{"remove_obstacle": {"id": 2}}"#),
    (
        "set_voxels",
        r#"{"set_voxels": {"resolution": 0.1, "origin": [0.0, 0.0, 0.0], "occupied": [[1, 2, 3], [1, 2, 4]]}} (`free` in place of `occupied` frees the cells)"#,
    ),
    (
        "set_voxel_blocks",
        r#"{"set_voxel_blocks": {"resolution": 0.1, "origin": [0.0, 0.0, 0.0], "occupied": [{"min": [0, 0, 4], "mask": 7}]}} (`free` in place of `occupied` frees the cells)"#,
    ),
    ("set_sun", r#"{"set_sun": {"elevation": 0.5, "azimuth": 1.0}}"#),
    ("set_bounds", r#"{"set_bounds": [-20.0, -20.0, 20.0, 20.0]}"#),
    ("clear", r#"{"clear": {}}"#),
];

/// A map-delta document that cannot be read: where and why, and a valid example
/// of the delta kind at fault.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{error}; {hint}")]
pub struct DeltasJsonError {
    /// Where and why, e.g. `deltas[2].upsert_obstacle.cylinder: unknown field …`.
    pub error: ScenarioError,
    /// A valid example of the kind at fault (of a delta, or of the whole array).
    pub hint: String,
}

impl DeltasJsonError {
    /// The path of the field at fault, e.g. `deltas[2].set_sun`.
    pub fn path(&self) -> &str {
        self.error.path()
    }

    /// The position in the array of the delta at fault, if the fault is in one.
    pub fn index(&self) -> Option<usize> {
        let rest = self.path().strip_prefix("deltas[")?;
        rest[..rest.find(']')?].parse().ok()
    }

    fn new(error: ScenarioError) -> Self {
        let path = error.path();
        let text = error.to_string();
        // The kind at fault: the one the path names, else the one a misspelt kind
        // is nearest to.
        let named = path.strip_prefix("deltas[").and_then(|rest| rest.split_once("].")).map(|(_, rest)| {
            let end = rest.find(['.', '[']).unwrap_or(rest.len());
            &rest[..end]
        });
        let suggested = text.split_once("(did you mean `").and_then(|(_, rest)| rest.split_once('`')).map(|(k, _)| k);
        let example = named.or(suggested).and_then(|k| DELTA_EXAMPLES.iter().find(|(name, _)| *name == k));
        let hint = match (example, path) {
            (Some((name, example)), _) => format!("a valid {name}: {example}"),
            (None, "deltas") => {
                format!("write a JSON array of deltas, e.g. [{}, {}]", DELTA_EXAMPLES[1].1, DELTA_EXAMPLES[4].1)
            }
            (None, _) => format!(
                "a delta is an object with one key, its kind ({}), e.g. {}; docs/deltas.md shows each",
                DELTA_EXAMPLES.iter().map(|(k, _)| *k).collect::<Vec<_>>().join(", "),
                DELTA_EXAMPLES[1].1
            ),
        };
        DeltasJsonError { error, hint }
    }
}

/// Reads a JSON array of map deltas (the spelling of `docs/deltas.md`). Only the
/// form is checked here; values (a negative radius, an unknown id to remove) are
/// checked by the map they are applied to, which rejects the batch whole. Errors
/// name the field, under `deltas` (`deltas[2].set_sun: missing field `azimuth``),
/// and show a valid example of the kind at fault.
pub fn deltas_from_json(json: &str) -> Result<Vec<MapDelta>, DeltasJsonError> {
    parse_json::<Vec<MapDelta>>(json, "deltas").map_err(DeltasJsonError::new)
}

/// A delta as written (see [`MapDelta`]'s `Serialize`): borrows the map's cells.
#[derive(Serialize)]
#[serde(rename_all = "snake_case")]
pub(crate) enum DeltaOut<'a> {
    UpsertObstacle(RawObstacle),
    RemoveObstacle(RawId),
    SetVoxels(RunOut<'a, CellIndex>),
    SetVoxelBlocks(RunOut<'a, VoxelBlock>),
    SetSun(RawSun),
    SetBounds([f64; 4]),
    Clear(Empty),
}

#[derive(Serialize)]
pub(crate) struct RunOut<'a, T> {
    resolution: f64,
    origin: [f64; 3],
    #[serde(skip_serializing_if = "Option::is_none")]
    occupied: Option<&'a [T]>,
    #[serde(skip_serializing_if = "Option::is_none")]
    free: Option<&'a [T]>,
}

impl<'a, T> RunOut<'a, T> {
    fn new(resolution: f64, origin: &Point3<f64>, items: &'a [T], occupied: bool) -> Self {
        let (occupied, free) = if occupied { (Some(items), None) } else { (None, Some(items)) };
        RunOut { resolution, origin: origin.coords.into(), occupied, free }
    }
}

impl<'a> DeltaOut<'a> {
    pub(crate) fn of(delta: &'a MapDelta) -> Self {
        match delta {
            MapDelta::UpsertObstacle { id, obstacle } => DeltaOut::UpsertObstacle(RawObstacle::of(*id, obstacle)),
            MapDelta::RemoveObstacle { id } => DeltaOut::RemoveObstacle(RawId { id: *id }),
            MapDelta::SetVoxels { resolution, origin, cells, occupied } => {
                DeltaOut::SetVoxels(RunOut::new(*resolution, origin, cells, *occupied))
            }
            MapDelta::SetVoxelBlocks { resolution, origin, blocks, occupied } => {
                DeltaOut::SetVoxelBlocks(RunOut::new(*resolution, origin, blocks, *occupied))
            }
            MapDelta::SetSun(sun) => DeltaOut::SetSun(RawSun::of(sun)),
            MapDelta::SetBounds(bounds) => DeltaOut::SetBounds(bounds.to_array()),
            MapDelta::Clear => DeltaOut::Clear(Empty {}),
        }
    }
}

/// A delta as read (see [`MapDelta`]'s `Deserialize`). Values are not validated:
/// the map does that when the delta is applied.
#[derive(Deserialize)]
#[serde(rename_all = "snake_case")]
pub(crate) enum DeltaIn {
    UpsertObstacle(Upsert),
    RemoveObstacle(Object<RawId>),
    SetVoxels(Run<CellIndex>),
    SetVoxelBlocks(Run<Object<RawBlock>>),
    SetSun(Object<RawSun>),
    SetBounds([f64; 4]),
    Clear(Object<Empty>),
}

impl From<DeltaIn> for MapDelta {
    fn from(d: DeltaIn) -> Self {
        match d {
            DeltaIn::UpsertObstacle(Upsert { id, obstacle }) => MapDelta::UpsertObstacle { id, obstacle },
            DeltaIn::RemoveObstacle(r) => MapDelta::RemoveObstacle { id: r.id },
            DeltaIn::SetVoxels(Run { resolution, origin, items, occupied }) => {
                MapDelta::SetVoxels { resolution, origin: Point3::from(origin), cells: items, occupied }
            }
            DeltaIn::SetVoxelBlocks(Run { resolution, origin, items, occupied }) => MapDelta::SetVoxelBlocks {
                resolution,
                origin: Point3::from(origin),
                blocks: items.into_iter().map(|b| VoxelBlock { min: b.min, mask: b.mask }).collect(),
                occupied,
            },
            DeltaIn::SetSun(s) => MapDelta::SetSun(Sun { elevation: s.elevation, azimuth: s.azimuth }),
            DeltaIn::SetBounds(b) => {
                MapDelta::SetBounds(Bounds { min: Point2::new(b[0], b[1]), max: Point2::new(b[2], b[3]) })
            }
            DeltaIn::Clear(_) => MapDelta::Clear,
        }
    }
}

/// `remove_obstacle`'s value.
#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawId {
    id: u32,
}

/// `clear`'s value, `{}`.
#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct Empty {}

/// A 4³ block of cells: `{"min": [i, j, k], "mask": m}`, as [`VoxelBlock`].
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawBlock {
    min: CellIndex,
    mask: u64,
}

/// `upsert_obstacle`'s value: a scenario obstacle. Checked here (not after the
/// enum) so that an error's path names the delta's kind.
#[derive(Deserialize)]
#[serde(try_from = "Object<RawObstacle>")]
pub(crate) struct Upsert {
    id: u32,
    obstacle: Obstacle,
}

impl TryFrom<Object<RawObstacle>> for Upsert {
    type Error = &'static str;
    fn try_from(raw: Object<RawObstacle>) -> Result<Self, Self::Error> {
        Ok(Upsert { id: raw.id, obstacle: raw.geometry()?.1 })
    }
}

/// A voxel delta's value: the grid, and its items under `occupied` or `free`.
#[derive(Deserialize)]
#[serde(deny_unknown_fields, bound = "T: Deserialize<'de>")]
struct RawRun<T> {
    resolution: f64,
    origin: [f64; 3],
    #[serde(default, deserialize_with = "present")]
    occupied: Option<Vec<T>>,
    #[serde(default, deserialize_with = "present")]
    free: Option<Vec<T>>,
}

#[derive(Deserialize)]
#[serde(try_from = "Object<RawRun<T>>", bound = "T: Deserialize<'de>")]
pub(crate) struct Run<T> {
    resolution: f64,
    origin: [f64; 3],
    items: Vec<T>,
    occupied: bool,
}

impl<T> TryFrom<Object<RawRun<T>>> for Run<T> {
    type Error = &'static str;
    fn try_from(raw: Object<RawRun<T>>) -> Result<Self, Self::Error> {
        let RawRun { resolution, origin, occupied, free } = raw.0;
        let (items, occupied) = match (occupied, free) {
            (Some(items), None) => (items, true),
            (None, Some(items)) => (items, false),
            _ => return Err("needs exactly one of `occupied` or `free`"),
        };
        Ok(Run { resolution, origin, items, occupied })
    }
}

/// Reads one delta of a daemon recording made before deltas had this spelling
/// (serde's derived form: `{"UpsertObstacle": {"id": 1, "obstacle": {"Cylinder":
/// {"center": [2, 1], …}}}}`, `"Clear"`), or of this spelling, so that old
/// recordings still replay.
pub fn recorded_delta_from_value(value: serde_json::Value) -> Result<MapDelta, serde_json::Error> {
    let legacy = match &value {
        serde_json::Value::String(_) => true,
        serde_json::Value::Object(o) => o.keys().next().is_some_and(|k| k.starts_with(char::is_uppercase)),
        _ => false,
    };
    if legacy { crate::world::StoredDelta::deserialize(value) } else { MapDelta::deserialize(value) }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::world::Obstacle;

    fn every_kind() -> Vec<MapDelta> {
        let origin = Point3::new(-1.5, 0.25, 0.0);
        vec![
            MapDelta::UpsertObstacle {
                id: 1,
                obstacle: Obstacle::Cylinder(VerticalCylinder {
                    center: Point2::new(2.0, -1.0),
                    radius: 0.5,
                    height: 10.0,
                }),
            },
            MapDelta::UpsertObstacle {
                id: u32::MAX,
                obstacle: Obstacle::Box(AxisBox { min: Point3::new(4.0, 4.0, 0.5), max: Point3::new(5.0, 6.0, 3.0) }),
            },
            MapDelta::RemoveObstacle { id: 7 },
            MapDelta::SetVoxels { resolution: 0.1, origin, cells: vec![[1, 2, 3], [-4, 0, 1 << 20]], occupied: true },
            MapDelta::SetVoxels { resolution: 0.1, origin, cells: vec![[1, 2, 3]], occupied: false },
            MapDelta::SetVoxels { resolution: 0.1, origin, cells: vec![], occupied: false },
            MapDelta::SetVoxelBlocks {
                resolution: 0.1,
                origin,
                blocks: vec![VoxelBlock { min: [0, 0, 4], mask: u64::MAX }, VoxelBlock { min: [-4, 8, 0], mask: 1 }],
                occupied: true,
            },
            MapDelta::SetVoxelBlocks {
                resolution: 0.1,
                origin,
                blocks: vec![VoxelBlock { min: [0, 0, 0], mask: 6 }],
                occupied: false,
            },
            MapDelta::SetSun(Sun { elevation: -0.0, azimuth: 1e-300 }),
            MapDelta::SetBounds(Bounds { min: Point2::new(-20.0, -20.0), max: Point2::new(20.0, 0.1 + 0.2) }),
            MapDelta::Clear,
        ]
    }

    /// Every kind goes to JSON and back to the same delta, bit for bit.
    #[test]
    fn every_kind_round_trips() {
        let deltas = every_kind();
        let text = serde_json::to_string(&deltas).unwrap();
        assert_eq!(deltas_from_json(&text).unwrap(), deltas);
        for d in &deltas {
            let one = serde_json::to_string(std::slice::from_ref(d)).unwrap();
            let back = deltas_from_json(&one).unwrap();
            assert_eq!(format!("{back:?}"), format!("[{d:?}]"), "{one}");
        }
        // Bits: -0.0 and a float that prints long stay exact.
        let MapDelta::SetSun(sun) = &deltas_from_json(&text).unwrap()[8] else { panic!() };
        assert_eq!(sun.elevation.to_bits(), (-0.0f64).to_bits());
    }

    /// The spelling itself: each kind as `docs/deltas.md` writes it.
    #[test]
    fn each_kind_is_written_as_documented() {
        let written: Vec<String> = every_kind().iter().map(|d| serde_json::to_string(d).unwrap()).collect();
        let expected = [
            r#"{"upsert_obstacle":{"id":1,"cylinder":{"x":2.0,"y":-1.0,"radius":0.5,"height":10.0}}}"#,
            r#"{"upsert_obstacle":{"id":4294967295,"box":{"min":[4.0,4.0,0.5],"max":[5.0,6.0,3.0]}}}"#,
            r#"{"remove_obstacle":{"id":7}}"#,
            r#"{"set_voxels":{"resolution":0.1,"origin":[-1.5,0.25,0.0],"occupied":[[1,2,3],[-4,0,1048576]]}}"#,
            r#"{"set_voxels":{"resolution":0.1,"origin":[-1.5,0.25,0.0],"free":[[1,2,3]]}}"#,
            r#"{"set_voxels":{"resolution":0.1,"origin":[-1.5,0.25,0.0],"free":[]}}"#,
            r#"{"set_voxel_blocks":{"resolution":0.1,"origin":[-1.5,0.25,0.0],"occupied":[{"min":[0,0,4],"mask":18446744073709551615},{"min":[-4,8,0],"mask":1}]}}"#,
            r#"{"set_voxel_blocks":{"resolution":0.1,"origin":[-1.5,0.25,0.0],"free":[{"min":[0,0,0],"mask":6}]}}"#,
            r#"{"set_sun":{"elevation":-0.0,"azimuth":1e-300}}"#,
            r#"{"set_bounds":[-20.0,-20.0,20.0,0.30000000000000004]}"#,
            r#"{"clear":{}}"#,
        ];
        assert_eq!(written, expected);
    }

    /// The obstacle of an upsert is a scenario obstacle, and a scenario's `voxels`
    /// is a `set_voxels` value: the same text reads the same in both places.
    #[test]
    fn an_upsert_holds_a_scenario_obstacle_and_set_voxels_a_scenario_voxels() {
        let obstacle = r#"{"id": 3, "box": {"min": [4.0, 4.0, 0.0], "max": [5.0, 6.0, 3.0]}}"#;
        let voxels = r#"{"resolution": 0.5, "origin": [0.0, 0.0, 0.0], "occupied": [[1, 2, 3]]}"#;
        let map = format!(
            r#"{{"bounds": [-10, -10, 10, 10], "sun": {{"elevation": 0.7, "azimuth": 2.1}}, "obstacles": [{obstacle}], "voxels": {voxels}}}"#
        );
        let (_, from_map) = map_from_json(&map).unwrap();
        let deltas =
            deltas_from_json(&format!(r#"[{{"upsert_obstacle": {obstacle}}}, {{"set_voxels": {voxels}}}]"#)).unwrap();
        let from_deltas = World::empty(*from_map.bounds(), *from_map.sun()).apply(&deltas).unwrap();
        assert!(from_deltas.same_content(&from_map));
    }

    /// Every example the errors and the docs show is valid, and every kind has one.
    #[test]
    fn every_example_is_valid() {
        for (kind, text) in DELTA_EXAMPLES {
            for example in text.split(" or ").map(|e| e.split(" (").next().unwrap()) {
                let parsed = deltas_from_json(&format!("[{example}]")).unwrap_or_else(|e| panic!("{example}: {e}"));
                let written = serde_json::to_value(&parsed[0]).unwrap();
                assert_eq!(written.as_object().unwrap().keys().collect::<Vec<_>>(), [kind]);
            }
        }
        let kinds: Vec<String> = every_kind()
            .iter()
            .map(|d| serde_json::to_value(d).unwrap().as_object().unwrap().keys().next().unwrap().clone())
            .collect();
        for (kind, _) in DELTA_EXAMPLES {
            assert!(kinds.iter().any(|k| k == kind), "{kind}");
        }
    }

    /// `docs/deltas.md` shows every kind; its delta file is the tests' fixture, and
    /// applied to the map the doc creates it makes the snapshot the doc shows.
    #[test]
    fn the_docs_examples_read_and_agree() {
        let doc = include_str!("../../docs/deltas.md");
        let blocks: Vec<&str> =
            doc.split("```json\n").skip(1).map(|block| &block[..block.find("```").unwrap()]).collect();
        let [file, snapshot] = blocks[..] else { panic!("expected a delta file and a snapshot: {blocks:?}") };
        assert_eq!(file, include_str!("../../tests/data/deltas-every-kind.json"));
        let deltas = deltas_from_json(file).unwrap_or_else(|e| panic!("{e}"));
        let created = World::empty(Bounds::new([-10.0, -10.0, 10.0, 10.0]).unwrap(), Sun::new(0.7, 2.1).unwrap());
        let applied = created.apply(&deltas).unwrap();
        let (map, shown) = map_from_json(snapshot).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!((map, &shown), (Some(7), &applied));
        for (kind, _) in DELTA_EXAMPLES {
            assert!(doc.contains(&format!("{{\"{kind}\": ")), "docs/deltas.md has no {kind} example");
        }
        // The page on querying the daemon shows the same file.
        let clients = include_str!("../../docs/clients.md");
        assert!(clients.contains(&format!("```json\n{file}```")), "docs/clients.md does not show the delta file");
        // The error it shows is the one given.
        let bad = doc.split("$ cat bad.json\n").nth(1).and_then(|rest| rest.lines().next()).unwrap();
        let shown = doc.split("dyfos: bad.json: ").nth(1).and_then(|rest| rest.lines().next()).unwrap();
        assert_eq!(deltas_from_json(bad).unwrap_err().to_string(), shown);
    }

    /// Each bad document: the path its error names, and the example it shows.
    #[test]
    fn errors_name_the_field_and_show_an_example_of_the_kind() {
        let cases = [
            (r#"{"remove_obstacle": {"id": 3}}"#, "deltas", "write a JSON array of deltas"),
            (
                r#"[{"remove_obstacle": {"id": 3}}, {"UpsertObstacle": {}}]"#,
                "deltas[1]",
                "did you mean `upsert_obstacle`?",
            ),
            (r#"[{"SetSun": {"elevation": 0.5, "azimuth": 1.0}}]"#, "deltas[0]", "did you mean `set_sun`?"),
            (r#"[{"SetSun": {"elevation": 0.5, "azimuth": 1.0}}]"#, "deltas[0]", r#"a valid set_sun: {"set_sun": "#),
            (r#"[{"set_sunn": {"elevation": 0.5, "azimuth": 1.0}}]"#, "deltas[0]", "a valid set_sun"),
            (r#"[{"add_obstacle": {}}]"#, "deltas[0]", "a delta is an object with one key"),
            (r#"["clear"]"#, "deltas[0].clear", r#"a valid clear: {"clear": {}}"#),
            (r#"[3]"#, "deltas[0]", "a delta is an object with one key"),
            (r#"[{}]"#, "deltas[0]", "a delta is an object with one key"),
            (r#"[{"clear": {}, "set_sun": {}}]"#, "deltas[0]", "a delta is an object with one key"),
            (r#"[{"clear": null}]"#, "deltas[0].clear", r#"a valid clear: {"clear": {}}"#),
            (
                r#"[{"remove_obstacle": 3}]"#,
                "deltas[0].remove_obstacle",
                r#"a valid remove_obstacle: {"remove_obstacle""#,
            ),
            (r#"[{"remove_obstacle": {"id": -1}}]"#, "deltas[0].remove_obstacle.id", "a valid remove_obstacle"),
            (
                r#"[{"upsert_obstacle": {"id": 1, "cylinder": {"x": 0, "y": 0, "radius": 1, "height": 2}, "box": {"min": [0, 0, 0], "max": [1, 1, 1]}}}]"#,
                "deltas[0].upsert_obstacle",
                "a valid upsert_obstacle",
            ),
            (
                r#"[{"upsert_obstacle": {"id": 1, "obstacle": {"Cylinder": {"center": [2, 1], "radius": 0.5, "height": 10}}}}]"#,
                "deltas[0].upsert_obstacle",
                r#"{"upsert_obstacle": {"id": 1, "cylinder": {"x": 2.0"#,
            ),
            (r#"[{"upsert_obstacle": {"id": 1, "cone": {}}}]"#, "deltas[0].upsert_obstacle", "a valid upsert_obstacle"),
            (
                r#"[{"upsert_obstacle": {"id": 1, "box": {"min": [0, 0], "max": [1, 1, 1]}}}]"#,
                "deltas[0].upsert_obstacle.box.min",
                "a valid upsert_obstacle",
            ),
            (
                r#"[{"set_voxels": {"resolution": 0.1, "origin": [0, 0, 0]}}]"#,
                "deltas[0].set_voxels",
                "a valid set_voxels",
            ),
            (
                r#"[{"set_voxels": {"resolution": 0.1, "origin": [0, 0, 0], "occupied": [], "free": []}}]"#,
                "deltas[0].set_voxels",
                "exactly one of `occupied` or `free`",
            ),
            (
                r#"[{"set_voxels": {"resolution": 0.1, "origin": [0, 0, 0], "cells": [[1, 2, 3]], "occupied": true}}]"#,
                "deltas[0].set_voxels",
                "a valid set_voxels",
            ),
            (
                r#"[{"set_voxel_blocks": {"resolution": 0.1, "origin": [0, 0, 0], "occupied": [{"min": [0, 0, 0], "mask": 1, "x": 1}]}}]"#,
                "deltas[0].set_voxel_blocks.occupied[0]",
                "a valid set_voxel_blocks",
            ),
            (
                r#"[{"set_voxel_blocks": {"resolution": 0.1, "origin": [0, 0, 0], "free": [[[0, 0, 0], 1]]}}]"#,
                "deltas[0].set_voxel_blocks.free[0]",
                "a valid set_voxel_blocks",
            ),
            (
                r#"[{"set_sun": {"elevation": 0.5}}]"#,
                "deltas[0].set_sun",
                r#"a valid set_sun: {"set_sun": {"elevation": 0.5, "azimuth": 1.0}}"#,
            ),
            (r#"[{"set_sun": [0.5, 1.0]}]"#, "deltas[0].set_sun", "a valid set_sun"),
            (r#"[{"set_bounds": {"min": [0, 0], "max": [1, 1]}}]"#, "deltas[0].set_bounds", "a valid set_bounds"),
            (r#"[{"set_bounds": [0, 0, 1e999, 1]}]"#, "deltas[0].set_bounds[2]", "a valid set_bounds"),
            (r#"[{"clear": {}}] x"#, "deltas", "write a JSON array"),
        ];
        for (text, path, hint) in cases {
            let err = deltas_from_json(text).unwrap_err();
            let message = err.to_string();
            assert_eq!(err.path(), path, "`{text}` gave `{message}`");
            assert!(message.starts_with(path), "`{text}` gave `{message}`");
            assert!(message.contains(hint), "`{text}` gave `{message}`");
        }
        let err = deltas_from_json(r#"[{"clear": {}}, {"clear": {}}, {"set_sun": {}}]"#).unwrap_err();
        assert_eq!(err.index(), Some(2));
        assert_eq!(deltas_from_json("{}").unwrap_err().index(), None);
    }

    /// A snapshot of any world reads back as that world, version included.
    #[test]
    fn a_snapshot_reads_back_as_its_map() {
        let base = World::empty(Bounds::new([-10.0, -10.0, 10.0, 10.0]).unwrap(), Sun::new(0.7, 2.1).unwrap());
        let mut batch = every_kind();
        batch.retain(|d| !matches!(d, MapDelta::RemoveObstacle { .. } | MapDelta::Clear));
        let world = base.apply(&batch).unwrap();
        assert!(world.voxels().is_some() && world.obstacles().len() == 2);
        let text = map_to_json(Some(9), &world).to_string();
        assert_eq!(map_from_json(&text).unwrap(), (Some(9), world.clone()));
        assert_eq!(map_from_json(&world.to_json().to_string()).unwrap(), (None, world));
    }

    /// Snapshots are validated as scenarios are, with the same paths.
    #[test]
    fn a_bad_snapshot_names_its_field() {
        let good = r#"{"map": 7, "version": 3, "bounds": [-10, -10, 10, 10], "sun": {"elevation": 0.7, "azimuth": 2.1},
            "obstacles": [{"id": 1, "cylinder": {"x": 2, "y": 1, "radius": 0.5, "height": 10}}]}"#;
        assert!(map_from_json(good).is_ok());
        let cases = [
            ("\"radius\": 0.5", "\"radius\": -0.5", "obstacles[0].cylinder"),
            ("\"version\": 3", "\"version\": -3", "version"),
            ("\"map\": 7", "\"mapp\": 7", ""),
            ("\"elevation\": 0.7", "\"elevation\": 7", "sun.elevation"),
            ("[-10, -10, 10, 10]", "[10, -10, -10, 10]", "bounds"),
            ("\"cylinder\"", "\"cone\"", "obstacles[0]"),
        ];
        for (from, to, path) in cases {
            let err = map_from_json(&good.replacen(from, to, 1)).unwrap_err();
            assert_eq!(err.path(), path, "`{to}` gave `{err}`");
        }
    }

    /// Recordings made before this spelling hold serde's derived form: it still
    /// reads, as does this spelling.
    #[test]
    fn recordings_in_the_old_spelling_still_read() {
        let old = serde_json::json!([
            {"UpsertObstacle": {"id": 1, "obstacle": {"Cylinder": {"center": [2.0, -1.0], "radius": 0.5, "height": 10.0}}}},
            {"UpsertObstacle": {"id": 4294967295u32, "obstacle": {"Box": {"min": [4.0, 4.0, 0.5], "max": [5.0, 6.0, 3.0]}}}},
            {"RemoveObstacle": {"id": 7}},
            {"SetVoxels": {"resolution": 0.1, "origin": [-1.5, 0.25, 0.0], "cells": [[1, 2, 3], [-4, 0, 1048576]], "occupied": true}},
            {"SetVoxels": {"resolution": 0.1, "origin": [-1.5, 0.25, 0.0], "cells": [[1, 2, 3]], "occupied": false}},
            {"SetVoxels": {"resolution": 0.1, "origin": [-1.5, 0.25, 0.0], "cells": [], "occupied": false}},
            {"SetVoxelBlocks": {"resolution": 0.1, "origin": [-1.5, 0.25, 0.0],
                "blocks": [{"min": [0, 0, 4], "mask": u64::MAX}, {"min": [-4, 8, 0], "mask": 1}], "occupied": true}},
            {"SetVoxelBlocks": {"resolution": 0.1, "origin": [-1.5, 0.25, 0.0], "blocks": [{"min": [0, 0, 0], "mask": 6}], "occupied": false}},
            {"SetSun": {"elevation": -0.0, "azimuth": 1e-300}},
            {"SetBounds": {"min": [-20.0, -20.0], "max": [20.0, 0.30000000000000004]}},
            "Clear",
        ]);
        let serde_json::Value::Array(items) = old else { unreachable!() };
        let read: Vec<MapDelta> = items.into_iter().map(|v| recorded_delta_from_value(v).unwrap()).collect();
        assert_eq!(read, every_kind());
        for d in every_kind() {
            assert_eq!(recorded_delta_from_value(serde_json::to_value(&d).unwrap()).unwrap(), d);
        }
        // The old spelling is not a second way to write deltas by hand.
        assert!(deltas_from_json(r#"[{"RemoveObstacle": {"id": 7}}]"#).is_err());
    }
}
