//! The sight fan: which obstacles can block the sight lines of one query.
//!
//! Every sight line of a query runs from the sensor P to a target q within `radius`
//! (R) of the marker m, in xy. The point `P + t·(q − P)` lies within `t·|q − m| ≤ R`
//! (in xy) of the point `P + t·(m − P)` of the segment m–P, so every sight line lies
//! within R of that segment, in xy. An obstacle whose xy footprint (a disc of radius
//! r around c, at distance D from m) stays farther than r + R from the segment m–P
//! cannot touch any of them. Two cheap tests prove that:
//!
//! - distance: every point of the segment is within L = |P − m| of m, so the
//!   footprint is out of reach when D − r − R > L;
//! - azimuth: seen from m, the segment points along one azimuth α; the distance from
//!   c to the ray from m at α is `D·sin δ` (δ: the angle between α and c's azimuth,
//!   below π/2) or at least D, so the footprint is out of reach when
//!   `δ > asin((r + R)/D)`.
//!
//! [`World::sight_fan`] does all of that once per query: it lists each obstacle (and
//! the voxel grid, by its box) in the azimuth buckets its interval covers, nearest
//! first with the smallest L at which it matters. A candidate then looks up the one
//! bucket of P − m and runs the exact tests only on the obstacles listed there up to
//! L. The verdict is [`World::any_contact`]'s, bit for bit: the exact tests are the
//! same and an obstacle is left out only when it cannot touch any segment. The
//! grid's box covers most buckets; its lines are tested against its covers' boxes
//! near them, less those the same reasoning about the one sensor puts out of every
//! line's reach (a wall behind the sensor, a floor far below the lines).
//!
//! Floating point: every radius is padded (`FanPad`) far beyond the rounding of
//! the points and of the exact tests (a grazing contact is reported within about
//! 2e-8 of the distance to the obstacle's centre), each interval is widened by one
//! bucket on each side (the azimuth of P − m, and the footprint's edges, are computed
//! without trigonometry, to within a few ulps), and sensors within `CLOSE` of m (whose azimuth rounding
//! could make it wrong) use the list of obstacles within reach of that disc instead.
//! Sensors farther than the fan's range fall back to [`World::any_contact`].

use super::sight_path::SightPath;
use super::{Leaf, NearBricks, Segment, World};
use crate::math::{Point3, Vector3};
use std::f64::consts::PI;

/// Sight lines made at once, on the stack ([`World::any_sight_line_contact`]).
const SIGHT_BATCH: usize = 16;

/// Azimuth buckets around the marker.
const BUCKETS: usize = 128;

/// Sensors at most this far from the marker (in xy) use the list of obstacles near
/// the marker, not a bucket: there the azimuth of P − m is not well defined.
const CLOSE: f64 = 0.01;

/// How much every footprint's radius grows, m: an absolute part and a part per metre
/// of distance involved (the exact tests' rounding grows with the distances).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct FanPad {
    absolute: f64,
    relative: f64,
    /// Whether intervals are widened by a bucket on each side.
    widen: bool,
}

impl FanPad {
    /// The pad the queries use.
    pub(crate) const SAFE: FanPad = FanPad { absolute: 1e-6, relative: 1e-7, widen: true };
}

impl Default for FanPad {
    fn default() -> Self {
        FanPad::SAFE
    }
}

/// An obstacle in a bucket: its leaf, and the distance of the sensor from the marker
/// (xy) from which it may block a sight line.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Entry {
    from: f64,
    leaf: u32,
}

/// The obstacles that can block a query's sight lines, by azimuth from the marker
/// ([`World::sight_fan`]). Built once per query; a candidate's lookup allocates
/// nothing.
#[derive(Debug, Clone, Default)]
pub struct SightFan {
    /// The marker.
    x: f64,
    y: f64,
    z: f64,
    /// Every target lies within this of the marker, in xy, at its height.
    radius: f64,
    /// Sensors farther than this from the marker (xy) fall back to the BVH.
    range: f64,
    /// `entries[starts[b]..starts[b + 1]]` is bucket b, nearest first.
    starts: Vec<u32>,
    entries: Vec<Entry>,
    /// The obstacles within reach of a sensor within `CLOSE` of the marker.
    close: Vec<Entry>,
    /// The voxel grid's bricks near every sight line the fan serves.
    bricks: NearBricks,
    /// How much the footprints, and the reasoning about one sensor's lines against
    /// the grid's covers, are padded ([`FanPad::SAFE`] but in tests; against a
    /// solid it is always [`FanPad::SAFE`], a constant the candidate loop folds).
    pad: FanPad,
}

/// Where an azimuth falls in [0, 4): a pseudo-angle (the "diamond angle"), monotone
/// in the azimuth over [0, 2π), without trigonometry.
#[inline]
fn diamond(dx: f64, dy: f64) -> f64 {
    if dy >= 0.0 {
        if dx >= 0.0 { dy / (dx + dy) } else { 1.0 - dx / (dy - dx) }
    } else if dx < 0.0 {
        2.0 + dy / (dx + dy)
    } else {
        3.0 + dx / (dx - dy)
    }
}

/// The bucket of the direction (dx, dy), not both zero.
#[inline]
fn bucket(dx: f64, dy: f64) -> usize {
    // The quotients are in [0, 1]; NaN (never for a nonzero vector) maps to 0.
    ((diamond(dx, dy) * (BUCKETS as f64 / 4.0)) as usize).min(BUCKETS - 1)
}

