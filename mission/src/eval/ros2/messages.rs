//! The ROS 2 messages of the ROS 2 profile as Rust structs whose fields follow
//! the `.msg` definitions in order, so that serializing one with a CDR serializer
//! gives ROS 2's bytes (fixed-size arrays as tuples, sequences and strings with
//! their length).

use serde::ser::{SerializeTuple, Serializer};
use serde::{Deserialize, Serialize};

/// `builtin_interfaces/Time` (also `Duration`, same fields).
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize)]
pub struct Time {
    pub sec: i32,
    pub nanosec: u32,
}

/// `std_msgs/Header`.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct Header {
    pub stamp: Time,
    pub frame_id: String,
}

/// `geometry_msgs/Point` and `geometry_msgs/Vector3`.
#[derive(Debug, Clone, Copy, Default, Serialize)]
pub struct Point {
    pub x: f64,
    pub y: f64,
    pub z: f64,
}

impl From<[f64; 3]> for Point {
    fn from([x, y, z]: [f64; 3]) -> Self {
        Point { x, y, z }
    }
}

/// `geometry_msgs/Quaternion`.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct Quaternion {
    pub x: f64,
    pub y: f64,
    pub z: f64,
    pub w: f64,
}

impl Default for Quaternion {
    fn default() -> Self {
        Quaternion { x: 0.0, y: 0.0, z: 0.0, w: 1.0 }
    }
}

impl From<[f64; 4]> for Quaternion {
    /// From (x, y, z, w).
    fn from([x, y, z, w]: [f64; 4]) -> Self {
        Quaternion { x, y, z, w }
    }
}

/// `geometry_msgs/Pose`.
#[derive(Debug, Clone, Copy, Default, Serialize)]
pub struct Pose {
    pub position: Point,
    pub orientation: Quaternion,
}

/// `geometry_msgs/PoseStamped`.
#[derive(Debug, Clone, Default, Serialize)]
pub struct PoseStamped {
    pub header: Header,
    pub pose: Pose,
}

/// `float64[36]`: serde writes arrays of at most 32 elements by itself.
fn float64_36<S: Serializer>(values: &[f64; 36], s: S) -> Result<S::Ok, S::Error> {
    let mut tuple = s.serialize_tuple(36)?;
    for v in values {
        tuple.serialize_element(v)?;
    }
    tuple.end()
}

/// `geometry_msgs/PoseWithCovariance`.
#[derive(Debug, Clone, Serialize)]
pub struct PoseWithCovariance {
    pub pose: Pose,
    /// Row-major 6 × 6 over (x, y, z, roll, pitch, yaw).
    #[serde(serialize_with = "float64_36")]
    pub covariance: [f64; 36],
}

/// `geometry_msgs/PoseWithCovarianceStamped`.
#[derive(Debug, Clone, Serialize)]
pub struct PoseWithCovarianceStamped {
    pub header: Header,
    pub pose: PoseWithCovariance,
}

/// `geometry_msgs/Transform`.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct Transform {
    pub translation: Point,
    pub rotation: Quaternion,
}

/// `geometry_msgs/TransformStamped`.
#[derive(Debug, Clone, Serialize)]
pub struct TransformStamped {
    pub header: Header,
    pub child_frame_id: String,
    pub transform: Transform,
}

/// `tf2_msgs/TFMessage`.
#[derive(Debug, Clone, Serialize)]
pub struct TfMessage {
    pub transforms: Vec<TransformStamped>,
}

/// `nav_msgs/Path`.
#[derive(Debug, Clone, Serialize)]
pub struct Path {
    pub header: Header,
    pub poses: Vec<PoseStamped>,
}

/// `std_msgs/ColorRGBA`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct ColorRgba {
    pub r: f32,
    pub g: f32,
    pub b: f32,
    pub a: f32,
}

/// `sensor_msgs/CompressedImage`.
#[derive(Debug, Clone, Default, Serialize)]
pub struct CompressedImage {
    pub header: Header,
    pub format: String,
    pub data: Vec<u8>,
}

/// `visualization_msgs/UVCoordinate`.
#[derive(Debug, Clone, Copy, Default, Serialize)]
pub struct UvCoordinate {
    pub u: f32,
    pub v: f32,
}

/// `visualization_msgs/MeshFile`.
#[derive(Debug, Clone, Default, Serialize)]
pub struct MeshFile {
    pub filename: String,
    pub data: Vec<u8>,
}

/// `visualization_msgs/Marker`.
#[derive(Debug, Clone, Default, Serialize)]
pub struct Marker {
    pub header: Header,
    pub ns: String,
    pub id: i32,
    #[serde(rename = "type")]
    pub kind: i32,
    pub action: i32,
    pub pose: Pose,
    pub scale: Point,
    pub color: ColorRgba,
    pub lifetime: Time,
    pub frame_locked: bool,
    pub points: Vec<Point>,
    pub colors: Vec<ColorRgba>,
    pub texture_resource: String,
    pub texture: CompressedImage,
    pub uv_coordinates: Vec<UvCoordinate>,
    pub text: String,
    pub mesh_resource: String,
    pub mesh_file: MeshFile,
    pub mesh_use_embedded_materials: bool,
}

/// `Marker` types and actions.
pub mod marker {
    pub const ARROW: i32 = 0;
    pub const CUBE: i32 = 1;
    pub const SPHERE: i32 = 2;
    pub const CYLINDER: i32 = 3;
    pub const LINE_STRIP: i32 = 4;
    pub const LINE_LIST: i32 = 5;
    pub const CUBE_LIST: i32 = 6;
    pub const SPHERE_LIST: i32 = 7;
    pub const TEXT_VIEW_FACING: i32 = 9;
    pub const ADD: i32 = 0;
    pub const DELETE: i32 = 2;
}

/// `visualization_msgs/MarkerArray`.
#[derive(Debug, Clone, Serialize)]
pub struct MarkerArray {
    pub markers: Vec<Marker>,
}

/// `dyfos_msgs/RendezvousAnswer`.
#[derive(Debug, Clone, Serialize)]
pub struct RendezvousAnswer {
    pub header: Header,
    pub step: u32,
    pub algorithm: String,
    pub x: [f64; 4],
    pub cost: f64,
    pub measurement_covariance: [f64; 4],
    pub posterior_covariance: [f64; 9],
    pub viewer_position: Point,
    pub viewer_yaw: f64,
    pub sensor_pose: Pose,
    pub evaluations: u64,
    pub rejected_workspace: u64,
    pub rejected_collision: u64,
    pub rejected_occlusion: u64,
    pub micros: u64,
    pub map_version: u64,
    pub stop: String,
}

/// `dyfos_msgs/Measurement`.
#[derive(Debug, Clone, Serialize)]
pub struct Measurement {
    pub header: Header,
    pub step: u32,
    pub status: String,
    pub position: Point,
    pub measurement_covariance: [f64; 4],
    pub viewer_position: Point,
    pub viewer_yaw: f64,
    pub predicted_cost: f64,
}

/// `dyfos_msgs/Ape`.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Ape {
    pub header: Header,
    pub sample: u64,
    pub step: u32,
    pub updated: bool,
    pub ape_m: f64,
}
