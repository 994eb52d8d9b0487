//! What the 3D panels draw, before it is encoded for a profile: entities made of
//! primitives (Foxglove's `SceneEntity`, a group of RViz `Marker`s), and the
//! geometry both profiles share.

/// RGBA, each in [0, 1].
pub type Color = [f64; 4];

pub(crate) const fn color(r: f64, g: f64, b: f64, a: f64) -> Color {
    [r, g, b, a]
}

/// Simulated seconds as nanoseconds (the MCAP log time); negative times are 0.
pub(crate) fn nanos(t: f64) -> u64 {
    if t.is_finite() && t > 0.0 { (t * 1e9).round() as u64 } else { 0 }
}

/// A rotation by `yaw` about z, then `pitch` about the new y (Rz·Ry), as a
/// quaternion (x, y, z, w).
pub(crate) fn quaternion(yaw: f64, pitch: f64) -> [f64; 4] {
    let (sy, cy) = (yaw / 2.0).sin_cos();
    let (sp, cp) = (pitch / 2.0).sin_cos();
    // q = qz(yaw) ⊗ qy(pitch)
    [-sy * sp, cy * sp, sy * cp, cy * cp]
}

/// How the points of a [`Line`] connect.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum LineKind {
    /// Each point to the next.
    Strip,
    /// Each point to the next, and the last to the first.
    Loop,
    /// Pairs of points, each pair a segment.
    List,
}

/// A polyline through `points` (frame coordinates), `thickness` in pixels.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Line {
    pub kind: LineKind,
    pub points: Vec<[f64; 3]>,
    pub thickness: f64,
    pub color: Color,
}

/// A box centred at `center`, axis-aligned.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Cube {
    pub center: [f64; 3],
    pub size: [f64; 3],
    pub color: Color,
}

/// A ball centred at `center`.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Sphere {
    pub center: [f64; 3],
    pub diameter: f64,
    pub color: Color,
}

/// A vertical cylinder centred at `center`.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Cylinder {
    pub center: [f64; 3],
    pub radius: f64,
    pub height: f64,
    pub color: Color,
}

/// An arrow from `tail`, pointing `elevation` above the horizon and `azimuth`
/// from +x towards +y, `length` long.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Arrow {
    pub tail: [f64; 3],
    pub azimuth: f64,
    pub elevation: f64,
    pub length: f64,
    pub color: Color,
}

/// A label that always faces the viewer.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Text {
    pub position: [f64; 3],
    pub text: String,
    pub color: Color,
}

/// The primitives of one entity.
#[derive(Debug, Clone, Default, PartialEq)]
pub(crate) struct Primitives {
    pub arrows: Vec<Arrow>,
    pub cubes: Vec<Cube>,
    pub spheres: Vec<Sphere>,
    pub cylinders: Vec<Cylinder>,
    pub lines: Vec<Line>,
    pub texts: Vec<Text>,
}

/// A named group of primitives in `frame`; a later entity with the same id
/// replaces it (an empty one clears it). A frame-locked entity moves with its frame.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Entity {
    pub frame: &'static str,
    pub id: String,
    pub frame_locked: bool,
    pub primitives: Primitives,
}

impl Entity {
    pub fn new(frame: &'static str, id: impl Into<String>, frame_locked: bool, primitives: Primitives) -> Self {
        Entity { frame, id: id.into(), frame_locked, primitives }
    }
}

/// Points of the `k`-sigma ellipse of the 2-D covariance `[[sxx, sxy], [sxy, syy]]` about `center`.
pub(crate) fn ellipse(center: [f64; 2], cov: [[f64; 2]; 2], k: f64, z: f64) -> Vec<[f64; 3]> {
    let (a, b, c) = (cov[0][0], cov[0][1], cov[1][1]);
    let mid = (a + c) / 2.0;
    let rad = (((a - c) / 2.0).powi(2) + b * b).sqrt();
    let (l1, l2) = ((mid + rad).max(0.0), (mid - rad).max(0.0));
    let angle = 0.5 * (2.0 * b).atan2(a - c);
    let (s, co) = angle.sin_cos();
    // 36 points, to 0.1 mm: a drawing, drawn at every sample, so kept short.
    const N: usize = 36;
    let round = |v: f64| (v * 1e4).round() / 1e4;
    (0..N)
        .map(|i| {
            let t = i as f64 * std::f64::consts::TAU / N as f64;
            let (u, v) = (k * l1.sqrt() * t.cos(), k * l2.sqrt() * t.sin());
            [round(center[0] + co * u - s * v), round(center[1] + s * u + co * v), z]
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quaternion_is_yaw_then_pitch() {
        // Yaw 90° then pitch 90° (looking straight down while facing +y): the
        // rotated x axis is (0, 0, -1); the rotated y axis is (-1, 0, 0).
        let [x, y, z, w] = quaternion(std::f64::consts::FRAC_PI_2, std::f64::consts::FRAC_PI_2);
        let q = nalgebra::UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(w, x, y, z));
        let ex = q * nalgebra::Vector3::x();
        let ey = q * nalgebra::Vector3::y();
        assert!((ex - nalgebra::Vector3::new(0.0, 0.0, -1.0)).norm() < 1e-12, "{ex}");
        assert!((ey - nalgebra::Vector3::new(-1.0, 0.0, 0.0)).norm() < 1e-12, "{ey}");
    }

    #[test]
    fn ellipse_axes_follow_the_covariance() {
        // Variance 4 along the diagonal x = y, 1 across it: the 1-sigma ellipse
        // reaches 2 m along (1, 1)/√2 and 1 m across.
        let cov = [[2.5, 1.5], [1.5, 2.5]];
        let pts = ellipse([1.0, -1.0], cov, 1.0, 0.0);
        let r = |p: &[f64; 3]| (p[0] - 1.0).hypot(p[1] + 1.0);
        let max = pts.iter().map(r).fold(0.0, f64::max);
        let min = pts.iter().map(r).fold(f64::INFINITY, f64::min);
        assert!((max - 2.0).abs() < 1e-4 && (min - 1.0).abs() < 1e-2, "{min} {max}");
        assert!((pts[0][0] - 1.0 - 2f64.sqrt()).abs() < 1e-4 && (pts[0][1] + 1.0 - 2f64.sqrt()).abs() < 1e-4);
        assert_eq!(nanos(1.5), 1_500_000_000);
        assert_eq!(nanos(-1.0), 0);
    }
}
