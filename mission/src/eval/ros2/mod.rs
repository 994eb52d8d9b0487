//! The ROS 2 profile of a mission file ([`crate::eval::McapMission`],
//! [`crate::eval::McapProfile::Ros2`]): what rosbag2 (jazzy) writes when it
//! records the same topics, so `ros2 bag play`, RViz and every ROS 2 MCAP reader
//! take it as a bag.
//!
//! The header's profile is `ros2`; messages are CDR (`cdr`: XCDR1 little-endian
//! after the 4-byte encapsulation header `00 01 00 00`, as rmw serializes them);
//! schemas are `ros2msg`, named `pkg/msg/Type`, each holding the type's `.msg`
//! text and those of the types it uses, concatenated as rosbag2 does
//! ([`definitions`]). Stamps (`builtin_interfaces/Time`) are simulated time, the
//! same as the log times. Channels carry no QoS metadata: `ros2 bag play` then
//! publishes with its default QoS (reliable, volatile).
//!
//! | topic | type |
//! |---|---|
//! | `/tf` | `tf2_msgs/msg/TFMessage`, one transform each |
//! | `/map`, `/rover/estimate/covariance`, `/viewer/camera` | `visualization_msgs/msg/MarkerArray` |
//! | `/rover/pose`, `/viewer/pose` | `geometry_msgs/msg/PoseStamped` |
//! | `/rover/path`, `/rover/estimate/path` | `nav_msgs/msg/Path` (each pose stamped with its sample's time) |
//! | `/rover/estimate/pose`, `/dyfos/rendezvous/request` | `geometry_msgs/msg/PoseWithCovarianceStamped` (x, y, yaw; covariance rows and columns 0, 1, 5) |
//! | `/dyfos/rendezvous/answer` | `dyfos_msgs/msg/RendezvousAnswer` |
//! | `/dyfos/rendezvous/measurement` | `dyfos_msgs/msg/Measurement` (NaN where the viewer had no value) |
//! | `/dyfos/ape` | `dyfos_msgs/msg/Ape` |
//!
//! The `dyfos_msgs` types are defined in the `dyfos_msgs` package (`ros/dyfos_msgs/msg/`) and travel in the
//! file's schemas, so any MCAP reader decodes them; `ros2 bag play` publishes them
//! where `dyfos_msgs` is installed (`ros/install.sh`), and skips those three
//! topics elsewhere.
//!
//! Foxglove's scene entities become markers: the entity's id is the marker
//! namespace, its primitives the ids 0, 1, …; cubes or spheres of one size and
//! colour become one `CUBE_LIST` / `SPHERE_LIST`, a closed line a `LINE_STRIP`
//! back to its start, lines [`LINE_WIDTH_PER_PIXEL`] wide per pixel of Foxglove's
//! thickness, labels [`TEXT_HEIGHT`] high. Markers an entity no longer has are
//! deleted.

pub mod definitions;
mod messages;

use super::mission_mcap::scene::{self, Entity, LineKind};
use super::mission_mcap::{AnswerRecord, Encoding, Message, Topic};
use dyfos_shared::posterior::Belief;
use dyfos_shared::wire::mission::{Measurement, Observation};
use messages::{Header, Marker, MarkerArray, Point, Pose, PoseStamped, Time, marker};
use serde::Serialize;
use std::collections::BTreeMap;

/// Every channel a ROS 2-profile mission file may declare: topic and ROS 2 type,
/// in the order of [`Topic::ALL`]. A file declares those that carry messages.
pub const CHANNELS: [(&str, &str); 13] = [
    ("/tf", "tf2_msgs/msg/TFMessage"),
    ("/map", "visualization_msgs/msg/MarkerArray"),
    ("/rover/pose", "geometry_msgs/msg/PoseStamped"),
    ("/rover/path", "nav_msgs/msg/Path"),
    ("/rover/estimate/pose", "geometry_msgs/msg/PoseWithCovarianceStamped"),
    ("/rover/estimate/path", "nav_msgs/msg/Path"),
    ("/rover/estimate/covariance", "visualization_msgs/msg/MarkerArray"),
    ("/viewer/pose", "geometry_msgs/msg/PoseStamped"),
    ("/viewer/camera", "visualization_msgs/msg/MarkerArray"),
    ("/dyfos/rendezvous/request", "geometry_msgs/msg/PoseWithCovarianceStamped"),
    ("/dyfos/rendezvous/answer", "dyfos_msgs/msg/RendezvousAnswer"),
    ("/dyfos/rendezvous/measurement", "dyfos_msgs/msg/Measurement"),
    ("/dyfos/ape", "dyfos_msgs/msg/Ape"),
];

