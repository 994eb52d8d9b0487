//! Obstacles against the sight lines of one sensor, decided by each line's path
//! without making the lines.
//!
//! The sight line from the sensor P to a target q (SPEC §5.3,
//! [`Segment::sight_line`]) is `P + u·(q − P)`, u ∈ [0, 1], and a contact counts
//! only before its last `margin`. Its verdict against a solid is mostly read off
//! that path, with `q − P` as it is (no square root, no division by its length):
//!
//! - a vertical cylinder (axis c, radius r, height h): the line is within the
//!   heights over one interval of u (it is straight). Miss: over the u where it is
//!   within the heights (grown by the pad), its closest approach to the axis in xy
//!   is farther than r (grown by the pad). Hit: over the u where it is within the
//!   heights (shrunk by the pad), its closest approach is inside r (shrunk by the
//!   pad). The closest approach over an interval is the unconstrained one clamped
//!   into it (the distance is convex in u), evaluated at that point;
//! - an axis-aligned box: miss when the slabs of the box grown by the pad leave no
//!   u in [0, 1]; hit when those of the box shrunk by the pad leave some, their
//!   middle then a point inside the solid;
//!
//! a hit only where that point comes before the line's last `margin` (plus the
//! pad). Rounding moves a point by a few ulps of the coordinates, and an error in
//! an interval's end moves the line there by as little along the axis that set
//! it. Each inequality must hold by the pad (1e-6 m, and 1e-7 per metre of the
//! coordinates involved), far beyond the rounding of the exact tests
//! ([`VerticalCylinder::first_contact`], the box's slabs), so a verdict is the
//! exact test's. In doubt (a grazing line, a target at the sensor, a NaN) the
//! caller runs the exact test.
//!
//! [`Segment::sight_line`]: super::Segment::sight_line

use super::segment::clip_slab;
use super::{AxisBox, VerticalCylinder};
use crate::math::Point3;

/// The pad: an absolute part and a part per metre of the coordinates involved.
const PAD: (f64, f64) = (1e-6, 1e-7);

/// A solid whose verdict against one sensor's sight lines can often be read off
/// the lines' paths (the module doc says how, per shape).
pub(crate) trait SightPath {
    /// Whether some sight line from `sensor` to one of `targets` (each as
    /// [`Segment::sight_line`](super::Segment::sight_line) with `margin` makes it)
    /// touches the solid, when the lines' paths decide it by [`PAD`]; `None` when
    /// the exact test must. `[lo, hi]` holds every line (it sizes the pad).
    #[inline]
    fn touches_sight_lines(
        &self,
        sensor: &Point3<f64>,
        targets: &[Point3<f64>],
        margin: f64,
        lo: &Point3<f64>,
        hi: &Point3<f64>,
    ) -> Option<bool> {
        self.touches_sight_lines_by(sensor, targets, margin, lo, hi, PAD)
    }

    /// [`SightPath::touches_sight_lines`] by `pad` (tests make it too tight).
    fn touches_sight_lines_by(
        &self,
        sensor: &Point3<f64>,
        targets: &[Point3<f64>],
        margin: f64,
        lo: &Point3<f64>,
        hi: &Point3<f64>,
        pad: (f64, f64),
    ) -> Option<bool>;
}

impl SightPath for VerticalCylinder {
    #[inline(always)]
    fn touches_sight_lines_by(
        &self,
        sensor: &Point3<f64>,
        targets: &[Point3<f64>],
        margin: f64,
        lo: &Point3<f64>,
        hi: &Point3<f64>,
        pad: (f64, f64),
    ) -> Option<bool> {
        let (r, h) = (self.radius, self.height);
        // Every coordinate involved, relative to the axis, is at most `far`, and
        // every line's extent at most `long` (per axis, summed).
        let (cx, cy) = (self.center.x, self.center.y);
        let far = (lo.x - cx).abs().max((hi.x - cx).abs())
            + (lo.y - cy).abs().max((hi.y - cy).abs())
            + lo.z.abs().max(hi.z.abs());
        let long = (hi.x - lo.x) + (hi.y - lo.y) + (hi.z - lo.z);
        let m = pad.0 + pad.1 * (2.0 * far + long + r + h + margin);
        if !m.is_finite() {
            return None;
        }
        let grown2 = (r + m) * (r + m);
        // The sensor relative to the axis.
        let (px, py, pz) = (sensor.x - cx, sensor.y - cy, sensor.z);
        let mut decided = true;
        for q in targets {
            let (dx, dy, dz) = (q.x - sensor.x, q.y - sensor.y, q.z - sensor.z);
            match line_verdict([px, py, pz], [dx, dy, dz], r, h, margin, m, grown2) {
                Some(true) => return Some(true),
                Some(false) => {}
                None => decided = false,
            }
        }
        decided.then_some(false)
    }
}

