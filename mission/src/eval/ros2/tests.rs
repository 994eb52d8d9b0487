//! The ROS 2 profile's bytes against ROS 2's own serializer, and its markers.

use super::messages::*;
use super::*;
use crate::eval::mission_mcap::scene::{Cube, Line, Primitives, color};

// Golden messages: the bytes of rclpy's `serialize_message` (ROS 2 jazzy,
// rmw_fastrtps_cpp, from the PyPI wheels) for the messages built in each test,
// with the alignment padding set to zero. Fast CDR leaves padding bytes
// uninitialized (they differed between runs); every other byte is rclpy's.

const POSE_WITH_COVARIANCE_STAMPED: &[&str] = &[
    "00010000030000000065cd1d040000006d617000000000000000f83f00000000000002c0000000000000000000000000",
    "000000000000000000000000000000000000d03f000000000000e83f7b14ae47e17a843ffca9f1d24d62603f00000000",
    "0000000000000000000000000000000000000000fca9f1d24d62503ffca9f1d24d62603f7b14ae47e17a943f00000000",
    "000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000",
    "000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000",
    "000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000",
    "00000000000000000000000000000000000000000000000000000000fca9f1d24d62503f000000000000000000000000",
    "0000000000000000000000000000000000000000b81e85eb51b89e3f",
];

const MARKER: &[&str] = &[
    "0001000001000000020000000700000063616d657261000007000000766f78656c730000040000000600000000000000",
    "000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000",
    "00000000000000000000f03f9a9999999999b93f9a9999999999b93f9a9999999999b93f6666e63e0000003f6666263f",
    "0000803f00000000000000000100000002000000000000000000f03f0000000000000040000000000000084000000000",
    "000010400000000000001440000000000000184000000000010000000000000000000000000000000100000000000000",
    "010000000000000000000000000000000300000031320000010000000000000001000000000000000000000000",
];

const PATH: &[&str] = &[
    "000100000700000000000000040000006d617000020000000000000080b2e60e040000006d6170000000000000000000",
    "000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000",
    "0000f03f0100000080b2e60e040000006d617000000000000000f03f0000000000000000000000000000000000000000",
    "0000000000000000000000000000000000000000000000000000f03f",
];

const TRANSFORM_STAMPED: &[&str] = &[
    "0001000002000000000000000700000076696577657200000700000063616d65726100009a9999999999b93f00000000",
    "000000009a9999999999a9bf0000000000000000000000000000e03f00000000000000009a9999999999e93f",
];

fn bytes(hex: &[&str]) -> Vec<u8> {
    let hex = hex.concat();
    (0..hex.len()).step_by(2).map(|i| u8::from_str_radix(&hex[i..i + 2], 16).unwrap()).collect()
}

fn stamped(sec: i32, nanosec: u32, frame: &str) -> Header {
    Header { stamp: Time { sec, nanosec }, frame_id: frame.into() }
}

#[test]
fn a_pose_with_covariance_is_rclpys_bytes() {
    let mut covariance = [0.0; 36];
    for (k, v) in [(0, 0.01), (1, 0.002), (6, 0.002), (7, 0.02), (35, 0.03), (5, 0.001), (30, 0.001)] {
        covariance[k] = v;
    }
    let m = PoseWithCovarianceStamped {
        header: stamped(3, 500_000_000, "map"),
        pose: PoseWithCovariance {
            pose: Pose {
                position: [1.5, -2.25, 0.0].into(),
                orientation: Quaternion { x: 0.0, y: 0.0, z: 0.25, w: 0.75 },
            },
            covariance,
        },
    };
    assert_eq!(cdr(&m).unwrap(), bytes(POSE_WITH_COVARIANCE_STAMPED));
}

#[test]
fn a_marker_is_rclpys_bytes() {
    let m = Marker {
        header: stamped(1, 2, "camera"),
        ns: "voxels".into(),
        id: 4,
        kind: marker::CUBE_LIST,
        action: marker::ADD,
        scale: [0.1; 3].into(),
        color: ColorRgba { r: 0.45, g: 0.5, b: 0.65, a: 1.0 },
        frame_locked: true,
        points: vec![[1.0, 2.0, 3.0].into(), [4.0, 5.0, 6.0].into()],
        text: "12".into(),
        ..Marker::default()
    };
    assert_eq!(cdr(&m).unwrap(), bytes(MARKER));
}

