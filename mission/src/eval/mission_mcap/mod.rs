//! A mission as an MCAP file (the storage format of ROS 2 bags): [`McapMission`]
//! gathers what a process knows of a mission and writes it in one of two
//! profiles ([`McapProfile`]): Foxglove's JSON schemas, which Foxglove opens with
//! no configuration ([`super::foxglove`]), or ROS 2 messages in CDR as rosbag2
//! writes them, for `ros2 bag play` and RViz ([`super::ros2`]). Both carry the same
//! topics with the same values; only the encoding differs.
//!
//! Everything is in the `map` frame (REP 103: x east, y north, z up, metres),
//! stamped with simulated time (log time = publish time = the message's stamp, in
//! ns). The frames, on `/tf`: `map → rover` (true pose), `map → rover_estimate`
//! (EKF mean), `map → viewer` and `viewer → camera` (the camera's mount and
//! downward pitch, sent with each viewer pose).
//!
//! | topic | what it shows |
//! |---|---|
//! | `/tf` | the frames above |
//! | `/map` | obstacles (cylinders, boxes, voxels), waypoints, the sun's direction |
//! | `/rover/pose`, `/rover/path` | the true pose and path |
//! | `/rover/estimate/pose`, `/rover/estimate/path` | the EKF estimate and its path |
//! | `/rover/estimate/covariance` | the estimate's 95 % position ellipse |
//! | `/viewer/pose` | the viewer at take-off and at each rendezvous |
//! | `/viewer/camera` | the camera frustum and the line of sight at each rendezvous |
//! | `/dyfos/rendezvous/request` | the a priori belief sent to the viewer |
//! | `/dyfos/rendezvous/answer` | the daemon's x, E, R, Σ⁺, counts, time |
//! | `/dyfos/rendezvous/measurement` | the measurement and its R, or why none |
//! | `/dyfos/ape` | the absolute position error per sample |
//!
//! A file declares only the channels that carry messages (a rover without a
//! viewer has no `/viewer/camera`), each when its first message is written.
//! Messages are gathered in memory and written at the end, sorted by log time
//! (ties keep the order above), so the same recorded data gives the same bytes.
//! Chunks are not compressed (the crate is built without zstd/lz4).
//!
//! ```
//! use dyfos_mission::eval::{McapMission, McapProfile};
//! use dyfos_mission::mission::Mission;
//!
//! let mission = Mission::builtin();
//! let mut mcap = McapMission::new(&mission);
//! mcap.record_request(1, 0.0, &mission.initial_belief);
//! for profile in [McapProfile::Foxglove, McapProfile::Ros2] {
//!     let bytes = mcap.to_bytes(profile)?;
//!     let summary = mcap::Summary::read(&bytes)?.expect("a summary section");
//!     assert_eq!(summary.stats.unwrap().message_count, mcap.message_count() as u64);
//! }
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

pub(crate) mod scene;

use super::MissionTrace;
use super::{foxglove, ros2};
use crate::mission::Mission;
use dyfos_shared::answer::{Answer, EvalStats};
use dyfos_shared::params::Params;
use dyfos_shared::posterior::Belief;
use dyfos_shared::wire::mission::{Estimate, Measurement, Observation, Phase, TrueState};
use dyfos_shared::world::{Obstacle, World};
use scene::{Entity, LineKind, Primitives, color, nanos};
use serde_json::Value;
use std::collections::BTreeMap;
use std::collections::btree_map::Entry;
use std::path::Path;

/// How a mission file encodes its messages.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Default, clap::ValueEnum)]
pub enum McapProfile {
    /// JSON with Foxglove's JSON schemas: Foxglove opens the file as is.
    #[default]
    Foxglove,
    /// ROS 2 messages in CDR with `ros2msg` schemas, as rosbag2 writes them:
    /// `ros2 bag play`, RViz, and every ROS 2 MCAP reader.
    Ros2,
}

impl McapProfile {
    /// The name on the command line (`foxglove`, `ros2`).
    pub fn name(self) -> &'static str {
        match self {
            McapProfile::Foxglove => "foxglove",
            McapProfile::Ros2 => "ros2",
        }
    }

    /// The MCAP header's profile (`""` for none), the channels' message encoding
    /// and the schemas' encoding.
    fn encodings(self) -> (&'static str, &'static str, &'static str) {
        match self {
            McapProfile::Foxglove => ("", "json", "jsonschema"),
            McapProfile::Ros2 => ("ros2", "cdr", "ros2msg"),
        }
    }
}

/// The topics of a mission file, in the order ties in log time are written.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Topic {
    /// `/tf`
    Tf,
    /// `/map`
    Map,
    /// `/rover/pose`
    RoverPose,
    /// `/rover/path`
    RoverPath,
    /// `/rover/estimate/pose`
    EstimatePose,
    /// `/rover/estimate/path`
    EstimatePath,
    /// `/rover/estimate/covariance`
    EstimateCovariance,
    /// `/viewer/pose`
    ViewerPose,
    /// `/viewer/camera`
    ViewerCamera,
    /// `/dyfos/rendezvous/request`
    Request,
    /// `/dyfos/rendezvous/answer`
    Answer,
    /// `/dyfos/rendezvous/measurement`
    Measurement,
    /// `/dyfos/ape`
    Ape,
}