impl SightFan {
    /// Whether any obstacle may block a sight line from `sensor`: `false` only when
    /// [`World::any_sight_contact`] is sure to be `false` (nothing listed up to the
    /// sensor's distance), so the caller need not even make the segments.
    #[inline]
    pub fn may_block(&self, sensor: &Point3<f64>) -> bool {
        self.list(sensor).is_none_or(|(entries, l)| entries.first().is_some_and(|e| e.from <= l || e.from.is_nan()))
    }

    /// The entries for `sensor`, nearest first, with its distance from the marker
    /// in the plane; `None` when the fan cannot answer (beyond its range, a NaN, no
    /// buckets) and the BVH must.
    #[inline]
    fn list(&self, sensor: &Point3<f64>) -> Option<(&[Entry], f64)> {
        let (dx, dy) = (sensor.x - self.x, sensor.y - self.y);
        let l = (dx * dx + dy * dy).sqrt();
        if l.is_nan() || l > self.range || self.starts.is_empty() {
            return None;
        }
        let entries = if l <= CLOSE {
            &self.close[..]
        } else {
            let b = bucket(dx, dy);
            &self.entries[self.starts[b] as usize..self.starts[b + 1] as usize]
        };
        Some((entries, l))
    }
}

impl World {
    /// The sight fan of a query whose sight lines all end at targets within `radius`
    /// (xy) of `marker`, for sensors up to `range` (xy) from it (see [`SightFan`]).
    pub fn sight_fan(&self, marker: &Point3<f64>, radius: f64, range: f64) -> SightFan {
        self.sight_fan_padded(marker, radius, range, FanPad::SAFE)
    }

    pub(crate) fn sight_fan_padded(&self, marker: &Point3<f64>, radius: f64, range: f64, pad: FanPad) -> SightFan {
        let (mx, my) = (marker.x, marker.y);
        let mut listed: Vec<(Entry, std::ops::Range<usize>)> = Vec::with_capacity(self.leaves.len());
        let (sin_widen, cos_widen) = if pad.widen { (2.0 * PI / BUCKETS as f64).sin_cos() } else { (0.0, 1.0) };
        for (i, leaf) in self.leaves.iter().enumerate() {
            // The footprint: a disc around (cx, cy) of radius r.
            let (cx, cy, r) = match leaf {
                Leaf::Solid { shape: super::Obstacle::Cylinder(c), .. } => (c.center.x, c.center.y, c.radius),
                Leaf::Solid { .. } | Leaf::Voxels => {
                    let b = &self.boxes[i];
                    let (hx, hy) = (0.5 * (b.maxs.x - b.mins.x), 0.5 * (b.maxs.y - b.mins.y));
                    (b.mins.x + hx, b.mins.y + hy, hx.hypot(hy))
                }
            };
            let d = (cx - mx).hypot(cy - my);
            let reach = r + radius;
            let reach = reach + pad.absolute + pad.relative * (d + range + reach);
            let from = d - reach;
            // Out of reach of every sensor the fan serves (a NaN is kept, and then
            // listed everywhere below).
            if from > range {
                continue;
            }
            let entry = Entry { from, leaf: i as u32 };
            // A NaN is listed everywhere.
            if d <= reach || d.is_nan() {
                listed.push((entry, 0..BUCKETS));
                continue;
            }
            // The footprint's edges seen from the marker: the centre's direction turned
            // by ±(half + a bucket), sin(half) = reach / d, as vectors scaled by d (no
            // angle is formed; the bucket of widening covers their rounding).
            let along = (d * d - reach * reach).sqrt();
            let (c, s) = (along * cos_widen - reach * sin_widen, reach * cos_widen + along * sin_widen);
            let (ux, uy) = (cx - mx, cy - my);
            let first = bucket(ux * c + uy * s, uy * c - ux * s);
            let last = bucket(ux * c - uy * s, uy * c + ux * s);
            let count = (last + BUCKETS - first) % BUCKETS + 1;
            listed.push((entry, first..first + count));
        }
        // The buckets laid out in one array: the entries sorted once, nearest first
        // (the order is total: no two share a leaf), then counted and placed in that
        // order, so that every bucket is sorted.
        let nearest_first = |a: &Entry, b: &Entry| a.from.total_cmp(&b.from).then(a.leaf.cmp(&b.leaf));
        listed.sort_unstable_by(|a, b| nearest_first(&a.0, &b.0));
        let mut starts = vec![0u32; BUCKETS + 1];
        let mut close = Vec::new();
        for (entry, buckets) in &listed {
            for b in buckets.clone() {
                starts[b % BUCKETS + 1] += 1;
            }
            if entry.from <= CLOSE || entry.from.is_nan() {
                close.push(*entry);
            }
        }
        for b in 0..BUCKETS {
            starts[b + 1] += starts[b];
        }
        let mut next: Vec<u32> = starts[..BUCKETS].to_vec();
        let mut entries = vec![Entry { from: 0.0, leaf: 0 }; starts[BUCKETS] as usize];
        for (entry, buckets) in &listed {
            for b in buckets.clone() {
                let at = &mut next[b % BUCKETS];
                entries[*at as usize] = *entry;
                *at += 1;
            }
        }
        // Every sight line the fan serves lies within range + radius of the marker in
        // xy, padded as the footprints are; at any height within the grid.
        let bricks = match self.voxels.as_ref().and_then(|v| v.aabb().map(|b| (v, b))) {
            Some((v, (lo, hi))) => {
                let reach = range + radius;
                let reach = reach + pad.absolute.abs() + pad.relative.abs() * reach + 1e-6 * reach;
                v.near_bricks(&Point3::new(mx - reach, my - reach, lo.z), &Point3::new(mx + reach, my + reach, hi.z))
            }
            None => NearBricks::default(),
        };
        SightFan { x: mx, y: my, z: marker.z, radius, range, starts, entries, close, bricks, pad }
    }