/// Line width in metres per pixel of the Foxglove profile's line thickness
/// (RViz draws lines in metres).
pub const LINE_WIDTH_PER_PIXEL: f64 = 0.01;
/// Height of text markers (waypoint numbers), m.
pub const TEXT_HEIGHT: f64 = 0.3;
/// CDR, little-endian, no options: the encapsulation header rmw writes.
const ENCAPSULATION: [u8; 4] = [0x00, 0x01, 0x00, 0x00];

/// `value` as a ROS 2 serialized message: the encapsulation header, then CDR.
fn cdr(value: &impl Serialize) -> Result<Vec<u8>, String> {
    let mut bytes = ENCAPSULATION.to_vec();
    // Alignment counts from the first byte after the encapsulation header, which
    // is where the serializer's own count starts.
    cdr_encoding::to_writer::<_, byteorder::LittleEndian, _>(&mut bytes, value).map_err(|e| e.to_string())?;
    Ok(bytes)
}

/// One `/dyfos/ape` message of a ROS 2 profile file (`dyfos_msgs/Ape` in CDR):
/// the sample number and its error, m.
pub fn decode_ape(data: &[u8]) -> Result<(u64, f64), String> {
    let body = data
        .strip_prefix(&ENCAPSULATION)
        .ok_or("not little-endian CDR (its encapsulation header is not 00 01 00 00)")?;
    let (ape, _) = cdr_encoding::from_bytes::<messages::Ape, byteorder::LittleEndian>(body)
        .map_err(|e| format!("not a dyfos_msgs/Ape: {e}"))?;
    Ok((ape.sample, ape.ape_m))
}

/// The ROS 2 profile's encoding: CDR. It remembers how many markers each entity
/// drew, to delete those a later version of the entity no longer has.
#[derive(Debug, Default)]
pub(crate) struct Cdr {
    drawn: BTreeMap<(Topic, String), usize>,
}

impl Cdr {
    /// The markers of `entities` on `topic` at `ns`, and the deletions of those
    /// the entities drew before and no longer have.
    fn markers(&mut self, topic: Topic, ns: u64, entities: &[Entity]) -> Result<Vec<Marker>, String> {
        let mut markers = Vec::new();
        for e in entities {
            let drawn = entity_markers(ns, e)?;
            let before = self.drawn.insert((topic, e.id.clone()), drawn.len()).unwrap_or(0);
            let count = drawn.len();
            markers.extend(drawn);
            for id in count..before {
                markers.push(Marker {
                    header: header(ns, e.frame)?,
                    ns: e.id.clone(),
                    id: marker_id(id)?,
                    action: marker::DELETE,
                    ..Marker::default()
                });
            }
        }
        Ok(markers)
    }
}

impl Encoding for Cdr {
    fn schema(&self, topic: Topic) -> Result<(&'static str, Vec<u8>), String> {
        let name = CHANNELS[topic as usize].1;
        Ok((name, definitions::full_text(name)?.into_bytes()))
    }