impl Topic {
    /// Every topic.
    pub const ALL: [Topic; 13] = [
        Topic::Tf,
        Topic::Map,
        Topic::RoverPose,
        Topic::RoverPath,
        Topic::EstimatePose,
        Topic::EstimatePath,
        Topic::EstimateCovariance,
        Topic::ViewerPose,
        Topic::ViewerCamera,
        Topic::Request,
        Topic::Answer,
        Topic::Measurement,
        Topic::Ape,
    ];

    /// The topic's name in the file.
    pub fn name(self) -> &'static str {
        match self {
            Topic::Tf => "/tf",
            Topic::Map => "/map",
            Topic::RoverPose => "/rover/pose",
            Topic::RoverPath => "/rover/path",
            Topic::EstimatePose => "/rover/estimate/pose",
            Topic::EstimatePath => "/rover/estimate/path",
            Topic::EstimateCovariance => "/rover/estimate/covariance",
            Topic::ViewerPose => "/viewer/pose",
            Topic::ViewerCamera => "/viewer/camera",
            Topic::Request => "/dyfos/rendezvous/request",
            Topic::Answer => "/dyfos/rendezvous/answer",
            Topic::Measurement => "/dyfos/rendezvous/measurement",
            Topic::Ape => "/dyfos/ape",
        }
    }
}

/// One message of a mission file before it is encoded: what it says.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum Message {
    /// Frame `child` sits at `position` in `parent`, turned by `yaw` then `pitch`.
    Transform { parent: &'static str, child: &'static str, position: [f64; 3], yaw: f64, pitch: f64 },
    /// A pose in the map, turned by `yaw` about z.
    Pose { position: [f64; 3], yaw: f64 },
    /// The rover's estimate: mean (x, y, θ) on the ground and its covariance.
    Belief(Belief),
    /// Poses (x, y, θ) on the ground, each with its time (ns).
    Path(Vec<(u64, [f64; 3])>),
    /// Entities to add or replace.
    Scene(Vec<Entity>),
    /// The a priori belief of one rendezvous.
    Request(RendezvousRecord),
    /// The daemon's answer to one rendezvous (boxed: the largest by far).
    Answer(Box<AnswerRecord>),
    /// The viewer's measurement of one rendezvous, or why there is none.
    Measurement(Measurement),
    /// The absolute position error of one sample, m.
    Ape { sample: u64, step: u32, updated: bool, ape: f64 },
}

/// The path topics carry the whole path so far: every this many samples (10 s of
/// simulated time), at each arrival at a waypoint and at the last sample. The file
/// grows with samples² / this: the built-in mission's file is about 1.8 MB.
const PATH_EVERY: usize = 40;
/// Most voxels drawn as cubes (each is a scene primitive).
pub const MAX_VOXEL_CUBES: usize = 20_000;
/// The covariance ellipse holds 95 % of the position probability: √χ²₂(0.95).
const ELLIPSE_SIGMAS: f64 = 2.447_746_830_680_816;

/// The a priori belief the rover sent for one rendezvous.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RendezvousRecord {
    /// Waypoint index (1-based).
    pub step: u32,
    /// Simulated time, s.
    pub sim_time: f64,
    /// The belief.
    pub belief: Belief,
}

/// The daemon's answer to one rendezvous as the viewer got it: the payload of
/// `/dyfos/rendezvous/answer` (without the timestamp) and of the `rendezvous_answer`
/// field of the viewer's `answer` event.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct AnswerRecord {
    /// Waypoint index (1-based).
    pub step: u32,
    /// Simulated time the viewer got it, s.
    pub sim_time: f64,
    /// Search algorithm.
    pub algorithm: String,
    /// Sensor state x = (ρ, ψ, φ, ψ_v).
    pub x: [f64; 4],
    /// E = ln det Σ⁺.
    #[serde(rename = "E")]
    pub e: f64,
    /// Predicted measurement noise R, rows.
    #[serde(rename = "R")]
    pub r: [[f64; 2]; 2],
    /// Predicted posterior Σ⁺, rows.
    pub sigma_plus: [[f64; 3]; 3],
    /// Viewer position p_v.
    pub viewer_position: [f64; 3],
    /// Viewer yaw ψ_v.
    pub viewer_yaw: f64,
    /// Sensor position p_s.
    pub sensor_position: [f64; 3],
    /// Sensor orientation (x, y, z, w).
    pub sensor_quaternion: [f64; 4],
    /// Evaluation counts.
    pub evaluations: EvalStats,
    /// Compute time, µs.
    pub micros: u64,
    /// Map version searched.
    pub map_version: u64,
    /// Why the search stopped (snake_case).
    pub stop: String,
}

