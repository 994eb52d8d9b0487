//! The solid obstacles of SPEC §1: vertical cylinders and axis-aligned boxes.
//!
//! Both are closed solids, and their segment queries are exact (a slab test for the
//! box; a quadratic for the cylinder's side, slabs for its caps). parry's own
//! `Cylinder` is Y-axis and casts rays through GJK, which can miss grazing hits.
//!
//! ```
//! use dyfos_shared::world::{Obstacle, Segment, VerticalCylinder};
//! use nalgebra::{Point2, Point3, Vector3};
//!
//! let pole = Obstacle::Cylinder(VerticalCylinder { center: Point2::new(2.0, 0.0), radius: 0.5, height: 10.0 });
//! let ray = Segment::closed(Point3::new(0.0, 0.0, 1.0), Vector3::x(), 5.0);
//! assert_eq!(pole.first_contact(&ray), Some(1.5));
//! ```

use super::segment::{Segment, clip_slab, first_contact_aabb};
use crate::limits::MAX_COORDINATE;
use crate::math::{Point2, Point3};

/// A vertical cylinder standing on the ground, caps included.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct VerticalCylinder {
    /// Centre of the base, (x, y).
    pub center: Point2<f64>,
    /// Radius, m (> 0).
    pub radius: f64,
    /// Height, m (> 0); the solid spans z ∈ [0, height].
    pub height: f64,
}

/// An axis-aligned box, the closed solid between `min` and `max`; it may float.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct AxisBox {
    /// Minimum corner.
    pub min: Point3<f64>,
    /// Maximum corner (strictly greater on every axis).
    pub max: Point3<f64>,
}

/// One solid obstacle. A closed set, so an enum (`match`, no `dyn`).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub enum Obstacle {
    /// A vertical cylinder.
    Cylinder(VerticalCylinder),
    /// An axis-aligned box.
    Box(AxisBox),
}

/// Why an obstacle's geometry is invalid.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ObstacleError {
    /// A number is NaN, infinite or beyond ±1e6 m.
    #[error("{field} = {value} must be a finite number within ±1e6")]
    NotFinite {
        /// Which number.
        field: &'static str,
        /// Its value.
        value: f64,
    },
    /// A size that must be positive is not.
    #[error("{field} = {value} must be > 0")]
    NotPositive {
        /// Which number.
        field: &'static str,
        /// Its value.
        value: f64,
    },
    /// A box's min is not below its max on some axis.
    #[error("box min[{axis}] = {min} must be < max[{axis}] = {max}")]
    EmptyBox {
        /// 0, 1 or 2 for x, y, z.
        axis: usize,
        /// The min coordinate.
        min: f64,
        /// The max coordinate.
        max: f64,
    },
}

pub(crate) fn finite(field: &'static str, value: f64) -> Result<(), ObstacleError> {
    if value.is_finite() && value.abs() <= MAX_COORDINATE {
        Ok(())
    } else {
        Err(ObstacleError::NotFinite { field, value })
    }
}

impl Obstacle {
    /// Checks SPEC §11's rules: finite numbers, r, h > 0, box min < max per axis.
    pub fn validate(&self) -> Result<(), ObstacleError> {
        match self {
            Obstacle::Cylinder(c) => {
                finite("x", c.center.x)?;
                finite("y", c.center.y)?;
                finite("radius", c.radius)?;
                finite("height", c.height)?;
                if c.radius <= 0.0 {
                    return Err(ObstacleError::NotPositive { field: "radius", value: c.radius });
                }
                if c.height <= 0.0 {
                    return Err(ObstacleError::NotPositive { field: "height", value: c.height });
                }
            }
            Obstacle::Box(b) => {
                for axis in 0..3 {
                    finite("min", b.min[axis])?;
                    finite("max", b.max[axis])?;
                    if b.min[axis] >= b.max[axis] {
                        return Err(ObstacleError::EmptyBox { axis, min: b.min[axis], max: b.max[axis] });
                    }
                }
            }
        }
        Ok(())
    }

    /// The tight axis-aligned bounding box, as (min, max).
    pub fn aabb(&self) -> (Point3<f64>, Point3<f64>) {
        match self {
            Obstacle::Cylinder(c) => (
                Point3::new(c.center.x - c.radius, c.center.y - c.radius, 0.0),
                Point3::new(c.center.x + c.radius, c.center.y + c.radius, c.height),
            ),
            Obstacle::Box(b) => (b.min, b.max),
        }
    }

    /// The smallest `t ∈ [0, seg.length]` at which the segment is inside the closed
    /// solid (0 when it starts inside), or `None`. The segment's `end` is not applied.
    #[inline]
    pub fn first_contact(&self, seg: &Segment) -> Option<f64> {
        match self {
            Obstacle::Box(b) => first_contact_aabb(seg, &b.min, &b.max),
            Obstacle::Cylinder(c) => c.first_contact(seg),
        }
    }
}

