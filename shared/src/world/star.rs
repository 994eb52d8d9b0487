//! The collision star of SPEC §5.2, and the verdicts on it that a cylinder's
//! distance alone decides.
//!
//! A viewer at p with yaw ψ_v casts 10 closed segments of length L: 8 horizontal
//! at ψ_v + k·45°, then +z and −z. Against a vertical cylinder (axis at distance D
//! from p in xy, radius r, height h) the verdict is often known without the yaw:
//!
//! - hit: p inside the disc (D < r) and the vertical segments' span `[p_z − L,
//!   p_z + L]` meets `[0, h]`; or p beside the cylinder (D > r, `0 ≤ p_z ≤ h`) and
//!   even a horizontal segment 22.5° off the axis's direction (the worst any yaw
//!   gives: the 8 are 45° apart) enters the disc within L, that is
//!   `D·sin 22.5° < r` and `D·cos 22.5° − √(r² − D²·sin² 22.5°) < L` (the entry
//!   distance grows with the angle when D > r);
//! - miss: `D > r + L` (no segment gets within L of p in xy), or the star's span
//!   in z misses `[0, h]`, or p beside the cylinder (D > r) and above it
//!   (`p_z > h`: the horizontal segments run at p_z, the vertical ones outside the
//!   disc).
//!
//! Against a box the segments' own coordinates decide it as often: the
//! horizontal segments run at p_z and the vertical ones at p's (x, y), so
//!
//! - hit: p's (x, y) inside the box's rectangle and `[p_z − L, p_z + L]` meets
//!   the box's heights (a vertical segment; p inside the box is one such case);
//! - miss: p's (x, y) outside the rectangle and p_z outside the box's heights, or
//!   p farther than L from the rectangle in xy.
//!
//! Given the yaw's sine and cosine (a search over a grid of yaws has them), the
//! cases left (p beside the solid, at its heights) are decided the same way by
//! the 8 horizontal segments' own directions: against a cylinder by each
//! segment's distance from the axis and its entry into the disc, against a box
//! by each segment's slabs, each with the solid shrunk and grown by the margin.
//!
//! Each inequality must hold by [`MARGIN`] (m, and that much per metre of the
//! sizes involved), far beyond the rounding of the exact tests
//! ([`VerticalCylinder::first_contact`], the box's slabs), so the verdict is the
//! exact test's. Every other case (and the voxel grid) takes the exact test.

use super::segment::clip_slab;
use super::{AxisBox, Leaf, Nearby, Segment, VerticalCylinder, World};
use crate::math::{Point3, Vector3};
use std::f64::consts::FRAC_1_SQRT_2;

/// How far a distance must be inside its bound for a verdict without the exact test.
const MARGIN: f64 = 1e-6;

/// sin and cos of 22.5°, half the angle between two horizontal segments.
const SIN_HALF_GAP: f64 = 0.382_683_432_365_089_8;
const COS_HALF_GAP: f64 = 0.923_879_532_511_286_7;

/// Unit directions of the 8 horizontal segments at yaw 0 (k·45°).
const DIRECTIONS: [(f64, f64); 8] = [
    (1.0, 0.0),
    (FRAC_1_SQRT_2, FRAC_1_SQRT_2),
    (0.0, 1.0),
    (-FRAC_1_SQRT_2, FRAC_1_SQRT_2),
    (-1.0, 0.0),
    (-FRAC_1_SQRT_2, -FRAC_1_SQRT_2),
    (0.0, -1.0),
    (FRAC_1_SQRT_2, -FRAC_1_SQRT_2),
];

/// A viewer's collision star (SPEC §5.2).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Star {
    /// The viewer position p_v.
    pub center: Point3<f64>,
    /// The viewer yaw ψ_v.
    pub yaw: f64,
    /// The segments' length, `viewer_radius + safety_margin`.
    pub reach: f64,
}

impl Star {
    /// The 10 segments: 8 horizontal at ψ_v + k·45°, then +z, −z.
    #[inline]
    pub fn segments(&self) -> [Segment; 10] {
        self.segments_turned(self.yaw.sin_cos())
    }

    /// [`Star::segments`] given `turn`, `ψ_v.sin_cos()` (a search over a grid of
    /// yaws computes it once per yaw).
    #[inline]
    pub fn segments_turned(&self, turn: (f64, f64)) -> [Segment; 10] {
        let (s, c) = turn;
        let mut rays = [Segment::closed(self.center, Vector3::z(), self.reach); 10];
        for (ray, (dx, dy)) in rays.iter_mut().zip(DIRECTIONS) {
            ray.dir = Vector3::new(c * dx - s * dy, s * dx + c * dy, 0.0);
        }
        rays[9].dir = -Vector3::z();
        rays
    }

