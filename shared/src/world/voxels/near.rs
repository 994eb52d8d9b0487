//! The grid's bricks near one query, one bit each: the broad phase of the query's
//! collision stars and sight lines in a few word operations.
//!
//! A query asks, for every candidate, whether an occupied cell may be near its
//! collision star's box and near its sight lines' box
//! ([`VoxelGrid::may_touch_box`]): a descent through the tree's nodes and bricks,
//! hundreds of instructions even where the box is empty. Every box a query asks
//! about lies in a region known before its first candidate, so
//! [`VoxelGrid::near_bricks`] lists the region's non-empty 8³ bricks once, as bits.
//! A box whose bricks are all empty is then answered at once; one meeting a
//! non-empty brick gets the tree's test on the same cells, and one leaving the
//! region the tree's test as before. The answer is the tree's either way: `false`
//! only when no occupied cell's closed cube meets the box.

use super::bounds::Region;
use super::near_covers::{Gathered, NearCovers};
use super::tree::BRICK_SHIFT;
use super::{CellIndex, VoxelGrid};
use crate::math::Point3;
use arrayvec::ArrayVec;
use std::sync::Arc;

/// Most bricks the region spans along an axis: a row of x is one word, a layer's
/// rows of y are one word.
const SPAN: i64 = 64;

/// Cells of a brick's side.
const SIDE: i64 = 1 << BRICK_SHIFT;

/// The non-empty bricks of a grid within a region ([`VoxelGrid::near_bricks`]).
/// Built once per query; its tests allocate nothing.
#[derive(Debug, Clone)]
pub struct NearBricks {
    /// The region's bricks (cell index >> 3), inclusive; `hi < lo` on some axis
    /// when it is empty.
    lo: [i64; 3],
    hi: [i64; 3],
    /// Per axis, whether no brick below `lo` (`open_lo`) or above `hi`
    /// (`open_hi`) holds an occupied cell: a box reaching past such an edge is
    /// cut to it.
    open_lo: [bool; 3],
    open_hi: [bool; 3],
    /// The region's minimum corner, m, and 1 / the resolution.
    corner: [f64; 3],
    per_cell: f64,
    /// Rows per layer: the region's bricks along y.
    ny: i64,
    /// Row `(z − lo z)·ny + (y − lo y)`: bit `x − lo x` set when that brick holds
    /// an occupied cell.
    rows: Vec<u64>,
    /// Per layer `z − lo z`: bit `y − lo y` set when row (y, z) is not empty.
    layers: Vec<u64>,
    /// The covers of the region's nodes (shared: a search narrowing the query's
    /// region for a group of candidates copies the bricks, not the covers).
    covers: Arc<NearCovers>,
}

impl Default for NearBricks {
    /// No region: every box gets the tree's test.
    fn default() -> Self {
        NearBricks {
            lo: [0; 3],
            hi: [-1; 3],
            open_lo: [false; 3],
            open_hi: [false; 3],
            corner: [0.0; 3],
            per_cell: 0.0,
            ny: 0,
            rows: Vec::new(),
            layers: Vec::new(),
            covers: Arc::default(),
        }
    }
}

/// Where a box's cells lie against a region.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Cells {
    /// Past an open edge: no occupied cell near the box.
    None,
    /// Cells `first..=last` from the region's minimum cell, within the region.
    Within(CellIndex, CellIndex),
    /// Beyond the region, or not finite.
    Outside,
}

/// Bits `first..=last` of a word, each in 0..64, `first <= last`.
#[inline]
fn bits(first: i64, last: i64) -> u64 {
    (u64::MAX >> (63 - last)) & (u64::MAX << first)
}

impl NearBricks {
    /// Forgets the region (every box then gets the tree's test), keeping the buffers.
    pub fn clear(&mut self) {
        (self.lo, self.hi) = ([0; 3], [-1; 3]);
    }

