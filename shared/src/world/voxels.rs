//! The occupancy grid of SPEC §1: closed cubic cells, occupied or free.
//!
//! Cells are kept as a sorted set (the map's canonical content) and, for queries, as a
//! dense bitmap over the occupied cells' bounding box. A segment walks the grid
//! cell by cell (Amanatides & Woo); because cells are closed, a segment running
//! exactly along a cell face or through an edge also touches the neighbours there,
//! and the walk checks those too.
//!
//! ```
//! use dyfos_shared::world::{Segment, VoxelGrid};
//! use nalgebra::{Point3, Vector3};
//!
//! let grid = VoxelGrid::new(0.5, Point3::origin(), [[4, 0, 0]]).unwrap();
//! let ray = Segment::closed(Point3::new(0.0, 0.25, 0.25), Vector3::x(), 10.0);
//! assert_eq!(grid.first_contact(&ray), Some(2.0));
//! ```

use super::obstacle::{ObstacleError, finite};
use super::segment::{Segment, clip_slab};
use crate::limits::{MAX_OCCUPIED_VOXELS, MAX_VOXEL_GRID_CELLS, MAX_VOXEL_INDEX};
use crate::math::Point3;
use std::collections::BTreeSet;

/// A cell index (i, j, k): the closed cube `origin + resolution·[i, i+1]×[j, j+1]×[k, k+1]`.
pub type CellIndex = [i64; 3];

/// Why a voxel grid or voxel update is invalid.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum VoxelError {
    /// Resolution or origin is not a positive / finite number.
    #[error("voxels.{0}")]
    Geometry(#[from] ObstacleError),
    /// A cell index is beyond ±2^20.
    #[error("cell index {index:?} is beyond ±{MAX_VOXEL_INDEX}")]
    IndexOutOfRange {
        /// The offending index.
        index: CellIndex,
    },
    /// More occupied cells than the map may hold.
    #[error("{count} occupied cells exceed the limit of {MAX_OCCUPIED_VOXELS}")]
    TooManyCells {
        /// How many there would be.
        count: usize,
    },
    /// The occupied cells span a box too large for the dense query bitmap.
    #[error("occupied cells span {cells} grid cells, more than the limit of {MAX_VOXEL_GRID_CELLS}")]
    GridTooLarge {
        /// The bounding box's cell count.
        cells: u64,
    },
}

/// A 3D occupancy grid: resolution, origin and the occupied cells.
#[derive(Debug, Clone, PartialEq)]
pub struct VoxelGrid {
    resolution: f64,
    origin: Point3<f64>,
    occupied: BTreeSet<CellIndex>,
    dense: Dense,
}

/// The dense bitmap over the occupied cells' bounding box.
#[derive(Debug, Clone, PartialEq, Default)]
struct Dense {
    lo: CellIndex,
    dims: [i64; 3],
    bits: Vec<u64>,
}

impl Dense {
    fn build(occupied: &BTreeSet<CellIndex>) -> Result<Self, VoxelError> {
        let Some(first) = occupied.first() else {
            return Ok(Dense::default());
        };
        let (mut lo, mut hi) = (*first, *first);
        for c in occupied {
            for a in 0..3 {
                lo[a] = lo[a].min(c[a]);
                hi[a] = hi[a].max(c[a]);
            }
        }
        let dims = [hi[0] - lo[0] + 1, hi[1] - lo[1] + 1, hi[2] - lo[2] + 1];
        let cells = dims.iter().map(|d| *d as u64).try_fold(1u64, |acc, d| acc.checked_mul(d));
        let cells = cells.unwrap_or(u64::MAX);
        if cells > MAX_VOXEL_GRID_CELLS {
            return Err(VoxelError::GridTooLarge { cells });
        }
        let mut dense = Dense { lo, dims, bits: vec![0; cells.div_ceil(64) as usize] };
        for c in occupied {
            let i = dense.linear(c).expect("cell inside its own bounding box");
            dense.bits[i / 64] |= 1 << (i % 64);
        }
        Ok(dense)
    }

    #[inline]
    fn linear(&self, c: &CellIndex) -> Option<usize> {
        let (x, y, z) = (c[0] - self.lo[0], c[1] - self.lo[1], c[2] - self.lo[2]);
        let inside = (0..self.dims[0]).contains(&x) && (0..self.dims[1]).contains(&y) && (0..self.dims[2]).contains(&z);
        inside.then(|| ((z * self.dims[1] + y) * self.dims[0] + x) as usize)
    }

    #[inline]
    fn get(&self, c: &CellIndex) -> bool {
        self.linear(c).is_some_and(|i| self.bits[i / 64] >> (i % 64) & 1 == 1)
    }
}

