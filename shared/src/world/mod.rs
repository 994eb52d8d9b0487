//! The environment model M of SPEC §1: bounds, sun, obstacles, voxels, and the
//! segment queries the constraints need.
//!
//! A [`World`] is immutable. A batch of [`MapDelta`]s makes a new one
//! ([`World::apply`]), or fails whole and leaves the old one as it was: that is what
//! makes map updates atomic for the daemon. Queries go through a bounding-volume
//! hierarchy (parry's `Bvh`) whose leaves are the obstacles, plus one leaf for the
//! voxel grid, each tested exactly; a world of at most [`SCAN_LEAVES`] leaves is
//! scanned leaf by leaf instead, with the same verdicts. A search's per-candidate
//! queries go through two per-query indexes over the same leaves instead, with the
//! same verdicts: the leaves near every collision star ([`Nearby`]) and the sight
//! fan ([`SightFan`]).
//!
//! ```
//! use dyfos_shared::world::{Bounds, MapDelta, Obstacle, Segment, Sun, VerticalCylinder, World};
//! use nalgebra::{Point2, Point3, Vector3};
//!
//! let world = World::empty(Bounds::new([-10.0, -10.0, 10.0, 10.0]).unwrap(), Sun::new(0.7, 2.1).unwrap());
//! let pole = Obstacle::Cylinder(VerticalCylinder { center: Point2::new(2.0, 0.0), radius: 0.5, height: 10.0 });
//! let world = world.apply(&[MapDelta::UpsertObstacle { id: 7, obstacle: pole }]).unwrap();
//! assert_eq!(world.version(), 1);
//! let ray = Segment::closed(Point3::new(0.0, 0.0, 1.0), Vector3::x(), 5.0);
//! assert!(world.any_contact(&[ray]));
//! ```

mod delta;
mod fan;
mod nearby;
mod obstacle;
pub mod octomap;
mod region;
mod segment;
mod sight_path;
mod star;
mod voxels;

pub(crate) use delta::StoredDelta;
pub use delta::{MapDelta, MapDeltaError, MapDeltaErrorKind};
pub use fan::SightFan;
pub use nearby::Nearby;
pub use obstacle::{AxisBox, Obstacle, ObstacleError, VerticalCylinder};
pub use segment::{Segment, SegmentEnd};
pub use star::Star;
pub use voxels::{CellIndex, NearBricks, VoxelBlock, VoxelError, VoxelGrid};

use crate::limits::{MAX_COORDINATE, MAX_OBSTACLES};
use crate::math::{Point2, Point3, Vector3};
use parry3d_f64::bounding_volume::Aabb;
use parry3d_f64::partitioning::{Bvh, BvhBuildStrategy, TraversalAction};
use segment::first_contact_aabb;
use std::collections::BTreeMap;
use std::f64::consts::FRAC_PI_2;
use std::sync::OnceLock;

/// The map's axis-aligned rectangle, `[x_min, y_min, x_max, y_max]` in files.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Bounds {
    /// (x_min, y_min).
    pub min: Point2<f64>,
    /// (x_max, y_max).
    pub max: Point2<f64>,
}

/// Why bounds are invalid.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("bounds {bounds:?}: {problem}")]
pub struct BoundsError {
    /// The rejected bounds.
    pub bounds: [f64; 4],
    /// What is wrong.
    pub problem: &'static str,
}

impl Bounds {
    /// Checks finite numbers within ±1e6 and min < max.
    pub fn new(b: [f64; 4]) -> Result<Self, BoundsError> {
        if !b.iter().all(|v| v.is_finite() && v.abs() <= MAX_COORDINATE) {
            return Err(BoundsError { bounds: b, problem: "every number must be finite and within ±1e6" });
        }
        if !(b[0] < b[2] && b[1] < b[3]) {
            return Err(BoundsError { bounds: b, problem: "need x_min < x_max and y_min < y_max" });
        }
        Ok(Bounds { min: Point2::new(b[0], b[1]), max: Point2::new(b[2], b[3]) })
    }

    /// `[x_min, y_min, x_max, y_max]`.
    pub fn to_array(&self) -> [f64; 4] {
        [self.min.x, self.min.y, self.max.x, self.max.y]
    }

    /// Whether (x, y) is inside, boundary included.
    #[inline]
    pub fn contains(&self, x: f64, y: f64) -> bool {
        self.min.x <= x && x <= self.max.x && self.min.y <= y && y <= self.max.y
    }
}

