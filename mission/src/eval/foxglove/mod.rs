//! The Foxglove profile of a mission file ([`crate::eval::McapMission`],
//! [`crate::eval::McapProfile::Foxglove`]): Foxglove opens it with no configuration.
//!
//! Messages are JSON (`message_encoding = "json"`) with JSON-schema schemas
//! (`encoding = "jsonschema"`). Where Foxglove has a well-known schema —
//! `foxglove.FrameTransform`, `foxglove.SceneUpdate`, `foxglove.PoseInFrame`,
//! `foxglove.PosesInFrame` — the file carries Foxglove's own schema under its own
//! name (copied from `foxglove/foxglove-sdk`, MIT, in `schemas/`), so the 3D panel
//! draws it at once. The rendezvous exchange and the APE use schemas of their own
//! (`dyfos.*`), with the paper's names (`E`, `R`, `sigma_plus`, `ape_m`).
//!
//! | topic | schema | what it shows |
//! |---|---|---|
//! | `/tf` | `foxglove.FrameTransform` | the frames |
//! | `/map` | `foxglove.SceneUpdate` | obstacles (cylinders, boxes, voxels), waypoints, the sun's direction |
//! | `/rover/pose`, `/rover/path` | `foxglove.PoseInFrame`, `foxglove.PosesInFrame` | the true pose and path |
//! | `/rover/estimate/pose`, `/rover/estimate/path` | same | the EKF estimate and its path |
//! | `/rover/estimate/covariance` | `foxglove.SceneUpdate` | the estimate's 95 % position ellipse |
//! | `/viewer/pose` | `foxglove.PoseInFrame` | the viewer at take-off and at each rendezvous |
//! | `/viewer/camera` | `foxglove.SceneUpdate` | the camera frustum and the line of sight at each rendezvous |
//! | `/dyfos/rendezvous/request` | `dyfos.RendezvousRequest` | the a priori belief sent to the viewer |
//! | `/dyfos/rendezvous/answer` | `dyfos.RendezvousAnswer` | the daemon's x, E, R, Σ⁺, counts, time |
//! | `/dyfos/rendezvous/measurement` | `dyfos.Measurement` | the measurement and its R, or why none |
//! | `/dyfos/ape` | `dyfos.Ape` | the absolute position error per sample (plot `.ape_m`) |

mod scene;

use super::mission_mcap::{Encoding, Message, Topic};
use dyfos_shared::wire::mission::Observation;
use scene::timestamp;
use serde_json::{Value, json};

/// Foxglove's JSON schemas (MIT, `foxglove/foxglove-sdk` `schemas/jsonschema/`).
const FRAME_TRANSFORM: &str = include_str!("schemas/FrameTransform.json");
const SCENE_UPDATE: &str = include_str!("schemas/SceneUpdate.json");
const POSE_IN_FRAME: &str = include_str!("schemas/PoseInFrame.json");
const POSES_IN_FRAME: &str = include_str!("schemas/PosesInFrame.json");
/// Our own.
const REQUEST: &str = include_str!("schemas/dyfos.RendezvousRequest.json");
const ANSWER: &str = include_str!("schemas/dyfos.RendezvousAnswer.json");
const MEASUREMENT: &str = include_str!("schemas/dyfos.Measurement.json");
const APE: &str = include_str!("schemas/dyfos.Ape.json");

/// Every channel a Foxglove-profile mission file may declare: topic and schema
/// name (see [`schema`]), in the order of [`Topic::ALL`]. A file declares those
/// that carry messages.
pub const CHANNELS: [(&str, &str); 13] = [
    ("/tf", "foxglove.FrameTransform"),
    ("/map", "foxglove.SceneUpdate"),
    ("/rover/pose", "foxglove.PoseInFrame"),
    ("/rover/path", "foxglove.PosesInFrame"),
    ("/rover/estimate/pose", "foxglove.PoseInFrame"),
    ("/rover/estimate/path", "foxglove.PosesInFrame"),
    ("/rover/estimate/covariance", "foxglove.SceneUpdate"),
    ("/viewer/pose", "foxglove.PoseInFrame"),
    ("/viewer/camera", "foxglove.SceneUpdate"),
    ("/dyfos/rendezvous/request", "dyfos.RendezvousRequest"),
    ("/dyfos/rendezvous/answer", "dyfos.RendezvousAnswer"),
    ("/dyfos/rendezvous/measurement", "dyfos.Measurement"),
    ("/dyfos/ape", "dyfos.Ape"),
];

