//! The occupancy grid of SPEC §1: closed cubic cells, occupied or free.
//!
//! The cells live in a sparse tree ([`tree`]: 64³ blocks of 8³ bricks of bits),
//! shared between versions of a map, and a segment finds its first contact by
//! walking that tree level by level ([`walk`]), exactly as a walk over every cell
//! would: closed cubes, grazing counts. Each brick and node keeps the box of its
//! occupied cells ([`bounds`]), so the walk passes a block whose cells lie away
//! from the segment (a floor under a sight line) without walking them. The design
//! carries [`MAX_OCCUPIED_VOXELS`] cells at 1–3 bytes each on surfaces;
//! `dyfos-bench octomap` measures it.
//!
//! ```
//! use dyfos_shared::world::{Segment, VoxelGrid};
//! use nalgebra::{Point3, Vector3};
//!
//! let grid = VoxelGrid::new(0.5, Point3::origin(), [[4, 0, 0]]).unwrap();
//! let ray = Segment::closed(Point3::new(0.0, 0.25, 0.25), Vector3::x(), 10.0);
//! assert_eq!(grid.first_contact(&ray), Some(2.0));
//! ```

mod batch;
mod bounds;
mod cover;
mod near;
mod near_covers;
mod tree;
mod walk;

use super::obstacle::{ObstacleError, finite};
use super::segment::{Segment, clip_slab};
use crate::limits::{MAX_OCCUPIED_VOXELS, MAX_VOXEL_BLOCKS_SPANNED, MAX_VOXEL_INDEX};
use crate::math::{Point3, floor};
pub use near::NearBricks;
use tree::{Tree, TreeLimit};

/// A cell index (i, j, k): the closed cube `origin + resolution·[i, i+1]×[j, j+1]×[k, k+1]`.
pub type CellIndex = [i64; 3];

/// 4 × 4 × 4 cells in one 64-bit mask: the compact form of voxel updates, uploads,
/// snapshots and stored maps. Cell `min + (x, y, z)` (each 0..4) is bit `16x + 4y + z`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub struct VoxelBlock {
    /// The block's minimum cell; every index a multiple of 4.
    pub min: CellIndex,
    /// Which of its cells are meant.
    pub mask: u64,
}

impl VoxelBlock {
    /// Its cells, in order (x, then y, then z).
    pub fn cells(&self) -> impl Iterator<Item = CellIndex> + '_ {
        let mut mask = self.mask;
        std::iter::from_fn(move || {
            if mask == 0 {
                return None;
            }
            let b = i64::from(mask.trailing_zeros());
            mask &= mask - 1;
            Some([self.min[0] + (b >> 4), self.min[1] + (b >> 2 & 3), self.min[2] + (b & 3)])
        })
    }

    /// Groups cells (any order, duplicates allowed) into blocks, in block order.
    pub fn from_cells(cells: impl IntoIterator<Item = CellIndex>) -> Vec<VoxelBlock> {
        let mut blocks = std::collections::BTreeMap::<CellIndex, u64>::new();
        for c in cells {
            let min = c.map(|v| v & !3);
            *blocks.entry(min).or_default() |= 1 << ((c[0] & 3) * 16 + (c[1] & 3) * 4 + (c[2] & 3));
        }
        blocks.into_iter().map(|(min, mask)| VoxelBlock { min, mask }).collect()
    }

    fn check(&self) -> Result<(), VoxelError> {
        if self.min.iter().any(|v| v & 3 != 0) {
            return Err(VoxelError::MisalignedBlock { min: self.min });
        }
        check_index(&self.min)?;
        if self.min.iter().any(|v| v.unsigned_abs() + 3 > MAX_VOXEL_INDEX.unsigned_abs()) {
            return self.cells().try_for_each(|c| check_index(&c));
        }
        Ok(())
    }
}

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
    /// A block's minimum cell is not a multiple of 4 on every axis.
    #[error("voxel block at {min:?}: a block's minimum cell must be a multiple of 4 on every axis")]
    MisalignedBlock {
        /// The offending corner.
        min: CellIndex,
    },
    /// More occupied cells than a map may hold.
    #[error(
        "{count} occupied cells exceed the limit of {MAX_OCCUPIED_VOXELS} a map holds; use a coarser resolution or split the area into maps"
    )]
    TooManyCells {
        /// How many there would be.
        count: u64,
    },
    /// The occupied cells are spread over too large a box.
    #[error(
        "the occupied cells span {blocks} blocks of 64³ cells, more than the limit of {MAX_VOXEL_BLOCKS_SPANNED}; keep a map's cells within a few kilometres at 0.05 m, or split it"
    )]
    GridTooLarge {
        /// 64³ blocks in the occupied cells' bounding box.
        blocks: u64,
    },
}