    /// The cube holding every segment: half-side `reach` around the viewer.
    #[inline]
    pub fn bounds(&self) -> (Point3<f64>, Point3<f64>) {
        let r = Vector3::repeat(self.reach);
        (self.center - r, self.center + r)
    }

    /// Whether some segment touches `cylinder`, when the distances decide it by
    /// [`MARGIN`] whatever the yaw; `None` when the exact test must.
    #[inline]
    pub fn touches_cylinder(&self, cylinder: &VerticalCylinder) -> Option<bool> {
        self.touches_cylinder_by(cylinder, MARGIN)
    }

    /// [`Star::touches_cylinder`] with the inequalities held by `margin`.
    #[inline(always)]
    fn touches_cylinder_by(&self, cylinder: &VerticalCylinder, margin: f64) -> Option<bool> {
        let (p, l, r, h) = (&self.center, self.reach, cylinder.radius, cylinder.height);
        let m = margin * (1.0 + r + l);
        let (dx, dy) = (p.x - cylinder.center.x, p.y - cylinder.center.y);
        let d = (dx * dx + dy * dy).sqrt();
        if d > r + l + m || p.z - l > h + m || p.z + l < -m {
            return Some(false);
        }
        if d < r - m {
            return (p.z - l < h - m && p.z + l > m).then_some(true);
        }
        if d > r + m && m < p.z && p.z < h - m {
            let off = d * SIN_HALF_GAP;
            if off < r - m && d * COS_HALF_GAP - (r * r - off * off).sqrt() < l - m {
                return Some(true);
            }
        }
        if d > r + m && p.z > h + m {
            return Some(false);
        }
        None
    }

    /// Whether some segment touches `cylinder` when p is beside it, within its
    /// heights, and the horizontal segments' directions (`turn`, the yaw's
    /// `sin_cos()`) decide it by [`MARGIN`]; `None` otherwise.
    #[inline(never)]
    pub fn touches_cylinder_beside(&self, cylinder: &VerticalCylinder, turn: (f64, f64)) -> Option<bool> {
        self.touches_cylinder_beside_by(cylinder, turn, MARGIN)
    }

    #[inline(always)]
    fn touches_cylinder_beside_by(&self, cylinder: &VerticalCylinder, turn: (f64, f64), margin: f64) -> Option<bool> {
        let (p, l, r, h) = (&self.center, self.reach, cylinder.radius, cylinder.height);
        let m = margin * (1.0 + r + l);
        let (wx, wy) = (cylinder.center.x - p.x, cylinder.center.y - p.y);
        // Outside the disc the vertical segments miss; within the heights the
        // horizontal ones are tested against the disc shrunk and grown by m.
        if !(wx * wx + wy * wy > (r + m) * (r + m) && m < p.z && p.z < h - m) {
            return None;
        }
        let (shrunk, grown) = (r - m, r + m);
        let (s, c) = turn;
        let mut missed = true;
        // Segments k and k + 4 are opposite: the one pointing away from the axis
        // misses (p is outside the disc), the other enters it at
        // `along − √(r² − off²)` if `off ≤ r`.
        for (dx, dy) in &DIRECTIONS[..4] {
            let (ux, uy) = (c * dx - s * dy, s * dx + c * dy);
            let along = (wx * ux + wy * uy).abs();
            let off = (wx * uy - wy * ux).abs();
            if off < shrunk && along - (shrunk * shrunk - off * off).sqrt() < l - m {
                return Some(true);
            }
            missed &= off > grown || along - (grown * grown - off * off).sqrt() > l + m;
        }
        missed.then_some(false)
    }

    /// Whether some segment touches the box `b`, when p's coordinates decide it by
    /// [`MARGIN`] whatever the yaw; `None` when the exact test must. Out of line:
    /// boxes are rarer than cylinders, and the loop over a short list stays small.
    #[inline(never)]
    pub fn touches_box(&self, b: &AxisBox) -> Option<bool> {
        self.touches_box_by(b, MARGIN)
    }