/// The sun's direction: elevation above the horizon and azimuth from +x towards +y.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Sun {
    /// Elevation, rad, in [−π/2, π/2].
    pub elevation: f64,
    /// Azimuth, rad.
    pub azimuth: f64,
}

/// Why a sun is invalid.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("sun.{field} = {value} {rule}")]
pub struct SunError {
    /// `elevation` or `azimuth`.
    pub field: &'static str,
    /// The rejected value.
    pub value: f64,
    /// What it must satisfy.
    pub rule: &'static str,
}

impl Sun {
    /// Checks elevation ∈ [−π/2, π/2] and a finite azimuth (|az| ≤ 1e6).
    pub fn new(elevation: f64, azimuth: f64) -> Result<Self, SunError> {
        if !(elevation.is_finite() && elevation.abs() <= FRAC_PI_2) {
            return Err(SunError { field: "elevation", value: elevation, rule: "must be in [-π/2, π/2]" });
        }
        if !(azimuth.is_finite() && azimuth.abs() <= MAX_COORDINATE) {
            return Err(SunError { field: "azimuth", value: azimuth, rule: "must be a finite number" });
        }
        Ok(Sun { elevation, azimuth })
    }

    /// The unit vector ŝ from the scene towards the sun (SPEC §1).
    pub fn direction(&self) -> Vector3<f64> {
        let (se, ce) = self.elevation.sin_cos();
        let (sa, ca) = self.azimuth.sin_cos();
        Vector3::new(ce * ca, ce * sa, se)
    }
}

/// What a segment touched, for reports (`dyfos eval`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Blocker {
    /// The obstacle with this id.
    Obstacle(u32),
    /// An occupied voxel cell.
    Voxels,
}

/// One leaf of the query BVH.
#[derive(Debug, Clone, Copy)]
enum Leaf {
    Solid { id: u32, shape: Obstacle },
    Voxels,
}

/// Leaves are padded by this much so that a segment exactly touching an obstacle's
/// face always reaches the exact leaf test.
const LEAF_PAD: f64 = 1e-7;

/// Worlds with at most this many leaves are queried by a scan of the leaves' boxes,
/// without a BVH: over so few boxes a hierarchy prunes little, a search's
/// per-candidate queries go through its own indexes anyway ([`Nearby`],
/// [`SightFan`]), and building the hierarchy was a large share of a fresh
/// process's search.
pub const SCAN_LEAVES: usize = 128;

/// Most leaves gathered on the stack for a batch of segments before falling back to
/// one BVH walk per segment.
const GATHER_CAPACITY: usize = 32;

/// The environment model: an immutable snapshot at one version.
#[derive(Debug, Clone)]
pub struct World {
    version: u64,
    bounds: Bounds,
    sun: Sun,
    obstacles: BTreeMap<u32, Obstacle>,
    voxels: Option<VoxelGrid>,
    /// Built at the first query, from `boxes`, when there are more than
    /// [`SCAN_LEAVES`]: a world read only for its content (a client's map snapshot,
    /// a daemon's map change on its IPC thread) never pays for it.
    bvh: OnceLock<Bvh>,
    /// The padded box of each leaf.
    boxes: Vec<Aabb>,
    leaves: Vec<Leaf>,
}

impl PartialEq for World {
    /// Equal content and version; the acceleration structure is derived.
    fn eq(&self, other: &Self) -> bool {
        self.version == other.version
            && self.bounds == other.bounds
            && self.sun == other.sun
            && self.obstacles == other.obstacles
            && self.voxels == other.voxels
    }
}

impl World {
    /// A world with no obstacles, at version 0.
    pub fn empty(bounds: Bounds, sun: Sun) -> Self {
        Self::assemble(0, bounds, sun, BTreeMap::new(), None)
    }

    /// A world with the given content. Obstacles are validated; ids must be unique.
    pub fn new(
        version: u64,
        bounds: Bounds,
        sun: Sun,
        obstacles: impl IntoIterator<Item = (u32, Obstacle)>,
        voxels: Option<VoxelGrid>,
    ) -> Result<Self, MapDeltaErrorKind> {
        let mut map = BTreeMap::new();
        for (id, obstacle) in obstacles {
            obstacle.validate().map_err(|source| MapDeltaErrorKind::InvalidObstacle { id, source })?;
            if map.insert(id, obstacle).is_some() {
                return Err(MapDeltaErrorKind::DuplicateId { id });
            }
            if map.len() > MAX_OBSTACLES {
                return Err(MapDeltaErrorKind::TooManyObstacles { count: map.len() });
            }
        }
        Ok(Self::assemble(version, bounds, sun, map, voxels))
    }

