//! Missions as MCAP files (`dyfos-rover --mcap`, `dyfos-viewer --mcap`; the demo's
//! files are checked in `mission.rs`, and decoded by an independent ROS 2 reader
//! in `tests/ros2_mcap/`): read back with the `mcap` crate's reader, every channel
//! has its schema and encoding and carries messages, every Foxglove message has
//! exactly the fields its schema declares, and what the files say — poses,
//! rendezvous beliefs, answers, measurements, APE — is what the mission's event
//! logs and the evaluation's trace say. In the ROS 2 profile, every schema is the
//! full rosbag2 definition of its type and the messages are where they belong.

use dyfos_mission::eval::foxglove::CHANNELS;
use dyfos_mission::eval::{MissionTrace, ros2};
use dyfos_mission::mission::Mission;
use dyfos_shared::wire::mission::Observation;
use dyfos_tests::Sandbox;
use dyfos_tests::mission::{MissionFiles, Robot, small_mission, steps_of};
use serde_json::{Value, json};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// One message read back: log time and JSON.
struct Read {
    log_time: u64,
    data: Value,
}

/// Checks the summary of a mission file: its profile, the message and schema
/// encoding and the schema name of each channel (one of `channels`), and that
/// every declared channel carries messages. Returns the declared topics.
fn check_summary(bytes: &[u8], profile: &str, encodings: (&str, &str), channels: &[(&str, &str)]) -> Vec<String> {
    let header = mcap::read::LinearReader::new(bytes)
        .expect("an MCAP file")
        .find_map(|r| match r.expect("a record") {
            mcap::records::Record::Header(h) => Some(h),
            _ => None,
        })
        .expect("a header");
    assert_eq!(header.profile, profile);
    let summary = mcap::Summary::read(bytes).expect("a readable summary").expect("a summary section");
    let stats = summary.stats.as_ref().expect("statistics");
    let mut topics = Vec::new();
    for c in summary.channels.values() {
        assert_eq!(c.message_encoding, encodings.0, "{}", c.topic);
        let schema = c.schema.as_ref().unwrap_or_else(|| panic!("{} has no schema", c.topic));
        assert_eq!(schema.encoding, encodings.1, "{}", c.topic);
        let expected = channels.iter().find(|(t, _)| *t == c.topic).unwrap_or_else(|| panic!("unknown {}", c.topic));
        assert_eq!(schema.name, expected.1, "{}", c.topic);
        let count = stats.channel_message_counts.get(&c.id).copied().unwrap_or(0);
        assert!(count > 0, "{} is declared without a message", c.topic);
        topics.push(c.topic.clone());
    }
    topics.sort();
    topics
}

/// Reads `path` with the crate's reader: checks the summary (Foxglove's profile,
/// JSON messages, JSON-schema schemas, no channel without messages), every message
/// against the schema stored in the file, log times against the `timestamp`
/// fields, and returns the messages by topic (every topic of [`CHANNELS`], empty
/// where the file has none).
fn read_mission(path: &Path) -> BTreeMap<String, Vec<Read>> {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let summary = mcap::Summary::read(&bytes).expect("a readable summary").expect("a summary section");
    check_summary(&bytes, "", ("json", "jsonschema"), &CHANNELS);

    let mut by_topic: BTreeMap<String, Vec<Read>> = CHANNELS.iter().map(|(t, _)| (t.to_string(), Vec::new())).collect();
    let mut last = 0;
    let mut count = 0u64;
    for message in mcap::MessageStream::new(&bytes).expect("a readable file") {
        let message = message.expect("a readable message");
        let topic = message.channel.topic.clone();
        let schema = message.channel.schema.as_ref().expect("a schema");
        let schema: Value = serde_json::from_slice(&schema.data).expect("the schema is JSON");
        let data: Value = serde_json::from_slice(&message.data).expect("the message is JSON");
        if let Err(e) = conforms(&data, &schema, &topic) {
            panic!("{topic}: {e}\n{data}");
        }
        assert!(message.log_time >= last, "{topic}: messages are in log-time order");
        last = message.log_time;
        assert_eq!(message.publish_time, message.log_time);
        if let Some(t) = data.get("timestamp") {
            let ns = t["sec"].as_u64().unwrap() * 1_000_000_000 + t["nsec"].as_u64().unwrap();
            assert_eq!(ns, message.log_time, "{topic}: log time = the message's timestamp (simulated time)");
        }
        count += 1;
        by_topic.entry(topic).or_default().push(Read { log_time: message.log_time, data });
    }
    assert_eq!(summary.stats.expect("statistics").message_count, count);
    by_topic
}

