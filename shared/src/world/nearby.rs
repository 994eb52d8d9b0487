//! The obstacles near a region: a short list a query makes once for the region all
//! its collision stars stay in.
//!
//! Every viewer position of a query lies within a known distance of the marker
//! (ρ_max plus the camera's mounting offset), so every collision segment lies in a
//! box around the marker known before the first candidate. [`World::nearby`] lists
//! the leaves (obstacles, the voxel grid) whose padded boxes meet that box, once;
//! a candidate then compares its star's box with those few boxes instead of walking
//! the BVH, and runs the exact tests on the leaves that meet it.
//!
//! The verdict is [`World::any_contact`]'s, bit for bit: a leaf left out of the list
//! has a padded box that misses the region, so it misses every segment in it (the
//! padding, 1e-7 m, is far above the rounding of a segment's end point), and the
//! exact tests are the same. A batch whose box is not inside the region, or a list
//! too long to pay, falls back to the BVH.

use super::{Leaf, NearBricks, Segment, World};
use crate::math::Point3;

/// Above this many leaves near the region, a candidate walks the BVH instead.
const MOST: usize = 48;

/// The leaves whose padded boxes meet a region ([`World::nearby`]).
#[derive(Debug, Clone, Default)]
pub struct Nearby {
    /// The region, `[lo, hi]`.
    lo: [f64; 3],
    hi: [f64; 3],
    /// Per leaf listed: its padded box, `[min x, min y, min z, max x, max y, max z]`.
    boxes: Vec<[f64; 6]>,
    leaves: Vec<u32>,
    /// Too many leaves near the region: use the BVH.
    crowded: bool,
    /// The voxel grid's bricks near the region (none without a grid).
    bricks: NearBricks,
}

impl Nearby {
    /// How many leaves are listed.
    pub fn len(&self) -> usize {
        self.leaves.len()
    }

    /// Whether no leaf is near the region.
    pub fn is_empty(&self) -> bool {
        self.leaves.is_empty()
    }
}

impl World {
    /// The leaves near the closed box `[lo, hi]`, for [`World::any_contact_near`].
    pub fn nearby(&self, lo: &Point3<f64>, hi: &Point3<f64>) -> Nearby {
        let mut near = Nearby { lo: [lo.x, lo.y, lo.z], hi: [hi.x, hi.y, hi.z], ..Nearby::default() };
        for (i, b) in self.boxes.iter().enumerate() {
            let (mins, maxs) = (b.mins, b.maxs);
            // Not `any(miss)`: a NaN keeps the leaf.
            if (0..3).any(|a| maxs[a] < lo[a] || mins[a] > hi[a]) {
                continue;
            }
            near.boxes.push([mins.x, mins.y, mins.z, maxs.x, maxs.y, maxs.z]);
            near.leaves.push(i as u32);
        }
        near.crowded = near.leaves.len() > MOST;
        if let Some(v) = &self.voxels
            && near.leaves.iter().any(|l| matches!(self.leaves[*l as usize], Leaf::Voxels))
        {
            near.bricks = v.near_bricks(lo, hi);
        }
        near
    }