    fn assemble(
        version: u64,
        bounds: Bounds,
        sun: Sun,
        obstacles: BTreeMap<u32, Obstacle>,
        voxels: Option<VoxelGrid>,
    ) -> Self {
        let mut leaves: Vec<Leaf> =
            obstacles.iter().map(|(id, shape)| Leaf::Solid { id: *id, shape: *shape }).collect();
        let mut boxes: Vec<Aabb> = obstacles.values().map(|o| padded(o.aabb())).collect();
        if let Some(aabb) = voxels.as_ref().and_then(VoxelGrid::aabb) {
            leaves.push(Leaf::Voxels);
            boxes.push(padded(aabb));
        }
        World { version, bounds, sun, obstacles, voxels, bvh: OnceLock::new(), boxes, leaves }
    }

    /// Builds the index over the leaves now if the world has one and no query has
    /// built it yet: a search calls it before its first candidate, so that
    /// evaluating candidates allocates nothing.
    pub fn build_index(&self) {
        self.bvh();
    }

    /// The bounding-volume hierarchy over the leaves, built on first use; `None`
    /// for a world of at most [`SCAN_LEAVES`] leaves, which is scanned.
    #[inline]
    fn bvh(&self) -> Option<&Bvh> {
        if self.boxes.len() <= SCAN_LEAVES {
            return None;
        }
        Some(match self.bvh.get() {
            Some(bvh) => bvh,
            None => self.build_bvh(),
        })
    }

    /// Kept out of line so that the check in [`World::bvh`] is all a search pays.
    #[cold]
    #[inline(never)]
    fn build_bvh(&self) -> &Bvh {
        self.bvh.get_or_init(|| Bvh::from_leaves(BvhBuildStrategy::Binned, &self.boxes))
    }

    /// The same content at `version`: a map's content read back (a snapshot, a
    /// file) carries the version it was taken at, not the count of its deltas.
    pub fn at_version(mut self, version: u64) -> World {
        self.version = version;
        self
    }

    /// The map version: 0 when created, +1 per accepted delta.
    pub fn version(&self) -> u64 {
        self.version
    }

    /// The map bounds.
    pub fn bounds(&self) -> &Bounds {
        &self.bounds
    }

    /// The sun.
    pub fn sun(&self) -> &Sun {
        &self.sun
    }

    /// Obstacles by id.
    pub fn obstacles(&self) -> &BTreeMap<u32, Obstacle> {
        &self.obstacles
    }

    /// The voxel grid, if any.
    pub fn voxels(&self) -> Option<&VoxelGrid> {
        self.voxels.as_ref()
    }

    /// The map as the JSON object `dyfos map snapshot` prints (without its `map` id):
    /// `version`, `bounds`, `sun`, `obstacles` in scenario form, and `voxels` if any
    /// ([`crate::map_json::map_to_json`]; [`crate::map_json::map_from_json`] reads it back).
    pub fn to_json(&self) -> serde_json::Value {
        crate::map_json::map_to_json(None, self)
    }

    /// Whether `other` holds the same bounds, sun, obstacles and voxels, whatever
    /// the versions.
    pub fn same_content(&self, other: &World) -> bool {
        self.bounds == other.bounds
            && self.sun == other.sun
            && self.obstacles == other.obstacles
            && self.voxels == other.voxels
    }

    /// A 64-bit digest of the content ([`World::same_content`] worlds share it):
    /// the map id a scenario's map gets when none is given, so the same scenario
    /// reuses its map in the daemon.
    pub fn content_id(&self) -> u64 {
        let voxels = self.voxels.as_ref().map(VoxelGrid::digest);
        let text = format!("{:?}{:?}{:?}{:?}", self.bounds, self.sun, self.obstacles, voxels);
        // FNV-1a, 64 bit.
        text.bytes().fold(0xcbf29ce484222325u64, |h, b| (h ^ u64::from(b)).wrapping_mul(0x100000001b3))
    }

    /// This world with `deltas` applied in order, all or none (SPEC §1). The version
    /// grows by one per delta. On error, names the first failing delta.
    pub fn apply(&self, deltas: &[MapDelta]) -> Result<World, MapDeltaError> {
        delta::apply(self, deltas)
    }