/// Whether `value` has exactly what `schema` (JSON Schema, as Foxglove writes
/// them) declares: no key the schema lacks, every required key, the right types.
fn conforms(value: &Value, schema: &Value, at: &str) -> Result<(), String> {
    if let Some(options) = schema.get("oneOf").and_then(Value::as_array) {
        return match options.iter().any(|o| o.get("const") == Some(value)) {
            true => Ok(()),
            false => Err(format!("{at} = {value} is none of {options:?}")),
        };
    }
    let kind = schema.get("type").and_then(Value::as_str).ok_or_else(|| format!("{at}: schema without a type"))?;
    let ok = match kind {
        "object" => {
            let object = value.as_object().ok_or_else(|| format!("{at} is not an object"))?;
            let properties = schema["properties"].as_object().ok_or_else(|| format!("{at}: no properties"))?;
            for (key, v) in object {
                let property = properties.get(key).ok_or_else(|| format!("{at}.{key} is not in the schema"))?;
                conforms(v, property, &format!("{at}.{key}"))?;
            }
            for key in schema.get("required").and_then(Value::as_array).into_iter().flatten() {
                let key = key.as_str().unwrap();
                if !object.contains_key(key) {
                    return Err(format!("{at}.{key} is required"));
                }
            }
            true
        }
        "array" => {
            let items = value.as_array().ok_or_else(|| format!("{at} is not an array"))?;
            for (i, v) in items.iter().enumerate() {
                conforms(v, &schema["items"], &format!("{at}[{i}]"))?;
            }
            true
        }
        "number" => value.is_number(),
        "integer" => value.is_u64() || value.is_i64(),
        "string" => value.is_string(),
        "boolean" => value.is_boolean(),
        other => return Err(format!("{at}: unknown schema type {other}")),
    };
    if ok { Ok(()) } else { Err(format!("{at} = {value} is not of type {kind}")) }
}

fn xy(v: &Value) -> [f64; 2] {
    [v["x"].as_f64().unwrap(), v["y"].as_f64().unwrap()]
}

/// The yaw of a Foxglove quaternion that turns about z only.
fn yaw(q: &Value) -> f64 {
    assert_eq!((q["x"].as_f64(), q["y"].as_f64()), (Some(0.0), Some(0.0)), "a pure yaw: {q}");
    2.0 * q["z"].as_f64().unwrap().atan2(q["w"].as_f64().unwrap())
}

fn same_angle(a: f64, b: f64) -> bool {
    dyfos_shared::math::wrap_angle(a - b).abs() < 1e-12
}

fn ns(t: f64) -> u64 {
    (t * 1e9).round() as u64
}

/// The true (and estimated) poses of a `--mcap` rover file are the trace's, sample
/// for sample; the APE series is the trace's errors.
fn rover_poses_match(topics: &BTreeMap<String, Vec<Read>>, trace: &MissionTrace) {
    let mut truth = trace.truth.clone();
    truth.sort_by_key(|t| t.sample);
    let poses = &topics["/rover/pose"];
    assert_eq!(poses.len(), truth.len());
    for (p, t) in poses.iter().zip(&truth) {
        assert_eq!(p.log_time, ns(t.sim_time));
        assert_eq!(p.data["frame_id"], "map");
        assert_eq!(xy(&p.data["pose"]["position"]), [t.pose[0], t.pose[1]], "sample {}", t.sample);
        assert!(same_angle(yaw(&p.data["pose"]["orientation"]), t.pose[2]), "sample {}", t.sample);
    }
    let mut estimates = trace.estimates.clone();
    estimates.sort_by_key(|e| e.sample);
    let poses = &topics["/rover/estimate/pose"];
    assert_eq!(poses.len(), estimates.len());
    for (p, e) in poses.iter().zip(&estimates) {
        assert_eq!(xy(&p.data["pose"]["position"]), [e.belief.mean.x, e.belief.mean.y], "sample {}", e.sample);
        assert!(same_angle(yaw(&p.data["pose"]["orientation"]), e.belief.mean.z));
    }
    assert_eq!(topics["/rover/estimate/covariance"].len(), estimates.len());
    // The last path holds every pose.
    let path = &topics["/rover/path"].last().unwrap().data["poses"];
    assert_eq!(path.as_array().unwrap().len(), truth.len());
    assert_eq!(xy(&path[truth.len() - 1]["position"]), [truth.last().unwrap().pose[0], truth.last().unwrap().pose[1]]);
    let ape: Vec<f64> = topics["/dyfos/ape"].iter().map(|r| r.data["ape_m"].as_f64().unwrap()).collect();
    assert_eq!(ape, trace.errors());
    // Frames: the rover's true and estimated poses, the viewer and its camera.
    let mut frames: Vec<(String, String)> = topics["/tf"]
        .iter()
        .map(|r| {
            (r.data["parent_frame_id"].as_str().unwrap().into(), r.data["child_frame_id"].as_str().unwrap().into())
        })
        .collect();
    frames.sort();
    frames.dedup();
    let expected = [("map", "rover"), ("map", "rover_estimate"), ("map", "viewer"), ("viewer", "camera")];
    assert_eq!(frames, expected.map(|(p, c)| (p.to_string(), c.to_string())));
    let rover_tf = topics["/tf"].iter().filter(|r| r.data["child_frame_id"] == "rover").count();
    assert_eq!(rover_tf, truth.len());
}