    /// [`World::nearby`] of the closed box `[lo, hi]`, written into `into` (its
    /// buffers reused: no allocation once they are large enough), taken from
    /// `from`'s list when `from`'s region holds the box and is not crowded (every
    /// leaf near the box is then near `from`'s region, so listed there), else from
    /// every leaf; the voxel grid only when an occupied cell may be near the box. A
    /// search whose candidates share a small region (a grid's arc of yaws) narrows
    /// the query's list once for all of them.
    pub fn nearby_within(&self, from: &Nearby, lo: &Point3<f64>, hi: &Point3<f64>, into: &mut Nearby) {
        into.lo = [lo.x, lo.y, lo.z];
        into.hi = [hi.x, hi.y, hi.z];
        into.boxes.clear();
        into.leaves.clear();
        // The grid's box is large: it stays listed only when an occupied cell may be
        // near the box (then each star is checked again, as for any list).
        let grid = self.voxels.is_some();
        let meets = |b: &[f64; 6], leaf: u32| {
            !misses(b, lo, hi)
                && (!grid || !matches!(self.leaves[leaf as usize], Leaf::Voxels) || self.voxels_may_touch(lo, hi))
        };
        let inside = (0..3).all(|a| from.lo[a] <= lo[a] && hi[a] <= from.hi[a]);
        if inside && !from.crowded {
            // Bricks of the same grid, over a region holding this one.
            into.bricks.clone_from(&from.bricks);
            for (b, leaf) in from.boxes.iter().zip(&from.leaves) {
                if meets(b, *leaf) {
                    into.boxes.push(*b);
                    into.leaves.push(*leaf);
                }
            }
        } else {
            into.bricks.clear();
            for (i, b) in self.boxes.iter().enumerate() {
                let b = [b.mins.x, b.mins.y, b.mins.z, b.maxs.x, b.maxs.y, b.maxs.z];
                if meets(&b, i as u32) {
                    into.boxes.push(b);
                    into.leaves.push(i as u32);
                }
            }
        }
        into.crowded = into.leaves.len() > MOST;
    }

    /// [`World::any_contact`]'s verdict on the batch `segments` makes, all inside
    /// the closed box `[lo, hi]`, testing exactly only the listed leaves whose boxes
    /// meet it; the batch is made only if one does (most stars meet nothing). Falls
    /// back to the BVH when the box is not inside the list's region.
    pub fn any_contact_near<S: AsRef<[Segment]>>(
        &self,
        near: &Nearby,
        lo: &Point3<f64>,
        hi: &Point3<f64>,
        segments: impl FnOnce() -> S,
    ) -> bool {
        self.contact_near(near, lo, hi, segments, |_| None)
    }

    /// [`World::any_contact_near`], where `decide` may give a listed leaf's verdict
    /// on the batch without the exact test (`None`: test it). `decide` must agree
    /// with the exact test wherever it answers.
    #[inline]
    pub(super) fn contact_near<S: AsRef<[Segment]>>(
        &self,
        near: &Nearby,
        lo: &Point3<f64>,
        hi: &Point3<f64>,
        segments: impl FnOnce() -> S,
        decide: impl Fn(&Leaf) -> Option<bool>,
    ) -> bool {
        let inside = (0..3).all(|a| near.lo[a] <= lo[a] && hi[a] <= near.hi[a]);
        if !inside || near.crowded {
            return self.any_contact_within(segments().as_ref(), lo, hi);
        }
        let mut made: Option<S> = None;
        let mut segments = Some(segments);
        for (b, leaf_id) in near.boxes.iter().zip(&near.leaves) {
            if misses(b, lo, hi) {
                continue;
            }
            let leaf = &self.leaves[*leaf_id as usize];
            // The grid's box is large: skip it when no occupied cell is near the star,
            // before making the batch (a map without a grid has no such leaf).
            if self.voxels.is_some()
                && let Leaf::Voxels = leaf
                && !self.voxels_may_touch_near(&near.bricks, lo, hi)
            {
                continue;
            }
            match decide(leaf) {
                Some(true) => return true,
                Some(false) => continue,
                None => {}
            }
            let batch = made.get_or_insert_with(|| (segments.take().expect("made once"))());
            if self.leaf_touches_near(*leaf_id, batch.as_ref(), &near.bricks, lo, hi) {
                return true;
            }
        }
        false
    }
}