    #[inline]
    fn leaf_contact(&self, leaf: u32, seg: &Segment) -> Option<f64> {
        match &self.leaves[leaf as usize] {
            Leaf::Solid { shape, .. } => shape.first_contact(seg),
            Leaf::Voxels => self.voxels.as_ref().and_then(|v| v.first_contact(seg)),
        }
    }

    /// Whether an occupied voxel may come near the closed box `[lo, hi]`: the grid's
    /// leaf spans the whole grid, so the queries ask this before testing it.
    #[inline]
    fn voxels_may_touch(&self, lo: &Point3<f64>, hi: &Point3<f64>) -> bool {
        self.voxels.as_ref().is_some_and(|v| v.may_touch_box(lo, hi))
    }

    /// [`World::voxels_may_touch`], settled by the query's bricks `near` where they can.
    /// Out of line: inlined into the candidate loops, it slows them on maps without
    /// a grid, where it is never called.
    #[inline(never)]
    fn voxels_may_touch_near(&self, near: &NearBricks, lo: &Point3<f64>, hi: &Point3<f64>) -> bool {
        self.voxels.as_ref().is_some_and(|v| v.may_touch_box_near(near, lo, hi))
    }

    /// [`World::voxels_may_touch_near`] by the bricks' bits alone
    /// ([`VoxelGrid::bricks_may_touch_box`]).
    #[inline(never)]
    fn voxel_bricks_may_touch(&self, near: &NearBricks, lo: &Point3<f64>, hi: &Point3<f64>) -> bool {
        self.voxels.as_ref().is_some_and(|v| v.bricks_may_touch_box(near, lo, hi))
    }

    /// Whether any of `segments` touches leaf `leaf` up to its own end.
    #[inline]
    fn leaf_touches(&self, leaf: u32, segments: &[Segment]) -> bool {
        segments.iter().any(|s| self.leaf_contact(leaf, s).is_some_and(|t| s.reaches(t)))
    }

    /// [`World::leaf_touches`] for segments of a query whose voxel bricks near them
    /// are `near`, all inside the closed box `[lo, hi]`: the same answer.
    #[inline]
    fn leaf_touches_near(
        &self,
        leaf: u32,
        segments: &[Segment],
        near: &NearBricks,
        lo: &Point3<f64>,
        hi: &Point3<f64>,
    ) -> bool {
        match (&self.leaves[leaf as usize], &self.voxels) {
            (Leaf::Voxels, Some(v)) => v.any_contact_near(segments, near, lo, hi),
            _ => self.leaf_touches(leaf, segments),
        }
    }

    /// Whether any segment touches any obstacle or occupied voxel, each up to its own
    /// [`SegmentEnd`]. Stops at the first contact; allocates nothing.
    pub fn any_contact(&self, segments: &[Segment]) -> bool {
        let Some((lo, hi)) = span(segments) else {
            return false;
        };
        self.any_contact_within(segments, &lo, &hi)
    }

    /// [`World::any_contact`] for segments the caller knows lie in the closed box
    /// `[lo, hi]` (a box in closed form, e.g. a collision star's cube; a segment's
    /// end may round outside it by far less than the leaves' padding): the same
    /// verdict, without computing the segments' span.
    pub fn any_contact_within(&self, segments: &[Segment], lo: &Point3<f64>, hi: &Point3<f64>) -> bool {
        let (lo, hi) = (*lo, *hi);
        // Gather the leaves near the whole batch once (the batch is compact: a
        // viewer's collision star, or the sight lines to one rover).
        let mut near = [0u32; GATHER_CAPACITY];
        let mut count = 0;
        let gathered = self.leaves_meeting_box(&lo, &hi, |leaf| {
            if count == GATHER_CAPACITY {
                return false;
            }
            near[count] = leaf;
            count += 1;
            true
        });
        if !gathered {
            return segments.iter().any(|s| self.segment_contact(s));
        }
        // The grid's leaf spans the whole grid: drop it when no occupied cell is near
        // the batch at all (a viewer's collision star in open space).
        if let (Some(v), Some(i)) =
            (&self.voxels, near[..count].iter().position(|l| matches!(self.leaves[*l as usize], Leaf::Voxels)))
            && !v.may_touch_box(&lo, &hi)
        {
            near.copy_within(i + 1..count, i);
            count -= 1;
        }
        segments
            .iter()
            .any(|s| near[..count].iter().any(|leaf| self.leaf_contact(*leaf, s).is_some_and(|t| s.reaches(t))))
    }