    #[inline(always)]
    fn touches_box_by(&self, b: &AxisBox, margin: f64) -> Option<bool> {
        let (p, l) = (&self.center, self.reach);
        let m = margin * (1.0 + l + p.x.abs() + p.y.abs() + p.z.abs());
        // How far p is outside the rectangle along x and y (negative: inside).
        let dx = (b.min.x - p.x).max(p.x - b.max.x);
        let dy = (b.min.y - p.y).max(p.y - b.max.y);
        if dx < -m && dy < -m {
            return (p.z - l < b.max.z - m && p.z + l > b.min.z + m).then_some(true);
        }
        if dx > m || dy > m {
            let (ox, oy) = (dx.max(0.0), dy.max(0.0));
            if p.z > b.max.z + m || p.z < b.min.z - m || ox * ox + oy * oy > (l + m) * (l + m) {
                return Some(false);
            }
        }
        None
    }

    /// [`Star::touches_box`], and where it does not decide, with p beside the box
    /// within its heights, the horizontal segments' directions (`turn`, the yaw's
    /// `sin_cos()`) by [`MARGIN`]; `None` when the exact test must.
    #[inline(never)]
    pub fn touches_box_turned(&self, b: &AxisBox, turn: (f64, f64)) -> Option<bool> {
        self.touches_box_by(b, MARGIN).or_else(|| self.touches_box_beside_by(b, turn, MARGIN))
    }

    #[inline(always)]
    fn touches_box_beside_by(&self, b: &AxisBox, turn: (f64, f64), margin: f64) -> Option<bool> {
        let (p, l) = (&self.center, self.reach);
        let m = margin * (1.0 + l + p.x.abs() + p.y.abs() + p.z.abs());
        // Outside the rectangle the vertical segments miss; within the heights the
        // horizontal ones are tested against it shrunk and grown by m.
        let outside = (b.min.x - p.x).max(p.x - b.max.x).max((b.min.y - p.y).max(p.y - b.max.y));
        if !(outside > m && b.min.z + m < p.z && p.z < b.max.z - m) {
            return None;
        }
        let (s, c) = turn;
        let mut missed = true;
        for (dx, dy) in DIRECTIONS {
            let (ux, uy) = (c * dx - s * dy, s * dx + c * dy);
            let meets = |grow: f64, length: f64| {
                let (mut t0, mut t1) = (0.0, length);
                clip_slab(p.x, ux, b.min.x - grow, b.max.x + grow, &mut t0, &mut t1)
                    && clip_slab(p.y, uy, b.min.y - grow, b.max.y + grow, &mut t0, &mut t1)
            };
            if meets(-m, l - m) {
                return Some(true);
            }
            missed &= !meets(m, l + m);
        }
        missed.then_some(false)
    }
}

impl World {
    /// Whether the star touches anything: [`World::any_contact`]'s verdict on its
    /// segments, bit for bit, through the short list `near` (as
    /// [`World::any_contact_near`]), a cylinder's distance deciding it where it can
    /// ([`Star::touches_cylinder`]); the segments are made only for an exact test.
    pub fn star_contact_near(&self, near: &Nearby, star: &Star) -> bool {
        let (lo, hi) = star.bounds();
        self.contact_near(
            near,
            &lo,
            &hi,
            || star.segments(),
            |leaf| match leaf {
                Leaf::Solid { shape: super::Obstacle::Cylinder(c), .. } => star.touches_cylinder(c),
                Leaf::Solid { shape: super::Obstacle::Box(b), .. } => star.touches_box(b),
                Leaf::Voxels => None,
            },
        )
    }