/// The small mission run once with each side writing its MCAP file.
struct McapRun<'a> {
    mission: &'a Mission,
    rover_file: PathBuf,
    viewer_file: PathBuf,
    rover: Robot,
    viewer: Robot,
    trace: MissionTrace,
}

/// Runs the small mission with `--mcap FILE` and then `extra` on both sides, and
/// hands the run to `check` while its files exist.
fn with_mcap_mission(name: &str, extra: &[&str], check: impl FnOnce(McapRun)) {
    let (sandbox, _daemon) = Sandbox::with_daemon(name);
    let mission = small_mission();
    let files = MissionFiles::new(&sandbox, &mission);
    let (rover_file, viewer_file) = files.mcap_files();
    let rover_args = [&["--mcap", rover_file.to_str().unwrap()][..], extra].concat();
    let viewer_args = [&["--mcap", viewer_file.to_str().unwrap()][..], extra].concat();
    let (rover, viewer, trace) = files.run("m", 7, &viewer_args, &rover_args);
    check(McapRun { mission: &mission, rover_file, viewer_file, rover, viewer, trace });
}

#[test]
fn rover_and_viewer_write_missions_that_match_their_event_logs() {
    with_mcap_mission("mission-mcap", &[], |McapRun { mission, rover_file, viewer_file, rover, viewer, trace }| {
        let n = mission.waypoints.len();

        // The rover's file: its own poses, its requests, the measurements it used.
        let topics = read_mission(&rover_file);
        rover_poses_match(&topics, &trace);
        let rover_events = rover.events();
        let sent = steps_of(&rover_events, "rendezvous_sent");
        let requests = &topics["/dyfos/rendezvous/request"];
        assert_eq!(requests.len(), n);
        for (r, (k, e)) in requests.iter().zip(&sent) {
            assert_eq!(r.data["step"], json!(k));
            assert_eq!((&r.data["mean"], &r.data["cov"]), (&e["mean"], &e["cov"]), "step {k}");
            assert_eq!(r.log_time, ns(e["sim_time"].as_f64().unwrap()));
        }
        let measurements = &topics["/dyfos/rendezvous/measurement"];
        let updated = steps_of(&rover_events, "updated");
        assert_eq!(measurements.len(), n);
        assert_eq!(updated.len(), n, "every rendezvous measured: {rover_events:?}");
        for (m, (k, e)) in measurements.iter().zip(&updated) {
            assert_eq!((&m.data["step"], m.data["status"].as_str()), (&json!(k), Some("observed")));
            assert_eq!((&m.data["position"], &m.data["R"]), (&e["z"], &e["R"]), "step {k}");
        }
        assert!(topics["/dyfos/rendezvous/answer"].is_empty(), "the rover never sees the daemon's answers");
        assert_eq!(topics["/map"].len(), 1, "the map once (the sun stands still)");
        let map = &topics["/map"][0].data["entities"];
        let cylinders =
            map.as_array().unwrap().iter().filter(|e| !e["cylinders"].as_array().unwrap().is_empty()).count();
        assert_eq!(cylinders, mission.world.obstacles().len());

        // The viewer's file: the beliefs it got, the daemon's answers, where it looked from.
        let topics = read_mission(&viewer_file);
        let viewer_events = viewer.events();
        let received = steps_of(&viewer_events, "rendezvous_received");
        let requests = &topics["/dyfos/rendezvous/request"];
        assert_eq!(requests.len(), n);
        for (r, (k, e)) in requests.iter().zip(&received) {
            assert_eq!((&r.data["step"], &r.data["mean"], &r.data["cov"]), (&json!(k), &e["mean"], &e["cov"]));
        }
        let answers = &topics["/dyfos/rendezvous/answer"];
        let logged = steps_of(&viewer_events, "answer");
        assert_eq!(answers.len(), n);
        for (a, (k, e)) in answers.iter().zip(&logged) {
            let a = &a.data;
            assert_eq!(a["step"], json!(k));
            assert_eq!(
                (&a["E"], &a["R"], &a["viewer_position"]),
                (&e["cost"], &e["R"], &e["viewer_position"]),
                "step {k}"
            );
            assert_eq!((&a["evaluations"]["total"], &a["map_version"]), (&e["evaluations"], &e["map_version"]));
            assert_eq!((&a["algorithm"], a["sigma_plus"].as_array().map(Vec::len)), (&json!("dyfos"), Some(3)));
        }
        let poses = &topics["/viewer/pose"];
        assert_eq!(poses.len(), n + 1, "take-off and each rendezvous");
        for (p, (_, e)) in poses[1..].iter().zip(&logged) {
            let position = &p.data["pose"]["position"];
            assert_eq!(json!([position["x"], position["y"], position["z"]]), e["viewer_position"]);
            assert!(same_angle(yaw(&p.data["pose"]["orientation"]), e["viewer_yaw"].as_f64().unwrap()));
        }
        let cameras = &topics["/viewer/camera"];
        assert_eq!(cameras.len(), n);
        for c in cameras {
            let ids: Vec<&str> =
                c.data["entities"].as_array().unwrap().iter().map(|e| e["id"].as_str().unwrap()).collect();
            assert_eq!(ids, ["frustum", "line_of_sight"]);
            assert_eq!(c.data["entities"][0]["frame_id"], "camera");
        }
        // Its measurements are those the rover got (same numbers, through the topic).
        let theirs: Vec<&Value> = measurements.iter().map(|m| &m.data).collect();
        let ours: Vec<&Value> = topics["/dyfos/rendezvous/measurement"].iter().map(|m| &m.data).collect();
        assert_eq!(ours, theirs);
        let observed =
            trace.measurements.iter().filter(|m| matches!(m.observation, Observation::Observed { .. })).count();
        assert_eq!(observed, n);
        assert!(topics["/rover/pose"].is_empty(), "the viewer does not record the truth");
    });
}

