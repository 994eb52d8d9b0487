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
use dyfos_shared::world::{AxisBox, Bounds, CellIndex, Obstacle, Sun, VoxelGrid, World};

/// Cell side of the building, m.
pub const RESOLUTION: f64 = 0.05;
/// Room pitch in cells (5 m).
pub const ROOM_CELLS: i64 = 100;
/// Wall height in cells (3 m).
pub const WALL_CELLS: i64 = 60;
/// Doorway width and height in cells (1 m × 2 m).
const DOOR: (i64, i64) = (20, 40);
/// A 1.2 × 0.8 m table top at 0.75 m in each room, off centre: its cells across x
/// and y in the room, and its layer.
const TABLE: (std::ops::Range<i64>, std::ops::Range<i64>, i64) = (60..84, 20..36, 15);

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
        TABLE.0.contains(&ri) && TABLE.1.contains(&rj) && k == TABLE.2
    }

    /// The occupied cells, in x, y, z order.
    pub fn cells(&self) -> impl Iterator<Item = CellIndex> + '_ {
        let side = self.side;
        (0..side).flat_map(move |i| {
            (0..side).flat_map(move |j| (0..=WALL_CELLS).filter(move |k| self.solid(i, j, *k)).map(move |k| [i, j, k]))
        })
    }

    /// The same building as boxes, each the union of a run of its cells (cell
    /// (i, j, k) spans [i, i + 1] × [j, j + 1] × [k, k + 1] cells): the floor slab,
    /// each wall line's pieces between doorways and the lintels above them, and the
    /// tables. Walls cross where lines meet; the boxes overlap there. Ids from 1.
    pub fn boxes(&self) -> Vec<(u32, Obstacle)> {
        let cell = |c: i64| c as f64 * RESOLUTION;
        let cube = |lo: [i64; 3], hi: [i64; 3]| {
            Obstacle::Box(AxisBox {
                min: Point3::new(cell(lo[0]), cell(lo[1]), cell(lo[2])),
                max: Point3::new(cell(hi[0]), cell(hi[1]), cell(hi[2])),
            })
        };
        let side = self.side;
        let mut boxes = vec![cube([0, 0, 0], [side, side, 1])];
        // The wall lines across x (at i) and across y (at j): ROOM_CELLS apart, and
        // the last cell of the building.
        let lines: Vec<i64> = (0..side).step_by(ROOM_CELLS as usize).chain([side - 1]).collect();
        let (door_lo, door_hi) = (ROOM_CELLS / 2 - DOOR.0 / 2 + 1, ROOM_CELLS / 2 + DOOR.0 / 2);
        for &at in &lines {
            // Along the line, room by room: solid up to the doorway, the lintel over
            // it, solid after it.
            let mut pieces = Vec::new();
            for room in (0..side).step_by(ROOM_CELLS as usize) {
                let end = (room + ROOM_CELLS).min(side);
                pieces.push(((room, room + door_lo), 1));
                pieces.push(((room + door_lo, room + door_hi), DOOR.1 + 1));
                pieces.push(((room + door_hi, end), 1));
            }
            for ((a, b), k) in pieces {
                boxes.push(cube([at, a, k], [at + 1, b, WALL_CELLS + 1]));
                boxes.push(cube([a, at, k], [b, at + 1, WALL_CELLS + 1]));
            }
        }
        for a in (0..side).step_by(ROOM_CELLS as usize) {
            for b in (0..side).step_by(ROOM_CELLS as usize) {
                boxes.push(cube(
                    [a + TABLE.0.start, b + TABLE.1.start, TABLE.2],
                    [a + TABLE.0.end, b + TABLE.1.end, TABLE.2 + 1],
                ));
            }
        }
        (1..).zip(boxes).collect()
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_boxes_hold_exactly_the_cells() {
        for side in [ROOM_CELLS, 2 * ROOM_CELLS] {
            let b = Building { side };
            let boxes = b.boxes();
            let inside = |i: i64, j: i64, k: i64| {
                let c = Point3::new(i as f64 + 0.5, j as f64 + 0.5, k as f64 + 0.5) * RESOLUTION;
                boxes.iter().any(|(_, o)| match o {
                    Obstacle::Box(x) => (0..3).all(|a| x.min[a] < c[a] && c[a] < x.max[a]),
                    Obstacle::Cylinder(_) => false,
                })
            };
            // Every layer where the building changes, and one beyond it.
            for k in [0, 1, TABLE.2, DOOR.1, DOOR.1 + 1, WALL_CELLS, WALL_CELLS + 1] {
                for i in 0..side {
                    for j in 0..side {
                        assert_eq!(inside(i, j, k), b.solid(i, j, k), "side {side}: cell ({i}, {j}, {k})");
                    }
                }
            }
        }
    }
}
