//! A mission as an MCAP file (the storage format of ROS 2 bags) that Foxglove
//! opens with no configuration: [`McapMission`].
//!
//! Messages are JSON (`message_encoding = "json"`) with JSON-schema schemas
//! (`encoding = "jsonschema"`). Where Foxglove has a well-known schema —
//! `foxglove.FrameTransform`, `foxglove.SceneUpdate`, `foxglove.PoseInFrame`,
//! `foxglove.PosesInFrame` — the file carries Foxglove's own schema under its own
//! name (copied from `foxglove/foxglove-sdk`, MIT, in `schemas/`), so the 3D panel
//! draws it at once. The rendezvous exchange and the APE use schemas of their own
//! (`dyfos.*`), with the paper's names (`E`, `R`, `sigma_plus`, `ape_m`).
//!
//! Everything is in the `map` frame (REP 103: x east, y north, z up, metres),
//! stamped with simulated time (log time = publish time = the message's
//! `timestamp`, in ns). The frames, as `foxglove.FrameTransform`s on `/tf`:
//! `map → rover` (true pose), `map → rover_estimate` (EKF mean), `map → viewer`
//! and `viewer → camera` (the camera's mount and downward pitch).
//!
//! | topic | schema | what it shows |
//! |---|---|---|
//! | `/tf` | `foxglove.FrameTransform` | the frames above |
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
//!
//! Messages are gathered in memory and written at the end, sorted by log time
//! (ties keep the order above), so the same recorded data gives the same bytes.
//! Chunks are not compressed (the crate is built without zstd/lz4).
//!
//! ```
//! use dyfos_client::eval::McapMission;
//! use dyfos_client::mission::Mission;
//!
//! let mission = Mission::builtin();
//! let mut mcap = McapMission::new(&mission);
//! mcap.record_request(1, 0.0, &mission.initial_belief);
//! let bytes = mcap.to_bytes()?;
//! let summary = mcap::Summary::read(&bytes)?.expect("a summary section");
//! assert_eq!(summary.stats.unwrap().message_count, mcap.message_count() as u64);
//! # Ok::<(), mcap::McapError>(())
//! ```

mod scene;

use super::MissionTrace;
use crate::mission::Mission;
use dyfos_shared::answer::{Answer, EvalStats};
use dyfos_shared::params::Params;
use dyfos_shared::posterior::Belief;
use dyfos_shared::wire::mission::{Estimate, Measurement, Observation, Phase, TrueState};
use dyfos_shared::world::{Obstacle, World};
use scene::{LINE_LIST, LINE_LOOP, Primitives, color, nanos, timestamp};
use serde_json::{Value, json};
use std::collections::BTreeMap;
use std::path::Path;

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

/// Every channel of a mission file: topic and schema name (see [`schema`]).
/// Channels are written in this order, all of them, even those without messages.
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

#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
enum Topic {
    Tf,
    Map,
    RoverPose,
    RoverPath,
    EstimatePose,
    EstimatePath,
    EstimateCovariance,
    ViewerPose,
    ViewerCamera,
    Request,
    Answer,
    Measurement,
    Ape,
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
    /// The file could not be written.
    #[error("cannot write {path}: {source}; check that its directory exists and is writable")]
    Io {
        /// The file.
        path: String,
        /// The error.
        source: std::io::Error,
    },
}

