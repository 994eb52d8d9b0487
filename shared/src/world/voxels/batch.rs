//! A batch of segments close together (the sight lines from one sensor, a
//! collision star) tested against the grid at once.
//!
//! On its own, each segment finds the nodes around it and tests it against their
//! covers' boxes ([`super::walk`]'s `clears_nodes`), turning every box into metres
//! again; the segments of a batch share those nodes. Here the boxes of the covers
//! near the batch's box are gathered once, in metres, and a segment that clears
//! every one of them (by the clearance margin) touches no occupied cell, for the
//! same reason as there: the boxes hold every occupied cell near it. Only that
//! verdict is taken from them; any other segment gets the exact test, so the
//! answer is the exact tests' own. A sight line clear of the floor below it and
//! of the walls beside it costs a few box tests instead of a look-up of its nodes.

use super::bounds::{Clearance, Region};
use super::tree::NODE_SHIFT;
use super::{NearBricks, VoxelGrid};
use crate::math::floor;
use crate::world::segment::Segment;

/// Most nodes a batch's box may meet for their covers to be gathered.
const BATCH_NODES: i64 = 16;

/// Most boxes gathered for a batch.
const BATCH_BOXES: usize = 40;

impl VoxelGrid {
    /// Whether any of `segments` touches an occupied cell up to its own end, for
    /// segments of a query whose bricks near them are `near`: the verdict of
    /// [`VoxelGrid::first_contact_near`] on each of them, the same answer.
    pub fn any_contact_near(&self, segments: &[Segment], near: &NearBricks) -> bool {
        let mut regions = [Region::default(); BATCH_BOXES];
        let gathered = self.covers_near(segments, &mut regions).map(|n| &regions[..n]);
        segments.iter().any(|s| {
            if let Some(regions) = gathered
                && self.clears_all(s, 0.0, s.length.max(0.0), regions)
            {
                return false;
            }
            self.first_contact_near(s, near).is_some_and(|t| s.reaches(t))
        })
    }

    /// Whether the part `[t0, t1]` of `seg` stays more than the clearance margin
    /// away from every box of `regions`.
    #[inline]
    fn clears_all(&self, seg: &Segment, t0: f64, t1: f64, regions: &[Region]) -> bool {
        let inv_dir = [1.0 / seg.dir[0], 1.0 / seg.dir[1], 1.0 / seg.dir[2]];
        let clearance = Clearance::new(self.resolution, self.origin, seg, inv_dir, true);
        clearance.enabled() && regions.iter().all(|r| clearance.clears_region(seg, t0, t1, r))
    }

    /// The boxes of the covers of the nodes near `segments` that meet the cells
    /// within a cell of the segments' box; `None` when the box is not finite, or
    /// the nodes or boxes are too many (then each segment gets the exact test).
    /// Written to `regions`; how many.
    fn covers_near(&self, segments: &[Segment], regions: &mut [Region; BATCH_BOXES]) -> Option<usize> {
        let (cells_lo, cells_end) = self.tree.bounds()?;
        let first = segments.first()?;
        let (mut lo, mut hi) = (first.origin, first.origin);
        for s in segments {
            let end = s.point_at(s.length.max(0.0));
            for p in [s.origin, end] {
                lo = lo.inf(&p);
                hi = hi.sup(&p);
            }
        }
        let inv_resolution = 1.0 / self.resolution;
        let mut len = 0;
        let (mut first, mut last) = ([0i64; 3], [0i64; 3]);
        for a in 0..3 {
            // The cells near the box, one more on each side for rounding.
            let to_cell = |v: f64| floor((v - self.origin[a]) * inv_resolution);
            let (l, h) = (to_cell(lo[a]) - 1.0, to_cell(hi[a]) + 1.0);
            if !(l.is_finite() && h.is_finite()) {
                return None;
            }
            (first[a], last[a]) = (l.max((cells_lo[a] - 1) as f64) as i64, h.min(cells_end[a] as f64) as i64);
            if first[a] > last[a] {
                return Some(0);
            }
        }
        let nodes = (0..3).map(|a| (last[a] >> NODE_SHIFT) - (first[a] >> NODE_SHIFT) + 1).product::<i64>();
        if nodes > BATCH_NODES {
            return None;
        }
        for x in first[0] >> NODE_SHIFT..=last[0] >> NODE_SHIFT {
            for y in first[1] >> NODE_SHIFT..=last[1] >> NODE_SHIFT {
                for z in first[2] >> NODE_SHIFT..=last[2] >> NODE_SHIFT {
                    let Some(boxes) = self.tree.node_cover([x, y, z]) else { continue };
                    for b in boxes {
                        // A box beyond the cells near the batch is farther than a cell
                        // from every segment.
                        if (0..3).any(|a| b.hi[a] < first[a] || b.lo[a] > last[a]) {
                            continue;
                        }
                        if len == BATCH_BOXES {
                            return None;
                        }
                        regions[len] = Region::of(self.resolution, &self.origin, &b);
                        len += 1;
                    }
                }
            }
        }
        Some(len)
    }
}