    /// The cells whose closed cubes may meet the closed box `[lo, hi]`, as
    /// [`VoxelGrid::may_touch_box`] takes them (one more on each side for
    /// rounding), cut at open edges.
    #[inline]
    fn cells(&self, lo: &Point3<f64>, hi: &Point3<f64>) -> Cells {
        // First on every axis: a NaN anywhere settles nothing.
        let mut u = [[0.0; 2]; 3];
        for a in 0..3 {
            u[a] = [(lo[a] - self.corner[a]) * self.per_cell - 2.0, (hi[a] - self.corner[a]) * self.per_cell + 1.0];
            if u[a][0].is_nan() || u[a][1].is_nan() || u[a][0] > u[a][1] {
                return Cells::Outside;
            }
        }
        let mut first = [0i64; 3];
        let mut last = [0i64; 3];
        for a in 0..3 {
            let [u0, u1] = u[a];
            let end = ((self.hi[a] - self.lo[a] + 1) * SIDE) as f64;
            if end <= 0.0 {
                return Cells::Outside;
            }
            if u1 < 0.0 || u0 >= end {
                let past_open = (u1 < 0.0 && self.open_lo[a]) || (u0 >= end && self.open_hi[a]);
                return if past_open { Cells::None } else { Cells::Outside };
            }
            // Non-negative: the casts are floors.
            let f = if u0 >= 0.0 {
                u0
            } else if self.open_lo[a] {
                0.0
            } else {
                return Cells::Outside;
            };
            let l = if u1 < end {
                u1
            } else if self.open_hi[a] {
                end - 1.0
            } else {
                return Cells::Outside;
            };
            (first[a], last[a]) = (f as i64, l as i64);
        }
        Cells::Within(first, last)
    }

    /// Whether every brick holding a cell of `first..=last` (from the region's
    /// minimum cell, within the region) is empty.
    #[inline]
    fn all_empty(&self, first: &CellIndex, last: &CellIndex) -> bool {
        let xs = bits(first[0] >> BRICK_SHIFT, last[0] >> BRICK_SHIFT);
        let ys = bits(first[1] >> BRICK_SHIFT, last[1] >> BRICK_SHIFT);
        for z in first[2] >> BRICK_SHIFT..=last[2] >> BRICK_SHIFT {
            let mut rows = self.layers[z as usize] & ys;
            while rows != 0 {
                let y = i64::from(rows.trailing_zeros());
                rows &= rows - 1;
                if self.rows[(z * self.ny + y) as usize] & xs != 0 {
                    return false;
                }
            }
        }
        true
    }
}

impl VoxelGrid {
    /// The non-empty bricks near the closed box `[lo, hi]` (m), for
    /// [`VoxelGrid::may_touch_box_near`]: those of the cells a box inside `[lo, hi]`
    /// may touch, cut to the occupied cells and, on each axis, to the
    /// [`SPAN`] bricks around the middle of the rest.
    pub fn near_bricks(&self, lo: &Point3<f64>, hi: &Point3<f64>) -> NearBricks {
        let (Some((cells_lo, cells_end)), Ok((first, last))) = (self.tree.bounds(), self.cells_near(lo, hi)) else {
            return NearBricks::default();
        };
        let mut near = NearBricks::default();
        for a in 0..3 {
            let (l, h) = (first[a] >> BRICK_SHIFT, last[a] >> BRICK_SHIFT);
            let cut = (h - l + 1 - SPAN).max(0);
            near.lo[a] = l + cut / 2;
            near.hi[a] = h - (cut - cut / 2);
            // Every occupied cell lies in cells_lo..cells_end.
            near.open_lo[a] = near.lo[a] <= cells_lo[a] >> BRICK_SHIFT;
            near.open_hi[a] = near.hi[a] >= (cells_end[a] - 1) >> BRICK_SHIFT;
            near.corner[a] = self.origin[a] + (near.lo[a] * SIDE) as f64 * self.resolution;
        }
        near.per_cell = 1.0 / self.resolution;
        let depth = (near.hi[2] - near.lo[2] + 1) as usize;
        near.ny = near.hi[1] - near.lo[1] + 1;
        near.rows = vec![0; depth * near.ny as usize];
        near.layers = vec![0; depth];
        let (rlo, ny, rows, layers) = (near.lo, near.ny, &mut near.rows, &mut near.layers);
        self.tree.for_each_brick_in(near.lo, near.hi, |b| {
            let (x, y, z) = (b[0] - rlo[0], b[1] - rlo[1], b[2] - rlo[2]);
            rows[(z * ny + y) as usize] |= 1 << x;
            layers[z as usize] |= 1 << y;
        });
        near.covers = Arc::new(NearCovers::of(self, near.lo.map(|b| b * SIDE), near.hi.map(|b| b * SIDE + SIDE - 1)));
        near
    }

