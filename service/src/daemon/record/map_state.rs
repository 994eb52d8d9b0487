//! A map as recorded: its full state (`/dyfosd/map_state`) and each change to it
//! (`/dyfosd/map_change`), from which a replay rebuilds every version it saw.

use super::exchange::recorded_deltas;
use dyfos_shared::wire::map::{MapId, world_from_content};
use dyfos_shared::world::{Bounds, MapDelta, Sun, World};
use serde::{Deserialize, Serialize};

/// A map's content as recorded: obstacle upserts, then one voxel run if it has a
/// grid (what [`world_from_content`] rebuilds).
pub fn content_of(world: &World) -> Vec<MapDelta> {
    let mut out: Vec<MapDelta> =
        world.obstacles().iter().map(|(id, o)| MapDelta::UpsertObstacle { id: *id, obstacle: *o }).collect();
    if let Some(grid) = world.voxels() {
        out.push(MapDelta::SetVoxelBlocks {
            resolution: grid.resolution(),
            origin: grid.origin(),
            blocks: grid.blocks().collect(),
            occupied: true,
        });
    }
    out
}

/// A map's full state (`/dyfosd/map_state`, and the content of `create` and
/// `upload` changes).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct MapState {
    /// The map.
    pub map: MapId,
    /// Its version.
    pub version: u64,
    /// Bounds (x_min, y_min, x_max, y_max).
    pub bounds: [f64; 4],
    /// The sun.
    pub sun: Sun,
    /// Obstacles and voxels, as [`content_of`] writes them.
    #[serde(deserialize_with = "recorded_deltas")]
    pub content: Vec<MapDelta>,
}

impl MapState {
    /// The state of `world` as map `map`.
    pub fn of(map: MapId, world: &World) -> Self {
        MapState {
            map,
            version: world.version(),
            bounds: world.bounds().to_array(),
            sun: *world.sun(),
            content: content_of(world),
        }
    }

    /// The map again.
    pub fn rebuild(&self) -> Result<World, String> {
        let bounds = Bounds::new(self.bounds).map_err(|e| e.to_string())?;
        world_from_content(self.version, bounds, self.sun, &self.content).map_err(|e| e.to_string())
    }
}

/// What changed a map (`/dyfosd/map_change`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ChangeCause {
    /// `create`: a new empty map (content in the record).
    Create,
    /// A map request's deltas.
    Apply,
    /// A rendezvous query's inline deltas.
    Inline,
    /// A completed upload (content in the record).
    Upload,
    /// The map was deleted.
    Delete,
}

/// A map change as recorded.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct MapChange {
    /// The map.
    pub map: MapId,
    /// What changed it.
    pub cause: ChangeCause,
    /// The version the deltas were applied to (`apply`, `inline`).
    pub from_version: Option<u64>,
    /// The version it produced (for `delete`, the version deleted).
    pub version: u64,
    /// The deltas (`apply`, `inline`).
    #[serde(default, skip_serializing_if = "Vec::is_empty", deserialize_with = "recorded_deltas")]
    pub deltas: Vec<MapDelta>,
    /// The whole new map (`create`, `upload`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub state: Option<MapState>,
}

#[cfg(test)]
mod tests {
    use super::*;
    use dyfos_shared::world::{Obstacle, VerticalCylinder};

    #[test]
    fn a_map_state_rebuilds_the_map() {
        // Awkward numbers: no short decimal form, the smallest subnormal.
        let obstacle = Obstacle::Cylinder(VerticalCylinder {
            center: nalgebra::Point2::new(0.1 + 0.7, 5e-324),
            radius: 1.0 / 7.0,
            height: 2.5,
        });
        let bounds = Bounds::new([-5.0, -5.0, 5.0, 5.0]).unwrap();
        let world = World::empty(bounds, Sun::new(0.4, 0.1 + 0.2).unwrap())
            .apply(&[MapDelta::UpsertObstacle { id: 4, obstacle }])
            .unwrap()
            .apply(&[MapDelta::SetVoxels {
                resolution: 0.3,
                origin: nalgebra::Point3::new(-1.0 / 3.0, 0.0, 0.0),
                cells: vec![[1, 2, 3], [4, 5, 6]],
                occupied: true,
            }])
            .unwrap();
        let state: MapState = serde_json::from_str(&serde_json::to_string(&MapState::of(4, &world)).unwrap()).unwrap();
        let rebuilt = state.rebuild().unwrap();
        assert!(rebuilt.same_content(&world));
        assert_eq!(rebuilt.version(), world.version());
    }
}