    /// [`World::star_contact_near`] given `turn`, `star.yaw.sin_cos()`: the
    /// horizontal segments' directions decide more leaves without the exact test
    /// ([`Star::touches_cylinder_beside`], [`Star::touches_box_turned`]).
    #[inline]
    pub fn star_contact_near_turned(&self, near: &Nearby, star: &Star, turn: (f64, f64)) -> bool {
        let (lo, hi) = star.bounds();
        self.contact_near(
            near,
            &lo,
            &hi,
            || star.segments_turned(turn),
            |leaf| match leaf {
                Leaf::Solid { shape: super::Obstacle::Cylinder(c), .. } => {
                    star.touches_cylinder(c).or_else(|| star.touches_cylinder_beside(c, turn))
                }
                Leaf::Solid { shape: super::Obstacle::Box(b), .. } => star.touches_box_turned(b, turn),
                Leaf::Voxels => None,
            },
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::Point2;
    use crate::world::tests::Lcg;
    use crate::world::{Bounds, Obstacle, Sun};
    use std::f64::consts::TAU;

    /// Counts the stars whose distance verdict differs from the exact test's, over
    /// stars placed around a cylinder at every distance and height, many grazing
    /// one of the bounds; and the verdicts given at all (hits, misses).
    fn disagreements(margin: f64) -> ([usize; 2], usize, usize) {
        let mut rng = Lcg(5);
        let (mut wrong, mut hits, mut misses) = ([0, 0], 0, 0);
        for _ in 0..200 {
            let cylinder = VerticalCylinder {
                center: Point2::new(rng.next() * 200.0 - 100.0, rng.next() * 200.0 - 100.0),
                radius: 0.05 + rng.next() * 2.0,
                height: 0.1 + rng.next() * 5.0,
            };
            let l = 0.1 + rng.next();
            let (r, h) = (cylinder.radius, cylinder.height);
            for k in 0..400 {
                // Distances and heights at the bounds the verdicts use, give or
                // take a hair, or anywhere.
                let off = |rng: &mut Lcg, x: f64| x + (rng.next() - 0.5) * 4e-6;
                let grazing_gap = {
                    // The D where a segment 22.5° off enters the disc at exactly L.
                    // D·c − √(r² − D²s²) = L  ⇔  D² − 2LcD + L² − r² = 0.
                    let c = COS_HALF_GAP;
                    l * c + (l * l * c * c - l * l + r * r).sqrt()
                };
                let d = match k % 5 {
                    0 => off(&mut rng, r),
                    1 => off(&mut rng, r + l),
                    2 => off(&mut rng, grazing_gap),
                    _ => rng.next() * (r + 2.0 * l),
                };
                let z = match k % 4 {
                    0 => off(&mut rng, h),
                    1 => off(&mut rng, h + l),
                    2 => off(&mut rng, -l),
                    _ => rng.next() * (h + 3.0 * l) - 1.5 * l,
                };
                let a = rng.next() * TAU;
                let star = Star {
                    center: Point3::new(cylinder.center.x + d * a.cos(), cylinder.center.y + d * a.sin(), z),
                    yaw: rng.next() * TAU,
                    reach: l,
                };
                let want = star.segments().iter().any(|s| cylinder.first_contact(s).is_some_and(|t| s.reaches(t)));
                let alone = star.touches_cylinder_by(&cylinder, margin);
                let beside = star.touches_cylinder_beside_by(&cylinder, star.yaw.sin_cos(), margin);
                for got in [alone, beside] {
                    match got {
                        Some(true) => hits += 1,
                        Some(false) => misses += 1,
                        None => {}
                    }
                }
                wrong[0] += usize::from(alone.is_some_and(|g| g != want));
                wrong[1] += usize::from(beside.is_some_and(|g| g != want));
            }
        }
        (wrong, hits, misses)
    }

    #[test]
    fn the_half_gap_constants_are_those_of_22_5_degrees() {
        let (s, c) = (std::f64::consts::PI / 8.0).sin_cos();
        assert!((s - SIN_HALF_GAP).abs() < 1e-16 && (c - COS_HALF_GAP).abs() < 1e-16);
    }

    /// The distance verdicts are the exact test's, and decide most stars.
    #[test]
    fn a_cylinders_distance_verdicts_are_the_exact_tests() {
        let (wrong, hits, misses) = disagreements(MARGIN);
        assert_eq!(wrong, [0, 0]);
        assert!(hits > 5_000 && misses > 5_000, "{hits} hits, {misses} misses: the test tests little");
    }

    /// The test above can fail: verdicts with the margin made negative (bounds
    /// 1e-6 m too loose) contradict the exact test at the grazing stars.
    #[test]
    fn verdicts_past_the_bounds_disagree_with_the_exact_test() {
        let (wrong, _, _) = disagreements(-MARGIN);
        assert!(wrong[0] > 0 && wrong[1] > 0, "the cases never graze a bound: {wrong:?}");
    }

    /// Counts the stars whose box verdict differs from the exact test's, over
    /// stars placed around a box on and off its faces (give or take a hair) and
    /// a reach away from them; and the verdicts given at all (hits, misses).
    fn box_disagreements(margin: f64) -> ([usize; 2], usize, usize) {
        let mut rng = Lcg(13);
        let (mut wrong, mut hits, mut misses) = ([0, 0], 0, 0);
        for _ in 0..200 {
            let min = Point3::new(rng.next() * 200.0 - 100.0, rng.next() * 200.0 - 100.0, rng.next() * 3.0);
            let b = AxisBox { min, max: min + Vector3::new(0.05, 0.05, 0.05) + Vector3::repeat(2.0 * rng.next()) };
            let l = 0.1 + rng.next();
            for _ in 0..400 {
                let off = |rng: &mut Lcg, x: f64| x + (rng.next() - 0.5) * 4e-6;
                let mut center = Point3::origin();
                for a in 0..3 {
                    let (lo, hi) = (b.min[a], b.max[a]);
                    center[a] = match (rng.next() * 7.0) as usize {
                        0 => off(&mut rng, lo),
                        1 => off(&mut rng, hi),
                        2 => off(&mut rng, lo - l),
                        3 => off(&mut rng, hi + l),
                        4 | 5 => lo + rng.next() * (hi - lo),
                        _ => lo - 1.5 * l + rng.next() * (hi - lo + 3.0 * l),
                    };
                }
                let star = Star { center, yaw: rng.next() * TAU, reach: l };
                let want =
                    star.segments().iter().any(|s| Obstacle::Box(b).first_contact(s).is_some_and(|t| s.reaches(t)));
                let alone = star.touches_box_by(&b, margin);
                let beside = star.touches_box_beside_by(&b, star.yaw.sin_cos(), margin);
                for got in [alone, beside] {
                    match got {
                        Some(true) => hits += 1,
                        Some(false) => misses += 1,
                        None => {}
                    }
                }
                wrong[0] += usize::from(alone.is_some_and(|g| g != want));
                wrong[1] += usize::from(beside.is_some_and(|g| g != want));
            }
        }
        (wrong, hits, misses)
    }

    /// The box verdicts are the exact test's, and decide many stars.
    #[test]
    fn a_boxs_coordinate_verdicts_are_the_exact_tests() {
        let (wrong, hits, misses) = box_disagreements(MARGIN);
        assert_eq!(wrong, [0, 0]);
        assert!(hits > 5_000 && misses > 5_000, "{hits} hits, {misses} misses: the test tests little");
    }

    /// The test above can fail: box verdicts with the margin made negative
    /// contradict the exact test at the grazing stars.
    #[test]
    fn box_verdicts_past_the_bounds_disagree_with_the_exact_test() {
        let (wrong, _, _) = box_disagreements(-MARGIN);
        assert!(wrong[0] > 0 && wrong[1] > 0, "the cases never graze a bound: {wrong:?}");
    }

    /// Through the short list (the query's, crowded, and one narrowed around each
    /// star), with or without the yaw's sine and cosine given, the star's verdict
    /// is the scan's on a dense map of cylinders and boxes.
    #[test]
    fn the_star_agrees_with_the_scan() {
        let mut rng = Lcg(9);
        let obstacles: Vec<(u32, Obstacle)> = (0..60)
            .map(|i| {
                let (x, y) = (rng.next() * 16.0 - 8.0, rng.next() * 16.0 - 8.0);
                let o = if i % 3 == 2 {
                    let min = Point3::new(x, y, rng.next() * 2.0);
                    Obstacle::Box(AxisBox { min, max: min + Vector3::new(rng.next(), rng.next(), rng.next() * 2.0) })
                } else {
                    Obstacle::Cylinder(VerticalCylinder {
                        center: Point2::new(x, y),
                        radius: 0.1 + rng.next() * 0.7,
                        height: 0.3 + rng.next() * 3.0,
                    })
                };
                (i + 1, o)
            })
            .collect();
        let world = World::new(
            0,
            Bounds::new([-10.0, -10.0, 10.0, 10.0]).unwrap(),
            Sun::new(0.5, 0.0).unwrap(),
            obstacles,
            None,
        )
        .unwrap();
        let near = world.nearby(&Point3::new(-9.0, -9.0, -1.0), &Point3::new(9.0, 9.0, 5.0));
        let (mut hits, mut misses) = (0, 0);
        let mut narrow = Nearby::default();
        for _ in 0..20_000 {
            let star = Star {
                center: Point3::new(rng.next() * 16.0 - 8.0, rng.next() * 16.0 - 8.0, rng.next() * 4.0 - 0.5),
                yaw: rng.next() * TAU,
                reach: 0.625,
            };
            let want = world.any_contact_by_scan(&star.segments());
            assert_eq!(world.star_contact_near(&near, &star), want, "{star:?}");
            let (lo, hi) = star.bounds();
            world.nearby_within(&near, &(lo - Vector3::repeat(0.3)), &(hi + Vector3::repeat(0.3)), &mut narrow);
            assert_eq!(world.star_contact_near(&narrow, &star), want, "{star:?}");
            assert_eq!(world.star_contact_near_turned(&narrow, &star, star.yaw.sin_cos()), want, "{star:?}");
            if want { hits += 1 } else { misses += 1 }
        }
        assert!(hits > 3000 && misses > 3000, "{hits} hits, {misses} misses");
    }
}