    fn encode(&mut self, topic: Topic, ns: u64, message: &Message) -> Result<Vec<u8>, String> {
        let header = header(ns, "map")?;
        match message {
            Message::Transform { parent, child, position, yaw, pitch } => cdr(&messages::TfMessage {
                transforms: vec![messages::TransformStamped {
                    header: Header { frame_id: parent.to_string(), ..header },
                    child_frame_id: child.to_string(),
                    transform: messages::Transform {
                        translation: (*position).into(),
                        rotation: scene::quaternion(*yaw, *pitch).into(),
                    },
                }],
            }),
            Message::Pose { position, yaw } => cdr(&PoseStamped { header, pose: pose(*position, *yaw) }),
            Message::Belief(belief) => cdr(&belief_pose(header, belief)),
            Message::Request(r) => cdr(&belief_pose(header, &r.belief)),
            Message::Path(poses) => {
                let poses = poses
                    .iter()
                    .map(|(t, p)| {
                        Ok(PoseStamped { header: self::header(*t, "map")?, pose: pose([p[0], p[1], 0.0], p[2]) })
                    })
                    .collect::<Result<_, String>>()?;
                cdr(&messages::Path { header, poses })
            }
            Message::Scene(entities) => cdr(&MarkerArray { markers: self.markers(topic, ns, entities)? }),
            Message::Answer(a) => cdr(&answer(header, a)),
            Message::Measurement(m) => cdr(&measurement(header, m)),
            Message::Ape { sample, step, updated, ape } => {
                cdr(&messages::Ape { header, sample: *sample, step: *step, updated: *updated, ape_m: *ape })
            }
        }
    }
}

/// A header at `ns` in `frame`; an error past `builtin_interfaces/Time`'s range.
fn header(ns: u64, frame: &str) -> Result<Header, String> {
    let sec = i32::try_from(ns / 1_000_000_000)
        .map_err(|_| format!("simulated time {} s is past what a ROS 2 stamp holds", ns / 1_000_000_000))?;
    // Below 10⁹, so it fits.
    let nanosec = (ns % 1_000_000_000) as u32;
    Ok(Header { stamp: Time { sec, nanosec }, frame_id: frame.to_string() })
}

fn pose(position: [f64; 3], yaw: f64) -> Pose {
    Pose { position: position.into(), orientation: scene::quaternion(yaw, 0.0).into() }
}

/// A belief (x, y, θ) as a pose on the ground with its covariance in rows and
/// columns x, y and yaw (0, 1, 5) of the 6 × 6.
fn belief_pose(header: Header, belief: &Belief) -> messages::PoseWithCovarianceStamped {
    const AXES: [usize; 3] = [0, 1, 5];
    let c = belief.cov.to_rows();
    let mut covariance = [0.0; 36];
    for (i, row) in AXES.iter().enumerate() {
        for (j, col) in AXES.iter().enumerate() {
            covariance[row * 6 + col] = c[i][j];
        }
    }
    let m = belief.mean;
    messages::PoseWithCovarianceStamped {
        header,
        pose: messages::PoseWithCovariance { pose: pose([m.x, m.y, 0.0], m.z), covariance },
    }
}

fn answer(header: Header, a: &AnswerRecord) -> messages::RendezvousAnswer {
    let [[r00, r01], [r10, r11]] = a.r;
    messages::RendezvousAnswer {
        header,
        step: a.step,
        algorithm: a.algorithm.clone(),
        x: a.x,
        cost: a.e,
        measurement_covariance: [r00, r01, r10, r11],
        posterior_covariance: std::array::from_fn(|k| a.sigma_plus[k / 3][k % 3]),
        viewer_position: a.viewer_position.into(),
        viewer_yaw: a.viewer_yaw,
        sensor_pose: Pose { position: a.sensor_position.into(), orientation: a.sensor_quaternion.into() },
        evaluations: a.evaluations.total,
        rejected_workspace: a.evaluations.workspace,
        rejected_collision: a.evaluations.collision,
        rejected_occlusion: a.evaluations.occlusion,
        micros: a.micros,
        map_version: a.map_version,
        stop: a.stop.clone(),
    }
}

fn measurement(header: Header, m: &Measurement) -> messages::Measurement {
    let nan = f64::NAN;
    let (status, position, r) = match &m.observation {
        Observation::Observed { position, r } => {
            let [[r00, r01], [r10, r11]] = r.to_rows();
            ("observed", [position[0], position[1], 0.0], [r00, r01, r10, r11])
        }
        Observation::NotObserved(why) => (why.name(), [nan; 3], [nan; 4]),
    };
    let (viewer_position, viewer_yaw) = m.viewer.map_or(([nan; 3], nan), |v| (v.position, v.yaw));
    messages::Measurement {
        header,
        step: m.step,
        status: status.to_string(),
        position: position.into(),
        measurement_covariance: r,
        viewer_position: viewer_position.into(),
        viewer_yaw,
        predicted_cost: m.predicted_cost.unwrap_or(nan),
    }
}