impl VerticalCylinder {
    /// See [`Obstacle::first_contact`].
    #[inline]
    pub fn first_contact(&self, seg: &Segment) -> Option<f64> {
        let (o, d) = (&seg.origin, &seg.dir);
        let (ox, oy) = (o.x - self.center.x, o.y - self.center.y);
        let c = ox * ox + oy * oy - self.radius * self.radius;
        let a = d.x * d.x + d.y * d.y;
        // The line's miss in xy first: it settles most segments, and is cheaper
        // than clipping to the height (the same verdict and t in either order).
        let b = ox * d.x + oy * d.y;
        let disc = b * b - a * c;
        if a != 0.0 && disc < 0.0 {
            return None;
        }
        let (mut t0, mut t1) = (0.0, seg.length.max(0.0));
        if !clip_slab(o.z, d.z, 0.0, self.height, &mut t0, &mut t1) {
            return None;
        }
        if a == 0.0 {
            // Vertical segment: inside the disc for all t, or never.
            return (c <= 0.0).then_some(t0);
        }
        let sq = disc.sqrt();
        // Stable roots: avoid cancelling −b against sq.
        let q = -(b + b.signum() * sq);
        let (mut ta, mut tb) = if q == 0.0 { (0.0, 0.0) } else { (q / a, c / q) };
        if ta > tb {
            std::mem::swap(&mut ta, &mut tb);
        }
        let lo = t0.max(ta);
        (lo <= t1.min(tb)).then_some(lo)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::Vector3;

    fn pole() -> Obstacle {
        Obstacle::Cylinder(VerticalCylinder { center: Point2::new(2.0, 0.0), radius: 0.5, height: 3.0 })
    }

    fn seg(o: [f64; 3], d: [f64; 3], len: f64) -> Segment {
        Segment::closed(Point3::from(o), Vector3::from(d).normalize(), len)
    }

    #[test]
    fn ray_through_cylinder_side() {
        assert_eq!(pole().first_contact(&seg([0.0, 0.0, 1.0], [1.0, 0.0, 0.0], 10.0)), Some(1.5));
        // Stops short of the side.
        assert_eq!(pole().first_contact(&seg([0.0, 0.0, 1.0], [1.0, 0.0, 0.0], 1.4999)), None);
        // Ends exactly on the side: closed solid, touching counts.
        assert_eq!(pole().first_contact(&seg([0.0, 0.0, 1.0], [1.0, 0.0, 0.0], 1.5)), Some(1.5));
        // Diagonal through, from 45° off-axis: distance to the circle by geometry.
        let s = seg([0.0, -2.0, 1.0], [1.0, 1.0, 0.0], 10.0);
        let t = pole().first_contact(&s).unwrap();
        let p = s.point_at(t);
        assert!(((p.x - 2.0).powi(2) + p.y.powi(2) - 0.25).abs() < 1e-12);
        assert!(((2.0f64).sqrt() * 2.0 - 0.5 - t).abs() < 1e-12);
    }

    #[test]
    fn grazing_the_cylinder_counts() {
        // Tangent to the side at (2, 0.5).
        assert_eq!(pole().first_contact(&seg([0.0, 0.5, 1.0], [1.0, 0.0, 0.0], 10.0)), Some(2.0));
        assert_eq!(pole().first_contact(&seg([0.0, 0.5 + 1e-9, 1.0], [1.0, 0.0, 0.0], 10.0)), None);
        // Skims the top cap at z = h.
        assert_eq!(pole().first_contact(&seg([0.0, 0.0, 3.0], [1.0, 0.0, 0.0], 10.0)), Some(1.5));
        assert_eq!(pole().first_contact(&seg([0.0, 0.0, 3.0 + 1e-9], [1.0, 0.0, 0.0], 10.0)), None);
    }

    #[test]
    fn from_inside_and_through_caps() {
        assert_eq!(pole().first_contact(&seg([2.1, 0.1, 1.0], [0.0, 1.0, 0.0], 0.01)), Some(0.0));
        // Down onto the top cap.
        assert_eq!(pole().first_contact(&seg([2.2, 0.0, 5.0], [0.0, 0.0, -1.0], 3.0)), Some(2.0));
        assert_eq!(pole().first_contact(&seg([2.2, 0.0, 5.0], [0.0, 0.0, -1.0], 1.99)), None);
        // Vertical ray just outside the radius.
        assert_eq!(pole().first_contact(&seg([2.5 + 1e-9, 0.0, 5.0], [0.0, 0.0, -1.0], 10.0)), None);
        // Slanted ray entering through the top cap.
        let s = seg([2.0, 0.0, 4.0], [0.1, 0.0, -1.0], 10.0);
        let t = pole().first_contact(&s).unwrap();
        assert!((s.point_at(t).z - 3.0).abs() < 1e-12);
    }

    #[test]
    fn box_contacts() {
        let b = Obstacle::Box(AxisBox { min: Point3::new(1.0, -1.0, 2.0), max: Point3::new(2.0, 1.0, 3.0) });
        assert_eq!(b.first_contact(&seg([0.0, 0.0, 2.5], [1.0, 0.0, 0.0], 5.0)), Some(1.0));
        // Under a floating box.
        assert_eq!(b.first_contact(&seg([0.0, 0.0, 1.0], [1.0, 0.0, 0.0], 5.0)), None);
        // Along its bottom face: closed, touches.
        assert_eq!(b.first_contact(&seg([0.0, 0.0, 2.0], [1.0, 0.0, 0.0], 5.0)), Some(1.0));
        // Through an edge diagonally.
        let s = seg([0.0, 0.0, 1.0], [1.0, 0.0, 1.0], 5.0);
        assert!((b.first_contact(&s).unwrap() - 2f64.sqrt()).abs() < 1e-12);
        // Inside.
        assert_eq!(b.first_contact(&seg([1.5, 0.0, 2.5], [0.0, 0.0, 1.0], 0.1)), Some(0.0));
    }

    #[test]
    fn validation() {
        let bad = Obstacle::Cylinder(VerticalCylinder { center: Point2::new(0.0, f64::NAN), radius: 1.0, height: 1.0 });
        assert!(matches!(bad.validate(), Err(ObstacleError::NotFinite { field: "y", .. })));
        let bad = Obstacle::Box(AxisBox { min: Point3::new(0.0, 0.0, 1.0), max: Point3::new(1.0, 1.0, 1.0) });
        assert!(matches!(bad.validate(), Err(ObstacleError::EmptyBox { axis: 2, .. })));
    }
}