    /// Calls `visit` with each leaf whose node boxes all meet the closed box
    /// `[lo, hi]`, in the index's order, until `visit` returns `false`; returns
    /// whether the walk ended without being stopped. Allocates nothing.
    pub(crate) fn leaves_meeting_box(
        &self,
        lo: &Point3<f64>,
        hi: &Point3<f64>,
        mut visit: impl FnMut(u32) -> bool,
    ) -> bool {
        // Not `any(miss)`: a NaN keeps the node.
        let misses = |mins: &Point3<f64>, maxs: &Point3<f64>| (0..3).any(|a| maxs[a] < lo[a] || mins[a] > hi[a]);
        let Some(bvh) = self.bvh() else {
            return (0u32..).zip(&self.boxes).filter(|(_, b)| !misses(&b.mins, &b.maxs)).all(|(leaf, _)| visit(leaf));
        };
        let mut finished = true;
        bvh.traverse(|node| {
            if misses(&node.mins(), &node.maxs()) {
                return TraversalAction::Prune;
            }
            if let Some(leaf) = node.leaf_data()
                && !visit(leaf)
            {
                finished = false;
                return TraversalAction::EarlyExit;
            }
            TraversalAction::Continue
        });
        finished
    }

    /// Calls `visit` with each leaf the segment touches (up to its end) and the
    /// distance of first contact, in the index's order, until `visit` returns
    /// `false`; returns whether the walk ended without being stopped.
    fn contacts_along(&self, seg: &Segment, mut visit: impl FnMut(u32, f64) -> bool) -> bool {
        let Some(bvh) = self.bvh() else {
            return (0u32..)
                .zip(&self.boxes)
                .filter(|(_, b)| first_contact_aabb(seg, &b.mins, &b.maxs).is_some())
                .filter_map(|(leaf, _)| Some((leaf, self.leaf_contact(leaf, seg).filter(|t| seg.reaches(*t))?)))
                .all(|(leaf, t)| visit(leaf, t));
        };
        let mut finished = true;
        bvh.traverse(|node| {
            if first_contact_aabb(seg, &node.mins(), &node.maxs()).is_none() {
                return TraversalAction::Prune;
            }
            if let Some(leaf) = node.leaf_data()
                && let Some(t) = self.leaf_contact(leaf, seg).filter(|t| seg.reaches(*t))
                && !visit(leaf, t)
            {
                finished = false;
                return TraversalAction::EarlyExit;
            }
            TraversalAction::Continue
        });
        finished
    }

    /// Whether one segment touches anything, by a BVH walk with early exit.
    fn segment_contact(&self, seg: &Segment) -> bool {
        !self.contacts_along(seg, |_, _| false)
    }

    /// Every obstacle the segment touches (up to its end), nearest first, with the
    /// distance of first contact. For reports, not for the search.
    pub fn contacts(&self, seg: &Segment) -> Vec<(Blocker, f64)> {
        let mut found = Vec::new();
        self.contacts_along(seg, |leaf, t| {
            let blocker = match self.leaves[leaf as usize] {
                Leaf::Solid { id, .. } => Blocker::Obstacle(id),
                Leaf::Voxels => Blocker::Voxels,
            };
            found.push((blocker, t));
            true
        });
        found.sort_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)));
        found
    }

    /// The same check as [`World::any_contact`] by testing every obstacle: the
    /// reference the BVH is tested against.
    pub fn any_contact_by_scan(&self, segments: &[Segment]) -> bool {
        segments.iter().any(|s| {
            self.obstacles.values().any(|o| o.first_contact(s).is_some_and(|t| s.reaches(t)))
                || self.voxels.as_ref().and_then(|v| v.first_contact(s)).is_some_and(|t| s.reaches(t))
        })
    }
}

fn padded((lo, hi): (Point3<f64>, Point3<f64>)) -> Aabb {
    let pad = Vector3::repeat(LEAF_PAD);
    Aabb::new(lo - pad, hi + pad)
}