/// One mission's record, written as an MCAP file Foxglove opens as is (see the
/// module documentation for the channels). Fill it with what a process knows —
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

    /// The MCAP file's bytes.
    pub fn to_bytes(&self) -> Result<Vec<u8>, mcap::McapError> {
        let mut writer =
            mcap::WriteOptions::new().compression(None).profile("").create(std::io::Cursor::new(Vec::new()))?;
        let mut schema_ids = BTreeMap::new();
        let mut channel_ids = Vec::with_capacity(CHANNELS.len());
        for (topic, name) in CHANNELS {
            let id = match schema_ids.get(name) {
                Some(id) => *id,
                None => {
                    let data = schema(name).unwrap_or("{}");
                    let id = writer.add_schema(name, "jsonschema", data.as_bytes())?;
                    schema_ids.insert(name, id);
                    id
                }
            };
            channel_ids.push(writer.add_channel(id, topic, "json", &BTreeMap::new())?);
        }
        let mut sequence = vec![0u32; CHANNELS.len()];
        for (topic, ns, message) in self.messages() {
            let k = topic as usize;
            let header = mcap::records::MessageHeader {
                channel_id: channel_ids[k],
                sequence: sequence[k],
                log_time: ns,
                publish_time: ns,
            };
            sequence[k] += 1;
            writer.write_to_known_channel(&header, message.to_string().as_bytes())?;
        }
        writer.finish()?;
        Ok(writer.into_inner().into_inner())
    }

    /// Writes the MCAP file to `path` (created or replaced).
    pub fn write(&self, path: &Path) -> Result<(), McapWriteError> {
        let bytes = self.to_bytes()?;
        std::fs::write(path, bytes).map_err(|source| McapWriteError::Io { path: path.display().to_string(), source })
    }

    /// Runs `run` with a recording of `mission` if `path` is given, then writes the
    /// file, whatever `run` returned: a failed run leaves its file too. A write error
    /// is the result if the run succeeded, and a log line if it did not.
    pub fn around<R, E: From<McapWriteError>>(
        path: Option<&Path>,
        mission: &Mission,
        run: impl FnOnce(&mut Option<McapMission>) -> Result<R, E>,
    ) -> Result<R, E> {
        let mut mcap = path.map(|_| McapMission::new(mission));
        let result = run(&mut mcap);
        if let (Some(path), Some(mcap)) = (path, &mcap) {
            match mcap.write(path) {
                Ok(()) => tracing::info!("mission written to {}", path.display()),
                Err(e) if result.is_ok() => return Err(e.into()),
                Err(e) => tracing::error!("{e}"),
            }
        }
        result
    }

    /// Every message: topic, log time (ns), JSON; sorted by time, stable.
    fn messages(&self) -> Vec<(Topic, u64, Value)> {
        let mut out = Vec::new();
        self.map_messages(&mut out);
        self.rover_messages(&mut out);
        self.rendezvous_messages(&mut out);
        out.sort_by_key(|(topic, ns, _)| (*ns, *topic));
        out
    }

    /// The map at time 0, the sun again at each rendezvous when it moves; the
    /// viewer at take-off and its camera mount.
    fn map_messages(&self, out: &mut Vec<(Topic, u64, Value)>) {
        let mut entities = Vec::new();
        let grey = || color(0.55, 0.55, 0.6, 1.0);
        for (id, o) in self.world.obstacles() {
            let mut p = Primitives::default();
            match o {
                Obstacle::Cylinder(c) => p.cylinders.push(scene::cylinder(
                    [c.center.x, c.center.y, c.height / 2.0],
                    c.radius,
                    c.height,
                    grey(),
                )),
                Obstacle::Box(b) => {
                    let center = (b.min.coords + b.max.coords) / 2.0;
                    let size = b.max.coords - b.min.coords;
                    p.cubes.push(scene::cube(center.into(), size.into(), grey()));
                }
            }
            entities.push(scene::entity(0, "map", &format!("obstacle-{id}"), false, p));
        }
        if let Some(grid) = self.world.voxels() {
            let res = grid.resolution();
            let o = grid.origin();
            let mut p = Primitives::default();
            for c in grid.cells_sorted().into_iter().take(MAX_VOXEL_CUBES) {
                let center = std::array::from_fn(|i| o[i] + res * (c[i] as f64 + 0.5));
                p.cubes.push(scene::cube(center, [res; 3], color(0.45, 0.5, 0.65, 1.0)));
            }
            entities.push(scene::entity(0, "map", "voxels", false, p));
        }
        let mut p = Primitives::default();
        for (i, w) in self.waypoints.iter().enumerate() {
            p.spheres.push(scene::sphere([w[0], w[1], 0.05], 0.2, color(0.1, 0.6, 0.2, 1.0)));
            p.texts.push(scene::text([w[0], w[1], 0.4], &format!("{}", i + 1), color(0.1, 0.6, 0.2, 1.0)));
        }
        let route: Vec<[f64; 3]> = self.waypoints.iter().map(|w| [w[0], w[1], 0.02]).collect();
        p.lines.push(scene::line(scene::LINE_STRIP, &route, 1.0, color(0.1, 0.6, 0.2, 0.6)));
        entities.push(scene::entity(0, "map", "waypoints", false, p));
        entities.push(self.sun_entity(0, self.world.sun().azimuth));
        out.push((Topic::Map, 0, scene::scene_update(entities)));
        if self.sun_azimuth_rate != 0.0 {
            for r in &self.requests {
                let ns = nanos(r.sim_time);
                let azimuth = self.world.sun().azimuth + self.sun_azimuth_rate * r.sim_time;
                out.push((Topic::Map, ns, scene::scene_update(vec![self.sun_entity(ns, azimuth)])));
            }
        }
        let (position, yaw) = self.viewer_start;
        out.push((Topic::Tf, 0, scene::frame_transform(0, "map", "viewer", position, yaw, 0.0)));
        let t_vs: [f64; 3] = self.params.t_vs.into();
        out.push((Topic::Tf, 0, scene::frame_transform(0, "viewer", "camera", t_vs, 0.0, self.params.camera_pitch)));
        out.push((Topic::ViewerPose, 0, scene::pose_in_map(0, position, yaw)));
    }

    /// An arrow from the map's centre towards the sun.
    fn sun_entity(&self, ns: u64, azimuth: f64) -> Value {
        let b = self.world.bounds();
        let center = [(b.min.x + b.max.x) / 2.0, (b.min.y + b.max.y) / 2.0, 0.0];
        let size = (b.max.x - b.min.x).max(b.max.y - b.min.y);
        let elevation = self.world.sun().elevation;
        let mut p = Primitives::default();
        p.arrows.push(scene::arrow(center, azimuth, elevation, (size / 4.0).max(0.5), color(1.0, 0.75, 0.0, 1.0)));
        scene::entity(ns, "map", "sun", false, p)
    }

    /// True and estimated poses, paths, the covariance ellipse, the APE.
    fn rover_messages(&self, out: &mut Vec<(Topic, u64, Value)>) {
        let mut truth = self.trace.truth.clone();
        truth.sort_by_key(|t| t.sample);
        truth.dedup_by_key(|t| t.sample);
        let mut path = Vec::with_capacity(truth.len());
        let mut driving = true;
        for (i, t) in truth.iter().enumerate() {
            let ns = nanos(t.sim_time);
            let [x, y, theta] = t.pose;
            out.push((Topic::Tf, ns, scene::frame_transform(ns, "map", "rover", [x, y, 0.0], theta, 0.0)));
            out.push((Topic::RoverPose, ns, scene::pose_in_map(ns, [x, y, 0.0], theta)));
            path.push(t.pose);
            let arrived = driving && t.phase != Phase::Driving;
            driving = t.phase == Phase::Driving;
            if i % PATH_EVERY == 0 || arrived || i + 1 == truth.len() {
                out.push((Topic::RoverPath, ns, scene::path_in_map(ns, &path)));
            }
        }
        let mut estimates = self.trace.estimates.clone();
        estimates.sort_by_key(|e| e.sample);
        estimates.dedup_by_key(|e| e.sample);
        let mut path = Vec::with_capacity(estimates.len());
        let mut driving = true;
        for (i, e) in estimates.iter().enumerate() {
            let ns = nanos(e.sim_time);
            let m = e.belief.mean;
            out.push((Topic::Tf, ns, scene::frame_transform(ns, "map", "rover_estimate", [m.x, m.y, 0.0], m.z, 0.0)));
            out.push((Topic::EstimatePose, ns, scene::pose_in_map(ns, [m.x, m.y, 0.0], m.z)));
            path.push([m.x, m.y, m.z]);
            let arrived = driving && e.phase != Phase::Driving;
            driving = e.phase == Phase::Driving;
            if i % PATH_EVERY == 0 || arrived || i + 1 == estimates.len() {
                out.push((Topic::EstimatePath, ns, scene::path_in_map(ns, &path)));
            }
            let c = e.belief.cov.to_rows();
            let ring = scene::ellipse([m.x, m.y], [[c[0][0], c[0][1]], [c[1][0], c[1][1]]], ELLIPSE_SIGMAS, 0.03);
            let mut p = Primitives::default();
            p.lines.push(scene::line(LINE_LOOP, &ring, 2.0, color(0.2, 0.4, 1.0, 1.0)));
            let entity = scene::entity(ns, "map", "covariance", false, p);
            out.push((Topic::EstimateCovariance, ns, scene::scene_update(vec![entity])));
        }
        for (t, e) in self.trace.pairs() {
            let ns = nanos(t.sim_time);
            let ape = (e.belief.mean.x - t.pose[0]).hypot(e.belief.mean.y - t.pose[1]);
            out.push((
                Topic::Ape,
                ns,
                json!({"timestamp": timestamp(ns), "sample": t.sample, "step": t.step, "updated": e.updated, "ape_m": ape}),
            ));
        }
    }

    /// Requests, answers, measurements; the viewer's pose, frustum and line of sight.
    fn rendezvous_messages(&self, out: &mut Vec<(Topic, u64, Value)>) {
        for r in &self.requests {
            let ns = nanos(r.sim_time);
            let mean: [f64; 3] = r.belief.mean.into();
            out.push((
                Topic::Request,
                ns,
                json!({"timestamp": timestamp(ns), "step": r.step, "mean": mean, "cov": r.belief.cov.to_rows()}),
            ));
        }
        for a in &self.answers {
            let ns = nanos(a.sim_time);
            let mut message = json!({"timestamp": timestamp(ns)});
            if let (Some(obj), Ok(Value::Object(fields))) = (message.as_object_mut(), serde_json::to_value(a)) {
                obj.extend(fields.into_iter().filter(|(k, _)| k != "sim_time"));
            }
            out.push((Topic::Answer, ns, message));
        }
        for m in &self.trace.measurements {
            let ns = nanos(m.sim_time);
            let mut message = json!({"timestamp": timestamp(ns), "step": m.step});
            let obj = message.as_object_mut().expect("an object");
            match &m.observation {
                Observation::Observed { position, r } => {
                    obj.insert("status".into(), json!("observed"));
                    obj.insert("position".into(), json!(position));
                    obj.insert("R".into(), json!(r.to_rows()));
                }
                Observation::NotObserved(why) => {
                    obj.insert("status".into(), json!(why.name()));
                }
            }
            if let Some(v) = m.viewer {
                obj.insert("viewer_position".into(), json!(v.position));
                obj.insert("viewer_yaw".into(), json!(v.yaw));
            }
            if let Some(e) = m.predicted_cost {
                obj.insert("predicted_E".into(), json!(e));
            }
            out.push((Topic::Measurement, ns, message));
            if let Some(v) = m.viewer {
                out.push((Topic::Tf, ns, scene::frame_transform(ns, "map", "viewer", v.position, v.yaw, 0.0)));
                out.push((Topic::ViewerPose, ns, scene::pose_in_map(ns, v.position, v.yaw)));
                out.push((Topic::ViewerCamera, ns, self.camera_scene(ns, m, v.position, v.yaw)));
            }
        }
    }

    /// The frustum (camera frame, between ρ_min and ρ_max) and the line of sight
    /// from the camera to the rover's marker (its true position at the waypoint when
    /// recorded, else the measured one); green when observed, red when not.
    fn camera_scene(&self, ns: u64, m: &Measurement, viewer: [f64; 3], yaw: f64) -> Value {
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
        frustum.lines.push(scene::line(LINE_LIST, &segments, 1.5, tint.clone()));
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
            sight.lines.push(scene::line(LINE_LIST, &[camera, target], 2.0, tint));
        }
        scene::scene_update(vec![
            scene::entity(ns, "camera", "frustum", true, frustum),
            scene::entity(ns, "map", "line_of_sight", false, sight),
        ])
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use dyfos_shared::math::Cov2;
    use dyfos_shared::wire::mission::{NoMeasurement, ViewerPose};

    fn sample_mission() -> McapMission {
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
    fn every_topic_has_its_schema_and_messages_are_in_time_order() {
        for (_, name) in CHANNELS {
            let s: Value = serde_json::from_str(schema(name).unwrap()).unwrap();
            assert_eq!(s["title"], name);
        }
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
        let last_path = messages.iter().rev().find(|(t, _, _)| *t == Topic::RoverPath).unwrap();
        assert_eq!(last_path.2["poses"].as_array().unwrap().len(), 20);
        // Same record, same bytes.
        assert_eq!(m.to_bytes().unwrap(), m.clone().to_bytes().unwrap());
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
            json!({"event": "rendezvous_received", "sim_time": 0.25, "step": 1, "mean": b.mean.as_slice(), "cov": b.cov.to_rows()}),
            json!({"event": "answer", "sim_time": 0.5, "step": 1, "rendezvous_answer": answer}),
            json!({"event": "arrived", "sim_time": 1.0, "step": 1}),
        ];
        assert_eq!(m.record_viewer_events(&events), 2);
        assert_eq!(m.requests[0].belief, b);
        assert_eq!(m.answers[0], answer);
        let messages = m.messages();
        let (_, ns, a) = messages.iter().find(|(t, _, _)| *t == Topic::Answer).unwrap();
        assert_eq!(*ns, 500_000_000);
        assert_eq!(a["E"], -10.0);
        assert_eq!(a["evaluations"]["occlusion"], 3);
        assert!(a.get("sim_time").is_none());
    }
}