fn check_index(index: &CellIndex) -> Result<(), VoxelError> {
    // `unsigned_abs`: a peer may send `i64::MIN`, whose `abs` overflows.
    if index.iter().all(|i| i.unsigned_abs() <= MAX_VOXEL_INDEX.unsigned_abs()) {
        Ok(())
    } else {
        Err(VoxelError::IndexOutOfRange { index: *index })
    }
}

impl VoxelGrid {
    /// A grid with the given occupied cells. Checks resolution > 0, a finite origin,
    /// index ranges and the capacity limits.
    pub fn new(
        resolution: f64,
        origin: Point3<f64>,
        occupied: impl IntoIterator<Item = CellIndex>,
    ) -> Result<Self, VoxelError> {
        finite("resolution", resolution)?;
        if resolution <= 0.0 {
            return Err(ObstacleError::NotPositive { field: "resolution", value: resolution }.into());
        }
        for a in 0..3 {
            finite("origin", origin[a])?;
        }
        let mut set = BTreeSet::new();
        for c in occupied {
            check_index(&c)?;
            set.insert(c);
            if set.len() > MAX_OCCUPIED_VOXELS {
                return Err(VoxelError::TooManyCells { count: set.len() });
            }
        }
        let dense = Dense::build(&set)?;
        Ok(VoxelGrid { resolution, origin, occupied: set, dense })
    }

    /// This grid with `cells` set occupied (`occupied = true`) or free. Atomic: on
    /// error `self` is untouched.
    pub fn with_cells(&self, cells: &[CellIndex], occupied: bool) -> Result<Self, VoxelError> {
        cells.iter().try_for_each(check_index)?;
        let mut set = self.occupied.clone();
        for c in cells {
            if occupied {
                set.insert(*c);
            } else {
                set.remove(c);
            }
        }
        if set.len() > MAX_OCCUPIED_VOXELS {
            return Err(VoxelError::TooManyCells { count: set.len() });
        }
        let dense = Dense::build(&set)?;
        Ok(VoxelGrid { resolution: self.resolution, origin: self.origin, occupied: set, dense })
    }

    /// Cell side, m.
    pub fn resolution(&self) -> f64 {
        self.resolution
    }

    /// Minimum corner of cell (0, 0, 0).
    pub fn origin(&self) -> Point3<f64> {
        self.origin
    }

    /// The occupied cells in index order.
    pub fn occupied(&self) -> impl ExactSizeIterator<Item = &CellIndex> {
        self.occupied.iter()
    }

    /// Whether cell `c` is occupied.
    pub fn is_occupied(&self, c: &CellIndex) -> bool {
        self.dense.get(c)
    }

    /// The bounding box of the occupied cells, as (min, max), or `None` if empty.
    pub fn aabb(&self) -> Option<(Point3<f64>, Point3<f64>)> {
        if self.occupied.is_empty() {
            return None;
        }
        let d = &self.dense;
        let corner = |i: [i64; 3]| self.origin + nalgebra::Vector3::from(i.map(|v| v as f64)) * self.resolution;
        Some((corner(d.lo), corner([d.lo[0] + d.dims[0], d.lo[1] + d.dims[1], d.lo[2] + d.dims[2]])))
    }