/// The box spanned by the segments' end points, or `None` for no segments.
fn span(segments: &[Segment]) -> Option<(Point3<f64>, Point3<f64>)> {
    let first = segments.first()?;
    let (mut lo, mut hi) = (first.origin, first.origin);
    for s in segments {
        let end = s.point_at(s.length.max(0.0));
        for p in [s.origin, end] {
            lo = lo.inf(&p);
            hi = hi.sup(&p);
        }
    }
    Some((lo, hi))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A tiny seeded generator for the world's tests (the crate does not depend on rand).
    pub(super) struct Lcg(pub(super) u64);
    impl Lcg {
        pub(super) fn next(&mut self) -> f64 {
            self.0 = self.0.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (self.0 >> 11) as f64 / (1u64 << 53) as f64
        }
        pub(super) fn below(&mut self, n: i64) -> i64 {
            (self.next() * n as f64) as i64
        }
    }

    /// `n` cylinders and boxes over 20 × 20 m, and a sparse voxel grid if asked:
    /// the random world the indexes and shortcuts are tested against the scan on.
    pub(super) fn random_world(rng: &mut Lcg, n: usize, voxels: bool) -> World {
        let obstacles = (0..n).map(|i| {
            let o = if i % 3 == 2 {
                let min = Point3::new(rng.next() * 20.0 - 10.0, rng.next() * 20.0 - 10.0, rng.next() * 2.0);
                Obstacle::Box(AxisBox {
                    min,
                    max: min + Vector3::new(0.2, 0.2, 0.2) + Vector3::repeat(rng.next() * 2.0),
                })
            } else {
                Obstacle::Cylinder(VerticalCylinder {
                    center: Point2::new(rng.next() * 20.0 - 10.0, rng.next() * 20.0 - 10.0),
                    radius: 0.25 + rng.next(),
                    height: 0.5 + rng.next() * 10.0,
                })
            };
            (i as u32 * 3 + 1, o)
        });
        let obstacles: Vec<_> = obstacles.collect();
        let grid = voxels.then(|| {
            let cells: Vec<_> = (0..40)
                .map(|_| [(rng.next() * 40.0) as i64, (rng.next() * 40.0) as i64, (rng.next() * 6.0) as i64])
                .collect();
            VoxelGrid::new(0.5, Point3::new(-10.0, -10.0, 0.0), cells).unwrap()
        });
        World::new(0, Bounds::new([-10.0, -10.0, 10.0, 10.0]).unwrap(), Sun::new(0.5, 0.0).unwrap(), obstacles, grid)
            .unwrap()
    }

    #[test]
    fn the_index_agrees_with_a_scan_of_every_obstacle() {
        let mut rng = Lcg(11);
        // Scanned leaf by leaf up to SCAN_LEAVES, through a BVH above.
        for n in [0, 1, 2, 25, SCAN_LEAVES, SCAN_LEAVES + 1, 200] {
            let world = random_world(&mut rng, n, true);
            let mut hits = 0;
            for i in 0..3000 {
                let o = Point3::new(rng.next() * 20.0 - 10.0, rng.next() * 20.0 - 10.0, rng.next() * 6.0);
                let segs: Vec<Segment> = (0..(1 + i % 10))
                    .map(|_| {
                        let d = Vector3::new(rng.next() - 0.5, rng.next() - 0.5, rng.next() - 0.5).normalize();
                        Segment::closed(o, d, rng.next() * 8.0)
                    })
                    .collect();
                let expected = world.any_contact_by_scan(&segs);
                assert_eq!(world.any_contact(&segs), expected, "n = {n}, {segs:?}");
                assert_eq!(segs.iter().any(|s| !world.contacts(s).is_empty()), expected);
                hits += usize::from(expected);
            }
            assert_eq!(world.bvh.get().is_some(), world.leaves.len() > SCAN_LEAVES, "n = {n}");
            if n >= 25 {
                assert!(hits > 300, "n = {n}: only {hits} hits");
            }
        }
    }

    /// A dense map of cylinders (some short) and boxes (one floating), and segments
    /// made to graze them: tangent to a side, along a top or a face, ending exactly
    /// on a surface, vertical at a rim, from far outside, and sight-line fans.
    fn grazing_cases(rng: &mut Lcg, n: usize) -> (World, Vec<Vec<Segment>>) {
        let mut obstacles = Vec::new();
        for i in 0..n {
            let o = if i % 5 == 4 {
                let min = Point3::new(
                    rng.next() * 18.0 - 9.0,
                    rng.next() * 18.0 - 9.0,
                    if i % 10 == 9 { 1.0 + rng.next() * 2.0 } else { 0.0 },
                );
                Obstacle::Box(AxisBox {
                    min,
                    max: min + Vector3::new(0.3 + rng.next() * 2.0, 0.3 + rng.next(), 0.5 + rng.next() * 3.0),
                })
            } else {
                Obstacle::Cylinder(VerticalCylinder {
                    center: Point2::new(rng.next() * 18.0 - 9.0, rng.next() * 18.0 - 9.0),
                    radius: 0.2 + rng.next(),
                    height: if i % 2 == 0 { 10.0 } else { 0.5 + rng.next() * 3.0 },
                })
            };
            obstacles.push((i as u32 + 1, o));
        }
        let world = World::new(
            0,
            Bounds::new([-10.0, -10.0, 10.0, 10.0]).unwrap(),
            Sun::new(0.5, 0.0).unwrap(),
            obstacles.clone(),
            None,
        )
        .unwrap();
        let mut batches = Vec::new();
        let unit = |v: Vector3<f64>| v.normalize();
        for k in 0..6000 {
            let (_, o) = obstacles[k % obstacles.len()];
            let mut segs = Vec::new();
            match (o, k % 6) {
                // Tangent to the side at height z, from either way, touching or 1e-12 off.
                (Obstacle::Cylinder(c), 0 | 1) => {
                    let a = rng.next() * std::f64::consts::TAU;
                    let (n, t) = (Vector3::new(a.cos(), a.sin(), 0.0), Vector3::new(-a.sin(), a.cos(), 0.0));
                    let off = [0.0, 1e-12, -1e-12][k % 3];
                    let p = Point3::new(c.center.x, c.center.y, rng.next() * c.height * 1.2) + n * (c.radius + off);
                    let back = rng.next() * 6.0;
                    segs.push(Segment::closed(p - t * back, t, back + rng.next() * 3.0));
                }
                // Along the top, or ending exactly on the side (open or closed end).
                (Obstacle::Cylinder(c), 2 | 3) => {
                    let a = rng.next() * std::f64::consts::TAU;
                    let n = Vector3::new(a.cos(), a.sin(), 0.0);
                    let z = if k % 6 == 2 { c.height } else { rng.next() * c.height };
                    let target = Point3::new(c.center.x, c.center.y, z) + n * c.radius;
                    let from = target
                        + unit(Vector3::new(n.x + rng.next() - 0.5, n.y + rng.next() - 0.5, rng.next() - 0.3))
                            * (0.5 + rng.next() * 6.0);
                    let margin = [0.0, 1e-6, -1e-12][k % 3];
                    segs.extend(Segment::sight_line(&from, &target, margin));
                    let d = target - from;
                    segs.push(Segment::closed(from, d / d.norm(), d.norm()));
                }
                // Vertical at the rim, and a collision star around a point near it.
                (Obstacle::Cylinder(c), _) => {
                    let a = rng.next() * std::f64::consts::TAU;
                    let p =
                        Point3::new(c.center.x + c.radius * a.cos(), c.center.y + c.radius * a.sin(), c.height + 2.0);
                    segs.push(Segment::closed(p, -Vector3::z(), 2.0 + [0.0, -1e-12, 1e-12][k % 3]));
                    let q = p + Vector3::new(rng.next() - 0.5, rng.next() - 0.5, -rng.next() * 3.0) * 1.5;
                    for j in 0..8 {
                        let b = a + f64::from(j) * std::f64::consts::FRAC_PI_4;
                        segs.push(Segment::closed(q, Vector3::new(b.cos(), b.sin(), 0.0), 0.625));
                    }
                }
                // Along a box face or edge, and through from outside the map.
                (Obstacle::Box(b), 0..=2) => {
                    let y = [b.min.y, b.max.y, b.min.y + 0.5 * (b.max.y - b.min.y)][k % 3];
                    let z = [b.max.z, b.min.z, b.max.z][k % 3];
                    let from = Point3::new(b.min.x - 1.0 - rng.next() * 30.0, y, z);
                    segs.push(Segment::closed(from, Vector3::x(), b.min.x - from.x + [0.0, 1e-12, -1e-12][k % 3]));
                }
                // A sight-line fan from a sensor to points around the box.
                (Obstacle::Box(b), _) => {
                    let centre = b.min + (b.max - b.min) * 0.5;
                    let from = centre + Vector3::new(rng.next() - 0.5, rng.next() - 0.5, 0.5) * 12.0;
                    for j in 0..9 {
                        let a = f64::from(j) * 0.7;
                        let to = Point3::new(centre.x + 2.0 * a.cos(), centre.y + 2.0 * a.sin(), 0.2);
                        segs.extend(Segment::sight_line(&from, &to, 1e-6));
                    }
                }
            }
            batches.push(segs);
        }
        // And plain random segments, long and short.
        for i in 0..3000 {
            let o = Point3::new(rng.next() * 30.0 - 15.0, rng.next() * 30.0 - 15.0, rng.next() * 12.0 - 1.0);
            let d = unit(Vector3::new(rng.next() - 0.5, rng.next() - 0.5, rng.next() - 0.5));
            batches.push(vec![Segment::closed(o, d, rng.next() * [1.0, 8.0, 40.0][i % 3])]);
        }
        (world, batches)
    }

    /// The broad phase decides nothing itself: every verdict, bit for bit, is the one
    /// of testing every obstacle, on segments that graze the obstacles.
    #[test]
    fn any_contact_agrees_with_scan_on_grazing_segments() {
        let mut rng = Lcg(23);
        for n in [1, 3, 25, 60, 300] {
            let (world, batches) = grazing_cases(&mut rng, n);
            let (mut hits, mut misses) = (0, 0);
            for segs in &batches {
                let expected = world.any_contact_by_scan(segs);
                assert_eq!(world.any_contact(segs), expected, "n = {n}, {segs:?}");
                for s in segs {
                    assert_eq!(
                        world.any_contact(std::slice::from_ref(s)),
                        world.any_contact_by_scan(std::slice::from_ref(s)),
                        "n = {n}, {s:?}"
                    );
                }
                if expected { hits += 1 } else { misses += 1 }
            }
            assert!(hits > 1000 && misses > 1000, "n = {n}: {hits} hits, {misses} misses");
        }
    }

    #[test]
    fn the_index_is_built_at_the_first_query_and_kept_by_clones() {
        let mut rng = Lcg(5);
        let world = random_world(&mut rng, 200, true);
        // Read for its content only (a snapshot): no index.
        assert!(world.bvh.get().is_none());
        let unqueried = world.clone();
        let seg = Segment::closed(Point3::new(0.0, 0.0, 1.0), Vector3::new(1.0, 0.0, 0.0), 8.0);
        let hit = world.any_contact(&[seg]);
        assert!(world.bvh.get().is_some());
        let queried = world.clone();
        assert!(queried.bvh.get().is_some(), "a clone of a queried world keeps its index");
        assert!(unqueried.bvh.get().is_none());
        assert_eq!(unqueried.any_contact(&[seg]), hit);
        assert_eq!(world.any_contact_by_scan(&[seg]), hit);
    }

    #[test]
    fn a_small_world_is_scanned_without_an_index() {
        let mut rng = Lcg(5);
        let world = random_world(&mut rng, SCAN_LEAVES - 1, true);
        world.build_index();
        let seg = Segment::closed(Point3::new(0.0, 0.0, 1.0), Vector3::new(1.0, 0.0, 0.0), 8.0);
        assert_eq!(world.any_contact(&[seg]), world.any_contact_by_scan(&[seg]));
        assert!(world.bvh.get().is_none());
    }

    #[test]
    fn open_end_excludes_the_target() {
        let b = Obstacle::Box(AxisBox { min: Point3::new(1.0, -1.0, 0.0), max: Point3::new(2.0, 1.0, 1.0) });
        let world =
            World::new(0, Bounds::new([-5.0, -5.0, 5.0, 5.0]).unwrap(), Sun::new(0.5, 0.0).unwrap(), [(1, b)], None)
                .unwrap();
        // Target on the box's face: the sight line ends there and is not occluded.
        let to_face = Segment::sight_line(&Point3::new(0.0, 0.0, 0.5), &Point3::new(1.0, 0.0, 0.5), 1e-6).unwrap();
        assert!(!world.any_contact(&[to_face]));
        // Target behind the box: occluded.
        let behind = Segment::sight_line(&Point3::new(0.0, 0.0, 0.5), &Point3::new(3.0, 0.0, 0.5), 1e-6).unwrap();
        assert!(world.any_contact(&[behind]));
        assert_eq!(world.contacts(&behind), vec![(Blocker::Obstacle(1), 1.0)]);
    }

    #[test]
    fn sun_direction() {
        let s = Sun::new(FRAC_PI_2, 0.3).unwrap().direction();
        assert!((s - Vector3::z()).norm() < 1e-15);
        assert!(Sun::new(1.6, 0.0).is_err());
        assert!(Bounds::new([0.0, 0.0, 0.0, 1.0]).is_err());
    }
}