impl AnswerRecord {
    /// The record of `answer` to the rendezvous of `step`, received at `sim_time`.
    pub fn new(step: u32, sim_time: f64, answer: &Answer) -> Self {
        let json = answer.to_json();
        let p = &answer.posterior;
        AnswerRecord {
            step,
            sim_time,
            algorithm: answer.algorithm.name().to_string(),
            x: answer.x.to_array(),
            e: answer.cost,
            r: answer.r,
            sigma_plus: std::array::from_fn(|i| std::array::from_fn(|j| p[(i, j)])),
            viewer_position: answer.viewer_position.coords.into(),
            viewer_yaw: answer.viewer_yaw,
            sensor_position: answer.sensor_position.coords.into(),
            sensor_quaternion: serde_json::from_value(json["sensor_quaternion"].clone())
                .unwrap_or([0.0, 0.0, 0.0, 1.0]),
            evaluations: answer.evaluations,
            micros: answer.micros,
            map_version: answer.map_version,
            stop: json["stop"].as_str().unwrap_or_default().to_string(),
        }
    }
}

/// Why a mission file could not be written.
#[derive(Debug, thiserror::Error)]
pub enum McapWriteError {
    /// The MCAP writer failed.
    #[error("cannot encode the mission as MCAP: {0}")]
    Mcap(#[from] mcap::McapError),
    /// A message could not be encoded in the profile's encoding.
    #[error("cannot encode a message of {topic}: {reason}")]
    Encode {
        /// The message's topic.
        topic: &'static str,
        /// What the encoder said.
        reason: String,
    },
    /// The file could not be written.
    #[error("cannot write {path}: {source}; check that its directory exists and is writable")]
    Io {
        /// The file.
        path: String,
        /// The error.
        source: std::io::Error,
    },
}

/// A profile's encoding of messages (see [`super::foxglove`], [`super::ros2`]).
pub(crate) trait Encoding {
    /// The schema name and data of a topic's channel.
    fn schema(&self, topic: Topic) -> Result<(&'static str, Vec<u8>), String>;
    /// The bytes of one message of `topic` at `ns`.
    fn encode(&mut self, topic: Topic, ns: u64, message: &Message) -> Result<Vec<u8>, String>;
}

/// One mission's record, written as an MCAP file in either profile (see the
/// module documentation for the topics). Fill it with what a process knows —
/// the demo with the evaluation's [`MissionTrace`] and the viewer's event log, the
/// rover with its own samples, the viewer with its requests, answers and
/// measurements — then [`McapMission::write`] it.
#[derive(Debug, Clone)]
pub struct McapMission {
    world: World,
    waypoints: Vec<[f64; 2]>,
    params: Params,
    viewer_start: ([f64; 3], f64),
    sun_azimuth_rate: f64,
    trace: MissionTrace,
    requests: Vec<RendezvousRecord>,
    answers: Vec<AnswerRecord>,
}

impl McapMission {
    /// An empty record of `mission` (its map, waypoints, camera and viewer start).
    pub fn new(mission: &Mission) -> Self {
        McapMission {
            world: mission.world.clone(),
            waypoints: mission.waypoints.clone(),
            params: mission.params,
            viewer_start: mission.viewer_start,
            sun_azimuth_rate: mission.sun_azimuth_rate,
            trace: MissionTrace::default(),
            requests: Vec::new(),
            answers: Vec::new(),
        }
    }

    /// A ground-truth sample.
    pub fn record_truth(&mut self, truth: &TrueState) {
        self.trace.truth.push(*truth);
    }

    /// An estimate sample.
    pub fn record_estimate(&mut self, estimate: &Estimate) {
        self.trace.estimates.push(*estimate);
    }

    /// The rendezvous belief of `step`, sent or received at `sim_time` (repeats of a
    /// step are ignored).
    pub fn record_request(&mut self, step: u32, sim_time: f64, belief: &Belief) {
        if !self.requests.iter().any(|r| r.step == step) {
            self.requests.push(RendezvousRecord { step, sim_time, belief: *belief });
        }
    }

    /// The daemon's answer for a rendezvous (repeats of a step are ignored).
    pub fn record_answer(&mut self, answer: AnswerRecord) {
        if !self.answers.iter().any(|a| a.step == answer.step) {
            self.answers.push(answer);
        }
    }

    /// The viewer's measurement (or non-measurement) of a step (repeats are ignored).
    pub fn record_measurement(&mut self, measurement: &Measurement) {
        if !self.trace.measurements.iter().any(|m| m.step == measurement.step) {
            self.trace.measurements.push(*measurement);
        }
    }