    /// The smallest `t ∈ [0, seg.length]` at which the segment touches an occupied
    /// closed cell, or `None`. The segment's `end` is not applied.
    pub fn first_contact(&self, seg: &Segment) -> Option<f64> {
        let (lo, hi) = self.aabb()?;
        let (mut t0, mut t1) = (0.0, seg.length.max(0.0));
        for a in 0..3 {
            if !clip_slab(seg.origin[a], seg.dir[a], lo[a], hi[a], &mut t0, &mut t1) {
                return None;
            }
        }
        let r = self.resolution;
        // Grid coordinates of the entry point, in cells.
        let g = |t: f64, a: usize| (seg.origin[a] + seg.dir[a] * t - self.origin[a]) / r;
        let mut cell = [0i64; 3];
        let mut step = [0i64; 3];
        let mut t_max = [f64::INFINITY; 3];
        let mut t_delta = [f64::INFINITY; 3];
        // Axes along which the segment lies exactly on a cell boundary: there the
        // closed cells on both sides are touched.
        let mut twin = [false; 3];
        // The walk never leaves the dense box (plus the layer of cells touching it):
        // entry coordinates are clamped into it and the walk ends when it steps out.
        // With cells far smaller than the float spacing of `t` (or of the entry
        // point), rounding could otherwise start the walk far outside, or stall `t`
        // while the cells advance forever.
        let (box_lo, box_end) =
            (self.dense.lo, std::array::from_fn::<i64, 3, _>(|a| self.dense.lo[a] + self.dense.dims[a]));
        for a in 0..3 {
            // Snap entry points within 1e-9 cells of a plane onto it, so rounding in
            // the clip does not decide whether a face or edge is touched.
            let raw = g(t0, a).clamp((box_lo[a] - 1) as f64, box_end[a] as f64);
            let ga = if (raw - raw.round()).abs() < 1e-9 { raw.round() } else { raw };
            let fa = ga.floor();
            cell[a] = fa as i64;
            let on_plane = ga == fa;
            let d = seg.dir[a];
            if d > 0.0 {
                step[a] = 1;
                t_delta[a] = r / d;
                t_max[a] = t0 + (fa + 1.0 - ga) * r / d;
                twin[a] = on_plane; // the cell behind touches the entry point
            } else if d < 0.0 {
                step[a] = -1;
                t_delta[a] = -r / d;
                // On a plane moving down, the current (upper) cell touches only at
                // entry; the walk steps down at t0 itself.
                t_max[a] = t0 + (ga - fa) * r / -d;
            } else {
                twin[a] = on_plane;
            }
        }
        if self.touches_any(cell, &twin, [false; 3], &step) {
            return Some(t0);
        }
        loop {
            let t_next = t_max[0].min(t_max[1]).min(t_max[2]);
            if t_next.is_nan() || t_next > t1 {
                return None;
            }
            // Every axis whose boundary is crossed at t_next steps together; the cells
            // reached by stepping any subset of them touch the segment at t_next.
            let tied = [t_max[0] == t_next, t_max[1] == t_next, t_max[2] == t_next];
            // Stepping further out of the box reaches no cell that touches it.
            if (0..3)
                .any(|a| tied[a] && ((step[a] > 0 && cell[a] >= box_end[a]) || (step[a] < 0 && cell[a] < box_lo[a])))
            {
                return None;
            }
            for a in 0..3 {
                if tied[a] {
                    cell[a] += step[a];
                    t_max[a] += t_delta[a];
                }
            }
            // Twins on moving axes touch only the start point, so they count while the
            // walk is still there (several axes can step at t0 itself).
            let at_start = t_next <= t0;
            let still: [bool; 3] = std::array::from_fn(|a| twin[a] && (step[a] == 0 || at_start));
            if self.touches_any(cell, &still, tied, &step) {
                return Some(t_next.max(t0));
            }
        }
    }