#[test]
fn a_path_and_a_transform_are_rclpys_bytes() {
    let poses = (0..2)
        .map(|k| PoseStamped {
            header: stamped(k, 250_000_000, "map"),
            pose: Pose { position: [k as f64, 0.0, 0.0].into(), orientation: Quaternion::default() },
        })
        .collect();
    let path = super::messages::Path { header: stamped(7, 0, "map"), poses };
    assert_eq!(cdr(&path).unwrap(), bytes(PATH));
    let tf = TransformStamped {
        header: stamped(2, 0, "viewer"),
        child_frame_id: "camera".into(),
        transform: Transform {
            translation: [0.1, 0.0, -0.05].into(),
            rotation: Quaternion { x: 0.0, y: 0.5, z: 0.0, w: 0.8 },
        },
    };
    assert_eq!(cdr(&tf).unwrap(), bytes(TRANSFORM_STAMPED));
}

#[test]
fn every_channel_has_a_full_definition() {
    for (topic, (name, ty)) in Topic::ALL.iter().zip(CHANNELS) {
        assert_eq!(topic.name(), name);
        let (schema_name, text) = Cdr::default().schema(*topic).unwrap();
        assert_eq!(schema_name, ty);
        let text = String::from_utf8(text).unwrap();
        assert!(text.starts_with(definitions::msg(ty).unwrap()), "{ty}");
    }
}

#[test]
fn stamps_are_split_and_bounded() {
    let h = header(2_000_000_007, "map").unwrap();
    assert_eq!((h.stamp.sec, h.stamp.nanosec, h.frame_id.as_str()), (2, 7, "map"));
    assert!(header(u64::MAX, "map").unwrap_err().contains("past what a ROS 2 stamp holds"));
}

fn line_of_sight(points: usize) -> Message {
    let mut p = Primitives::default();
    for _ in 0..points {
        let points = vec![[0.0; 3], [1.0, 1.0, 1.0]];
        p.lines.push(Line { kind: LineKind::List, points, thickness: 2.0, color: color(0.0, 1.0, 0.0, 1.0) });
    }
    Message::Scene(vec![Entity::new("map", "line_of_sight", false, p)])
}

#[test]
fn markers_an_entity_no_longer_has_are_deleted() {
    let mut cdr = Cdr::default();
    let ids = |markers: Vec<Marker>| markers.iter().map(|m| (m.ns.clone(), m.id, m.action)).collect::<Vec<_>>();
    let sight = |n| (String::from("line_of_sight"), n, marker::ADD);
    let gone = |n| (String::from("line_of_sight"), n, marker::DELETE);
    let Message::Scene(two) = line_of_sight(2) else { unreachable!() };
    let Message::Scene(none) = line_of_sight(0) else { unreachable!() };
    assert_eq!(ids(cdr.markers(Topic::ViewerCamera, 1, &two).unwrap()), [sight(0), sight(1)]);
    assert_eq!(ids(cdr.markers(Topic::ViewerCamera, 2, &none).unwrap()), [gone(0), gone(1)]);
    assert_eq!(ids(cdr.markers(Topic::ViewerCamera, 3, &none).unwrap()), []);
    // Entities are counted per topic: the same id elsewhere is another set of markers.
    assert_eq!(ids(cdr.markers(Topic::Map, 4, &two).unwrap()), [sight(0), sight(1)]);
    assert!(!cdr.encode(Topic::ViewerCamera, 5, &line_of_sight(1)).unwrap().is_empty());
}

#[test]
fn cubes_alike_are_one_list_and_a_loop_closes() {
    let mut p = Primitives::default();
    for k in 0..3 {
        p.cubes.push(Cube { center: [k as f64, 0.0, 0.0], size: [0.2; 3], color: color(0.5, 0.5, 0.5, 1.0) });
    }
    let ring = vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0]];
    p.lines.push(Line { kind: LineKind::Loop, points: ring, thickness: 2.0, color: color(0.0, 0.0, 1.0, 1.0) });
    let markers = entity_markers(5, &Entity::new("map", "voxels", false, p)).unwrap();
    assert_eq!(
        markers.iter().map(|m| (m.id, m.kind)).collect::<Vec<_>>(),
        [(0, marker::CUBE_LIST), (1, marker::LINE_STRIP)]
    );
    assert_eq!(markers[0].points.len(), 3);
    assert_eq!(markers[0].scale.x, 0.2);
    assert_eq!(markers[1].points.len(), 4);
    assert_eq!((markers[1].points[3].x, markers[1].points[3].y), (0.0, 0.0));
    assert_eq!(markers[1].scale.x, 2.0 * LINE_WIDTH_PER_PIXEL);
    assert_eq!(markers[1].header.stamp.nanosec, 5);
}