    /// Everything of an evaluation's trace: truth, estimates, measurements.
    pub fn record_trace(&mut self, trace: &MissionTrace) {
        self.trace.truth.extend_from_slice(&trace.truth);
        self.trace.estimates.extend_from_slice(&trace.estimates);
        for m in &trace.measurements {
            self.record_measurement(m);
        }
    }

    /// The rendezvous requests (`rendezvous_received`, with `cov`) and the daemon's
    /// answers (`answer`, with `rendezvous_answer`) of a viewer's event log
    /// ([`crate::mission::log::read_events`]); returns how many were taken.
    pub fn record_viewer_events(&mut self, events: &[Value]) -> usize {
        let mut n = 0;
        for e in events {
            match e["event"].as_str() {
                Some("rendezvous_received") => {
                    let (Some(step), Some(t)) = (e["step"].as_u64(), e["sim_time"].as_f64()) else { continue };
                    let mean = serde_json::from_value::<[f64; 3]>(e["mean"].clone());
                    let cov = serde_json::from_value::<[[f64; 3]; 3]>(e["cov"].clone());
                    if let (Ok(mean), Ok(cov), Ok(step)) = (mean, cov, u32::try_from(step))
                        && let Ok(belief) = Belief::new(mean, cov)
                    {
                        self.record_request(step, t, &belief);
                        n += 1;
                    }
                }
                Some("answer") => {
                    if let Ok(a) = serde_json::from_value::<AnswerRecord>(e["rendezvous_answer"].clone()) {
                        self.record_answer(a);
                        n += 1;
                    }
                }
                _ => {}
            }
        }
        n
    }

    /// How many messages the file will hold.
    pub fn message_count(&self) -> usize {
        self.messages().len()
    }

    /// The MCAP file's bytes in `profile`.
    pub fn to_bytes(&self, profile: McapProfile) -> Result<Vec<u8>, McapWriteError> {
        match profile {
            McapProfile::Foxglove => self.encode(profile, &mut foxglove::Json),
            McapProfile::Ros2 => self.encode(profile, &mut ros2::Cdr::default()),
        }
    }

    fn encode(&self, profile: McapProfile, encoding: &mut impl Encoding) -> Result<Vec<u8>, McapWriteError> {
        let (header_profile, message_encoding, schema_encoding) = profile.encodings();
        let mut writer = mcap::WriteOptions::new()
            .compression(None)
            .profile(header_profile)
            .create(std::io::Cursor::new(Vec::new()))?;
        let mut schema_ids = BTreeMap::new();
        let mut channels: BTreeMap<Topic, (u16, u32)> = BTreeMap::new();
        for (topic, ns, message) in self.messages() {
            let data = encoding
                .encode(topic, ns, &message)
                .map_err(|reason| McapWriteError::Encode { topic: topic.name(), reason })?;
            // Declared with its first message: a channel without messages is never declared.
            let (channel_id, sequence) = match channels.entry(topic) {
                Entry::Occupied(c) => c.into_mut(),
                Entry::Vacant(c) => {
                    let (name, schema) = encoding
                        .schema(topic)
                        .map_err(|reason| McapWriteError::Encode { topic: topic.name(), reason })?;
                    let schema_id = match schema_ids.get(name) {
                        Some(id) => *id,
                        None => {
                            let id = writer.add_schema(name, schema_encoding, &schema)?;
                            schema_ids.insert(name, id);
                            id
                        }
                    };
                    let id = writer.add_channel(schema_id, topic.name(), message_encoding, &BTreeMap::new())?;
                    c.insert((id, 0))
                }
            };
            let header = mcap::records::MessageHeader {
                channel_id: *channel_id,
                sequence: *sequence,
                log_time: ns,
                publish_time: ns,
            };
            *sequence += 1;
            writer.write_to_known_channel(&header, &data)?;
        }
        writer.finish()?;
        Ok(writer.into_inner().into_inner())
    }

    /// Writes the MCAP file in `profile` to `path` (created or replaced).
    pub fn write(&self, path: &Path, profile: McapProfile) -> Result<(), McapWriteError> {
        let bytes = self.to_bytes(profile)?;
        std::fs::write(path, bytes).map_err(|source| McapWriteError::Io { path: path.display().to_string(), source })
    }

    /// Runs `run` with a recording of `mission` if `path` is given, then writes the
    /// file in `profile`, whatever `run` returned: a failed run leaves its file too.
    /// A write error is the result if the run succeeded, and a log line if it did not.
    pub fn around<R, E: From<McapWriteError>>(
        path: Option<&Path>,
        profile: McapProfile,
        mission: &Mission,
        run: impl FnOnce(&mut Option<McapMission>) -> Result<R, E>,
    ) -> Result<R, E> {
        let mut mcap = path.map(|_| McapMission::new(mission));
        let result = run(&mut mcap);
        if let (Some(path), Some(mcap)) = (path, &mcap) {
            match mcap.write(path, profile) {
                Ok(()) => tracing::info!("mission written to {}", path.display()),
                Err(e) if result.is_ok() => return Err(e.into()),
                Err(e) => tracing::error!("{e}"),
            }
        }
        result
    }