fn marker_id(k: usize) -> Result<i32, String> {
    i32::try_from(k).map_err(|_| format!("marker id {k} is past int32"))
}

fn rgba(c: scene::Color) -> messages::ColorRgba {
    messages::ColorRgba { r: c[0] as f32, g: c[1] as f32, b: c[2] as f32, a: c[3] as f32 }
}

/// The markers of one entity at `ns`: namespace = the entity's id, ids 0, 1, … in
/// the order cylinders, cubes, spheres, lines, texts, arrows.
fn entity_markers(ns: u64, e: &Entity) -> Result<Vec<Marker>, String> {
    let base = Marker {
        header: header(ns, e.frame)?,
        ns: e.id.clone(),
        action: marker::ADD,
        frame_locked: e.frame_locked,
        ..Marker::default()
    };
    let p = &e.primitives;
    let mut out: Vec<Marker> = Vec::new();
    let mut push = |kind: i32, pose: Pose, scale: [f64; 3], color: scene::Color, points: Vec<Point>, text: &str| {
        out.push(Marker {
            kind,
            pose,
            scale: scale.into(),
            color: rgba(color),
            points,
            text: text.to_string(),
            ..base.clone()
        });
    };
    let at = |center: [f64; 3]| pose(center, 0.0);
    for c in &p.cylinders {
        push(marker::CYLINDER, at(c.center), [2.0 * c.radius, 2.0 * c.radius, c.height], c.color, vec![], "");
    }
    // Many cubes (or spheres) alike are one list marker: a voxel map is one marker, not thousands.
    match &p.cubes[..] {
        [first, rest @ ..]
            if !rest.is_empty() && rest.iter().all(|c| c.size == first.size && c.color == first.color) =>
        {
            let points = p.cubes.iter().map(|c| c.center.into()).collect();
            push(marker::CUBE_LIST, Pose::default(), first.size, first.color, points, "");
        }
        cubes => {
            for c in cubes {
                push(marker::CUBE, at(c.center), c.size, c.color, vec![], "");
            }
        }
    }
    match &p.spheres[..] {
        [first, rest @ ..]
            if !rest.is_empty() && rest.iter().all(|s| s.diameter == first.diameter && s.color == first.color) =>
        {
            let points = p.spheres.iter().map(|s| s.center.into()).collect();
            push(marker::SPHERE_LIST, Pose::default(), [first.diameter; 3], first.color, points, "");
        }
        spheres => {
            for s in spheres {
                push(marker::SPHERE, at(s.center), [s.diameter; 3], s.color, vec![], "");
            }
        }
    }
    for l in &p.lines {
        let mut points: Vec<Point> = l.points.iter().map(|p| (*p).into()).collect();
        let kind = match l.kind {
            LineKind::Strip => marker::LINE_STRIP,
            LineKind::Loop => {
                if let Some(first) = l.points.first() {
                    points.push((*first).into());
                }
                marker::LINE_STRIP
            }
            LineKind::List => marker::LINE_LIST,
        };
        let width = l.thickness * LINE_WIDTH_PER_PIXEL;
        push(kind, Pose::default(), [width, 0.0, 0.0], l.color, points, "");
    }
    for t in &p.texts {
        push(marker::TEXT_VIEW_FACING, at(t.position), [0.0, 0.0, TEXT_HEIGHT], t.color, vec![], &t.text);
    }
    for a in &p.arrows {
        // RViz's arrow: along +x of its pose, scale = (length, shaft diameter, head diameter).
        let pose = Pose { position: a.tail.into(), orientation: scene::quaternion(a.azimuth, -a.elevation).into() };
        push(marker::ARROW, pose, [a.length, a.length * 0.04, a.length * 0.1], a.color, vec![], "");
    }
    for (k, m) in out.iter_mut().enumerate() {
        m.id = marker_id(k)?;
    }
    Ok(out)
}

#[cfg(test)]
mod tests;
