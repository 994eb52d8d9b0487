//! The covers of the grid's nodes near one query, in metres: what a batch of
//! segments is tested against before any walk, made once per query.
//!
//! A batch (a collision star, the sight lines from one sensor) is first tested
//! against the covers' boxes of the nodes near it ([`super::batch`]); found in the
//! tree and turned into metres per batch, they cost a look-up per node and a
//! conversion per box each time. Every batch of a query lies in a region known
//! before its first candidate (the one [`super::NearBricks`] holds), so the boxes
//! of that region's nodes are listed here once, by node, already in metres
//! ([`Region::of`]). A batch then takes the boxes of its nodes that meet its own
//! box; those are the boxes the tree would give it, bar some that cannot be near
//! any of its segments, so the verdict, decided by the exact tests wherever a box
//! does not clear a segment, is the same.

use super::bounds::Region;
use super::tree::NODE_SHIFT;
use super::{CellIndex, VoxelGrid};
use crate::math::Point3;
use arrayvec::ArrayVec;

/// The covers' boxes of the nodes of a region ([`NearCovers::of`]).
#[derive(Debug, Clone, Default)]
pub(super) struct NearCovers {
    /// The region's nodes (cell index >> 6), the first, and how many along each axis.
    first: [i64; 3],
    count: [i64; 3],
    /// `regions[starts[n]..starts[n + 1]]` are node n's boxes, n counting x
    /// fastest, then y, then z.
    starts: Vec<u32>,
    regions: Vec<Region>,
}

/// What [`NearCovers::gather`] found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Gathered {
    /// Every box near the batch is in the caller's list.
    All,
    /// More nodes or boxes than the caller takes: test each segment exactly.
    TooMany,
}

impl NearCovers {
    /// The covers of `grid`'s nodes holding the cells `first..=last`; none (every
    /// batch then gets the exact tests) where the coordinates are so large against
    /// the cells that rounding nears the clearance margin, as
    /// [`Clearance`](super::bounds::Clearance) refuses them.
    pub(super) fn of(grid: &VoxelGrid, first: CellIndex, last: CellIndex) -> NearCovers {
        let corner = |c: i64, a: usize| (grid.origin[a] + c as f64 * grid.resolution).abs();
        let scale =
            (0..3).map(|a| grid.origin[a].abs().max(corner(first[a], a)).max(corner(last[a] + 1, a))).sum::<f64>();
        if !(scale.is_finite() && scale * (-24f64).exp2() <= grid.resolution) {
            return NearCovers::default();
        }
        let lo = first.map(|c| c >> NODE_SHIFT);
        let count: [i64; 3] = std::array::from_fn(|a| (last[a] >> NODE_SHIFT) - lo[a] + 1);
        let nodes = count.iter().map(|n| *n as usize).product::<usize>();
        let mut covers = NearCovers { first: lo, count, starts: Vec::with_capacity(nodes + 1), regions: Vec::new() };
        covers.starts.push(0);
        for z in lo[2]..lo[2] + count[2] {
            for y in lo[1]..lo[1] + count[1] {
                for x in lo[0]..lo[0] + count[0] {
                    if let Some(boxes) = grid.tree.node_cover([x, y, z]) {
                        covers.regions.extend(boxes.map(|b| Region::of(grid.resolution, &grid.origin, &b)));
                    }
                    covers.starts.push(covers.regions.len() as u32);
                }
            }
        }
        covers
    }

    /// Pushes onto `out` the boxes of the nodes holding the cells `first..=last`
    /// (inside the region) that meet the closed box `[lo, hi]`, for a batch whose
    /// segments lie in `[lo, hi]` and whose cells near them lie in `first..=last`.
    /// A box left out misses `[lo, hi]`: its cells lie more than the clearance
    /// margin beyond it, far more than a segment's end rounds past it, so no
    /// segment of the batch comes near them.
    pub(super) fn gather<const N: usize>(
        &self,
        first: CellIndex,
        last: CellIndex,
        lo: &Point3<f64>,
        hi: &Point3<f64>,
        most_nodes: i64,
        out: &mut ArrayVec<Region, N>,
    ) -> Gathered {
        let (a, b) = (first.map(|c| c >> NODE_SHIFT), last.map(|c| c >> NODE_SHIFT));
        if self.starts.is_empty() || (0..3).map(|i| b[i] - a[i] + 1).product::<i64>() > most_nodes {
            return Gathered::TooMany;
        }
        debug_assert!((0..3).all(|i| self.first[i] <= a[i] && b[i] < self.first[i] + self.count[i]));
        for z in a[2]..=b[2] {
            for y in a[1]..=b[1] {
                let row = ((z - self.first[2]) * self.count[1] + (y - self.first[1])) * self.count[0] - self.first[0];
                let (from, to) = (self.starts[(row + a[0]) as usize], self.starts[(row + b[0] + 1) as usize]);
                for r in &self.regions[from as usize..to as usize] {
                    // Not `any(miss)` negated: a NaN keeps the box.
                    let misses = (0..3).any(|i| r.hi[i] < lo[i] || r.lo[i] > hi[i]);
                    if !misses && out.try_push(*r).is_err() {
                        return Gathered::TooMany;
                    }
                }
            }
        }
        Gathered::All
    }
}
