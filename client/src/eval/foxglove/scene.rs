//! Foxglove's well-known messages as JSON values, with exactly the fields of the
//! schemas in `schemas/` (checked by the tests against the schemas themselves).

use serde_json::{Value, json};

/// Simulated seconds as nanoseconds (the MCAP log time); negative times are 0.
pub(super) fn nanos(t: f64) -> u64 {
    if t.is_finite() && t > 0.0 { (t * 1e9).round() as u64 } else { 0 }
}

/// `{sec, nsec}` of a log time.
pub(super) fn timestamp(ns: u64) -> Value {
    json!({"sec": ns / 1_000_000_000, "nsec": ns % 1_000_000_000})
}

pub(super) fn vec3(v: [f64; 3]) -> Value {
    json!({"x": v[0], "y": v[1], "z": v[2]})
}

/// A rotation by `yaw` about z, then `pitch` about the new y (Rz·Ry), as a quaternion.
pub(super) fn quaternion(yaw: f64, pitch: f64) -> Value {
    let (sy, cy) = (yaw / 2.0).sin_cos();
    let (sp, cp) = (pitch / 2.0).sin_cos();
    // q = qz(yaw) ⊗ qy(pitch)
    json!({"x": -sy * sp, "y": cy * sp, "z": sy * cp, "w": cy * cp})
}

pub(super) fn pose(position: [f64; 3], yaw: f64) -> Value {
    json!({"position": vec3(position), "orientation": quaternion(yaw, 0.0)})
}

pub(super) fn color(r: f64, g: f64, b: f64, a: f64) -> Value {
    json!({"r": r, "g": g, "b": b, "a": a})
}

/// `foxglove.FrameTransform`: `child` sits at `position`, turned by `yaw` then `pitch`, in `parent`.
pub(super) fn frame_transform(ns: u64, parent: &str, child: &str, position: [f64; 3], yaw: f64, pitch: f64) -> Value {
    json!({
        "timestamp": timestamp(ns),
        "parent_frame_id": parent,
        "child_frame_id": child,
        "translation": vec3(position),
        "rotation": quaternion(yaw, pitch),
    })
}

/// `foxglove.PoseInFrame` in the `map` frame.
pub(super) fn pose_in_map(ns: u64, position: [f64; 3], yaw: f64) -> Value {
    json!({"timestamp": timestamp(ns), "frame_id": "map", "pose": pose(position, yaw)})
}

/// `foxglove.PosesInFrame` in the `map` frame, from (x, y, θ) poses on the ground.
pub(super) fn path_in_map(ns: u64, poses: &[[f64; 3]]) -> Value {
    let poses: Vec<Value> = poses.iter().map(|p| pose([p[0], p[1], 0.0], p[2])).collect();
    json!({"timestamp": timestamp(ns), "frame_id": "map", "poses": poses})
}

/// The primitives of one `foxglove.SceneEntity`; every list the schema requires,
/// empty unless filled.
#[derive(Default)]
pub(super) struct Primitives {
    pub arrows: Vec<Value>,
    pub cubes: Vec<Value>,
    pub spheres: Vec<Value>,
    pub cylinders: Vec<Value>,
    pub lines: Vec<Value>,
    pub texts: Vec<Value>,
}

/// `foxglove.SceneEntity` `id` in `frame`, shown until replaced by the same id.
pub(super) fn entity(ns: u64, frame: &str, id: &str, frame_locked: bool, p: Primitives) -> Value {
    json!({
        "timestamp": timestamp(ns),
        "frame_id": frame,
        "id": id,
        "lifetime": {"sec": 0, "nsec": 0},
        "frame_locked": frame_locked,
        "metadata": [],
        "arrows": p.arrows,
        "cubes": p.cubes,
        "spheres": p.spheres,
        "cylinders": p.cylinders,
        "lines": p.lines,
        "triangles": [],
        "texts": p.texts,
        "models": [],
    })
}

/// `foxglove.SceneUpdate` adding or replacing `entities`.
pub(super) fn scene_update(entities: Vec<Value>) -> Value {
    json!({"deletions": [], "entities": entities})
}

/// LINE_STRIP, LINE_LOOP and LINE_LIST of `foxglove.LinePrimitive`.
pub(super) const LINE_STRIP: u32 = 0;
pub(super) const LINE_LOOP: u32 = 1;
pub(super) const LINE_LIST: u32 = 2;

/// `foxglove.LinePrimitive` through `points` (frame coordinates), `thickness` in pixels.
pub(super) fn line(kind: u32, points: &[[f64; 3]], thickness: f64, color: Value) -> Value {
    json!({
        "type": kind,
        "pose": pose([0.0; 3], 0.0),
        "thickness": thickness,
        "scale_invariant": true,
        "points": points.iter().map(|p| vec3(*p)).collect::<Vec<_>>(),
        "color": color,
        "colors": [],
        "indices": [],
    })
}

/// `foxglove.CubePrimitive` centred at `center`.
pub(super) fn cube(center: [f64; 3], size: [f64; 3], color: Value) -> Value {
    json!({"pose": pose(center, 0.0), "size": vec3(size), "color": color})
}

/// `foxglove.SpherePrimitive` centred at `center`.
pub(super) fn sphere(center: [f64; 3], diameter: f64, color: Value) -> Value {
    json!({"pose": pose(center, 0.0), "size": vec3([diameter; 3]), "color": color})
}

/// `foxglove.CylinderPrimitive`, a vertical cylinder centred at `center`.
pub(super) fn cylinder(center: [f64; 3], radius: f64, height: f64, color: Value) -> Value {
    json!({
        "pose": pose(center, 0.0),
        "size": vec3([2.0 * radius, 2.0 * radius, height]),
        "bottom_scale": 1.0,
        "top_scale": 1.0,
        "color": color,
    })
}

/// `foxglove.ArrowPrimitive` from `tail`, pointing at `elevation` above the
/// horizon and `azimuth` from +x towards +y.
pub(super) fn arrow(tail: [f64; 3], azimuth: f64, elevation: f64, length: f64, color: Value) -> Value {
    // An arrow points along its +x: yaw by the azimuth, then pitch up (−elevation about y).
    json!({
        "pose": {"position": vec3(tail), "orientation": quaternion(azimuth, -elevation)},
        "shaft_length": length * 0.8,
        "shaft_diameter": length * 0.04,
        "head_length": length * 0.2,
        "head_diameter": length * 0.1,
        "color": color,
    })
}

/// `foxglove.TextPrimitive`, a billboard label.
pub(super) fn text(position: [f64; 3], text: &str, color: Value) -> Value {
    json!({
        "pose": pose(position, 0.0),
        "billboard": true,
        "font_size": 14.0,
        "scale_invariant": true,
        "color": color,
        "text": text,
    })
}

/// Points of the `k`-sigma ellipse of the 2-D covariance `[[sxx, sxy], [sxy, syy]]` about `center`.
pub(super) fn ellipse(center: [f64; 2], cov: [[f64; 2]; 2], k: f64, z: f64) -> Vec<[f64; 3]> {
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
        let q = quaternion(std::f64::consts::FRAC_PI_2, std::f64::consts::FRAC_PI_2);
        let [x, y, z, w] = ["x", "y", "z", "w"].map(|k| q[k].as_f64().unwrap());
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
        assert_eq!(timestamp(2_000_000_007), json!({"sec": 2, "nsec": 7}));
    }
}