    /// The covers' boxes near the closed box `[lo, hi]`, holding a batch's
    /// segments, pushed onto `out` ([`NearCovers::gather`]); `None` when the box
    /// leaves `near`'s region (the tree must say). No box at all when no occupied
    /// cell is near the box.
    #[inline]
    pub(super) fn gather_covers<const N: usize>(
        &self,
        near: &NearBricks,
        lo: &Point3<f64>,
        hi: &Point3<f64>,
        most_nodes: i64,
        out: &mut ArrayVec<Region, N>,
    ) -> Option<Gathered> {
        match near.cells(lo, hi) {
            Cells::None => Some(Gathered::All),
            Cells::Outside => None,
            Cells::Within(first, last) => {
                let base = near.lo.map(|v| v * SIDE);
                let absolute = |c: CellIndex| std::array::from_fn(|a| c[a] + base[a]);
                Some(near.covers.gather(absolute(first), absolute(last), lo, hi, most_nodes, out))
            }
        }
    }

    /// [`VoxelGrid::may_touch_box`], settled by `near`'s bits when the box's bricks
    /// are all empty: `false` only when no occupied cell's closed cube meets the box.
    #[inline]
    pub fn may_touch_box_near(&self, near: &NearBricks, lo: &Point3<f64>, hi: &Point3<f64>) -> bool {
        self.may_touch_box_near_within(near, lo, hi, 16)
    }

    /// [`VoxelGrid::may_touch_box_near`] by `near`'s bits alone: `true` for a box
    /// meeting a non-empty brick or leaving the region. For the sight lines' box,
    /// long and rarely clear of every brick, where the tree's test seldom settles
    /// anything the exact walks would not.
    #[inline]
    pub fn bricks_may_touch_box(&self, near: &NearBricks, lo: &Point3<f64>, hi: &Point3<f64>) -> bool {
        self.may_touch_box_near_within(near, lo, hi, 0)
    }