impl From<TreeLimit> for VoxelError {
    fn from(limit: TreeLimit) -> Self {
        match limit {
            TreeLimit::Cells(count) => VoxelError::TooManyCells { count },
            TreeLimit::Span(blocks) => VoxelError::GridTooLarge { blocks },
        }
    }
}

/// A 3D occupancy grid: resolution, origin and the occupied cells.
#[derive(Clone)]
pub struct VoxelGrid {
    resolution: f64,
    origin: Point3<f64>,
    tree: Tree,
}

impl std::fmt::Debug for VoxelGrid {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("VoxelGrid")
            .field("resolution", &self.resolution)
            .field("origin", &self.origin)
            .field("cells", &self.len())
            .field("aabb", &self.aabb())
            .finish()
    }
}

impl PartialEq for VoxelGrid {
    /// The same resolution, origin and occupied cells.
    fn eq(&self, other: &Self) -> bool {
        self.resolution == other.resolution
            && self.origin == other.origin
            && self.tree.cells() == other.tree.cells()
            && self.tree.bricks().eq(other.tree.bricks())
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
        let empty = Self::empty(resolution, origin)?;
        let mut editor = empty.tree.edit();
        for c in occupied {
            check_index(&c)?;
            editor.edit_cell(c, true);
            // Bounded as it grows, not only at the end: the input may be endless.
            if editor.cells() > MAX_OCCUPIED_VOXELS as u64 {
                return Err(VoxelError::TooManyCells { count: editor.cells() });
            }
        }
        Ok(VoxelGrid { tree: editor.finish(MAX_OCCUPIED_VOXELS as u64, MAX_VOXEL_BLOCKS_SPANNED)?, ..empty })
    }

    /// A grid with no cells.
    pub fn empty(resolution: f64, origin: Point3<f64>) -> Result<Self, VoxelError> {
        finite("resolution", resolution)?;
        if resolution <= 0.0 {
            return Err(ObstacleError::NotPositive { field: "resolution", value: resolution }.into());
        }
        for a in 0..3 {
            finite("origin", origin[a])?;
        }
        Ok(VoxelGrid { resolution, origin, tree: Tree::default() })
    }

    /// This grid with `cells` set occupied (`occupied = true`) or free. Atomic: on
    /// error `self` is untouched.
    pub fn with_cells(&self, cells: &[CellIndex], occupied: bool) -> Result<Self, VoxelError> {
        cells.iter().try_for_each(check_index)?;
        let mut editor = self.tree.edit();
        for c in cells {
            editor.edit_cell(*c, occupied);
        }
        let tree = editor.finish(MAX_OCCUPIED_VOXELS as u64, MAX_VOXEL_BLOCKS_SPANNED)?;
        Ok(VoxelGrid { tree, ..*self })
    }

    /// This grid with the cells of `blocks` set occupied or free (cells outside a
    /// block's mask are untouched). Atomic like [`VoxelGrid::with_cells`].
    pub fn with_blocks(&self, blocks: &[VoxelBlock], occupied: bool) -> Result<Self, VoxelError> {
        blocks.iter().try_for_each(VoxelBlock::check)?;
        let mut editor = self.tree.edit();
        for b in blocks {
            let corner = b.min.map(|v| v & 4);
            editor.edit_brick(b.min.map(|v| v & !7), &tree::bits_of_block(b.mask, corner), occupied);
        }
        let tree = editor.finish(MAX_OCCUPIED_VOXELS as u64, MAX_VOXEL_BLOCKS_SPANNED)?;
        Ok(VoxelGrid { tree, ..*self })
    }

