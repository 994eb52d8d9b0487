//! Region queries: whether anything solid comes near a box.
//!
//! A search that checks many candidates whose segments share a region (a grid's
//! poses around one circle) asks once whether the region is clear; if it is, no
//! segment inside it can touch anything, and the per-candidate ray queries can be
//! skipped without changing a verdict.

use super::{Leaf, World};
use crate::math::{Point3, Vector3};

/// How far beyond the box [`World::box_is_clear`] looks, m: far more than the
/// rounding of any segment end or contact point computed inside the box.
const CLEARANCE: f64 = 1e-6;

impl World {
    /// Whether no obstacle and no occupied voxel comes within 1e-6 m of the
    /// closed box `[lo, hi]`; `false` when unsure (a large box over a voxel grid).
    /// When it is clear, [`World::any_contact`] is `false` for any batch of segments
    /// whose end points lie in the box. Allocates nothing.
    pub fn box_is_clear(&self, lo: &Point3<f64>, hi: &Point3<f64>) -> bool {
        let pad = Vector3::repeat(CLEARANCE);
        let (lo, hi) = (lo - pad, hi + pad);
        if !lo.iter().chain(hi.iter()).all(|v| v.is_finite()) {
            return false;
        }
        // An obstacle's padded box meets the box: not clear (its shape may miss the
        // box, but a search only loses the shortcut).
        self.leaves_meeting_box(&lo, &hi, |leaf| match self.leaves[leaf as usize] {
            Leaf::Solid { .. } => false,
            Leaf::Voxels => !self.voxels_may_touch(&lo, &hi),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::world::tests::{Lcg, random_world};
    use crate::world::{AxisBox, Bounds, Obstacle, Segment, Sun};

    /// Segments inside a clear box touch nothing, by the BVH and by the scan; and
    /// boxes around a contact are never clear.
    #[test]
    fn nothing_inside_a_clear_box_touches_anything() {
        let mut rng = Lcg(3);
        let mut clear_boxes = 0;
        for (n, voxels) in [(0, false), (5, false), (30, false), (10, true), (60, true)] {
            let world = random_world(&mut rng, n, voxels);
            for _ in 0..3000 {
                let lo = Point3::new(rng.next() * 22.0 - 11.0, rng.next() * 22.0 - 11.0, rng.next() * 5.0);
                let hi = lo + Vector3::new(rng.next() * 3.0, rng.next() * 3.0, rng.next() * 2.0);
                let inside = |rng: &mut Lcg| {
                    Point3::new(
                        lo.x + rng.next() * (hi.x - lo.x),
                        lo.y + rng.next() * (hi.y - lo.y),
                        lo.z + rng.next() * (hi.z - lo.z),
                    )
                };
                let segments: Vec<Segment> = (0..6)
                    .filter_map(|_| {
                        let (a, b) = (inside(&mut rng), inside(&mut rng));
                        Segment::sight_line(&a, &b, 0.0).map(|s| Segment { end: crate::world::SegmentEnd::Closed, ..s })
                    })
                    .collect();
                let touched = world.any_contact_by_scan(&segments);
                if world.box_is_clear(&lo, &hi) {
                    clear_boxes += 1;
                    assert!(!touched && !world.any_contact(&segments), "n = {n}: {lo:?}..{hi:?}");
                } else if n == 0 && !voxels {
                    panic!("an empty world is clear everywhere");
                }
                if touched {
                    assert!(!world.box_is_clear(&lo, &hi));
                }
            }
        }
        assert!(clear_boxes > 3000, "only {clear_boxes} clear boxes: the test tests little");
    }

    #[test]
    fn a_box_meeting_an_obstacle_is_not_clear() {
        let b = Obstacle::Box(AxisBox { min: Point3::new(1.0, 1.0, 0.0), max: Point3::new(2.0, 2.0, 1.0) });
        let world =
            World::new(0, Bounds::new([-5.0, -5.0, 5.0, 5.0]).unwrap(), Sun::new(0.5, 0.0).unwrap(), [(1, b)], None)
                .unwrap();
        assert!(!world.box_is_clear(&Point3::new(0.0, 0.0, 0.0), &Point3::new(1.0, 1.0, 1.0)));
        // Within the clearance of the face: not clear either.
        assert!(!world.box_is_clear(&Point3::new(0.0, 0.0, 0.0), &Point3::new(1.0 - 1e-7, 3.0, 1.0)));
        assert!(world.box_is_clear(&Point3::new(0.0, 0.0, 0.0), &Point3::new(0.99, 3.0, 1.0)));
        assert!(!world.box_is_clear(&Point3::new(0.0, 0.0, f64::NAN), &Point3::new(0.5, 0.5, 0.5)));
    }
}