    /// Whether `cell`, or a cell reached from it by un-stepping any subset of the
    /// `tied` axes or moving to the lower twin on `twin` axes, is occupied.
    #[inline]
    fn touches_any(&self, cell: CellIndex, twin: &[bool; 3], tied: [bool; 3], step: &[i64; 3]) -> bool {
        for mask in 0u8..8 {
            let mut c = cell;
            let mut ok = true;
            for a in 0..3 {
                if mask >> a & 1 == 1 {
                    if tied[a] {
                        c[a] -= step[a];
                    } else if twin[a] {
                        c[a] -= 1;
                    } else {
                        ok = false;
                    }
                }
            }
            if ok && self.dense.get(&c) {
                return true;
            }
        }
        false
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::Vector3;
    use crate::world::segment::first_contact_aabb;

    /// Reference: every occupied cell as a closed box.
    fn brute(grid: &VoxelGrid, seg: &Segment) -> Option<f64> {
        grid.occupied()
            .filter_map(|c| {
                let lo = grid.origin() + Vector3::from(c.map(|v| v as f64)) * grid.resolution();
                let hi = lo + Vector3::repeat(grid.resolution());
                first_contact_aabb(seg, &lo, &hi)
            })
            .min_by(f64::total_cmp)
    }

    /// A tiny deterministic generator (the shared crate does not depend on rand).
    struct Lcg(u64);
    impl Lcg {
        fn next(&mut self) -> f64 {
            self.0 = self.0.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (self.0 >> 11) as f64 / (1u64 << 53) as f64
        }
    }

    #[test]
    fn walk_agrees_with_every_cell_as_a_box() {
        let mut rng = Lcg(7);
        let mut cells = Vec::new();
        for _ in 0..60 {
            cells.push([(rng.next() * 10.0) as i64 - 2, (rng.next() * 10.0) as i64 - 2, (rng.next() * 4.0) as i64]);
        }
        let grid = VoxelGrid::new(0.25, Point3::new(-1.0, 0.5, 0.0), cells).unwrap();
        let mut hits = 0;
        for i in 0..20_000 {
            // Half the rays start on grid planes and run along axes or diagonals, to
            // exercise faces, edges and corners.
            let (o, d) = if i % 2 == 0 {
                let o = Point3::new(-1.5 + rng.next() * 4.0, rng.next() * 4.0, rng.next() * 1.2 - 0.1);
                let d = Vector3::new(rng.next() - 0.5, rng.next() - 0.5, rng.next() - 0.5);
                (o, d)
            } else {
                let snap = |v: f64| (v * 4.0).round() / 4.0;
                let o = Point3::new(snap(-1.5 + rng.next() * 4.0), snap(rng.next() * 4.0), snap(rng.next() * 1.2));
                let pick = |r: f64| [-1.0, 0.0, 1.0][(r * 3.0) as usize];
                let d = Vector3::new(pick(rng.next()), pick(rng.next()), pick(rng.next()));
                if d == Vector3::zeros() {
                    continue;
                }
                (o, d)
            };
            let seg = Segment::closed(o, d.normalize(), rng.next() * 5.0);
            let (a, b) = (grid.first_contact(&seg), brute(&grid, &seg));
            match (a, b) {
                (Some(x), Some(y)) => assert!((x - y).abs() < 1e-9, "{seg:?}: walk {x} vs boxes {y}"),
                _ => assert_eq!(a, b, "{seg:?}"),
            }
            hits += usize::from(b.is_some());
        }
        assert!(hits > 1000, "too few hits ({hits}) to mean anything");
    }

    #[test]
    fn along_a_face_touches() {
        let grid = VoxelGrid::new(1.0, Point3::origin(), [[2, 0, 0]]).unwrap();
        // Along the top face z = 1 and along the side face y = 0.
        let top = Segment::closed(Point3::new(0.0, 0.5, 1.0), Vector3::x(), 5.0);
        assert_eq!(grid.first_contact(&top), Some(2.0));
        let side = Segment::closed(Point3::new(0.0, 0.0, 0.5), Vector3::x(), 5.0);
        assert_eq!(grid.first_contact(&side), Some(2.0));
        let above = Segment::closed(Point3::new(0.0, 0.5, 1.0 + 1e-9), Vector3::x(), 5.0);
        assert_eq!(grid.first_contact(&above), None);
    }

    #[test]
    fn limits_are_checked() {
        assert!(matches!(VoxelGrid::new(0.0, Point3::origin(), []), Err(VoxelError::Geometry(_))));
        assert!(matches!(
            VoxelGrid::new(0.1, Point3::origin(), [[MAX_VOXEL_INDEX + 1, 0, 0]]),
            Err(VoxelError::IndexOutOfRange { .. })
        ));
        assert!(matches!(
            VoxelGrid::new(0.1, Point3::origin(), [[-MAX_VOXEL_INDEX, 0, 0], [MAX_VOXEL_INDEX, 1000, 1000]]),
            Err(VoxelError::GridTooLarge { .. })
        ));
    }

    /// Regression: `i64::MIN` from a peer overflowed `abs()` (a panic in the daemon).
    #[test]
    fn extreme_cell_indices_are_rejected_not_overflowed() {
        for bad in [i64::MIN, i64::MIN + 1, i64::MAX, -MAX_VOXEL_INDEX - 1] {
            assert!(
                matches!(VoxelGrid::new(0.5, Point3::origin(), [[0, bad, 0]]), Err(VoxelError::IndexOutOfRange { .. })),
                "{bad}"
            );
            let grid = VoxelGrid::new(0.5, Point3::origin(), [[0, 0, 0]]).unwrap();
            assert!(grid.with_cells(&[[bad, 0, 0]], true).is_err(), "{bad}");
        }
        assert!(VoxelGrid::new(0.5, Point3::origin(), [[-MAX_VOXEL_INDEX, 0, 0]]).is_ok());
    }

    /// Regression: with cells far smaller than the float spacing of the ray
    /// parameter, `t` stopped advancing and the walk never ended (a worker hung,
    /// deadline or not); far from the origin the entry cell saturated and overflowed.
    #[test]
    fn voxel_walk_with_cells_below_float_spacing_terminates() {
        let (tx, rx) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            let mut results = Vec::new();
            for (resolution, origin) in [(1e-17, 5.0), (1e-300, 5.0), (1e-300, 1e6), (1e-12, -1e6), (1e6, 0.0)] {
                let grid =
                    VoxelGrid::new(resolution, Point3::new(origin, 0.0, 0.0), [[0, 100, 100], [100, 100, 0]]).unwrap();
                for (y, z) in [(100.5, 50.5), (100.0, 0.0), (0.5, 0.5)] {
                    let o = Point3::new(origin - 1.0, y * resolution, z * resolution);
                    for d in [Vector3::x(), -Vector3::x(), Vector3::new(1.0, 1e-3, 1e-3).normalize()] {
                        results.push(grid.first_contact(&Segment::closed(o, d, 10.0)));
                    }
                }
            }
            let _ = tx.send(results);
        });
        let results = rx.recv_timeout(std::time::Duration::from_secs(60)).expect("every walk ends");
        assert_eq!(results.len(), 45);
        assert!(results.iter().flatten().all(|t| (0.0..=10.0).contains(t)), "{results:?}");
    }
}