    /// A grid whose occupied cells are the cubes `(min, side)`, `side` a power of two
    /// and every `min` a multiple of it (an octree's occupied nodes). The caller
    /// checks the total against [`MAX_OCCUPIED_VOXELS`] first.
    pub(crate) fn from_cubes(
        resolution: f64,
        origin: Point3<f64>,
        cubes: impl IntoIterator<Item = (CellIndex, i64)>,
    ) -> Result<Self, VoxelError> {
        let empty = Self::empty(resolution, origin)?;
        let mut editor = empty.tree.edit();
        for (min, side) in cubes {
            check_index(&min)?;
            check_index(&min.map(|v| v + side - 1))?;
            if side >= 8 {
                let full = [u64::MAX; 8];
                for x in (0..side).step_by(8) {
                    for y in (0..side).step_by(8) {
                        for z in (0..side).step_by(8) {
                            editor.edit_brick([min[0] + x, min[1] + y, min[2] + z], &full, true);
                        }
                    }
                }
            } else {
                for x in 0..side {
                    for y in 0..side {
                        for z in 0..side {
                            editor.edit_cell([min[0] + x, min[1] + y, min[2] + z], true);
                        }
                    }
                }
            }
            if editor.cells() > MAX_OCCUPIED_VOXELS as u64 {
                return Err(VoxelError::TooManyCells { count: editor.cells() });
            }
        }
        Ok(VoxelGrid { tree: editor.finish(MAX_OCCUPIED_VOXELS as u64, MAX_VOXEL_BLOCKS_SPANNED)?, ..empty })
    }

    /// Cell side, m.
    pub fn resolution(&self) -> f64 {
        self.resolution
    }

    /// Minimum corner of cell (0, 0, 0).
    pub fn origin(&self) -> Point3<f64> {
        self.origin
    }

    /// How many cells are occupied.
    pub fn len(&self) -> u64 {
        self.tree.cells()
    }

    /// Whether no cell is occupied.
    pub fn is_empty(&self) -> bool {
        self.tree.cells() == 0
    }