    /// Whether any of `segments`, the sight lines from `sensor` to targets within the
    /// fan's radius of its marker at the marker's height, touches anything:
    /// [`World::any_contact`]'s verdict, bit for bit, by the exact tests of the
    /// obstacles the fan lists for `sensor`, but for those the sensor's own
    /// distances or the grid's bricks rule out ([`World::sight_rules_out`]). `[lo, hi]`
    /// holds every segment (for the voxel grid's broad phase).
    pub fn any_sight_contact(
        &self,
        fan: &SightFan,
        sensor: &Point3<f64>,
        segments: &[Segment],
        lo: &Point3<f64>,
        hi: &Point3<f64>,
    ) -> bool {
        let Some((entries, l)) = fan.list(sensor) else {
            return self.any_contact(segments);
        };
        for e in entries {
            if e.from > l {
                break;
            }
            if self.sight_rules_out(fan, sensor, e.leaf, lo, hi) {
                continue;
            }
            if self.sight_leaf_touches(fan, sensor, e.leaf, segments, lo, hi) {
                return true;
            }
        }
        false
    }
}

impl World {
    /// [`World::any_sight_contact`] of the sight lines from `sensor` to each of
    /// `targets` ([`Segment::sight_line`] with `margin`), with one lookup of the
    /// fan, the lines made only once an obstacle listed for `sensor` is neither
    /// ruled out by its distances (most sensors: none is) nor decided by the lines'
    /// paths (a solid). The same exact tests on the same segments, where they
    /// run, so the same verdict. `[lo, hi]` holds every line.
    #[inline]
    pub fn any_sight_line_contact(
        &self,
        fan: &SightFan,
        sensor: &Point3<f64>,
        targets: &[Point3<f64>],
        margin: f64,
        lo: &Point3<f64>,
        hi: &Point3<f64>,
    ) -> bool {
        let Some((entries, l)) = fan.list(sensor).filter(|_| targets.len() <= SIGHT_BATCH) else {
            return self.sight_lines_by_chunks(fan, sensor, targets, margin, lo, hi);
        };
        // The lines are made (out of line) only from the first obstacle that is
        // not ruled out or decided without them.
        for (i, e) in entries.iter().enumerate() {
            if e.from > l {
                break;
            }
            if self.sight_rules_out(fan, sensor, e.leaf, lo, hi) {
                continue;
            }
            match self.sight_decided(e.leaf, sensor, targets, margin, lo, hi) {
                Some(true) => return true,
                Some(false) => {}
                None => return self.sight_lines_touch(fan, sensor, targets, margin, &entries[i..], l, lo, hi),
            }
        }
        false
    }

    /// The verdict on `leaf` of the sight lines from `sensor` to `targets`, when
    /// the lines' paths decide it without making them (a cylinder, a box: see
    /// `sight_path`); `None` when the exact test must.
    #[inline(always)]
    fn sight_decided(
        &self,
        leaf: u32,
        sensor: &Point3<f64>,
        targets: &[Point3<f64>],
        margin: f64,
        lo: &Point3<f64>,
        hi: &Point3<f64>,
    ) -> Option<bool> {
        match self.leaves[leaf as usize] {
            Leaf::Solid { shape: super::Obstacle::Cylinder(c), .. } => {
                c.touches_sight_lines(sensor, targets, margin, lo, hi)
            }
            Leaf::Solid { shape: super::Obstacle::Box(b), .. } => {
                b.touches_sight_lines(sensor, targets, margin, lo, hi)
            }
            Leaf::Voxels => None,
        }
    }

    /// Whether the fan's distances, or the grid's bricks, rule out that `leaf`
    /// touches a sight line from `sensor`.
    #[inline(always)]
    fn sight_rules_out(
        &self,
        fan: &SightFan,
        sensor: &Point3<f64>,
        leaf: u32,
        lo: &Point3<f64>,
        hi: &Point3<f64>,
    ) -> bool {
        match self.leaves[leaf as usize] {
            Leaf::Voxels => !self.voxel_bricks_may_touch(&fan.bricks, lo, hi),
            Leaf::Solid { shape: super::Obstacle::Cylinder(c), .. } => fan.misses_cylinder(sensor, &c),
            Leaf::Solid { shape: super::Obstacle::Box(b), .. } => fan.misses_box(sensor, &b),
        }
    }

    /// Whether any of `segments`, sight lines from `sensor`, touches `leaf`: for
    /// the grid, its covers' boxes the fan's reasoning puts out of every line's
    /// reach ([`SightFan::misses_box`]) left out before the lines are tested
    /// against the rest. The exact tests' verdict.
    #[inline]
    fn sight_leaf_touches(
        &self,
        fan: &SightFan,
        sensor: &Point3<f64>,
        leaf: u32,
        segments: &[Segment],
        lo: &Point3<f64>,
        hi: &Point3<f64>,
    ) -> bool {
        match (&self.leaves[leaf as usize], &self.voxels) {
            (Leaf::Voxels, Some(v)) => v.any_contact_near_kept(segments, &fan.bricks, lo, hi, |l, h| {
                !fan.misses_box_padded(
                    sensor,
                    &super::AxisBox { min: Point3::from(*l), max: Point3::from(*h) },
                    fan.pad,
                )
            }),
            _ => self.leaf_touches_near(leaf, segments, &fan.bricks, lo, hi),
        }
    }