    /// Every message: topic, log time (ns), content; sorted by time, stable.
    pub(crate) fn messages(&self) -> Vec<(Topic, u64, Message)> {
        let mut out = Vec::new();
        self.map_messages(&mut out);
        self.rover_messages(&mut out);
        self.rendezvous_messages(&mut out);
        out.sort_by_key(|(topic, ns, _)| (*ns, *topic));
        out
    }

    /// The map at time 0, the sun again at each rendezvous when it moves; the
    /// viewer at take-off and its camera mount.
    fn map_messages(&self, out: &mut Vec<(Topic, u64, Message)>) {
        let mut entities = Vec::new();
        let grey = color(0.55, 0.55, 0.6, 1.0);
        for (id, o) in self.world.obstacles() {
            let mut p = Primitives::default();
            match o {
                Obstacle::Cylinder(c) => p.cylinders.push(scene::Cylinder {
                    center: [c.center.x, c.center.y, c.height / 2.0],
                    radius: c.radius,
                    height: c.height,
                    color: grey,
                }),
                Obstacle::Box(b) => {
                    let center = (b.min.coords + b.max.coords) / 2.0;
                    let size = b.max.coords - b.min.coords;
                    p.cubes.push(scene::Cube { center: center.into(), size: size.into(), color: grey });
                }
            }
            entities.push(Entity::new("map", format!("obstacle-{id}"), false, p));
        }
        if let Some(grid) = self.world.voxels() {
            let res = grid.resolution();
            let o = grid.origin();
            let mut p = Primitives::default();
            for c in grid.cells_sorted().into_iter().take(MAX_VOXEL_CUBES) {
                let center = std::array::from_fn(|i| o[i] + res * (c[i] as f64 + 0.5));
                p.cubes.push(scene::Cube { center, size: [res; 3], color: color(0.45, 0.5, 0.65, 1.0) });
            }
            entities.push(Entity::new("map", "voxels", false, p));
        }
        let mut p = Primitives::default();
        let green = color(0.1, 0.6, 0.2, 1.0);
        for (i, w) in self.waypoints.iter().enumerate() {
            p.spheres.push(scene::Sphere { center: [w[0], w[1], 0.05], diameter: 0.2, color: green });
            p.texts.push(scene::Text { position: [w[0], w[1], 0.4], text: format!("{}", i + 1), color: green });
        }
        let route: Vec<[f64; 3]> = self.waypoints.iter().map(|w| [w[0], w[1], 0.02]).collect();
        p.lines.push(scene::Line {
            kind: LineKind::Strip,
            points: route,
            thickness: 1.0,
            color: color(0.1, 0.6, 0.2, 0.6),
        });
        entities.push(Entity::new("map", "waypoints", false, p));
        entities.push(self.sun_entity(self.world.sun().azimuth));
        out.push((Topic::Map, 0, Message::Scene(entities)));
        if self.sun_azimuth_rate != 0.0 {
            for r in &self.requests {
                let ns = nanos(r.sim_time);
                let azimuth = self.world.sun().azimuth + self.sun_azimuth_rate * r.sim_time;
                out.push((Topic::Map, ns, Message::Scene(vec![self.sun_entity(azimuth)])));
            }
        }
        let (position, yaw) = self.viewer_start;
        out.push((Topic::Tf, 0, Message::Transform { parent: "map", child: "viewer", position, yaw, pitch: 0.0 }));
        out.push((Topic::Tf, 0, self.camera_mount()));
        out.push((Topic::ViewerPose, 0, Message::Pose { position, yaw }));
    }

    /// `viewer → camera`: the camera's mount t_vs and its downward pitch.
    fn camera_mount(&self) -> Message {
        let t_vs: [f64; 3] = self.params.t_vs.into();
        Message::Transform {
            parent: "viewer",
            child: "camera",
            position: t_vs,
            yaw: 0.0,
            pitch: self.params.camera_pitch,
        }
    }

    /// An arrow from the map's centre towards the sun.
    fn sun_entity(&self, azimuth: f64) -> Entity {
        let b = self.world.bounds();
        let center = [(b.min.x + b.max.x) / 2.0, (b.min.y + b.max.y) / 2.0, 0.0];
        let size = (b.max.x - b.min.x).max(b.max.y - b.min.y);
        let elevation = self.world.sun().elevation;
        let mut p = Primitives::default();
        p.arrows.push(scene::Arrow {
            tail: center,
            azimuth,
            elevation,
            length: (size / 4.0).max(0.5),
            color: color(1.0, 0.75, 0.0, 1.0),
        });
        Entity::new("map", "sun", false, p)
    }