    /// The occupied cells in the grid's own order (by 64³ block, then 8³ brick,
    /// then cell, each x, then y, then z): the same for the same cells, however
    /// they were set.
    pub fn cells(&self) -> impl Iterator<Item = CellIndex> + '_ {
        self.tree.bricks().flat_map(|(min, bits)| tree::cells_of(min, bits))
    }

    /// The occupied cells sorted by index (x, then y, then z), as maps print them.
    pub fn cells_sorted(&self) -> Vec<CellIndex> {
        let mut cells: Vec<CellIndex> = self.cells().collect();
        cells.sort_unstable();
        cells
    }

    /// The occupied cells as non-empty 4³ blocks, in the grid's own order.
    pub fn blocks(&self) -> impl Iterator<Item = VoxelBlock> + '_ {
        self.tree.bricks().flat_map(|(min, bits)| {
            (0..8).filter_map(move |sub: i64| {
                let corner = [(sub >> 2) * 4, (sub >> 1 & 1) * 4, (sub & 1) * 4];
                let mask = tree::block_of(bits, corner);
                (mask != 0)
                    .then(|| VoxelBlock { min: [min[0] + corner[0], min[1] + corner[1], min[2] + corner[2]], mask })
            })
        })
    }

    /// Bytes the grid's storage takes (the root's index, nodes and bricks), shared
    /// with other versions of the same map.
    pub fn memory_bytes(&self) -> usize {
        let (root, nodes, bricks) = self.tree.counts();
        // A brick: its slot, its cells' box and its bits.
        root * 4 + nodes * (std::mem::size_of::<usize>() * 6 + 1024 + 80) + bricks * (2 + 4 + 64)
    }

    /// A 64-bit digest of resolution, origin and cells (FNV-1a over the bricks).
    pub fn digest(&self) -> u64 {
        let fnv =
            |h: u64, b: u64| b.to_le_bytes().iter().fold(h, |h, x| (h ^ u64::from(*x)).wrapping_mul(0x100000001b3));
        let mut h = 0xcbf29ce484222325u64;
        h = fnv(h, self.resolution.to_bits());
        for a in 0..3 {
            h = fnv(h, self.origin[a].to_bits());
        }
        for (min, bits) in self.tree.bricks() {
            for v in min.iter().map(|v| *v as u64).chain(bits.iter().copied()) {
                h = fnv(h, v);
            }
        }
        h
    }

    /// Whether cell `c` is occupied.
    pub fn is_occupied(&self, c: &CellIndex) -> bool {
        self.tree.get(*c)
    }

    /// The bounding box of the occupied cells, as (min, max), or `None` if empty.
    pub fn aabb(&self) -> Option<(Point3<f64>, Point3<f64>)> {
        let (lo, end) = self.tree.bounds()?;
        let corner = |i: [i64; 3]| self.origin + nalgebra::Vector3::from(i.map(|v| v as f64)) * self.resolution;
        Some((corner(lo), corner(end)))
    }

    /// Whether a segment inside the closed box `[lo, hi]` may touch an occupied cell:
    /// `false` only when no cell whose closed cube meets the box is occupied (a cheap
    /// broad phase for a batch of segments, e.g. a viewer's collision star).
    pub fn may_touch_box(&self, lo: &Point3<f64>, hi: &Point3<f64>) -> bool {
        self.may_touch_box_within(lo, hi, 512)
    }

    /// [`VoxelGrid::may_touch_box`] with at most `budget` node and brick lookups.
    fn may_touch_box_within(&self, lo: &Point3<f64>, hi: &Point3<f64>, budget: u32) -> bool {
        match self.cells_near(lo, hi) {
            Err(touch) => touch,
            Ok((first, last)) => self.tree.any_in_box(first, last, budget) != Some(false),
        }
    }

    /// The cells whose closed cubes may meet the closed box `[lo, hi]` (one more on
    /// each side for rounding), cut to the occupied cells' box plus one, as
    /// (first, last); or the answer of [`VoxelGrid::may_touch_box`] when that is
    /// already known: `Err(false)` none, `Err(true)` a bound is not finite.
    #[inline]
    fn cells_near(&self, lo: &Point3<f64>, hi: &Point3<f64>) -> Result<(CellIndex, CellIndex), bool> {
        let Some((cells_lo, cells_end)) = self.tree.bounds() else {
            return Err(false);
        };
        let mut first = [0i64; 3];
        let mut last = [0i64; 3];
        for a in 0..3 {
            let f = floor((lo[a] - self.origin[a]) / self.resolution) - 2.0;
            let l = floor((hi[a] - self.origin[a]) / self.resolution) + 1.0;
            if !(f.is_finite() && l.is_finite()) {
                return Err(true);
            }
            first[a] = (f.max((cells_lo[a] - 1) as f64)) as i64;
            last[a] = (l.min(cells_end[a] as f64)) as i64;
            if first[a] > last[a] {
                return Err(false);
            }
        }
        Ok((first, last))
    }

    /// The smallest `t ∈ [0, seg.length]` at which the segment touches an occupied
    /// closed cell, or `None`. The segment's `end` is not applied. Allocates nothing.
    pub fn first_contact(&self, seg: &Segment) -> Option<f64> {
        self.first_contact_with(seg, true, None, true)
    }

    /// [`VoxelGrid::first_contact`], the same answer bit for bit, for a segment of
    /// a query whose bricks near it are `near`: a short segment among empty bricks
    /// is settled by their bits.
    pub fn first_contact_near(&self, seg: &Segment, near: &NearBricks) -> Option<f64> {
        self.first_contact_with(seg, true, Some(near), true)
    }

    /// [`VoxelGrid::first_contact`], passing blocks by their cells' boxes or not
    /// (`boxes`), trying the covers of the nodes around the segment before the
    /// walk or not (`nodes`; a batch that already tried them skips them): the same
    /// answer, bit for bit, either way.
    pub(super) fn first_contact_with(
        &self,
        seg: &Segment,
        boxes: bool,
        near: Option<&NearBricks>,
        nodes: bool,
    ) -> Option<f64> {
        let (lo, end) = self.tree.bounds()?;
        let (box_lo, box_hi) = self.aabb()?;
        let (mut t0, mut t1) = (0.0, seg.length.max(0.0));
        for a in 0..3 {
            if !clip_slab(seg.origin[a], seg.dir[a], box_lo[a], box_hi[a], &mut t0, &mut t1) {
                return None;
            }
        }
        // A short segment in an empty neighbourhood (most of a collision star) is
        // settled by a few lookups of its box, without a walk.
        if t1 - t0 < 16.0 * self.resolution {
            let (a, b) = (seg.point_at(t0), seg.point_at(t1));
            let (lo, hi) = (a.inf(&b), a.sup(&b));
            let touch = match near {
                Some(near) => self.may_touch_box_near_within(near, &lo, &hi, 16),
                None => self.may_touch_box_within(&lo, &hi, 16),
            };
            if !touch {
                return None;
            }
        }
        let walk = walk::Walk::new(&self.tree, self.resolution, self.origin, seg, lo, end, boxes);
        // A segment clear of the covers of the few nodes around it (a sight line
        // above a floor) touches nothing: no walk.
        if nodes && walk.clears_nodes(t0, t1) {
            return None;
        }
        let mut best = f64::INFINITY;
        // Each level's walk is exact on its own; the coarser ones only skip empty
        // space faster. A segment within a block or two of a level gains nothing
        // from the levels above it but their set-up, so it starts lower.
        let cells = (t1 - t0) / self.resolution;
        if cells < 16.0 {
            walk.walk::<1>(t0, t1, &mut best);
        } else if cells < 64.0 {
            walk.walk::<2>(t0, t1, &mut best);
        } else {
            walk.walk::<{ walk::TOP }>(t0, t1, &mut best);
        }
        best.is_finite().then_some(best)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::Vector3;
    use crate::world::segment::first_contact_aabb;

    /// Reference: every occupied cell as a closed box.
    fn brute(grid: &VoxelGrid, seg: &Segment) -> Option<f64> {
        grid.cells()
            .filter_map(|c| {
                let lo = grid.origin() + Vector3::from(c.map(|v| v as f64)) * grid.resolution();
                let hi = lo + Vector3::repeat(grid.resolution());
                first_contact_aabb(seg, &lo, &hi)
            })
            .min_by(f64::total_cmp)
    }

    /// Asserts that the walk and every cell as a box agree on `seg`; whether it hits.
    fn agrees_with_boxes(grid: &VoxelGrid, seg: &Segment) -> bool {
        let (a, b) = (grid.first_contact(seg), brute(grid, seg));
        match (a, b) {
            (Some(x), Some(y)) => assert!((x - y).abs() < 1e-9, "{seg:?}: walk {x} vs boxes {y}"),
            _ => assert_eq!(a, b, "{seg:?}"),
        }
        b.is_some()
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
            hits += usize::from(agrees_with_boxes(&grid, &seg));
        }
        assert!(hits > 1000, "too few hits ({hits}) to mean anything");
    }

    /// Cells in clusters over several 64³ blocks (negative indices included), rays
    /// long enough to cross blocks and bricks, half of them on grid planes: the walk
    /// through the tree agrees with every cell as a box.
    #[test]
    fn tree_walk_agrees_with_every_cell_as_a_box_across_blocks() {
        let mut rng = Lcg(31);
        let mut cells = Vec::new();
        for cluster in 0..30 {
            let centre =
                [(rng.next() * 300.0) as i64 - 150, (rng.next() * 300.0) as i64 - 150, (rng.next() * 80.0) as i64 - 20];
            for _ in 0..(40 + cluster * 5) {
                cells.push([
                    centre[0] + (rng.next() * 12.0) as i64,
                    centre[1] + (rng.next() * 12.0) as i64,
                    centre[2] + (rng.next() * 6.0) as i64,
                ]);
            }
            // A wall along a block boundary (x = 64) and one on a brick boundary.
            for j in 0..40 {
                cells.push([64, centre[1] + j, centre[2]]);
                cells.push([centre[0] + j, 8, centre[2] + 1]);
            }
        }
        // Planes at exact binary fractions, so "on a plane" means the same to the walk
        // (which snaps within 1e-9 cells) and to the boxes.
        let grid = VoxelGrid::new(0.125, Point3::new(-3.0, 2.0, -1.0), cells).unwrap();
        let mut hits = 0;
        for i in 0..20_000 {
            let (o, d) = if i % 2 == 0 {
                let o = Point3::new(-18.0 + rng.next() * 36.0, -13.0 + rng.next() * 36.0, -3.0 + rng.next() * 10.0);
                (o, Vector3::new(rng.next() - 0.5, rng.next() - 0.5, (rng.next() - 0.5) * 0.5))
            } else {
                // Start on the grid's planes (some on 8- and 64-cell planes).
                let snap =
                    |v: f64, base: f64, every: f64| ((v - base) / (0.125 * every)).round() * 0.125 * every + base;
                let every = [1.0, 8.0, 64.0][i % 3];
                let o = Point3::new(
                    snap(-18.0 + rng.next() * 36.0, -3.0, every),
                    snap(-13.0 + rng.next() * 36.0, 2.0, every),
                    snap(-3.0 + rng.next() * 10.0, -1.0, 1.0),
                );
                let pick = |r: f64| [-1.0, 0.0, 1.0][(r * 3.0) as usize];
                let d = Vector3::new(pick(rng.next()), pick(rng.next()), pick(rng.next()));
                if d == Vector3::zeros() {
                    continue;
                }
                (o, d)
            };
            let seg = Segment::closed(o, d.normalize(), rng.next() * 30.0);
            hits += usize::from(agrees_with_boxes(&grid, &seg));
        }
        assert!(hits > 1000, "too few hits ({hits}) to mean anything");
    }

    /// The same cells set in any order, by cells or by blocks, make equal grids with
    /// the same cells, blocks and digest; an edit leaves the grid it started from as
    /// it was; freeing every cell empties the tree.
    #[test]
    fn content_not_history_defines_a_grid() {
        let mut rng = Lcg(5);
        let cells: Vec<CellIndex> = (0..5000)
            .map(|_| [(rng.next() * 400.0) as i64 - 200, (rng.next() * 90.0) as i64 - 45, (rng.next() * 30.0) as i64])
            .collect();
        let a = VoxelGrid::new(0.2, Point3::origin(), cells.iter().copied()).unwrap();
        let b = VoxelGrid::new(0.2, Point3::origin(), cells.iter().rev().copied()).unwrap();
        let c = VoxelGrid::empty(0.2, Point3::origin())
            .unwrap()
            .with_blocks(&VoxelBlock::from_cells(cells.iter().copied()), true)
            .unwrap();
        let mut sorted = cells.clone();
        sorted.sort_unstable();
        sorted.dedup();
        assert_eq!(a.len(), sorted.len() as u64);
        assert_eq!(a.cells_sorted(), sorted);
        assert!(a == b && a == c && a.digest() == c.digest());
        assert_eq!(a.cells().collect::<Vec<_>>(), c.cells().collect::<Vec<_>>());
        let blocks: Vec<VoxelBlock> = a.blocks().collect();
        assert_eq!(blocks.iter().map(|b| u64::from(b.mask.count_ones())).sum::<u64>(), a.len());
        assert_eq!(VoxelGrid::empty(0.2, Point3::origin()).unwrap().with_blocks(&blocks, true).unwrap(), a);
        // Free half the cells: the original grid keeps them.
        let freed = a.with_cells(&sorted[..2500], false).unwrap();
        assert_eq!(freed.cells_sorted(), sorted[2500..].to_vec());
        assert_eq!(a.cells_sorted(), sorted);
        assert!(sorted[..2500].iter().all(|c| a.is_occupied(c) && !freed.is_occupied(c)));
        let (lo, hi) = freed.aabb().unwrap();
        let lo_cell = sorted[2500..].iter().map(|c| c[0]).min().unwrap();
        assert!((lo.x - lo_cell as f64 * 0.2).abs() < 1e-9 && hi.x > lo.x);
        let none = freed.with_blocks(&freed.blocks().collect::<Vec<_>>(), false).unwrap();
        assert!(none.is_empty() && none.aabb().is_none() && none.cells().next().is_none());
        assert_eq!(none, VoxelGrid::empty(0.2, Point3::origin()).unwrap());
        assert!(matches!(
            a.with_blocks(&[VoxelBlock { min: [1, 0, 0], mask: 1 }], true),
            Err(VoxelError::MisalignedBlock { .. })
        ));
    }

    /// The broad phase never calls a box empty that a cell touches, and its exact
    /// answer (within budget) is the brute one.
    #[test]
    fn box_queries_agree_with_every_cell() {
        let mut rng = Lcg(17);
        let cells: Vec<CellIndex> = (0..400)
            .map(|_| [(rng.next() * 200.0) as i64 - 100, (rng.next() * 200.0) as i64 - 100, (rng.next() * 20.0) as i64])
            .collect();
        let grid = VoxelGrid::new(0.125, Point3::new(1.0, -2.0, 0.5), cells.iter().copied()).unwrap();
        let (mut empty, mut full) = (0, 0);
        for _ in 0..3000 {
            let lo =
                [(rng.next() * 220.0) as i64 - 110, (rng.next() * 220.0) as i64 - 110, (rng.next() * 24.0) as i64 - 2];
            let size = [(rng.next() * 12.0) as i64, (rng.next() * 12.0) as i64, (rng.next() * 6.0) as i64];
            let hi = [lo[0] + size[0], lo[1] + size[1], lo[2] + size[2]];
            let brute = cells.iter().any(|c| (0..3).all(|a| lo[a] <= c[a] && c[a] <= hi[a]));
            if let Some(found) = grid.tree.any_in_box(lo, hi, 10_000) {
                assert_eq!(found, brute, "{lo:?}..={hi:?}");
            }
            // The same box in metres, touching the cells' faces exactly.
            let corner = |c: [i64; 3]| grid.origin() + Vector3::from(c.map(|v| v as f64)) * grid.resolution();
            let (blo, bhi) = (corner(lo), corner(hi.map(|v| v + 1)));
            let touched = cells.iter().any(|c| (0..3).all(|a| lo[a] - 1 <= c[a] && c[a] <= hi[a] + 1));
            if !grid.may_touch_box(&blo, &bhi) {
                assert!(!touched, "{lo:?}..={hi:?} called empty");
                empty += 1;
            } else {
                full += usize::from(brute);
            }
        }
        assert!(empty > 500 && full > 100, "{empty} empty, {full} full");
    }

    /// The same on dense blocks and boxes across several 64³ nodes, where the test
    /// goes by the nodes' maps of non-empty bricks (whole bricks inside the box,
    /// bricks on its faces), before and after half the cells (and whole bricks) are
    /// cleared.
    #[test]
    fn box_queries_agree_with_every_cell_on_dense_blocks() {
        let mut rng = Lcg(23);
        let mut cells: Vec<CellIndex> = Vec::new();
        for x in -70i64..90 {
            for y in -20..30 {
                for z in 0..12 {
                    // Dense around x = 0 and x = 64 (two nodes), sparse elsewhere.
                    let p = if x.rem_euclid(64) < 12 { 0.5 } else { 0.002 };
                    if rng.next() < p {
                        cells.push([x, y, z]);
                    }
                }
            }
        }
        // Half the cells, and every cell of a slab: whole bricks become empty.
        let cleared: Vec<CellIndex> =
            cells.iter().copied().filter(|c| (0..12).contains(&c[0]) && c[1] < 8 || rng.next() < 0.5).collect();
        let full_grid = VoxelGrid::new(0.1, Point3::origin(), cells.iter().copied()).unwrap();
        let half_grid = full_grid.with_cells(&cleared, false).unwrap();
        let half: Vec<CellIndex> = cells.iter().copied().filter(|c| !cleared.contains(c)).collect();
        for (grid, cells) in [(&full_grid, &cells), (&half_grid, &half)] {
            let (mut found_yes, mut found_no) = (0, 0);
            for _ in 0..3000 {
                let lo =
                    [(rng.next() * 180.0) as i64 - 80, (rng.next() * 60.0) as i64 - 25, (rng.next() * 14.0) as i64 - 1];
                let size = [(rng.next() * 140.0) as i64, (rng.next() * 30.0) as i64, (rng.next() * 10.0) as i64];
                let hi = [lo[0] + size[0], lo[1] + size[1], lo[2] + size[2]];
                let brute = cells.iter().any(|c| (0..3).all(|a| lo[a] <= c[a] && c[a] <= hi[a]));
                let found = grid.tree.any_in_box(lo, hi, 100_000).expect("within budget");
                assert_eq!(found, brute, "{lo:?}..={hi:?}");
                if found { found_yes += 1 } else { found_no += 1 }
            }
            assert!(found_yes > 300 && found_no > 300, "{found_yes} found, {found_no} empty");
        }
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
