//! Line segments and their exact first contact with closed solids.

use crate::math::{Point3, Vector3};

/// Whether a segment's far end counts as reachable.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SegmentEnd {
    /// Contact at `t ≤ length` counts (collision rays, SPEC §5.2).
    Closed,
    /// Only contact at `t < length` counts (occlusion, SPEC §5.3: the segment is
    /// shortened by 1e-6 and the target itself never occludes).
    Open,
}

/// A segment `origin + t·dir`, `t ∈ [0, length]`, with a unit `dir`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Segment {
    /// Start point, world frame.
    pub origin: Point3<f64>,
    /// Unit direction, world frame.
    pub dir: Vector3<f64>,
    /// Length, m.
    pub length: f64,
    /// Whether contact exactly at `length` counts.
    pub end: SegmentEnd,
}

impl Segment {
    /// A closed segment from `origin` along the unit `dir`.
    #[inline]
    pub fn closed(origin: Point3<f64>, dir: Vector3<f64>, length: f64) -> Self {
        Segment { origin, dir, length, end: SegmentEnd::Closed }
    }

    /// The occlusion segment from `from` to `to` (SPEC §5.3): contact counts only at
    /// distance `< |to − from| − margin`. `None` when the points (nearly) coincide.
    #[inline]
    pub fn sight_line(from: &Point3<f64>, to: &Point3<f64>, margin: f64) -> Option<Self> {
        let delta = to - from;
        let norm = delta.norm();
        (norm > 0.0 && norm.is_finite()).then(|| Segment {
            origin: *from,
            dir: delta / norm,
            length: norm - margin,
            end: SegmentEnd::Open,
        })
    }

    /// Whether a first contact at `t` (already known to be ≥ 0) counts.
    #[inline]
    pub fn reaches(&self, t: f64) -> bool {
        match self.end {
            SegmentEnd::Closed => t <= self.length,
            SegmentEnd::Open => t < self.length,
        }
    }

    /// The point at `t`.
    #[inline]
    pub fn point_at(&self, t: f64) -> Point3<f64> {
        self.origin + self.dir * t
    }
}

/// Clips the parameter interval `[t0, t1]` to the closed slab `lo ≤ o + t·d ≤ hi`.
/// Returns `false` when the interval becomes empty.
#[inline]
pub(crate) fn clip_slab(o: f64, d: f64, lo: f64, hi: f64, t0: &mut f64, t1: &mut f64) -> bool {
    if d == 0.0 {
        return lo <= o && o <= hi;
    }
    let inv = 1.0 / d;
    let (mut ta, mut tb) = ((lo - o) * inv, (hi - o) * inv);
    if ta > tb {
        std::mem::swap(&mut ta, &mut tb);
    }
    *t0 = t0.max(ta);
    *t1 = t1.min(tb);
    *t0 <= *t1
}

/// First contact of `seg` with the closed box `[lo, hi]`, `t ∈ [0, seg.length]`.
#[inline]
pub(crate) fn first_contact_aabb(seg: &Segment, lo: &Point3<f64>, hi: &Point3<f64>) -> Option<f64> {
    let (mut t0, mut t1) = (0.0, seg.length.max(0.0));
    for a in 0..3 {
        if !clip_slab(seg.origin[a], seg.dir[a], lo[a], hi[a], &mut t0, &mut t1) {
            return None;
        }
    }
    Some(t0)
}