    /// True and estimated poses, paths, the covariance ellipse, the APE.
    fn rover_messages(&self, out: &mut Vec<(Topic, u64, Message)>) {
        let truth = in_sample_order(&self.trace.truth, |t| t.sample);
        let mut path = GrowingPath::new(truth.len());
        for (i, t) in truth.iter().enumerate() {
            let ns = nanos(t.sim_time);
            let [x, y, theta] = t.pose;
            let position = [x, y, 0.0];
            out.push((
                Topic::Tf,
                ns,
                Message::Transform { parent: "map", child: "rover", position, yaw: theta, pitch: 0.0 },
            ));
            out.push((Topic::RoverPose, ns, Message::Pose { position, yaw: theta }));
            out.extend(path.add(i, ns, t.pose, t.phase).map(|p| (Topic::RoverPath, ns, p)));
        }
        let estimates = in_sample_order(&self.trace.estimates, |e| e.sample);
        let mut path = GrowingPath::new(estimates.len());
        for (i, e) in estimates.iter().enumerate() {
            let ns = nanos(e.sim_time);
            let m = e.belief.mean;
            let position = [m.x, m.y, 0.0];
            out.push((
                Topic::Tf,
                ns,
                Message::Transform { parent: "map", child: "rover_estimate", position, yaw: m.z, pitch: 0.0 },
            ));
            out.push((Topic::EstimatePose, ns, Message::Belief(e.belief)));
            out.extend(path.add(i, ns, [m.x, m.y, m.z], e.phase).map(|p| (Topic::EstimatePath, ns, p)));
            let c = e.belief.cov.to_rows();
            let ring = scene::ellipse([m.x, m.y], [[c[0][0], c[0][1]], [c[1][0], c[1][1]]], ELLIPSE_SIGMAS, 0.03);
            let mut p = Primitives::default();
            p.lines.push(scene::Line {
                kind: LineKind::Loop,
                points: ring,
                thickness: 2.0,
                color: color(0.2, 0.4, 1.0, 1.0),
            });
            out.push((Topic::EstimateCovariance, ns, Message::Scene(vec![Entity::new("map", "covariance", false, p)])));
        }
        for (t, e) in self.trace.pairs() {
            let ns = nanos(t.sim_time);
            let ape = (e.belief.mean.x - t.pose[0]).hypot(e.belief.mean.y - t.pose[1]);
            out.push((Topic::Ape, ns, Message::Ape { sample: t.sample, step: t.step, updated: e.updated, ape }));
        }
    }

    /// Requests, answers, measurements; the viewer's pose, frustum and line of sight.
    fn rendezvous_messages(&self, out: &mut Vec<(Topic, u64, Message)>) {
        for r in &self.requests {
            out.push((Topic::Request, nanos(r.sim_time), Message::Request(*r)));
        }
        for a in &self.answers {
            out.push((Topic::Answer, nanos(a.sim_time), Message::Answer(Box::new(a.clone()))));
        }
        for m in &self.trace.measurements {
            let ns = nanos(m.sim_time);
            out.push((Topic::Measurement, ns, Message::Measurement(*m)));
            if let Some(v) = m.viewer {
                let (position, yaw) = (v.position, v.yaw);
                out.push((
                    Topic::Tf,
                    ns,
                    Message::Transform { parent: "map", child: "viewer", position, yaw, pitch: 0.0 },
                ));
                // The mount again with each viewer pose: tf2 (RViz) looks a frame up at a
                // marker's stamp, and a transform sent once answers for its own time only.
                out.push((Topic::Tf, ns, self.camera_mount()));
                out.push((Topic::ViewerPose, ns, Message::Pose { position, yaw }));
                out.push((Topic::ViewerCamera, ns, Message::Scene(self.camera_scene(m, position, yaw))));
            }
        }
    }