/// Whether the box `b` (`[min x, min y, min z, max x, max y, max z]`) misses the
/// closed box `[lo, hi]`. Not `any(miss)` negated: a NaN keeps the leaf.
#[inline]
fn misses(b: &[f64; 6], lo: &Point3<f64>, hi: &Point3<f64>) -> bool {
    b[3] < lo.x || b[0] > hi.x || b[4] < lo.y || b[1] > hi.y || b[5] < lo.z || b[2] > hi.z
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::Vector3;
    use crate::world::tests::{Lcg, random_world};
    use crate::world::{Obstacle, Star};
    use std::f64::consts::TAU;

    /// A collision star's segments and its cube, as the pipeline makes them.
    fn star(center: Point3<f64>, yaw: f64, reach: f64) -> ([Segment; 10], Point3<f64>, Point3<f64>) {
        let star = Star { center, yaw, reach };
        let (lo, hi) = star.bounds();
        (star.segments(), lo, hi)
    }

    /// Counts disagreements with the scan over collision stars placed anywhere in
    /// the region, and stars grazing obstacles.
    fn disagreements(shrink: f64) -> (usize, usize, usize) {
        let mut rng = Lcg(17);
        let (mut wrong, mut hits, mut misses) = (0, 0, 0);
        for (n, voxels) in [(0, false), (3, false), (25, false), (80, false), (10, true)] {
            let world = random_world(&mut rng, n, voxels);
            let marker = Point3::new(rng.next() * 4.0 - 2.0, rng.next() * 4.0 - 2.0, 0.3);
            let (half, reach) = (6.2, 0.6);
            let r = Vector3::repeat(half + reach);
            let mut near = world.nearby(&(marker - r), &(marker + r));
            // Shrinks every listed box, to show the cases graze their edges.
            for b in &mut near.boxes {
                for a in 0..3 {
                    b[a] += shrink;
                    b[a + 3] -= shrink;
                }
            }
            let obstacles: Vec<Obstacle> = world.obstacles().values().copied().collect();
            for k in 0..6000 {
                let graze = if k % 3 == 0 { obstacles.get(k % obstacles.len().max(1)) } else { None };
                // Grazing: the +x ray ends 1e-9 inside a cylinder's side, or on a box's
                // top face 1e-9 past its side.
                let (p, yaw) = match graze {
                    Some(Obstacle::Cylinder(c)) => {
                        let z = rng.next() * c.height;
                        (Point3::new(c.center.x - c.radius - reach + 1e-9, c.center.y, z), 0.0)
                    }
                    Some(Obstacle::Box(b)) => {
                        let y = b.min.y + rng.next() * (b.max.y - b.min.y);
                        (Point3::new(b.min.x - reach + 1e-9, y, b.max.z), 0.0)
                    }
                    None => {
                        let v = Vector3::new(rng.next() - 0.5, rng.next() - 0.5, rng.next() - 0.5) * 2.0 * half;
                        (marker + v / 3f64.sqrt(), rng.next() * TAU)
                    }
                };
                let (rays, lo, hi) = star(p, yaw, reach);
                let want = world.any_contact_by_scan(&rays);
                let got = world.any_contact_near(&near, &lo, &hi, || rays);
                if shrink == 0.0 {
                    // Narrowed to the star's own box, or to a box around it.
                    for grow in [0.0, 0.7] {
                        let g = Vector3::repeat(grow);
                        let mut narrow = Nearby::default();
                        world.nearby_within(&near, &(lo - g), &(hi + g), &mut narrow);
                        assert_eq!(world.any_contact_near(&narrow, &lo, &hi, || rays), want, "{rays:?}");
                    }
                }
                if got != want {
                    wrong += 1;
                    assert!(shrink > 0.0, "{rays:?}: {got} != {want}");
                }
                if want { hits += 1 } else { misses += 1 }
            }
        }
        (wrong, hits, misses)
    }

    #[test]
    fn the_short_list_agrees_with_the_scan() {
        let (wrong, hits, misses) = disagreements(0.0);
        assert_eq!(wrong, 0);
        assert!(hits > 3000 && misses > 3000, "{hits} hits, {misses} misses: the test tests little");
    }

    /// The test above can fail: boxes shrunk by 1e-6 m leave out obstacles that
    /// a ray touches.
    #[test]
    fn a_short_list_of_boxes_too_small_disagrees_with_the_scan() {
        let (wrong, _, _) = disagreements(1e-6);
        assert!(wrong > 0, "the cases never graze a box");
    }

    /// Over stars placed anywhere and grazing obstacles, with the list narrowed to
    /// each star's cube grown by `grow` (negative: a box that does not hold the
    /// star): the stars whose list is empty that touch something, and the stars
    /// whose list is empty.
    fn empty_lists_that_touch(grow: f64) -> (usize, usize) {
        let mut rng = Lcg(23);
        let (mut wrong, mut empty) = (0, 0);
        for (n, voxels) in [(12, false), (25, false), (80, false), (10, true)] {
            let world = random_world(&mut rng, n, voxels);
            let near = world.nearby(&Point3::new(-12.0, -12.0, -2.0), &Point3::new(12.0, 12.0, 6.0));
            let obstacles: Vec<Obstacle> = world.obstacles().values().copied().collect();
            let mut narrow = Nearby::default();
            let reach = 0.6;
            for k in 0..6000 {
                // Grazing: the +x ray ends 1e-9 inside a cylinder's side or a box's.
                let (p, yaw) = match obstacles.get(k % obstacles.len().max(1)).filter(|_| k % 2 == 0) {
                    Some(Obstacle::Cylinder(c)) => {
                        (Point3::new(c.center.x - c.radius - reach + 1e-9, c.center.y, rng.next() * c.height), 0.0)
                    }
                    Some(Obstacle::Box(b)) => {
                        let y = b.min.y + rng.next() * (b.max.y - b.min.y);
                        (Point3::new(b.min.x - reach + 1e-9, y, b.min.z + rng.next() * (b.max.z - b.min.z)), 0.0)
                    }
                    None => {
                        let p = Point3::new(rng.next() * 20.0 - 10.0, rng.next() * 20.0 - 10.0, rng.next() * 3.0);
                        (p, rng.next() * TAU)
                    }
                };
                let (rays, lo, hi) = star(p, yaw, reach);
                let g = Vector3::repeat(grow);
                world.nearby_within(&near, &(lo - g), &(hi + g), &mut narrow);
                if narrow.is_empty() {
                    empty += 1;
                    wrong += usize::from(world.any_contact_by_scan(&rays));
                }
            }
        }
        (wrong, empty)
    }

    /// An empty list narrowed to a box holding a star proves that the star
    /// touches nothing (a search skips the star then).
    #[test]
    fn an_empty_list_around_a_star_means_no_contact() {
        for grow in [0.0, 0.4] {
            let (wrong, empty) = empty_lists_that_touch(grow);
            assert_eq!(wrong, 0, "grown by {grow}");
            assert!(empty > 2000, "{empty} empty lists: the test tests little");
        }
    }

    /// The test above can fail: a box 1e-3 m short of the star's cube leaves out
    /// obstacles the star touches.
    #[test]
    fn an_empty_list_short_of_the_star_misses_contacts() {
        let (wrong, _) = empty_lists_that_touch(-1e-3);
        assert!(wrong > 0, "the cases never graze an obstacle");
    }

    /// A batch outside the region, or a crowded region, is answered by the BVH.
    #[test]
    fn batches_outside_the_region_fall_back() {
        let mut rng = Lcg(2);
        let world = random_world(&mut rng, 300, false);
        let near = world.nearby(&Point3::new(-1.0, -1.0, 0.0), &Point3::new(1.0, 1.0, 1.0));
        assert!(!near.crowded && !near.is_empty());
        let crowded = world.nearby(&Point3::new(-10.0, -10.0, 0.0), &Point3::new(10.0, 10.0, 10.0));
        assert!(crowded.crowded);
        for k in 0..3000 {
            let p = Point3::new(rng.next() * 16.0 - 8.0, rng.next() * 16.0 - 8.0, rng.next() * 4.0);
            let (rays, lo, hi) = star(p, f64::from(k) * 0.1, 0.6);
            let want = world.any_contact_by_scan(&rays);
            assert_eq!(world.any_contact_near(&near, &lo, &hi, || rays), want);
            assert_eq!(world.any_contact_near(&crowded, &lo, &hi, || rays), want);
        }
    }
}