    /// The sight lines made, tested against `entries` up to the sensor's distance
    /// `l` (the first is within it, not ruled out and not decided without them).
    #[allow(clippy::too_many_arguments)]
    #[inline(never)]
    fn sight_lines_touch(
        &self,
        fan: &SightFan,
        sensor: &Point3<f64>,
        targets: &[Point3<f64>],
        margin: f64,
        entries: &[Entry],
        l: f64,
        lo: &Point3<f64>,
        hi: &Point3<f64>,
    ) -> bool {
        let mut batch = [Segment::closed(Point3::origin(), Vector3::x(), 0.0); SIGHT_BATCH];
        let n = sight_lines(sensor, targets, margin, &mut batch);
        let Some((first, rest)) = entries.split_first() else {
            return false;
        };
        if self.sight_leaf_touches(fan, sensor, first.leaf, &batch[..n], lo, hi) {
            return true;
        }
        for e in rest {
            if e.from > l {
                break;
            }
            if self.sight_rules_out(fan, sensor, e.leaf, lo, hi) {
                continue;
            }
            let touches = match self.sight_decided(e.leaf, sensor, targets, margin, lo, hi) {
                Some(decided) => decided,
                None => self.sight_leaf_touches(fan, sensor, e.leaf, &batch[..n], lo, hi),
            };
            if touches {
                return true;
            }
        }
        false
    }

    /// [`World::any_sight_line_contact`] where the fan cannot answer, or the
    /// targets are more than a batch: a batch at a time.
    #[cold]
    #[inline(never)]
    fn sight_lines_by_chunks(
        &self,
        fan: &SightFan,
        sensor: &Point3<f64>,
        targets: &[Point3<f64>],
        margin: f64,
        lo: &Point3<f64>,
        hi: &Point3<f64>,
    ) -> bool {
        let mut batch = [Segment::closed(Point3::origin(), Vector3::x(), 0.0); SIGHT_BATCH];
        targets.chunks(SIGHT_BATCH).any(|chunk| {
            let n = sight_lines(sensor, chunk, margin, &mut batch);
            self.any_sight_contact(fan, sensor, &batch[..n], lo, hi)
        })
    }
}

/// The sight lines from `sensor` to each of `targets` (at most a batch) written
/// into `batch`; how many (a target at the sensor has none).
#[inline]
fn sight_lines(
    sensor: &Point3<f64>,
    targets: &[Point3<f64>],
    margin: f64,
    batch: &mut [Segment; SIGHT_BATCH],
) -> usize {
    let mut n = 0;
    for q in targets {
        if let Some(s) = Segment::sight_line(sensor, q, margin) {
            batch[n] = s;
            n += 1;
        }
    }
    n
}

impl SightFan {
    /// Whether no sight line from `sensor` can touch `cylinder`, by the fan's
    /// reasoning for this one sensor: every sight line lies within the radius of
    /// the segment marker–sensor in xy, and between their heights in z. Padded as
    /// the fan's footprints ([`FanPad::SAFE`]), so `true` only where the exact test
    /// is sure to find no contact.
    #[inline]
    fn misses_cylinder(&self, sensor: &Point3<f64>, cylinder: &super::VerticalCylinder) -> bool {
        self.misses_cylinder_padded(sensor, cylinder, FanPad::SAFE)
    }

    #[inline(always)]
    fn misses_cylinder_padded(&self, sensor: &Point3<f64>, cylinder: &super::VerticalCylinder, pad: FanPad) -> bool {
        let (vx, vy) = (sensor.x - self.x, sensor.y - self.y);
        let (wx, wy) = (cylinder.center.x - self.x, cylinder.center.y - self.y);
        let size = vx.abs() + vy.abs() + wx.abs() + wy.abs() + cylinder.radius + self.radius;
        let m = pad.absolute + pad.relative * size;
        if sensor.z.min(self.z) > cylinder.height + m || sensor.z.max(self.z) < -m {
            return true;
        }
        let vv = vx * vx + vy * vy;
        let along = if vv > 0.0 { (wx * vx + wy * vy) / vv } else { 0.0 };
        let t = along.clamp(0.0, 1.0);
        let (ex, ey) = (wx - t * vx, wy - t * vy);
        let reach = cylinder.radius + self.radius + m;
        if ex * ex + ey * ey > reach * reach {
            return true;
        }
        // The sight line to q is q + t·(sensor − q), within (1 − t)·radius of
        // marker + t·(sensor − marker) in xy: it can meet the disc only for t within
        // reach/|sensor − marker| of `along`, where, from a sensor above the marker,
        // its height is at least marker_z + t·(sensor_z − marker_z).
        if vv > 0.0 && sensor.z >= self.z {
            let t_lo = (along - reach / vv.sqrt()).max(0.0);
            return self.z + t_lo * (sensor.z - self.z) > cylinder.height + m;
        }
        false
    }

    /// Whether no sight line from `sensor` can touch `b`, by the same reasoning as
    /// [`SightFan::misses_cylinder`]: the sight line to q is `q + t·(sensor − q)`,
    /// at height `marker_z + t·(sensor_z − marker_z)` and within `(1 − t)·radius` of
    /// `marker + t·(sensor − marker)` in xy. The box's heights bound t; over those t
    /// the sight lines stay within a capsule in xy, which an axis (x, y, along or
    /// across the segment marker–sensor) separates from the box's rectangle. Padded
    /// as the fan's footprints, so `true` only where the exact test is sure to find
    /// no contact.
    #[inline]
    fn misses_box(&self, sensor: &Point3<f64>, b: &super::AxisBox) -> bool {
        self.misses_box_padded(sensor, b, FanPad::SAFE)
    }