    /// The frustum (camera frame, between ρ_min and ρ_max) and the line of sight
    /// from the camera to the rover's marker (its true position at the waypoint when
    /// recorded, else the measured one); green when observed, red when not.
    fn camera_scene(&self, m: &Measurement, viewer: [f64; 3], yaw: f64) -> Vec<Entity> {
        let p = &self.params;
        let observed = matches!(m.observation, Observation::Observed { .. });
        let tint = if observed { color(0.1, 0.8, 0.2, 1.0) } else { color(0.9, 0.15, 0.1, 1.0) };
        let (th, tv) = ((p.f_h / 2.0).tan(), (p.f_v / 2.0).tan());
        let corner = |d: f64, sy: f64, sz: f64| {
            let v = [1.0, sy * th, sz * tv];
            let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
            [d * v[0] / n, d * v[1] / n, d * v[2] / n]
        };
        let signs = [(1.0, 1.0), (-1.0, 1.0), (-1.0, -1.0), (1.0, -1.0)];
        let mut segments = Vec::new();
        for d in [p.rho_min, p.rho_max] {
            for k in 0..4 {
                let (a, b) = (signs[k], signs[(k + 1) % 4]);
                segments.push(corner(d, a.0, a.1));
                segments.push(corner(d, b.0, b.1));
            }
        }
        for (sy, sz) in signs {
            segments.push([0.0; 3]);
            segments.push(corner(p.rho_max, sy, sz));
        }
        let mut frustum = Primitives::default();
        frustum.lines.push(scene::Line { kind: LineKind::List, points: segments, thickness: 1.5, color: tint });
        // The camera in the map: p_s = p_v + Rz(ψ_v)·t_vs.
        let (s, c) = yaw.sin_cos();
        let t = p.t_vs;
        let camera = [viewer[0] + c * t.x - s * t.y, viewer[1] + s * t.x + c * t.y, viewer[2] + t.z];
        let at_waypoint =
            self.trace.truth.iter().filter(|t| t.step == m.step && t.phase != Phase::Driving).min_by_key(|t| t.sample);
        let target = match (at_waypoint, &m.observation) {
            (Some(t), _) => Some([t.pose[0], t.pose[1], p.marker_height]),
            (None, Observation::Observed { position, .. }) => Some([position[0], position[1], p.marker_height]),
            (None, Observation::NotObserved(_)) => None,
        };
        let mut sight = Primitives::default();
        if let Some(target) = target {
            sight.lines.push(scene::Line {
                kind: LineKind::List,
                points: vec![camera, target],
                thickness: 2.0,
                color: tint,
            });
        }
        vec![Entity::new("camera", "frustum", true, frustum), Entity::new("map", "line_of_sight", false, sight)]
    }
}

/// `samples` in sample order, each sample once.
fn in_sample_order<T: Clone>(samples: &[T], sample: impl Fn(&T) -> u64) -> Vec<T> {
    let mut sorted = samples.to_vec();
    sorted.sort_by_key(&sample);
    sorted.dedup_by_key(|t| sample(t));
    sorted
}

/// A path drawn as it grows: published every [`PATH_EVERY`] samples, at each
/// arrival at a waypoint, and at the last sample.
struct GrowingPath {
    points: Vec<(u64, [f64; 3])>,
    driving: bool,
    samples: usize,
}

impl GrowingPath {
    fn new(samples: usize) -> Self {
        GrowingPath { points: Vec::with_capacity(samples), driving: true, samples }
    }