/// Reads a ROS 2-profile file: checks the summary (profile `ros2`, CDR messages,
/// `ros2msg` schemas holding the full rosbag2 definition of their type, no channel
/// without messages), each message's encapsulation header, and the stamp of every
/// message that starts with a `std_msgs/Header` against its log time. Returns the
/// messages' log times by topic (every topic, empty where the file has none).
fn read_ros2(path: &Path) -> BTreeMap<String, Vec<u64>> {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    check_summary(&bytes, "ros2", ("cdr", "ros2msg"), &ros2::CHANNELS);
    let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
    for c in summary.channels.values() {
        let schema = c.schema.as_ref().unwrap();
        let text = ros2::definitions::full_text(&schema.name).unwrap();
        assert_eq!(std::str::from_utf8(&schema.data).unwrap(), text, "{}", c.topic);
    }
    let mut by_topic: BTreeMap<String, Vec<u64>> =
        ros2::CHANNELS.iter().map(|(t, _)| (t.to_string(), Vec::new())).collect();
    let mut last = 0;
    for message in mcap::MessageStream::new(&bytes).expect("a readable file") {
        let message = message.expect("a readable message");
        let topic = message.channel.topic.clone();
        assert_eq!(message.data[..4], [0, 1, 0, 0], "{topic}: CDR, little-endian");
        assert!(message.log_time >= last && message.publish_time == message.log_time, "{topic}");
        last = message.log_time;
        // TFMessage and MarkerArray start with a sequence; every other type with its header.
        if !matches!(topic.as_str(), "/tf" | "/map" | "/rover/estimate/covariance" | "/viewer/camera") {
            let word = |k: usize| u32::from_le_bytes(message.data[4 + 4 * k..8 + 4 * k].try_into().unwrap());
            let stamp = u64::from(word(0)) * 1_000_000_000 + u64::from(word(1));
            assert_eq!(stamp, message.log_time, "{topic}: the header's stamp is the log time");
        }
        by_topic.entry(topic).or_default().push(message.log_time);
    }
    by_topic
}