    #[inline(always)]
    fn misses_box_padded(&self, sensor: &Point3<f64>, b: &super::AxisBox, pad: FanPad) -> bool {
        // Everything relative to the marker. Each test is written to fail on a NaN.
        let (vx, vy, vz) = (sensor.x - self.x, sensor.y - self.y, sensor.z - self.z);
        let (lx, ly, lz) = (b.min.x - self.x, b.min.y - self.y, b.min.z - self.z);
        let (hx, hy, hz) = (b.max.x - self.x, b.max.y - self.y, b.max.z - self.z);
        let size = vx.abs() + vy.abs() + vz.abs() + lx.abs() + ly.abs() + lz.abs() + hx.abs() + hy.abs() + hz.abs();
        let m = pad.absolute + pad.relative * (size + self.radius);
        // The t at which the sight lines are within the box's heights.
        let (mut t0, mut t1) = (0.0f64, 1.0f64);
        if vz == 0.0 {
            if lz - m > 0.0 || hz + m < 0.0 {
                return true;
            }
        } else {
            let (a, c) = ((lz - m) / vz, (hz + m) / vz);
            t0 = t0.max(a.min(c));
            t1 = t1.min(a.max(c));
            if t0 > t1 {
                return true;
            }
        }
        // Over them, the sight lines stay within `reach` of the segment t0·v–t1·v.
        let reach = (1.0 - t0) * self.radius + m;
        let (ax, ay, bx, by) = (t0 * vx, t0 * vy, t1 * vx, t1 * vy);
        if ax.max(bx) + reach < lx || ax.min(bx) - reach > hx || ay.max(by) + reach < ly || ay.min(by) - reach > hy {
            return true;
        }
        // Along and across v, with v unnormalized: lengths scale by |v|.
        let (cx, cy, ex, ey) = (0.5 * (lx + hx), 0.5 * (ly + hy), 0.5 * (hx - lx), 0.5 * (hy - ly));
        let vv = vx * vx + vy * vy;
        let r = reach * vv.sqrt();
        let across = (cx * vy - cy * vx).abs() - (ex * vy.abs() + ey * vx.abs());
        let along = cx * vx + cy * vy;
        let half = ex * vx.abs() + ey * vy.abs();
        across > r || along + half < t0 * vv - r || along - half > t1 * vv + r
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::{Point2, Vector3};
    use crate::world::tests::Lcg;
    use crate::world::{AxisBox, Bounds, Obstacle, Sun, VerticalCylinder, VoxelGrid};
    use std::f64::consts::TAU;

    #[test]
    fn the_pseudo_angle_is_monotone_and_buckets_cover_the_circle() {
        let mut previous = -1.0;
        for k in 0..100_000 {
            let a = TAU * f64::from(k) / 100_000.0;
            let p = diamond(a.cos(), a.sin());
            assert!((0.0..4.0).contains(&p) && p >= previous, "{a}: {p} after {previous}");
            previous = p;
        }
        assert_eq!(bucket(1.0, 0.0), 0);
        assert_eq!(bucket(1.0, -1e-300), BUCKETS - 1);
        assert_eq!(bucket(-1.0, 0.0), BUCKETS / 2);
    }

    #[test]
    fn every_bucket_and_the_close_list_are_nearest_first() {
        let mut rng = Lcg(23);
        for n in [1, 25, 75, 200] {
            let marker = Point2::new(rng.next() * 4.0 - 2.0, rng.next() * 4.0 - 2.0);
            let world = world_around(&mut rng, marker, 0.5, 0.3, n, true);
            let fan = world.sight_fan(&Point3::new(marker.x, marker.y, 0.3), 0.5, 6.0);
            let sorted = |list: &[Entry]| list.windows(2).all(|w| (w[0].from, w[0].leaf) < (w[1].from, w[1].leaf));
            assert!(sorted(&fan.close), "n = {n}: {:?}", fan.close);
            for b in 0..BUCKETS {
                let bucket = &fan.entries[fan.starts[b] as usize..fan.starts[b + 1] as usize];
                assert!(sorted(bucket), "n = {n}, bucket {b}: {bucket:?}");
            }
            assert!(fan.entries.len() > n, "n = {n}: {} entries", fan.entries.len());
        }
    }

    /// A map of cylinders and boxes around the marker, some with footprints just
    /// out of reach of the rover's disc or just over it, at the azimuth of a
    /// perimeter point (`theta` + k·45°), some anywhere, and voxels.
    fn world_around(rng: &mut Lcg, marker: Point2<f64>, radius: f64, theta: f64, n: usize, voxels: bool) -> World {
        let obstacles: Vec<(u32, Obstacle)> = (0..n)
            .map(|i| {
                let a = if i % 4 == 0 { theta + TAU * (i / 4 % 8) as f64 / 8.0 } else { rng.next() * TAU };
                let u = Vector3::new(a.cos(), a.sin(), 0.0);
                let o = if i % 4 == 3 {
                    let d = rng.next() * 8.0;
                    let min = Point3::new(marker.x + d * u.x, marker.y + d * u.y, rng.next() * 1.5);
                    Obstacle::Box(AxisBox { min, max: min + Vector3::new(0.1, 0.1, 0.1) + Vector3::repeat(rng.next()) })
                } else {
                    let r = 0.1 + rng.next() * 0.8;
                    // Grazing the rover's disc (within 1e-5, in or out) or anywhere.
                    let d = if i % 4 == 0 { radius + r + (rng.next() - 0.5) * 2e-5 } else { 1.0 + rng.next() * 8.0 };
                    Obstacle::Cylinder(VerticalCylinder {
                        center: Point2::new(marker.x + d * u.x, marker.y + d * u.y),
                        radius: r,
                        height: 0.2 + rng.next() * 4.0,
                    })
                };
                (i as u32 + 1, o)
            })
            .collect();
        let grid = voxels.then(|| {
            let cells: Vec<_> = (0..80)
                .map(|_| [(rng.next() * 80.0) as i64, (rng.next() * 80.0) as i64, (rng.next() * 10.0) as i64])
                .collect();
            VoxelGrid::new(0.2, Point3::new(marker.x - 8.0, marker.y - 8.0, 0.0), cells).unwrap()
        });
        World::new(
            0,
            Bounds::new([marker.x - 20.0, marker.y - 20.0, marker.x + 20.0, marker.y + 20.0]).unwrap(),
            Sun::new(0.5, 0.0).unwrap(),
            obstacles,
            grid,
        )
        .unwrap()
    }

    /// The sight lines of a sensor to the marker and its perimeter, as the pipeline
    /// makes them.
    fn sight_lines(sensor: &Point3<f64>, marker: &Point3<f64>, radius: f64, theta: f64) -> Vec<Segment> {
        targets(marker, radius, theta).iter().filter_map(|q| Segment::sight_line(sensor, q, 1e-6)).collect()
    }

    /// The marker and its 8 perimeter points.
    fn targets(marker: &Point3<f64>, radius: f64, theta: f64) -> Vec<Point3<f64>> {
        let mut targets = vec![*marker];
        targets.extend((0..8).map(|k| {
            let a = theta + TAU * f64::from(k) / 8.0;
            Point3::new(marker.x + radius * a.cos(), marker.y + radius * a.sin(), marker.z)
        }));
        targets
    }

    /// The fan's verdict on the sight lines from `sensor` to `targets` (the same
    /// from both its entry points), and the scan's (the same as the BVH's).
    fn verdicts(world: &World, fan: &SightFan, sensor: &Point3<f64>, targets: &[Point3<f64>]) -> (bool, bool) {
        let segments: Vec<Segment> = targets.iter().filter_map(|q| Segment::sight_line(sensor, q, 1e-6)).collect();
        let lo = segments.iter().fold(*sensor, |lo, s| lo.inf(&s.point_at(s.length)));
        let hi = segments.iter().fold(*sensor, |hi, s| hi.sup(&s.point_at(s.length)));
        let want = world.any_contact_by_scan(&segments);
        assert_eq!(world.any_contact(&segments), want);
        let got = world.any_sight_contact(fan, sensor, &segments, &lo, &hi);
        assert_eq!(world.any_sight_line_contact(fan, sensor, targets, 1e-6, &lo, &hi), got);
        (got, want)
    }

    /// Counts the candidates whose fan verdict differs from the scan's, over random
    /// sensors: anywhere within range, grazing the listed obstacles, directly above
    /// the marker, within a hair of it, and beyond the range.
    fn disagreements(pad: FanPad) -> (usize, usize, usize) {
        let mut rng = Lcg(41);
        let (mut wrong, mut hits, mut misses) = (0, 0, 0);
        for (case, (n, voxels)) in
            [(0, false), (1, false), (4, false), (8, false), (12, false), (30, false), (20, true)]
                .into_iter()
                .enumerate()
        {
            let marker = Point3::new(rng.next() * 100.0 - 50.0, rng.next() * 100.0 - 50.0, 0.3);
            let radius = 0.4 + rng.next() * 0.6;
            let range = 6.0;
            let theta = rng.next() * TAU;
            let world = world_around(&mut rng, marker.xy(), radius, theta, n, voxels);
            let fan = world.sight_fan_padded(&marker, radius, range, pad);
            for k in 0..4000 {
                let sensor = match k % 8 {
                    // Directly above the marker, or within a hair of that.
                    0 => marker + Vector3::new(0.0, 0.0, 0.5 + rng.next() * 5.0),
                    1 => marker + Vector3::new((rng.next() - 0.5) * 0.02, (rng.next() - 0.5) * 0.02, 1.0 + rng.next()),
                    // Beyond the fan's range.
                    2 => marker + Vector3::new(range + rng.next(), rng.next() - 0.5, 1.0),
                    _ => {
                        let a = rng.next() * TAU;
                        let l = rng.next() * range;
                        marker + Vector3::new(l * a.cos(), l * a.sin(), rng.next() * 5.0 - 0.3)
                    }
                };
                let (got, want) = verdicts(&world, &fan, &sensor, &targets(&marker, radius, theta));
                assert!(fan.may_block(&sensor) || !got);
                if got != want {
                    wrong += 1;
                    assert!(pad != FanPad::SAFE, "case {case}, sensor {sensor:?}, theta {theta}: {got} != {want}");
                }
                if want { hits += 1 } else { misses += 1 }
            }
        }
        (wrong, hits, misses)
    }

    /// The fan's verdicts are the scan's on every candidate, blocked and clear.
    #[test]
    fn the_fan_agrees_with_the_scan() {
        let (wrong, hits, misses) = disagreements(FanPad::SAFE);
        assert_eq!(wrong, 0);
        assert!(hits > 3000 && misses > 3000, "{hits} hits, {misses} misses: the test tests little");
    }

    /// The test above can fail: footprints made 1e-5 m too small leave out
    /// obstacles that block.
    #[test]
    fn a_fan_too_tight_disagrees_with_the_scan() {
        let (wrong, _, _) = disagreements(FanPad { absolute: -1e-5, relative: 0.0, widen: false });
        assert!(wrong > 0, "the cases never graze the filter's edge");
    }

    /// Voxels around the marker at 0.1 m: columns, short walls and tables
    /// standing on the targets' plane, each its own box in its node's cover.
    fn voxel_building(marker: &Point3<f64>) -> World {
        let mut cells = Vec::new();
        for i in -80i64..80 {
            for j in -80i64..80 {
                for k in 0..12 {
                    let wall = i.rem_euclid(53) == 0 && (j.rem_euclid(40) - 20).abs() > 12 && k < 6;
                    let column = (i.rem_euclid(17) < 3 && j.rem_euclid(19) < 3) && k < 9;
                    let table = (5..14).contains(&i.rem_euclid(40)) && (25..31).contains(&j.rem_euclid(40)) && k == 4;
                    if wall || column || table {
                        cells.push([i, j, k]);
                    }
                }
            }
        }
        let origin = Point3::new(marker.x - 3.05, marker.y - 2.95, marker.z - 0.4);
        let grid = VoxelGrid::new(0.1, origin, cells).unwrap();
        let bounds = Bounds::new([marker.x - 20.0, marker.y - 20.0, marker.x + 20.0, marker.y + 20.0]).unwrap();
        World::new(0, bounds, Sun::new(0.5, 0.0).unwrap(), Vec::new(), Some(grid)).unwrap()
    }

    /// Over sensors anywhere in range of a marker in a voxel building (the fan
    /// reasoning about one sensor's lines against the covers' boxes, `pad` as
    /// given): the sensors whose verdict differs from the scan's, the blocked ones
    /// and the clear ones.
    fn voxel_disagreements(pad: FanPad) -> (usize, usize, usize) {
        let mut rng = Lcg(59);
        let (mut wrong, mut hits, mut misses) = (0, 0, 0);
        for _ in 0..6 {
            let marker = Point3::new(rng.next() * 100.0 - 50.0, rng.next() * 100.0 - 50.0, 0.3);
            let (radius, range, theta) = (0.5, 6.0, rng.next() * TAU);
            let world = voxel_building(&marker);
            let fan = world.sight_fan_padded(&marker, radius, range, pad);
            for _ in 0..2000 {
                let (a, l) = (rng.next() * TAU, rng.next() * range);
                let sensor = marker + Vector3::new(l * a.cos(), l * a.sin(), 0.5 + rng.next() * 4.0);
                let (got, want) = verdicts(&world, &fan, &sensor, &targets(&marker, radius, theta));
                wrong += usize::from(got != want);
                if want { hits += 1 } else { misses += 1 }
            }
        }
        (wrong, hits, misses)
    }

    /// On a voxel map the fan's verdicts are the scan's, blocked and clear.
    #[test]
    fn the_fan_agrees_with_the_scan_on_voxels() {
        let (wrong, hits, misses) = voxel_disagreements(FanPad::SAFE);
        assert_eq!(wrong, 0);
        assert!(hits > 2000 && misses > 2000, "{hits} hits, {misses} misses: the test tests little");
    }

    /// The test above can fail: reasoning 10 cm too tight about one sensor's lines
    /// leaves out covers' boxes the lines touch.
    #[test]
    fn a_fan_too_tight_on_voxels_disagrees_with_the_scan() {
        let (wrong, _, _) = voxel_disagreements(FanPad { absolute: -0.1, relative: 0.0, widen: true });
        assert!(wrong > 0, "no sight line touches a cell within 10 cm of its cover's edge");
    }

    /// Counts the sensors for which [`SightFan::misses_cylinder_padded`] says a
    /// cylinder is out of reach while a sight line touches it, over cylinders
    /// grazing the rover's disc and sensors anywhere in range; and the misses given.
    fn cylinder_disagreements(pad: FanPad) -> (usize, usize) {
        let mut rng = Lcg(77);
        let (mut wrong, mut missed) = (0, 0);
        for _ in 0..40 {
            let marker = Point3::new(rng.next() * 100.0 - 50.0, rng.next() * 100.0 - 50.0, 0.2 + rng.next());
            let radius = 0.4 + rng.next() * 0.6;
            let theta = rng.next() * TAU;
            let world = world_around(&mut rng, marker.xy(), radius, theta, 12, false);
            let fan = world.sight_fan(&marker, radius, 6.0);
            for _ in 0..500 {
                let (a, l) = (rng.next() * TAU, rng.next() * 6.0);
                let sensor = marker + Vector3::new(l * a.cos(), l * a.sin(), rng.next() * 5.0 - 0.5);
                let segments = sight_lines(&sensor, &marker, radius, theta);
                for o in world.obstacles().values() {
                    let Obstacle::Cylinder(c) = o else { continue };
                    if fan.misses_cylinder_padded(&sensor, c, pad) {
                        missed += 1;
                        if segments.iter().any(|s| c.first_contact(s).is_some_and(|t| s.reaches(t))) {
                            wrong += 1;
                        }
                    }
                }
            }
        }
        (wrong, missed)
    }

    /// A cylinder the sensor's distances put out of reach is never touched.
    #[test]
    fn a_cylinder_out_of_reach_is_missed_by_every_sight_line() {
        let (wrong, missed) = cylinder_disagreements(FanPad::SAFE);
        assert_eq!(wrong, 0);
        assert!(missed > 10_000, "{missed} misses: the test tests little");
    }

    /// The test above can fail: with the pad made 1e-5 m too small, cylinders
    /// grazing the rover's disc are said out of reach where a sight line touches them.
    #[test]
    fn a_cylinder_test_too_tight_disagrees_with_the_exact_test() {
        let (wrong, _) = cylinder_disagreements(FanPad { absolute: -1e-5, relative: 0.0, widen: false });
        assert!(wrong > 0, "the cases never graze the bound");
    }

    /// Counts the sensors for which [`SightFan::misses_box_padded`] says a box is
    /// out of reach while a sight line touches it, and the misses given: boxes
    /// anywhere around the marker, and boxes whose side grazes the sight line to
    /// the marker (a rover of radius 0, where the bound is tight) just beside or
    /// just across it.
    fn box_disagreements(pad: FanPad) -> (usize, usize) {
        let mut rng = Lcg(91);
        let (mut wrong, mut missed) = (0, 0);
        let mut check = |fan: &SightFan, sensor: &Point3<f64>, b: &AxisBox, segments: &[Segment]| {
            if fan.misses_box_padded(sensor, b, pad) {
                missed += 1;
                if segments.iter().any(|s| Obstacle::Box(*b).first_contact(s).is_some_and(|t| s.reaches(t))) {
                    wrong += 1;
                }
            }
        };
        for _ in 0..40 {
            let marker = Point3::new(rng.next() * 100.0 - 50.0, rng.next() * 100.0 - 50.0, 0.2 + rng.next());
            let radius = 0.4 + rng.next() * 0.6;
            let theta = rng.next() * TAU;
            let world = world_around(&mut rng, marker.xy(), radius, theta, 24, false);
            let fan = world.sight_fan(&marker, radius, 6.0);
            for _ in 0..500 {
                let (a, l) = (rng.next() * TAU, rng.next() * 6.0);
                let sensor = marker + Vector3::new(l * a.cos(), l * a.sin(), rng.next() * 5.0 - 0.5);
                let segments = sight_lines(&sensor, &marker, radius, theta);
                for o in world.obstacles().values() {
                    if let Obstacle::Box(b) = o {
                        check(&fan, &sensor, b, &segments);
                    }
                }
            }
        }
        for _ in 0..20_000 {
            let marker = Point3::new(rng.next() * 100.0 - 50.0, rng.next() * 100.0 - 50.0, 0.2 + rng.next());
            let fan = World::empty(Bounds::new([-60.0, -60.0, 60.0, 60.0]).unwrap(), Sun::new(0.5, 0.0).unwrap())
                .sight_fan(&marker, 0.0, 6.0);
            let (a, l) = (rng.next() * TAU, 0.5 + rng.next() * 5.5);
            let sensor = marker + Vector3::new(l * a.cos(), l * a.sin(), rng.next() * 5.0 - 0.5);
            let Some(segment) = Segment::sight_line(&sensor, &marker, 1e-6) else { continue };
            // A point of the sight line, and a box beyond it along x or y by
            // ±1e-5, over the heights where the line stays on this side of it.
            let v = sensor - marker;
            let x = marker + v * (0.2 + rng.next() * 0.6);
            let (axis, s) = (usize::from(rng.next() < 0.5), 0.1 + rng.next());
            let side = if rng.next() < 0.5 { 1.0 } else { -1.0 };
            let (mut min, mut max) = (x - Vector3::repeat(s), x + Vector3::repeat(s));
            let face = x[axis] + side * (rng.next() - 0.5) * 2e-5;
            if side > 0.0 {
                (min[axis], max[axis]) = (face, face + s);
            } else {
                (min[axis], max[axis]) = (face - s, face);
            }
            if (v[axis] * side > 0.0) == (v.z > 0.0) {
                max.z = x.z;
            } else {
                min.z = x.z;
            }
            check(&fan, &sensor, &AxisBox { min, max }, &[segment]);
        }
        (wrong, missed)
    }

    /// A box the sensor's distances put out of reach is never touched.
    #[test]
    fn a_box_out_of_reach_is_missed_by_every_sight_line() {
        let (wrong, missed) = box_disagreements(FanPad::SAFE);
        assert_eq!(wrong, 0);
        assert!(missed > 10_000, "{missed} misses: the test tests little");
    }

    /// The test above can fail: with the pad made 1e-5 m too small, boxes grazing
    /// a sight line are said out of reach where it touches them.
    #[test]
    fn a_box_test_too_tight_disagrees_with_the_exact_test() {
        let (wrong, _) = box_disagreements(FanPad { absolute: -1e-5, relative: 0.0, widen: false });
        assert!(wrong > 0, "the cases never graze the bound");
    }

    /// A voxel grid whose box holds the marker is listed in every bucket.
    #[test]
    fn a_grid_around_the_marker_is_always_tested() {
        let marker = Point3::new(0.0, 0.0, 0.3);
        let grid = VoxelGrid::new(0.5, Point3::new(-10.0, -10.0, 0.0), [[0, 0, 0], [39, 39, 3]]).unwrap();
        let world = World::new(
            0,
            Bounds::new([-10.0, -10.0, 10.0, 10.0]).unwrap(),
            Sun::new(0.5, 0.0).unwrap(),
            [],
            Some(grid),
        )
        .unwrap();
        let fan = world.sight_fan(&marker, 0.75, 6.0);
        assert!(fan.close.len() == 1 && (0..BUCKETS).all(|b| fan.starts[b + 1] - fan.starts[b] == 1));
    }
}
