//! Foxglove's well-known messages as JSON values, with exactly the fields of the
//! schemas in `schemas/` (checked by the tests against the schemas themselves).

use crate::eval::mission_mcap::scene::{self, Arrow, Color, Cube, Cylinder, Entity, Line, LineKind, Sphere, Text};
use serde_json::{Value, json};

/// `{sec, nsec}` of a log time.
pub(super) fn timestamp(ns: u64) -> Value {
    json!({"sec": ns / 1_000_000_000, "nsec": ns % 1_000_000_000})
}

fn vec3(v: [f64; 3]) -> Value {
    json!({"x": v[0], "y": v[1], "z": v[2]})
}

/// A rotation by `yaw` about z, then `pitch` about the new y.
fn quaternion(yaw: f64, pitch: f64) -> Value {
    let [x, y, z, w] = scene::quaternion(yaw, pitch);
    json!({"x": x, "y": y, "z": z, "w": w})
}

fn pose(position: [f64; 3], yaw: f64) -> Value {
    json!({"position": vec3(position), "orientation": quaternion(yaw, 0.0)})
}

fn color(c: Color) -> Value {
    json!({"r": c[0], "g": c[1], "b": c[2], "a": c[3]})
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
pub(super) fn path_in_map(ns: u64, poses: &[(u64, [f64; 3])]) -> Value {
    let poses: Vec<Value> = poses.iter().map(|(_, p)| pose([p[0], p[1], 0.0], p[2])).collect();
    json!({"timestamp": timestamp(ns), "frame_id": "map", "poses": poses})
}

/// `foxglove.SceneEntity`, shown until replaced by the same id.
fn entity(ns: u64, e: &Entity) -> Value {
    let p = &e.primitives;
    json!({
        "timestamp": timestamp(ns),
        "frame_id": e.frame,
        "id": e.id,
        "lifetime": {"sec": 0, "nsec": 0},
        "frame_locked": e.frame_locked,
        "metadata": [],
        "arrows": p.arrows.iter().map(arrow).collect::<Vec<_>>(),
        "cubes": p.cubes.iter().map(cube).collect::<Vec<_>>(),
        "spheres": p.spheres.iter().map(sphere).collect::<Vec<_>>(),
        "cylinders": p.cylinders.iter().map(cylinder).collect::<Vec<_>>(),
        "lines": p.lines.iter().map(line).collect::<Vec<_>>(),
        "triangles": [],
        "texts": p.texts.iter().map(text).collect::<Vec<_>>(),
        "models": [],
    })
}

/// `foxglove.SceneUpdate` adding or replacing `entities`, all stamped `ns`.
pub(super) fn scene_update(ns: u64, entities: &[Entity]) -> Value {
    json!({"deletions": [], "entities": entities.iter().map(|e| entity(ns, e)).collect::<Vec<_>>()})
}

/// `foxglove.LinePrimitive` (its `type`: LINE_STRIP 0, LINE_LOOP 1, LINE_LIST 2).
fn line(l: &Line) -> Value {
    let kind = match l.kind {
        LineKind::Strip => 0,
        LineKind::Loop => 1,
        LineKind::List => 2,
    };
    json!({
        "type": kind,
        "pose": pose([0.0; 3], 0.0),
        "thickness": l.thickness,
        "scale_invariant": true,
        "points": l.points.iter().map(|p| vec3(*p)).collect::<Vec<_>>(),
        "color": color(l.color),
        "colors": [],
        "indices": [],
    })
}

/// `foxglove.CubePrimitive`.
fn cube(c: &Cube) -> Value {
    json!({"pose": pose(c.center, 0.0), "size": vec3(c.size), "color": color(c.color)})
}

/// `foxglove.SpherePrimitive`.
fn sphere(s: &Sphere) -> Value {
    json!({"pose": pose(s.center, 0.0), "size": vec3([s.diameter; 3]), "color": color(s.color)})
}

/// `foxglove.CylinderPrimitive`, a vertical cylinder.
fn cylinder(c: &Cylinder) -> Value {
    json!({
        "pose": pose(c.center, 0.0),
        "size": vec3([2.0 * c.radius, 2.0 * c.radius, c.height]),
        "bottom_scale": 1.0,
        "top_scale": 1.0,
        "color": color(c.color),
    })
}

/// `foxglove.ArrowPrimitive`.
fn arrow(a: &Arrow) -> Value {
    // An arrow points along its +x: yaw by the azimuth, then pitch up (−elevation about y).
    json!({
        "pose": {"position": vec3(a.tail), "orientation": quaternion(a.azimuth, -a.elevation)},
        "shaft_length": a.length * 0.8,
        "shaft_diameter": a.length * 0.04,
        "head_length": a.length * 0.2,
        "head_diameter": a.length * 0.1,
        "color": color(a.color),
    })
}

/// `foxglove.TextPrimitive`, a billboard label.
fn text(t: &Text) -> Value {
    json!({
        "pose": pose(t.position, 0.0),
        "billboard": true,
        "font_size": 14.0,
        "scale_invariant": true,
        "color": color(t.color),
        "text": t.text,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn timestamps_split_seconds_and_nanoseconds() {
        assert_eq!(timestamp(2_000_000_007), json!({"sec": 2, "nsec": 7}));
    }
}