    /// [`VoxelGrid::may_touch_box_near`] with at most `budget` node and brick
    /// lookups in the tree.
    #[inline]
    pub(super) fn may_touch_box_near_within(
        &self,
        near: &NearBricks,
        lo: &Point3<f64>,
        hi: &Point3<f64>,
        budget: u32,
    ) -> bool {
        match near.cells(lo, hi) {
            Cells::None => false,
            Cells::Outside => self.may_touch_box_within(lo, hi, budget),
            Cells::Within(first, last) => {
                if near.all_empty(&first, &last) {
                    return false;
                }
                let base = near.lo.map(|v| v * SIDE);
                let absolute = |c: CellIndex| std::array::from_fn(|a| c[a] + base[a]);
                self.tree.any_in_box(absolute(first), absolute(last), budget) != Some(false)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::Vector3;
    use crate::world::Segment;
    use crate::world::tests::Lcg;

    /// Whether an occupied cell's closed cube meets the closed box `[lo, hi]`,
    /// cell by cell through the tree (a cell more below, never fewer).
    fn touched(grid: &VoxelGrid, lo: &Point3<f64>, hi: &Point3<f64>) -> bool {
        let cell = |v: f64, a: usize| ((v - grid.origin()[a]) / grid.resolution()).floor() as i64;
        let first = std::array::from_fn(|a| cell(lo[a], a) - 1);
        let last = std::array::from_fn(|a| cell(hi[a], a));
        grid.tree.any_in_box(first, last, u32::MAX).expect("within budget")
    }

    /// `count` square columns of cells from the floor up, each within `spread`
    /// cells of the origin, up to `side` cells wide and `top` high.
    fn columns(rng: &mut Lcg, count: usize, spread: i64, side: i64, top: i64) -> Vec<CellIndex> {
        let mut cells = Vec::new();
        for _ in 0..count {
            let at = |rng: &mut Lcg| (rng.next() * (2 * spread) as f64) as i64 - spread;
            let (x, y) = (at(rng), at(rng));
            let (side, top) = ((rng.next() * side as f64) as i64 + 1, (rng.next() * top as f64) as i64 + 1);
            for i in 0..side {
                for j in 0..side {
                    cells.extend((0..top).map(|k| [x + i, y + j, k]));
                }
            }
        }
        cells
    }

    /// Counts the boxes the bits call empty where a cell touches them, over grids
    /// of columns, a floor (or not) and scattered cells, and boxes from a cell's
    /// size to wider than the region, inside it and across its edges; and the
    /// boxes the bits settled, and those the tree calls empty.
    fn disagreements(lose_bits: bool) -> (usize, usize, usize) {
        let mut rng = Lcg(3);
        let (mut wrong, mut settled, mut empty) = (0, 0, 0);
        for case in 0..6 {
            let resolution = [0.1, 0.05, 0.25][case % 3];
            let origin = Point3::new(rng.next() * 10.0 - 5.0, rng.next() * 10.0 - 5.0, rng.next() - 0.5);
            let mut cells = columns(&mut rng, 12, 150, 12, 60);
            if case % 2 == 0 {
                for i in -150..150 {
                    for j in -150..150 {
                        if (i + j) % 5 == 0 {
                            cells.push([i, j, -1]);
                        }
                    }
                }
            }
            for _ in 0..200 {
                let r = |rng: &mut Lcg, n: f64| (rng.next() * n) as i64;
                cells.push([r(&mut rng, 300.0) - 150, r(&mut rng, 300.0) - 150, r(&mut rng, 80.0)]);
            }
            let grid = VoxelGrid::new(resolution, origin, cells).unwrap();
            let step = Vector3::new(rng.next() - 0.5, rng.next() - 0.5, 0.0) * 300.0 * resolution;
            let marker = origin + step + Vector3::new(0.0, 0.0, 3.0 * resolution);
            let around = Vector3::repeat((10.0 + rng.next() * 300.0) * resolution);
            let mut near = grid.near_bricks(&(marker - around), &(marker + around));
            if lose_bits {
                // Every brick of the region's middle layer said empty.
                let z = ((near.hi[2] - near.lo[2]) / 2) as usize;
                near.layers[z] = 0;
            }
            for _ in 0..4000 {
                let u = Vector3::new(rng.next() - 0.5, rng.next() - 0.5, rng.next() - 0.5);
                let c = marker + u.component_mul(&around) * 2.4;
                let scale = resolution * [0.5, 10.0, 80.0][(rng.next() * 3.0) as usize];
                let size = Vector3::new(rng.next(), rng.next(), rng.next()) * scale;
                let (lo, hi) = (c - size, c + size);
                let proven = !grid.may_touch_box_near(&near, &lo, &hi);
                // The bits alone prove less, never more wrongly.
                let by_bits = !grid.bricks_may_touch_box(&near, &lo, &hi);
                settled += usize::from(proven);
                empty += usize::from(!grid.may_touch_box(&lo, &hi));
                if (proven || by_bits) && touched(&grid, &lo, &hi) {
                    wrong += 1;
                }
            }
        }
        (wrong, settled, empty)
    }

    /// The bits never call a touched box empty, with the tree's test or alone, and
    /// settle most of the boxes the tree finds empty.
    #[test]
    fn near_bricks_never_call_a_touched_box_empty() {
        let (wrong, settled, empty) = disagreements(false);
        assert_eq!(wrong, 0);
        assert!(settled > 3000 && settled * 2 > empty, "{settled} settled of {empty} empty: the test tests little");
    }

    /// Counts the segments whose first contact with the bricks near them differs
    /// from the one without, bit for bit: short and long segments among columns
    /// and a floor, along cells' faces, inside the region and leaving it; and the
    /// hits and the short segments.
    fn contact_disagreements(lose_bits: bool) -> (usize, usize, usize) {
        let mut rng = Lcg(11);
        let mut cells = columns(&mut rng, 20, 100, 10, 40);
        cells.extend((-100..100).flat_map(|i| (-100..100).map(move |j| [i, j, -1])).filter(|c| (c[0] * c[1]) % 7 != 0));
        let grid = VoxelGrid::new(0.125, Point3::new(-1.0, 2.0, 0.0), cells).unwrap();
        let marker = Point3::new(-1.0, 2.0, 0.3);
        let around = Vector3::new(8.0, 8.0, 3.0);
        let mut near = grid.near_bricks(&(marker - around), &(marker + around));
        if lose_bits {
            // The floor's layer said empty.
            near.layers[0] = 0;
        }
        let (mut wrong, mut hits, mut short) = (0, 0, 0);
        for i in 0..20_000 {
            let a = marker
                + Vector3::new(rng.next() - 0.5, rng.next() - 0.5, rng.next() - 0.3).component_mul(&around) * 2.2;
            let length = if i % 2 == 0 { rng.next() * 2.0 } else { rng.next() * 12.0 };
            let d = Vector3::new(rng.next() - 0.5, rng.next() - 0.5, rng.next() - 0.5);
            // Every third along a grid plane, on a cell's face.
            let (a, d) = if i % 3 == 0 {
                let snap = |v: f64| (v * 8.0).round() / 8.0;
                (Point3::new(snap(a.x), snap(a.y), snap(a.z)), Vector3::new(d.x, d.y, 0.0))
            } else {
                (a, d)
            };
            let Some(seg) = Segment::sight_line(&a, &(a + d.normalize() * length), 1e-6) else { continue };
            let want = grid.first_contact(&seg);
            wrong += usize::from(grid.first_contact_near(&seg, &near).map(f64::to_bits) != want.map(f64::to_bits));
            hits += usize::from(want.is_some());
            short += usize::from(seg.length < 2.0);
        }
        (wrong, hits, short)
    }

    /// A segment's first contact is the same with the bricks near it and without.
    #[test]
    fn first_contact_near_is_first_contact() {
        let (wrong, hits, short) = contact_disagreements(false);
        assert_eq!(wrong, 0);
        assert!(hits > 2000 && short > 5000, "{hits} hits, {short} short: the test tests little");
    }

    /// The test above can fail: with the floor's bits lost, short segments
    /// touching the floor are said to touch nothing.
    #[test]
    fn first_contact_near_with_bits_lost_differs() {
        let (wrong, _, _) = contact_disagreements(true);
        assert!(wrong > 0, "no short segment settled by the floor's bits touches it");
    }

    /// The test above can fail: with a layer's bits lost, boxes there are called
    /// empty where cells touch them.
    #[test]
    fn near_bricks_with_bits_lost_call_touched_boxes_empty() {
        let (wrong, _, _) = disagreements(true);
        assert!(wrong > 0, "no touched box meets the middle layer's bricks");
    }
}