impl SightPath for AxisBox {
    #[inline(always)]
    fn touches_sight_lines_by(
        &self,
        sensor: &Point3<f64>,
        targets: &[Point3<f64>],
        margin: f64,
        lo: &Point3<f64>,
        hi: &Point3<f64>,
        pad: (f64, f64),
    ) -> Option<bool> {
        // Every coordinate involved (the lines', the box's) is at most `far`.
        let far =
            (0..3).map(|a| lo[a].abs().max(hi[a].abs()).max(self.min[a].abs()).max(self.max[a].abs())).sum::<f64>();
        let m = pad.0 + pad.1 * far;
        if !m.is_finite() {
            return None;
        }
        let (grown, shrunk) =
            ((self.min.map(|v| v - m), self.max.map(|v| v + m)), (self.min.map(|v| v + m), self.max.map(|v| v - m)));
        // A box thinner than twice the pad has no inside to shrink to (and the
        // slabs of an inverted one would not be empty).
        let thick = (0..3).all(|k| shrunk.0[k] < shrunk.1[k]);
        let mut decided = true;
        for q in targets {
            let d = q - sensor;
            // A NaN or an infinity in the sensor or the target: in doubt.
            if !(d.x + d.y + d.z).is_finite() {
                decided = false;
                continue;
            }
            let within = |(lo, hi): &(Point3<f64>, Point3<f64>)| {
                let (mut a, mut b) = (0.0, 1.0);
                (0..3).all(|k| clip_slab(sensor[k], d[k], lo[k], hi[k], &mut a, &mut b)).then_some((a, b))
            };
            if within(&grown).is_none() {
                continue;
            }
            match within(&shrunk).filter(|_| thick) {
                Some((a, b)) => {
                    let u = 0.5 * (a + b);
                    if (1.0 - u) * (1.0 - u) * d.norm_squared() > (margin + m) * (margin + m) {
                        return Some(true);
                    }
                    decided = false;
                }
                None => decided = false,
            }
        }
        decided.then_some(false)
    }
}

/// The verdict on the line `p + u·d`, u ∈ [0, 1] (`p` relative to the axis),
/// against the cylinder of radius `r` and height `h`, by the pad `m` (`grown2`:
/// `(r + m)²`).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn line_verdict(p: [f64; 3], d: [f64; 3], r: f64, h: f64, margin: f64, m: f64, grown2: f64) -> Option<bool> {
    let ([px, py, pz], [dx, dy, dz]) = (p, d);
    let dd = dx * dx + dy * dy;
    // The whole line (not only the segment) passes beside the grown disc: its
    // distance from the axis is |p × d| / |d| in xy.
    let cross = px * dy - py * dx;
    if cross * cross > grown2 * dd {
        return Some(false);
    }
    // A NaN or an infinity in the sensor or the target: in doubt (the tests
    // below would hold).
    if !(dx + dy + dz).is_finite() {
        return None;
    }
    // The unconstrained closest approach to the axis (any u when the line is vertical).
    let closest = if dd > 0.0 { -(px * dx + py * dy) / dd } else { 0.0 };
    let gap2 = |u: f64| {
        let (ex, ey) = (px + u * dx, py + u * dy);
        ex * ex + ey * ey
    };
    if gap2(closest.clamp(0.0, 1.0)) > grown2 {
        return Some(false);
    }
    // Within the heights grown by the pad.
    match heights(pz, dz, -m, h + m) {
        None => return Some(false),
        Some((a, b)) if gap2(closest.clamp(a, b)) > grown2 => return Some(false),
        Some(_) => {}
    }
    // Within the heights shrunk by the pad, inside the radius shrunk by it, before
    // the end.
    let shrunk = r - m;
    if let Some((a, b)) = heights(pz, dz, m, h - m) {
        let u = closest.clamp(a, b);
        let rest = (1.0 - u) * (1.0 - u) * (dd + dz * dz);
        if shrunk > 0.0 && gap2(u) < shrunk * shrunk && rest > (margin + m) * (margin + m) {
            return Some(true);
        }
    }
    None
}

