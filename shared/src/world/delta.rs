//! Map deltas (SPEC §1): the only way a map changes.

use super::voxels::{CellIndex, VoxelBlock};
use super::{Bounds, BoundsError, Obstacle, ObstacleError, Sun, SunError, VoxelError, VoxelGrid, World};
use crate::limits::MAX_OBSTACLES;
use crate::math::Point3;
use std::collections::BTreeMap;

/// One change to a map.
///
/// Its serde form in JSON (any human-readable format) is the one documented
/// spelling of `docs/deltas.md` ([`crate::map_json`]), e.g. `{"remove_obstacle":
/// {"id": 3}}`; in compact binary formats (the daemon's map store) it is
/// [`StoredDelta`]'s.
#[derive(Debug, Clone, PartialEq)]
pub enum MapDelta {
    /// Insert the obstacle, or replace the one with the same id.
    UpsertObstacle {
        /// Stable id.
        id: u32,
        /// Its geometry.
        obstacle: Obstacle,
    },
    /// Remove the obstacle with this id; an unknown id rejects the delta.
    RemoveObstacle {
        /// The id.
        id: u32,
    },
    /// Mark cells occupied (`occupied = true`) or free. The first such delta defines
    /// the grid's resolution and origin; later ones must repeat them exactly.
    SetVoxels {
        /// Cell side, m.
        resolution: f64,
        /// Minimum corner of cell (0, 0, 0).
        origin: Point3<f64>,
        /// The cells to set.
        cells: Vec<CellIndex>,
        /// Occupied or free.
        occupied: bool,
    },
    /// Mark the cells of 4³ blocks occupied (`occupied = true`) or free: the compact
    /// form of `SetVoxels` for large updates, uploads and snapshots. The same grid
    /// rules as `SetVoxels`.
    SetVoxelBlocks {
        /// Cell side, m.
        resolution: f64,
        /// Minimum corner of cell (0, 0, 0).
        origin: Point3<f64>,
        /// The blocks; cells outside a block's mask are untouched.
        blocks: Vec<VoxelBlock>,
        /// Occupied or free.
        occupied: bool,
    },
    /// Move the sun.
    SetSun(Sun),
    /// Change the map bounds.
    SetBounds(Bounds),
    /// Remove every obstacle and voxel; bounds and sun stay.
    Clear,
}

impl serde::Serialize for MapDelta {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        if s.is_human_readable() {
            serde::Serialize::serialize(&crate::map_json::DeltaOut::of(self), s)
        } else {
            StoredDelta::serialize(self, s)
        }
    }
}

impl<'de> serde::Deserialize<'de> for MapDelta {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        if d.is_human_readable() {
            <crate::map_json::DeltaIn as serde::Deserialize>::deserialize(d).map(MapDelta::from)
        } else {
            StoredDelta::deserialize(d)
        }
    }
}

/// [`MapDelta`] in compact binary formats: serde's derived layout, in which the
/// daemon's map store (bincode) has always written deltas; it must not change, or
/// stored maps stop reading. In JSON it is the spelling recordings used before
/// `docs/deltas.md` (read by [`crate::map_json::recorded_delta_from_value`]).
#[derive(serde::Serialize, serde::Deserialize)]
#[serde(remote = "MapDelta")]
pub(crate) enum StoredDelta {
    UpsertObstacle { id: u32, obstacle: Obstacle },
    RemoveObstacle { id: u32 },
    SetVoxels { resolution: f64, origin: Point3<f64>, cells: Vec<CellIndex>, occupied: bool },
    SetVoxelBlocks { resolution: f64, origin: Point3<f64>, blocks: Vec<VoxelBlock>, occupied: bool },
    SetSun(Sun),
    SetBounds(Bounds),
    Clear,
}