#[test]
fn rover_and_viewer_write_ros2_bags_on_request() {
    with_mcap_mission(
        "mission-ros2",
        &["--mcap-profile", "ros2"],
        |McapRun { mission, rover_file, viewer_file, rover, viewer, trace }| {
            let n = mission.waypoints.len();

            let topics = read_ros2(&rover_file);
            let mut truth: Vec<u64> = trace.truth.iter().map(|t| ns(t.sim_time)).collect();
            truth.sort();
            assert_eq!(topics["/rover/pose"], truth);
            assert_eq!(topics["/rover/estimate/pose"].len(), trace.estimates.len());
            assert_eq!(topics["/dyfos/ape"].len(), trace.errors().len());
            let rover_events = rover.events();
            let sent = steps_of(&rover_events, "rendezvous_sent");
            let times: Vec<u64> = sent.iter().map(|(_, e)| ns(e["sim_time"].as_f64().unwrap())).collect();
            assert_eq!(topics["/dyfos/rendezvous/request"], times);
            assert_eq!(topics["/dyfos/rendezvous/measurement"].len(), n);
            assert!(topics["/dyfos/rendezvous/answer"].is_empty());
            // `dyfos ape` reads the error from the ROS 2 profile's CDR as from the trace.
            let out =
                std::process::Command::new(dyfos_tests::bin("dyfos")).arg("ape").arg(&rover_file).output().unwrap();
            let stdout = String::from_utf8_lossy(&out.stdout);
            assert!(out.status.success(), "{stdout}\n{}", String::from_utf8_lossy(&out.stderr));
            let rmse =
                stdout.lines().find(|l| l.starts_with("RMSE")).unwrap_or_else(|| panic!("no RMSE row:\n{stdout}"));
            let expected = format!("{:.1}", trace.ape().expect("samples").centimetres()[0]);
            assert_eq!(rmse.split_whitespace().nth(1), Some(expected.as_str()), "{stdout}");

            let topics = read_ros2(&viewer_file);
            let events = viewer.events();
            assert_eq!(topics["/dyfos/rendezvous/request"].len(), steps_of(&events, "rendezvous_received").len());
            assert_eq!(topics["/dyfos/rendezvous/answer"].len(), n);
            assert_eq!(topics["/viewer/pose"].len(), n + 1, "take-off and each rendezvous");
            assert_eq!(topics["/viewer/camera"].len(), n);
            assert!(topics["/rover/pose"].is_empty(), "the viewer does not record the truth");
        },
    );
}

#[test]
fn a_message_with_a_misspelt_field_does_not_pass_the_check() {
    // The check above must be able to fail: a typo, a missing required field and a
    // wrong type are caught against Foxglove's own schema.
    let schema: Value =
        serde_json::from_str(dyfos_mission::eval::foxglove::schema("foxglove.PoseInFrame").unwrap()).unwrap();
    let good = json!({"timestamp": {"sec": 1, "nsec": 2}, "frame_id": "map",
                      "pose": {"position": {"x": 0.0, "y": 0.0, "z": 0.0}, "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}}});
    conforms(&good, &schema, "m").unwrap();
    let mut typo = good.clone();
    typo["pose"]["orientation"] = json!({"x": 0.0, "y": 0.0, "z": 0.0, "W": 1.0});
    assert!(conforms(&typo, &schema, "m").unwrap_err().contains("W is not in the schema"));
    let mut missing = good.clone();
    missing.as_object_mut().unwrap().remove("frame_id");
    assert!(conforms(&missing, &schema, "m").unwrap_err().contains("frame_id is required"));
    let mut wrong = good;
    wrong["timestamp"]["sec"] = json!(1.5);
    assert!(conforms(&wrong, &schema, "m").unwrap_err().contains("not of type integer"));
}