/// The u ∈ [0, 1] where `z + u·dz` is within `[lo, hi]`, if any.
#[inline(always)]
fn heights(z: f64, dz: f64, lo: f64, hi: f64) -> Option<(f64, f64)> {
    if dz == 0.0 {
        return (lo <= z && z <= hi).then_some((0.0, 1.0));
    }
    let (ua, ub) = ((lo - z) / dz, (hi - z) / dz);
    let (a, b) = (ua.min(ub).max(0.0), ua.max(ub).min(1.0));
    (a <= b).then_some((a, b))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::{Point2, Vector3};
    use crate::world::tests::Lcg;
    use crate::world::{Obstacle, Segment};
    use std::f64::consts::TAU;

    /// Verdicts that differ from the exact test's, hits and misses given.
    #[derive(Default)]
    struct Tally {
        wrong: usize,
        hits: usize,
        misses: usize,
    }

    impl Tally {
        /// Counts the verdict by `pad` of `shape` (which is `solid`) on the lines from
        /// `sensor` to the first target, then to all of `targets`, against the exact
        /// test on the lines [`Segment::sight_line`] makes.
        fn add(
            &mut self,
            shape: &impl SightPath,
            solid: Obstacle,
            sensor: &Point3<f64>,
            targets: &[Point3<f64>],
            pad: (f64, f64),
        ) {
            for targets in [&targets[..1], targets] {
                let want = targets
                    .iter()
                    .filter_map(|q| Segment::sight_line(sensor, q, 1e-6))
                    .any(|s| solid.first_contact(&s).is_some_and(|t| s.reaches(t)));
                let (lo, hi) = targets.iter().fold((*sensor, *sensor), |(lo, hi), q| (lo.inf(q), hi.sup(q)));
                if let Some(got) = shape.touches_sight_lines_by(sensor, targets, 1e-6, &lo, &hi, pad) {
                    self.wrong += usize::from(got != want);
                    if got { self.hits += 1 } else { self.misses += 1 }
                }
            }
        }
    }

    /// Counts the verdicts that differ from the exact test's, and the hits and
    /// misses given, over sensors and targets placed so that lines graze the
    /// cylinder's side, pass its top edge, end at its surface, start inside it, or
    /// run vertically or horizontally, each give or take a hair; and anywhere.
    fn disagreements(pad: (f64, f64)) -> Tally {
        let mut rng = Lcg(23);
        let mut tally = Tally::default();
        let hair = |rng: &mut Lcg| (rng.next() - 0.5) * 4e-6;
        for _ in 0..300 {
            let c = VerticalCylinder {
                center: Point2::new(rng.next() * 40.0 - 20.0, rng.next() * 40.0 - 20.0),
                radius: 0.05 + rng.next() * 1.5,
                height: 0.2 + rng.next() * 4.0,
            };
            let (r, h) = (c.radius, c.height);
            let at = |a: f64, d: f64, z: f64| Point3::new(c.center.x + d * a.cos(), c.center.y + d * a.sin(), z);
            for k in 0..300 {
                let a = rng.next() * TAU;
                let (sensor, target) = match k % 8 {
                    // Tangent to the side at a point within the heights.
                    0 => {
                        let touch = at(a, r + hair(&mut rng), rng.next() * h);
                        let along = Vector3::new(-a.sin(), a.cos(), (rng.next() - 0.5) * 0.5);
                        (touch + along * (0.5 + rng.next() * 5.0), touch - along * (0.5 + rng.next() * 5.0))
                    }
                    // Over (or through) the top edge, or the bottom one.
                    1 | 2 => {
                        let z = if k % 8 == 1 { h } else { 0.0 };
                        let edge = at(a, r * (0.2 + rng.next() * 0.8), z + hair(&mut rng));
                        let tilt = (rng.next() - 0.5) * 2.0;
                        let dir = Vector3::new(a.cos(), a.sin(), tilt);
                        (edge + dir * (0.5 + rng.next() * 5.0), edge - dir * (0.5 + rng.next() * 5.0))
                    }
                    // Ending at the surface (the last micrometre does not count).
                    3 => {
                        let end = at(a, r + hair(&mut rng) - 1e-6 * rng.next(), rng.next() * h);
                        (at(a, r + 0.5 + rng.next() * 5.0, rng.next() * 5.0), end)
                    }
                    // Starting inside the solid or at its surface.
                    4 => (
                        at(a, rng.next() * (r + 1e-5), rng.next() * h),
                        at(rng.next() * TAU, r + rng.next() * 5.0, 0.2),
                    ),
                    // Vertical, or horizontal, near the side.
                    5 => {
                        let p = at(a, r + hair(&mut rng), 0.0);
                        (p + Vector3::new(0.0, 0.0, h + 1.0), p + Vector3::new(0.0, 0.0, rng.next() * h))
                    }
                    6 => {
                        let z = rng.next() * (h + 1.0) - 0.5;
                        (at(a, r + rng.next() * 3.0, z), at(a + 1.0 + rng.next() * 4.0, r + rng.next() * 3.0, z))
                    }
                    _ => (at(a, rng.next() * 6.0, rng.next() * 6.0 - 0.5), at(rng.next() * TAU, rng.next() * 6.0, 0.2)),
                };
                // The line alone, and with targets around the sensor's own.
                let others = [target, at(rng.next() * TAU, r + 1.0 + rng.next() * 5.0, rng.next())];
                tally.add(&c, Obstacle::Cylinder(c), &sensor, &others, pad);
            }
        }
        tally
    }

    /// The verdicts are the exact test's, and decide most lines.
    #[test]
    fn a_cylinders_sight_line_verdicts_are_the_exact_tests() {
        let Tally { wrong, hits, misses } = disagreements(PAD);
        assert_eq!(wrong, 0);
        assert!(hits > 30_000 && misses > 30_000, "{hits} hits, {misses} misses: the test tests little");
    }

    /// The test above can fail: with the pad made negative (the bounds 1e-6 m too
    /// loose), the grazing lines get verdicts the exact test contradicts.
    #[test]
    fn sight_line_verdicts_past_the_bounds_disagree_with_the_exact_test() {
        let wrong = disagreements((-PAD.0, 0.0)).wrong;
        assert!(wrong > 0, "the cases never graze a bound");
    }

    /// Counts the box verdicts that differ from the exact test's, and the hits and
    /// misses given, over lines through a point on a face, an edge or a corner of
    /// the box (give or take a hair) from outside, ending at a face, starting
    /// inside, parallel to an axis; and boxes thinner than the pad.
    fn box_disagreements(pad: (f64, f64)) -> Tally {
        let mut rng = Lcg(31);
        let mut tally = Tally::default();
        let hair = |rng: &mut Lcg| (rng.next() - 0.5) * 4e-6;
        for i in 0..300 {
            let min = Point3::new(rng.next() * 40.0 - 20.0, rng.next() * 40.0 - 20.0, rng.next() * 3.0);
            let size = if i % 10 == 0 { Vector3::new(1e-6, 1.0, 1.0) } else { Vector3::repeat(0.05) };
            let b = AxisBox { min, max: min + size + Vector3::new(rng.next(), rng.next(), rng.next()) * 2.0 };
            // A point of the box's surface (on 1, 2 or 3 of its faces), moved a hair.
            let on_surface = |rng: &mut Lcg| {
                let mut p = Point3::origin();
                let faces = 1 + (rng.next() * 3.0) as usize;
                let first = (rng.next() * 3.0) as usize;
                for k in 0..3 {
                    let t =
                        if (k + 3 - first) % 3 < faces { f64::from(u8::from(rng.next() < 0.5)) } else { rng.next() };
                    p[k] = b.min[k] + t * (b.max[k] - b.min[k]) + hair(rng);
                }
                p
            };
            let away = |rng: &mut Lcg, p: &Point3<f64>| {
                let c = nalgebra::center(&b.min, &b.max);
                let out = (p - c).normalize() + Vector3::new(rng.next(), rng.next(), rng.next()) - Vector3::repeat(0.5);
                p + out * (0.5 + rng.next() * 5.0)
            };
            for k in 0..300 {
                let (sensor, target) = match k % 6 {
                    // From outside through a surface point, on, or just past it.
                    0 | 1 => {
                        let p = on_surface(&mut rng);
                        let from = away(&mut rng, &p);
                        (from, p + (p - from) * if k % 6 == 0 { rng.next() * 3.0 } else { 0.0 })
                    }
                    // Ending at the surface, from outside.
                    2 => {
                        let p = on_surface(&mut rng);
                        (away(&mut rng, &p), p)
                    }
                    // Starting inside or at the surface.
                    3 => {
                        let p = nalgebra::center(&b.min, &b.max);
                        let q = on_surface(&mut rng);
                        let inside = p + (q - p) * (rng.next() * 1.001);
                        (inside, away(&mut rng, &q))
                    }
                    // Parallel to an axis, along a face.
                    4 => {
                        let p = on_surface(&mut rng);
                        let mut q = p;
                        let k = (rng.next() * 3.0) as usize;
                        q[k] += (rng.next() - 0.5) * 10.0;
                        (p, q)
                    }
                    _ => {
                        let c = nalgebra::center(&b.min, &b.max);
                        let anywhere = |rng: &mut Lcg| {
                            c + (Vector3::new(rng.next(), rng.next(), rng.next()) - Vector3::repeat(0.5)) * 8.0
                        };
                        (anywhere(&mut rng), anywhere(&mut rng))
                    }
                };
                let p = on_surface(&mut rng);
                let others = [target, away(&mut rng, &p)];
                tally.add(&b, Obstacle::Box(b), &sensor, &others, pad);
            }
        }
        tally
    }

    /// The box verdicts are the exact test's, and decide most lines.
    #[test]
    fn a_boxs_sight_line_verdicts_are_the_exact_tests() {
        let Tally { wrong, hits, misses } = box_disagreements(PAD);
        assert_eq!(wrong, 0);
        assert!(hits > 30_000 && misses > 20_000, "{hits} hits, {misses} misses: the test tests little");
    }

    /// The test above can fail: with the pad made negative, the grazing lines get
    /// box verdicts the exact test contradicts.
    #[test]
    fn box_verdicts_past_the_bounds_disagree_with_the_exact_test() {
        let wrong = box_disagreements((-PAD.0, 0.0)).wrong;
        assert!(wrong > 0, "the cases never graze a bound");
    }

    /// A target at the sensor makes no line (never a hit), and a NaN is left to the
    /// exact test.
    #[test]
    fn a_target_at_the_sensor_or_a_nan_is_left_in_doubt_or_missed() {
        let c = VerticalCylinder { center: Point2::new(0.0, 0.0), radius: 1.0, height: 2.0 };
        let p = Point3::new(0.5, 0.0, 1.0);
        assert_ne!(c.touches_sight_lines(&p, &[p], 1e-6, &p, &p), Some(true));
        let nan = Point3::new(f64::NAN, 0.0, 0.0);
        assert_eq!(c.touches_sight_lines(&p, &[nan], 1e-6, &p, &p.sup(&Point3::new(1.0, 1.0, 1.0))), None);
        assert_eq!(c.touches_sight_lines(&p, &[nan], 1e-6, &nan, &nan), None);
        let b = AxisBox { min: Point3::new(0.0, -1.0, 0.0), max: Point3::new(1.0, 1.0, 2.0) };
        assert_ne!(b.touches_sight_lines(&p, &[p], 1e-6, &p, &p), Some(true));
        assert_eq!(b.touches_sight_lines(&p, &[nan], 1e-6, &p, &p.sup(&Point3::new(1.0, 1.0, 1.0))), None);
    }
}