    /// Adds sample `i` of the path; the path so far if it is to be published now.
    fn add(&mut self, i: usize, ns: u64, point: [f64; 3], phase: Phase) -> Option<Message> {
        self.points.push((ns, point));
        let arrived = self.driving && phase != Phase::Driving;
        self.driving = phase == Phase::Driving;
        (i.is_multiple_of(PATH_EVERY) || arrived || i + 1 == self.samples).then(|| Message::Path(self.points.clone()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use dyfos_shared::math::Cov2;
    use dyfos_shared::wire::mission::{NoMeasurement, ViewerPose};

    pub(crate) fn sample_mission() -> McapMission {
        let mission = Mission::builtin();
        let mut m = McapMission::new(&mission);
        let b = mission.initial_belief;
        for k in 0..20u64 {
            let phase = if k % 10 == 9 { Phase::AtWaypoint } else { Phase::Driving };
            let step = 1 + (k / 10) as u32;
            let t = k as f64 * 0.25;
            m.record_truth(&TrueState { sample: k, step, phase, sim_time: t, pose: [k as f64 * 0.1, 0.0, 0.1] });
            let belief = Belief { mean: nalgebra::Vector3::new(k as f64 * 0.1, 0.05, 0.1), ..b };
            m.record_estimate(&Estimate { sample: k, step, phase, updated: false, sim_time: t, belief });
        }
        m.record_request(1, 0.0, &b);
        m.record_request(1, 0.5, &b);
        let r = Cov2::from_rows(&[[0.01, 0.0], [0.0, 0.02]]).unwrap();
        let viewer = Some(ViewerPose { position: [1.0, 2.0, 3.0], yaw: 0.5 });
        m.record_measurement(&Measurement {
            step: 1,
            sim_time: 2.5,
            observation: Observation::Observed { position: [0.9, 0.0], r },
            viewer,
            predicted_cost: Some(-9.0),
        });
        m.record_measurement(&Measurement {
            step: 2,
            sim_time: 5.0,
            observation: Observation::NotObserved(NoMeasurement::Occluded),
            viewer,
            predicted_cost: None,
        });
        m
    }

    #[test]
    fn messages_are_in_time_order_and_paths_grow() {
        let m = sample_mission();
        let messages = m.messages();
        assert!(messages.windows(2).all(|w| w[0].1 <= w[1].1));
        let count = |t: Topic| messages.iter().filter(|(x, _, _)| *x == t).count();
        assert_eq!(count(Topic::RoverPose), 20);
        assert_eq!(count(Topic::Ape), 20);
        assert_eq!(count(Topic::Request), 1, "a repeated request is recorded once");
        assert_eq!(count(Topic::Measurement), 2);
        // Path: sample 0 (every 40th), 9 and 19 (arrivals; 19 is the last).
        assert_eq!(count(Topic::RoverPath), 3);
        let Some((_, _, Message::Path(last))) = messages.iter().rev().find(|(t, _, _)| *t == Topic::RoverPath) else {
            panic!("a path");
        };
        assert_eq!(last.len(), 20);
        assert_eq!(last[19], (nanos(19.0 * 0.25), [1.9000000000000001, 0.0, 0.1]));
        // The frustum (frame `camera`) has its frames at its own stamp, for tf2.
        let frames_at = |ns: u64| {
            let mut frames: Vec<&str> = messages
                .iter()
                .filter_map(|(t, at, m)| match m {
                    Message::Transform { child, .. } if *t == Topic::Tf && *at == ns => Some(*child),
                    _ => None,
                })
                .collect();
            frames.sort();
            frames
        };
        let cameras: Vec<u64> = messages.iter().filter(|(t, _, _)| *t == Topic::ViewerCamera).map(|m| m.1).collect();
        assert_eq!(cameras.len(), 2);
        for ns in cameras {
            let frames = frames_at(ns);
            assert!(frames.contains(&"camera") && frames.contains(&"viewer"), "at {ns} ns: {frames:?}");
        }
        // Same record, same bytes, in both profiles.
        for profile in [McapProfile::Foxglove, McapProfile::Ros2] {
            assert_eq!(m.to_bytes(profile).unwrap(), m.clone().to_bytes(profile).unwrap());
        }
    }

    /// The topics whose channels a file declares, and the message count of each.
    fn channels(bytes: &[u8]) -> BTreeMap<String, u64> {
        let summary = mcap::Summary::read(bytes).unwrap().expect("a summary");
        let stats = summary.stats.expect("statistics");
        summary
            .channels
            .values()
            .map(|c| (c.topic.clone(), stats.channel_message_counts.get(&c.id).copied().unwrap_or(0)))
            .collect()
    }

    #[test]
    fn only_channels_with_messages_are_declared() {
        // A rover without a viewer: its poses and the APE, no rendezvous at all.
        let mut m = sample_mission();
        m.requests.clear();
        m.answers.clear();
        m.trace.measurements.clear();
        for profile in [McapProfile::Foxglove, McapProfile::Ros2] {
            let declared = channels(&m.to_bytes(profile).unwrap());
            assert!(declared.values().all(|n| *n > 0), "{profile:?}: {declared:?}");
            let topics: Vec<&str> = declared.keys().map(String::as_str).collect();
            assert_eq!(
                topics,
                [
                    "/dyfos/ape",
                    "/map",
                    "/rover/estimate/covariance",
                    "/rover/estimate/path",
                    "/rover/estimate/pose",
                    "/rover/path",
                    "/rover/pose",
                    "/tf",
                    "/viewer/pose",
                ],
                "{profile:?}"
            );
        }
        // With everything recorded, every topic but the answer has messages.
        let declared = channels(&sample_mission().to_bytes(McapProfile::Ros2).unwrap());
        assert_eq!(declared.len(), Topic::ALL.len() - 1);
        assert!(!declared.contains_key(Topic::Answer.name()));
    }

    #[test]
    fn viewer_events_give_requests_and_answers() {
        let mission = Mission::builtin();
        let mut m = McapMission::new(&mission);
        let b = mission.initial_belief;
        let answer = AnswerRecord {
            step: 1,
            sim_time: 0.5,
            algorithm: "dyfos".into(),
            x: [2.0, 0.0, 0.0, 1.0],
            e: -10.0,
            r: [[0.01, 0.0], [0.0, 0.01]],
            sigma_plus: b.cov.to_rows(),
            viewer_position: [0.0, 0.0, 2.0],
            viewer_yaw: 1.0,
            sensor_position: [0.1, 0.0, 2.0],
            sensor_quaternion: [0.0, 0.0, 0.0, 1.0],
            evaluations: EvalStats { total: 10, workspace: 1, collision: 2, occlusion: 3 },
            micros: 1234,
            map_version: 3,
            stop: "finished".into(),
        };
        let events = vec![
            serde_json::json!({"event": "rendezvous_received", "sim_time": 0.25, "step": 1, "mean": b.mean.as_slice(), "cov": b.cov.to_rows()}),
            serde_json::json!({"event": "answer", "sim_time": 0.5, "step": 1, "rendezvous_answer": answer}),
            serde_json::json!({"event": "arrived", "sim_time": 1.0, "step": 1}),
        ];
        assert_eq!(m.record_viewer_events(&events), 2);
        assert_eq!(m.requests[0].belief, b);
        assert_eq!(m.answers[0], answer);
        let messages = m.messages();
        let (_, ns, a) = messages.iter().find(|(t, _, _)| *t == Topic::Answer).unwrap();
        assert_eq!(*ns, 500_000_000);
        assert_eq!(a, &Message::Answer(Box::new(answer)));
    }
}