/// Why a delta was rejected.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MapDeltaErrorKind {
    /// `RemoveObstacle` named an id the map does not have.
    #[error("no obstacle with id {id} to remove")]
    UnknownObstacle {
        /// The id.
        id: u32,
    },
    /// An obstacle's geometry is invalid.
    #[error("obstacle {id}: {source}")]
    InvalidObstacle {
        /// The obstacle's id.
        id: u32,
        /// What is wrong.
        #[source]
        source: ObstacleError,
    },
    /// Two obstacles with one id in a map's content.
    #[error("duplicate obstacle id {id}")]
    DuplicateId {
        /// The id.
        id: u32,
    },
    /// More obstacles than a map may hold.
    #[error("{count} obstacles exceed the limit of {MAX_OBSTACLES}")]
    TooManyObstacles {
        /// How many there would be.
        count: usize,
    },
    /// A voxel update is invalid.
    #[error(transparent)]
    Voxels(#[from] VoxelError),
    /// A voxel update's grid differs from the map's grid.
    #[error(
        "voxel grid mismatch: the map's grid has resolution {have_resolution} and origin {have_origin:?}, the delta says {resolution} and {origin:?}"
    )]
    VoxelGridMismatch {
        /// The map's resolution.
        have_resolution: f64,
        /// The map's origin.
        have_origin: [f64; 3],
        /// The delta's resolution.
        resolution: f64,
        /// The delta's origin.
        origin: [f64; 3],
    },
    /// A sun outside its range.
    #[error(transparent)]
    Sun(#[from] SunError),
    /// Bounds with min ≥ max or non-finite numbers.
    #[error(transparent)]
    Bounds(#[from] BoundsError),
}

/// A rejected batch: which delta failed and why. The map is unchanged.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("map delta #{index}: {kind}")]
pub struct MapDeltaError {
    /// Position of the failing delta in its batch.
    pub index: usize,
    /// Why it failed.
    #[source]
    pub kind: MapDeltaErrorKind,
}

pub(super) fn apply(world: &World, deltas: &[MapDelta]) -> Result<World, MapDeltaError> {
    let mut bounds = world.bounds;
    let mut sun = world.sun;
    let mut obstacles: BTreeMap<u32, Obstacle> = world.obstacles.clone();
    let mut voxels = world.voxels.clone();
    for (index, delta) in deltas.iter().enumerate() {
        apply_one(delta, &mut bounds, &mut sun, &mut obstacles, &mut voxels)
            .map_err(|kind| MapDeltaError { index, kind })?;
    }
    let version = world.version + deltas.len() as u64;
    Ok(World::assemble(version, bounds, sun, obstacles, voxels))
}

fn apply_one(
    delta: &MapDelta,
    bounds: &mut Bounds,
    sun: &mut Sun,
    obstacles: &mut BTreeMap<u32, Obstacle>,
    voxels: &mut Option<VoxelGrid>,
) -> Result<(), MapDeltaErrorKind> {
    match delta {
        MapDelta::UpsertObstacle { id, obstacle } => {
            obstacle.validate().map_err(|source| MapDeltaErrorKind::InvalidObstacle { id: *id, source })?;
            if !obstacles.contains_key(id) && obstacles.len() >= MAX_OBSTACLES {
                return Err(MapDeltaErrorKind::TooManyObstacles { count: obstacles.len() + 1 });
            }
            obstacles.insert(*id, *obstacle);
        }
        MapDelta::RemoveObstacle { id } => {
            obstacles.remove(id).ok_or(MapDeltaErrorKind::UnknownObstacle { id: *id })?;
        }
        MapDelta::SetVoxels { resolution, origin, cells, occupied } => {
            edit_grid(voxels, *resolution, origin, |grid| grid.with_cells(cells, *occupied))?;
        }
        MapDelta::SetVoxelBlocks { resolution, origin, blocks, occupied } => {
            edit_grid(voxels, *resolution, origin, |grid| grid.with_blocks(blocks, *occupied))?;
        }
        MapDelta::SetSun(s) => *sun = Sun::new(s.elevation, s.azimuth)?,
        MapDelta::SetBounds(b) => *bounds = Bounds::new(b.to_array())?,
        MapDelta::Clear => {
            obstacles.clear();
            *voxels = None;
        }
    }
    Ok(())
}

/// Applies `edit` to the map's grid (created empty by the first voxel delta),
/// after checking the delta names the grid's resolution and origin.
fn edit_grid(
    voxels: &mut Option<VoxelGrid>,
    resolution: f64,
    origin: &Point3<f64>,
    edit: impl FnOnce(&VoxelGrid) -> Result<VoxelGrid, VoxelError>,
) -> Result<(), MapDeltaErrorKind> {
    let updated = match voxels {
        Some(grid) if grid.resolution() == resolution && grid.origin() == *origin => edit(grid)?,
        Some(grid) => {
            return Err(MapDeltaErrorKind::VoxelGridMismatch {
                have_resolution: grid.resolution(),
                have_origin: grid.origin().coords.into(),
                resolution,
                origin: origin.coords.into(),
            });
        }
        None => edit(&VoxelGrid::empty(resolution, *origin)?)?,
    };
    *voxels = Some(updated);
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::world::{AxisBox, VerticalCylinder};
    use nalgebra::Point2;

    fn base() -> World {
        World::empty(Bounds::new([-10.0, -10.0, 10.0, 10.0]).unwrap(), Sun::new(0.5, 1.0).unwrap())
    }

    fn pole(x: f64) -> Obstacle {
        Obstacle::Cylinder(VerticalCylinder { center: Point2::new(x, 0.0), radius: 0.5, height: 3.0 })
    }

    #[test]
    fn batch_applies_in_order_and_counts_versions() {
        let w = base()
            .apply(&[
                MapDelta::UpsertObstacle { id: 1, obstacle: pole(1.0) },
                MapDelta::UpsertObstacle { id: 2, obstacle: pole(2.0) },
                MapDelta::UpsertObstacle { id: 1, obstacle: pole(3.0) },
                MapDelta::RemoveObstacle { id: 2 },
                MapDelta::SetVoxels {
                    resolution: 0.5,
                    origin: Point3::origin(),
                    cells: vec![[0, 0, 0], [1, 0, 0]],
                    occupied: true,
                },
                MapDelta::SetVoxels {
                    resolution: 0.5,
                    origin: Point3::origin(),
                    cells: vec![[0, 0, 0]],
                    occupied: false,
                },
            ])
            .unwrap();
        assert_eq!(w.version(), 6);
        assert_eq!(w.obstacles().len(), 1);
        assert_eq!(w.obstacles()[&1], pole(3.0));
        assert_eq!(w.voxels().unwrap().cells_sorted(), vec![[1, 0, 0]]);
        let cleared = w.apply(&[MapDelta::Clear]).unwrap();
        assert!(cleared.obstacles().is_empty() && cleared.voxels().is_none());
        assert_eq!(cleared.version(), 7);
    }

    #[test]
    fn a_bad_delta_rejects_the_whole_batch() {
        let w = base().apply(&[MapDelta::UpsertObstacle { id: 1, obstacle: pole(1.0) }]).unwrap();
        let bad_box = Obstacle::Box(AxisBox { min: Point3::new(0.0, 0.0, 0.0), max: Point3::new(1.0, f64::NAN, 1.0) });
        type Expect = fn(&MapDeltaErrorKind) -> bool;
        let cases: Vec<(MapDelta, Expect)> = vec![
            (MapDelta::RemoveObstacle { id: 9 }, |k| matches!(k, MapDeltaErrorKind::UnknownObstacle { id: 9 })),
            (MapDelta::UpsertObstacle { id: 5, obstacle: bad_box }, |k| {
                matches!(k, MapDeltaErrorKind::InvalidObstacle { id: 5, .. })
            }),
            (MapDelta::SetSun(Sun { elevation: 2.0, azimuth: 0.0 }), |k| matches!(k, MapDeltaErrorKind::Sun(_))),
            (MapDelta::SetBounds(Bounds { min: Point2::new(1.0, 0.0), max: Point2::new(0.0, 1.0) }), |k| {
                matches!(k, MapDeltaErrorKind::Bounds(_))
            }),
            (MapDelta::SetVoxels { resolution: -1.0, origin: Point3::origin(), cells: vec![], occupied: true }, |k| {
                matches!(k, MapDeltaErrorKind::Voxels(_))
            }),
        ];
        for (delta, expected) in cases {
            let batch = [MapDelta::UpsertObstacle { id: 2, obstacle: pole(2.0) }, delta];
            let err = w.apply(&batch).unwrap_err();
            assert_eq!(err.index, 1);
            assert!(expected(&err.kind), "{err}");
        }
        let with_grid = w
            .apply(&[MapDelta::SetVoxels {
                resolution: 0.5,
                origin: Point3::origin(),
                cells: vec![[0, 0, 0]],
                occupied: true,
            }])
            .unwrap();
        let err = with_grid
            .apply(&[MapDelta::SetVoxels { resolution: 0.25, origin: Point3::origin(), cells: vec![], occupied: true }])
            .unwrap_err();
        assert!(matches!(err.kind, MapDeltaErrorKind::VoxelGridMismatch { .. }));
        // The original is untouched.
        assert_eq!(w.version(), 1);
        assert_eq!(w.obstacles().len(), 1);
    }
}
