//! OctoMap maps at scale: a synthetic building of any size, written as
//! OctoMap's `.bt`, for load, update, restart and query figures beside the real
//! Freiburg map.
//!
//! The building is one storey of square rooms at 0.05 m: a floor slab one cell
//! thick, walls one cell thick and `WALL_CELLS` high on a `ROOM_CELLS` grid with a
//! doorway in every wall, and a table in every room. About 2.1 cells per square
//! cell of floor, so its side grows as the square root of the cells asked for.
//!
//! ```
//! use dyfos_bench::octomap::{Building, WALL_CELLS};
//!
//! let b = Building::with_cells(200_000);
//! let cells: Vec<_> = b.cells().collect();
//! assert!((cells.len() as f64 - 200_000.0).abs() < 30_000.0, "{}", cells.len());
//! assert!(cells.iter().all(|c| (0..b.side).contains(&c[0]) && (0..=WALL_CELLS).contains(&c[2])));
//! ```

use crate::numerical::{NumericalConfig, numerical_map};
use dyfos_shared::math::Point3;
use dyfos_shared::posterior::Belief;
use dyfos_shared::scenario::Scenario;
use dyfos_shared::world::{Bounds, CellIndex, Sun, VoxelGrid, World};

/// Cell side of the building, m.
pub const RESOLUTION: f64 = 0.05;
/// Room pitch in cells (5 m).
pub const ROOM_CELLS: i64 = 100;
/// Wall height in cells (3 m).
pub const WALL_CELLS: i64 = 60;
/// Doorway width and height in cells (1 m × 2 m).
const DOOR: (i64, i64) = (20, 40);

/// A square one-storey building of `side` × `side` cells.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Building {
    /// Cells per side.
    pub side: i64,
}

impl Building {
    /// The building whose cell count is closest to `cells` (whole rooms).
    pub fn with_cells(cells: u64) -> Self {
        // Floor side², walls ≈ 2·side·(side/ROOM)·WALL·(1 − door share) + tables.
        let per_side2 = 1.0 + 2.0 * WALL_CELLS as f64 / ROOM_CELLS as f64 * 0.85 + 0.05;
        let side = ((cells as f64 / per_side2).sqrt() / ROOM_CELLS as f64).round().max(1.0) as i64 * ROOM_CELLS;
        Building { side }
    }

    /// Whether (i, j, k) is solid.
    fn solid(&self, i: i64, j: i64, k: i64) -> bool {
        if k == 0 {
            return true; // the floor slab
        }
        if k > WALL_CELLS {
            return false;
        }
        let (ri, rj) = (i % ROOM_CELLS, j % ROOM_CELLS);
        let wall = |along: i64| {
            // A doorway centred in each wall, DOOR.0 wide and DOOR.1 high.
            let door = (along - ROOM_CELLS / 2).abs() < DOOR.0 / 2 && k <= DOOR.1;
            !door
        };
        if ri == 0 || i == self.side - 1 {
            return wall(rj);
        }
        if rj == 0 || j == self.side - 1 {
            return wall(ri);
        }
        // A 1.2 × 0.8 m table top at 0.75 m in each room, off centre.
        (60..84).contains(&ri) && (20..36).contains(&rj) && k == 15
    }

    /// The occupied cells, in x, y, z order.
    pub fn cells(&self) -> impl Iterator<Item = CellIndex> + '_ {
        let side = self.side;
        (0..side).flat_map(move |i| {
            (0..side).flat_map(move |j| (0..=WALL_CELLS).filter(move |k| self.solid(i, j, *k)).map(move |k| [i, j, k]))
        })
    }

    /// The map bounds: the building's square, cell (0, 0, 0) at the origin.
    pub fn bounds(&self) -> anyhow::Result<Bounds> {
        let side = self.side as f64 * RESOLUTION;
        Ok(Bounds::new([0.0, 0.0, side, side])?)
    }

    /// The sun of every building map.
    pub fn sun() -> Sun {
        Sun::new(0.6, 2.4).expect("a valid sun")
    }

    /// The building as a world with its cells as the voxel grid.
    pub fn world(&self) -> anyhow::Result<World> {
        let grid = VoxelGrid::new(RESOLUTION, Point3::origin(), self.cells())?;
        Ok(World::new(0, self.bounds()?, Self::sun(), [], Some(grid))?)
    }

    /// A scenario looking at the building in `world`: the rover in room (1, 1), the
    /// viewer below the ceiling, SPEC §10's other parameters.
    pub fn scenario(&self, world: World) -> anyhow::Result<Scenario> {
        let rover = self.room_centre(1, 1, 0.3);
        let belief = Belief::new(rover, [[0.04, 0.0, 0.0], [0.0, 0.04, 0.0], [0.0, 0.0, 0.02]])?;
        let mut params = numerical_map(1, 0, &NumericalConfig::paper()).params;
        params.z_max = 2.4;
        Ok(Scenario { world, belief, params })
    }

    /// The centre of room (a, b) at height `z`, m, with the building's cell
    /// (0, 0, 0) at the origin.
    pub fn room_centre(&self, a: i64, b: i64, z: f64) -> [f64; 3] {
        let c = |r: i64| (r * ROOM_CELLS + ROOM_CELLS / 2) as f64 * RESOLUTION;
        [c(a), c(b), z]
    }
}