/// The JSON schema of a schema name in [`CHANNELS`].
pub fn schema(name: &str) -> Option<&'static str> {
    Some(match name {
        "foxglove.FrameTransform" => FRAME_TRANSFORM,
        "foxglove.SceneUpdate" => SCENE_UPDATE,
        "foxglove.PoseInFrame" => POSE_IN_FRAME,
        "foxglove.PosesInFrame" => POSES_IN_FRAME,
        "dyfos.RendezvousRequest" => REQUEST,
        "dyfos.RendezvousAnswer" => ANSWER,
        "dyfos.Measurement" => MEASUREMENT,
        "dyfos.Ape" => APE,
        _ => return None,
    })
}

/// The Foxglove profile's encoding: JSON.
pub(crate) struct Json;

impl Encoding for Json {
    fn schema(&self, topic: Topic) -> Result<(&'static str, Vec<u8>), String> {
        let name = CHANNELS[topic as usize].1;
        let schema = schema(name).ok_or_else(|| format!("no schema {name}"))?;
        Ok((name, schema.as_bytes().to_vec()))
    }

    fn encode(&mut self, _topic: Topic, ns: u64, message: &Message) -> Result<Vec<u8>, String> {
        Ok(json(ns, message).to_string().into_bytes())
    }
}

/// The JSON of one message at `ns`.
fn json(ns: u64, message: &Message) -> Value {
    match message {
        Message::Transform { parent, child, position, yaw, pitch } => {
            scene::frame_transform(ns, parent, child, *position, *yaw, *pitch)
        }
        Message::Pose { position, yaw } => scene::pose_in_map(ns, *position, *yaw),
        Message::Belief(b) => scene::pose_in_map(ns, [b.mean.x, b.mean.y, 0.0], b.mean.z),
        Message::Path(poses) => scene::path_in_map(ns, poses),
        Message::Scene(entities) => scene::scene_update(ns, entities),
        Message::Request(r) => {
            let mean: [f64; 3] = r.belief.mean.into();
            json!({"timestamp": timestamp(ns), "step": r.step, "mean": mean, "cov": r.belief.cov.to_rows()})
        }
        Message::Answer(a) => {
            let mut message = json!({"timestamp": timestamp(ns)});
            if let (Some(obj), Ok(Value::Object(fields))) = (message.as_object_mut(), serde_json::to_value(a)) {
                obj.extend(fields.into_iter().filter(|(k, _)| k != "sim_time"));
            }
            message
        }
        Message::Measurement(m) => {
            let mut fields = serde_json::Map::new();
            fields.insert("timestamp".into(), timestamp(ns));
            fields.insert("step".into(), json!(m.step));
            match &m.observation {
                Observation::Observed { position, r } => {
                    fields.insert("status".into(), json!("observed"));
                    fields.insert("position".into(), json!(position));
                    fields.insert("R".into(), json!(r.to_rows()));
                }
                Observation::NotObserved(why) => {
                    fields.insert("status".into(), json!(why.name()));
                }
            }
            if let Some(v) = m.viewer {
                fields.insert("viewer_position".into(), json!(v.position));
                fields.insert("viewer_yaw".into(), json!(v.yaw));
            }
            if let Some(e) = m.predicted_cost {
                fields.insert("predicted_E".into(), json!(e));
            }
            Value::Object(fields)
        }
        Message::Ape { sample, step, updated, ape } => {
            json!({"timestamp": timestamp(ns), "sample": sample, "step": step, "updated": updated, "ape_m": ape})
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::eval::mission_mcap::Topic;

    #[test]
    fn every_topic_has_its_schema() {
        for (topic, (name, schema_name)) in Topic::ALL.iter().zip(CHANNELS) {
            assert_eq!(topic.name(), name);
            let s: Value = serde_json::from_str(schema(schema_name).unwrap()).unwrap();
            assert_eq!(s["title"], schema_name);
        }
    }
}
