//! The rover and viewer processes against a real `dyfosd` (SPEC §9, paper Fig. 2):
//! the mission reaches its goal, every step's messages happen in order and carry
//! what the other side sent, measurements beat dead reckoning, and a viewer killed
//! mid-run leaves the rover finishing on dead reckoning.

use dyfos_mission::mission::Mission;
use dyfos_shared::wire::mission::Observation;
use dyfos_tests::mission::{MissionFiles, finish, record_until_exit, small_mission, steps_of};
use dyfos_tests::{PATIENCE, Sandbox, bin};
use std::process::Command;
use std::time::{Duration, Instant};

#[test]
fn rover_reaches_the_goal_and_every_exchange_happens_in_order() {
    let (sandbox, _daemon) = Sandbox::with_daemon("mission-order");
    let mission = small_mission();
    let files = MissionFiles::new(&sandbox, &mission);
    let (rover, viewer, trace) = files.run("m", 7, &[], &[]);
    assert!(trace.finished(), "the goal was never reported");
    let n = mission.waypoints.len() as u64;

    // The rover: per step, send the rendezvous belief, arrive, update; then finish.
    let rover_events = rover.events();
    let kinds = ["start", "rendezvous_sent", "arrived", "updated", "dead_reckoning", "finished"];
    let seq: Vec<(String, u64)> = rover_events
        .iter()
        .filter(|e| kinds.iter().any(|k| e["event"] == *k))
        .map(|e| (e["event"].as_str().unwrap().to_string(), e["step"].as_u64().unwrap_or(0)))
        .collect();
    let mut expected = vec![("start".to_string(), 0)];
    for k in 1..=n {
        for e in ["rendezvous_sent", "arrived", "updated"] {
            expected.push((e.to_string(), k));
        }
    }
    expected.push(("finished".to_string(), 0));
    assert_eq!(seq, expected, "rover log:\n{}", rover.log());

    // The viewer: per step, receive, get an answer, fly there, send; then finish.
    let viewer_events = viewer.events();
    let kinds = ["rendezvous_received", "answer", "arrived", "measurement_sent", "no_answer", "finished"];
    let seq: Vec<(String, u64)> = viewer_events
        .iter()
        .filter(|e| kinds.iter().any(|k| e["event"] == *k))
        .map(|e| (e["event"].as_str().unwrap().to_string(), e["step"].as_u64().unwrap()))
        .collect();
    let mut expected = Vec::new();
    for k in 1..=n {
        for e in ["rendezvous_received", "answer", "arrived", "measurement_sent"] {
            expected.push((e.to_string(), k));
        }
    }
    expected.push(("finished".to_string(), n));
    assert_eq!(seq, expected, "viewer log:\n{}", viewer.log());
    assert_eq!(viewer_events[0]["event"], "map_synced", "the viewer uploads its map first");

    // Each side received exactly what the other sent.
    let sent = steps_of(&rover_events, "rendezvous_sent");
    let received = steps_of(&viewer_events, "rendezvous_received");
    for ((ks, s), (kr, r)) in sent.iter().zip(&received) {
        assert_eq!(ks, kr);
        assert_eq!(s["mean"], r["mean"], "step {ks}: the viewer got another belief than the rover sent");
    }
    assert_eq!(trace.measurements.len() as u64, n, "one measurement per rendezvous");
    for ((k, update), m) in steps_of(&rover_events, "updated").iter().zip(&trace.measurements) {
        assert_eq!(*k, u64::from(m.step));
        let Observation::Observed { position, r } = m.observation else { panic!("step {k} not observed: {m:?}") };
        assert_eq!(update["z"], serde_json::json!(position), "step {k}: the rover used another measurement");
        assert_eq!(update["R"], serde_json::json!(r.to_rows()));
        assert!(m.viewer.is_some() && m.predicted_cost.is_some());
    }
    // The rover's last estimate is where its log says it finished.
    let last = trace.estimates.last().unwrap();
    assert_eq!(rover_events.last().unwrap()["belief"], serde_json::json!(last.belief.mean.as_slice()));
}

#[test]
fn measurements_beat_dead_reckoning_on_every_seed() {
    let (sandbox, _daemon) = Sandbox::with_daemon("mission-ape");
    let files = MissionFiles::new(&sandbox, &small_mission());
    let mut with = Vec::new();
    let mut without = Vec::new();
    for seed in 1..=3 {
        let name = format!("dyfos-{seed}");
        let (_, _, trace) = files.run(&name, seed, &[], &[]);
        assert!(trace.updates() >= 3, "seed {seed}: only {} updates", trace.updates());
        with.push(trace.ape().unwrap().rmse);

        let name = format!("dead-{seed}");
        let recorder = files.recorder(&name);
        let mut rover = files.rover(&name, seed, "0", &["--dead-reckoning"]);
        let (status, trace) = record_until_exit(recorder, &mut rover);
        assert!(status.success(), "rover failed:\n{}", rover.log());
        assert!(
            trace.finished() && trace.updates() == 0,
            "{} estimates, {} truth, finished {}, {} updates; last {:?}",
            trace.estimates.len(),
            trace.truth.len(),
            trace.finished(),
            trace.updates(),
            trace.estimates.last()
        );
        without.push(trace.ape().unwrap().rmse);
    }
    for (seed, (w, wo)) in with.iter().zip(&without).enumerate() {
        assert!(w < wo, "seed {}: APE RMSE {w} m with dyfos, {wo} m dead reckoning", seed + 1);
    }
    let (w, wo) = (with.iter().sum::<f64>() / 3.0, without.iter().sum::<f64>() / 3.0);
    assert!(w < wo / 2.0, "mean APE RMSE {w} m with dyfos vs {wo} m dead reckoning");
}

#[test]
fn a_killed_viewer_leaves_the_rover_finishing_on_dead_reckoning() {
    let (sandbox, _daemon) = Sandbox::with_daemon("mission-kill");
    let mission = small_mission();
    let files = MissionFiles::new(&sandbox, &mission);
    // Paced at 10× so that the mission is still under way when the viewer dies; a
    // long measurement timeout, so that finishing in time needs the rover to notice
    // the dead viewer rather than wait it out.
    let (mut recorder, mut viewer, mut rover) = files.start("m", 3, "10", &[], &["--measurement-timeout", "60"]);
    // Kill the viewer once the rover has used its first measurement.
    let start = Instant::now();
    while recorder.trace().updates() == 0 {
        assert!(start.elapsed() < PATIENCE, "no first update:\n{}", viewer.log());
        assert!(rover.try_exit().is_none(), "the rover ended early:\n{}", rover.log());
        recorder.wait(Duration::from_millis(20));
        recorder.poll();
    }
    viewer.kill9();
    let (status, trace) = record_until_exit(recorder, &mut rover);
    assert!(status.success(), "rover failed:\n{}", rover.log());
    assert!(trace.finished());

    let events = rover.events();
    let n = mission.waypoints.len() as u64;
    let updated: Vec<u64> = steps_of(&events, "updated").iter().map(|(k, _)| *k).collect();
    let dead: Vec<(u64, String)> = steps_of(&events, "dead_reckoning")
        .iter()
        .map(|(k, e)| (*k, e["reason"].as_str().unwrap_or_default().to_string()))
        .collect();
    assert_eq!(updated.first(), Some(&1), "step 1 was measured before the kill");
    assert_eq!(updated.len() + dead.len(), n as usize, "each step is updated or dead-reckoned: {events:?}");
    let (last, reason) = dead.last().expect("the steps after the kill dead-reckon");
    assert_eq!(*last, n);
    assert_eq!(reason, "viewer gone", "the rover noticed the dead viewer");
    assert!(rover.log().contains("dead-reckoning"), "the log says so:\n{}", rover.log());
}

#[test]
fn bad_mission_files_are_refused_with_the_field_named() {
    let sandbox = Sandbox::new("mission-bad");
    let files = MissionFiles::new(&sandbox, &small_mission());
    let text = std::fs::read_to_string(&files.mission).unwrap().replacen("\"waypoints\"", "\"waypoint\"", 1);
    let bad = files.mission.with_file_name("bad.json");
    std::fs::write(&bad, text).unwrap();
    for binary in ["dyfos-rover", "dyfos-viewer"] {
        let out = Command::new(bin(binary)).arg("--mission").arg(&bad).output().unwrap();
        assert_eq!(out.status.code(), Some(2), "{binary}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains("unknown field `waypoint`"), "{binary}: {err}");
    }
}

#[test]
fn demo_prints_the_ape_table_and_draws_each_run() {
    let sandbox = Sandbox::new("mission-demo");
    let files = MissionFiles::new(&sandbox, &small_mission());
    let out_dir = sandbox.state_dir.with_extension("demo");
    let stdout = files.demo(&out_dir, &[]);
    let header = stdout.lines().find(|l| l.starts_with("APE (cm)")).expect("a table header");
    assert_eq!(header.split_whitespace().skip(2).collect::<Vec<_>>(), ["dyfos", "center", "dead-reckoning"]);
    let rmse: Vec<f64> = stdout
        .lines()
        .find(|l| l.starts_with("RMSE"))
        .expect("an RMSE row")
        .split_whitespace()
        .skip(1)
        .map(|v| v.parse().unwrap())
        .collect();
    assert_eq!(rmse.len(), 3);
    assert!(rmse[0] < rmse[2], "dyfos {} cm vs dead reckoning {} cm", rmse[0], rmse[2]);
    for arm in ["dyfos", "center", "dead-reckoning"] {
        let svg = std::fs::read_to_string(out_dir.join(format!("mission-{arm}.svg"))).unwrap();
        assert!(svg.starts_with("<svg") && svg.contains("<polyline"), "{arm}");
    }
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out_dir.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["runs"].as_array().unwrap().len(), 3);
    // One MCAP file per run (tests/tests/it/mission_mcap.rs checks their content):
    // the rover's samples from the recorded trace, the answers from the viewer's log.
    for (arm, run) in ["dyfos", "center", "dead-reckoning"].iter().zip(summary["runs"].as_array().unwrap()) {
        let bytes = std::fs::read(out_dir.join(format!("mission-{arm}-s1.mcap"))).unwrap();
        let file = mcap::Summary::read(&bytes).unwrap().expect("a summary");
        let stats = file.stats.expect("statistics");
        let messages = |id: &u16| stats.channel_message_counts.get(id).copied().unwrap_or(0);
        // Only channels that carry messages are declared (a run without a viewer has no camera).
        for (id, c) in &file.channels {
            assert!(messages(id) > 0, "{arm}: {} is declared without a message", c.topic);
        }
        let count =
            |topic: &str| file.channels.iter().find(|(_, c)| c.topic == topic).map_or(0, |(id, _)| messages(id));
        let rendezvous = if *arm == "dead-reckoning" { 0 } else { small_mission().waypoints.len() as u64 };
        assert_eq!(count("/dyfos/rendezvous/answer"), rendezvous, "{arm}");
        assert_eq!(count("/dyfos/rendezvous/request"), rendezvous, "{arm}");
        assert_eq!(count("/dyfos/rendezvous/measurement"), run["rendezvous"].as_u64().unwrap(), "{arm}");
        assert!(count("/rover/pose") > 20 && count("/dyfos/ape") == count("/rover/pose"), "{arm}");
    }
    let _ = std::fs::remove_dir_all(&out_dir);
}

#[test]
fn a_moving_sun_reaches_the_daemon_as_map_deltas() {
    let (sandbox, _daemon) = Sandbox::with_daemon("mission-sun");
    let rate = 0.02;
    let mission = Mission { sun_azimuth_rate: rate, ..small_mission() };
    let files = MissionFiles::new(&sandbox, &mission);
    let (_, viewer, trace) = files.run("m", 5, &[], &[]);
    assert!(trace.finished());

    let events = viewer.events();
    assert!(steps_of(&events, "resync").is_empty(), "the daemon's copy never went stale: {events:?}");
    let uploaded = events[0]["version"].as_u64().expect("map_synced first");
    let versions: Vec<u64> =
        steps_of(&events, "answer").iter().map(|(_, e)| e["map_version"].as_u64().unwrap()).collect();
    assert_eq!(versions.len(), mission.waypoints.len());
    // Time passes with every flight, so from step 2 on every query moves the sun
    // by one inline delta: one version each.
    for pair in versions.windows(2) {
        assert_eq!(pair[1], pair[0] + 1, "versions {versions:?}");
    }
    assert!(versions[0] <= uploaded + 1);
    let last = steps_of(&events, "rendezvous_received").last().unwrap().1["sim_time"].as_f64().unwrap();
    let world = sandbox.client().snapshot(1, PATIENCE).expect("snapshot");
    let expected = mission.world.sun().azimuth + rate * last;
    assert!((world.sun().azimuth - expected).abs() < 1e-9, "daemon sun {:?}, expected azimuth {expected}", world.sun());
    assert_eq!(world.version(), *versions.last().unwrap());
}

#[test]
fn the_example_mission_file_runs_in_the_demo_format() {
    let mission = Mission::load(Some(&dyfos_tests::data("mission-example.json"))).expect("the example parses");
    assert_eq!(mission.waypoints.len(), 4);
    assert_eq!(mission.world.obstacles().len(), 4);
    assert_eq!(mission.odometry.rot_per_m, 0.001);
    assert_eq!(mission.odometry.trans_per_m, dyfos_mission::sim::OdometryNoise::default().trans_per_m);
    assert_eq!(mission.sun_azimuth_rate, 0.01);
}

#[test]
fn a_killed_rover_lets_the_viewer_leave() {
    let (sandbox, _daemon) = Sandbox::with_daemon("mission-rover-kill");
    let files = MissionFiles::new(&sandbox, &small_mission());
    let (mut recorder, mut viewer, mut rover) = files.start("m", 4, "10", &[], &[]);
    let start = Instant::now();
    while recorder.trace().updates() == 0 {
        assert!(start.elapsed() < PATIENCE, "no first update:\n{}", rover.log());
        recorder.wait(Duration::from_millis(20));
        recorder.poll();
    }
    rover.kill9();
    // Long before its 120 s idle timeout, the viewer notices the rover is gone.
    let status = viewer.wait_exit();
    assert_eq!(status.code(), Some(1), "{}", viewer.log());
    assert!(viewer.log().contains("went away before reaching its goal"), "{}", viewer.log());
}

#[test]
fn a_mission_with_the_learned_noise_model_runs_end_to_end() {
    let model = dyfos_tests::data("learned/model.bin");
    let sandbox = Sandbox::new("mission-learned");
    let _daemon = sandbox.start_daemon(&["--model", model.to_str().unwrap()]);
    let mut mission = small_mission();
    mission.params.model = dyfos_shared::params::ModelKind::Learned;
    let files = MissionFiles::new(&sandbox, &mission);
    let (_, viewer, trace) = files.run("m", 2, &["--model", model.to_str().unwrap()], &[]);
    assert!(trace.finished());
    assert!(trace.updates() >= 3, "only {} updates:\n{}", trace.updates(), viewer.log());
    // Without the weights the viewer refuses to start, naming the problem.
    let out = Command::new(bin("dyfos-viewer")).arg("--mission").arg(&files.mission).output().unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("--model FILE"), "{}", String::from_utf8_lossy(&out.stderr));
}

/// `dyfos ape` prints, from the rover's `--mcap` file, the demo's table of the
/// error the evaluation measured; a file without `/dyfos/ape` is refused.
#[test]
fn dyfos_ape_prints_the_table_of_a_missions_mcap_file() {
    let (sandbox, _daemon) = Sandbox::with_daemon("mission-ape-cmd");
    let files = MissionFiles::new(&sandbox, &small_mission());
    let dir = sandbox.state_dir.with_extension("ape");
    std::fs::create_dir_all(&dir).unwrap();
    let (rover_mcap, viewer_mcap) = (dir.join("rover-run.mcap"), dir.join("viewer-run.mcap"));
    let (_, _, trace) =
        files.run("m", 2, &["--mcap", viewer_mcap.to_str().unwrap()], &["--mcap", rover_mcap.to_str().unwrap()]);
    let ape = trace.ape().expect("samples");

    let out = Command::new(bin("dyfos")).arg("ape").arg(&rover_mcap).arg(&rover_mcap).output().unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{stdout}\n{}", String::from_utf8_lossy(&out.stderr));
    let header = stdout.lines().find(|l| l.starts_with("APE (cm)")).expect("a table header");
    assert_eq!(header.split_whitespace().skip(2).collect::<Vec<_>>(), ["rover-run", "rover-run"]);
    for (row, value) in ["RMSE", "Median", "Mean", "Std", "Max"].iter().zip(ape.centimetres()) {
        let line = stdout.lines().find(|l| l.starts_with(row)).unwrap_or_else(|| panic!("no {row} row:\n{stdout}"));
        let expected = format!("{value:.1}");
        assert_eq!(line.split_whitespace().skip(1).collect::<Vec<_>>(), [&expected, &expected], "{stdout}");
    }
    assert!(stdout.contains(&format!("rover-run: {}", ape.count)), "{stdout}");

    let out = Command::new(bin("dyfos")).arg("ape").arg(&viewer_mcap).output().unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("has no /dyfos/ape messages"), "{err}");
    let out = Command::new(bin("dyfos")).arg("ape").arg(&files.mission).output().unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("is not an MCAP file"));
    let _ = std::fs::remove_dir_all(&dir);
}

/// Lines left out by the log's rate limit in the window still open at the exit are
/// summarised before the rover and the viewer exit.
#[test]
fn the_rover_and_viewer_say_at_exit_what_their_log_left_out() {
    use dyfos_mission::mission::topics::{Topics, TopicsConfig};
    use dyfos_shared::wire::mission::{AckMsg, ROVER_ACK_TOPIC, VIEWER_ACK_TOPIC};
    let (sandbox, _daemon) = Sandbox::with_daemon("mission-log-exit");
    let files = MissionFiles::new(&sandbox, &small_mission());
    // At 2× the last leg lasts a few seconds: the flood comes during it, most
    // likely in the log's last window (if a window ends meanwhile, its summary is
    // written anyway, and the counts must still add up).
    let (mut recorder, mut viewer, mut rover) = files.start("m", 3, "2", &[], &[]);
    let n = small_mission().waypoints.len() as u32;
    let start = Instant::now();
    while recorder.trace().step() < n {
        assert!(start.elapsed() < PATIENCE, "no last leg:\n{}", rover.log());
        recorder.wait(Duration::from_millis(20));
        recorder.poll();
    }
    // Malformed acknowledgements to both: each logs a few and counts the rest.
    let topics = Topics::open(&TopicsConfig {
        prefix: sandbox.prefix.clone(),
        domain: Some(sandbox.domain.clone()),
        mission: "m".into(),
    })
    .unwrap();
    // Kept until the end: a publisher that goes takes its unread samples along.
    let mut outboxes = Vec::new();
    for topic in [VIEWER_ACK_TOPIC, ROVER_ACK_TOPIC] {
        let outbox = topics.outbox::<AckMsg>("mission", topic).unwrap();
        for step in 0..40 {
            outbox.send(AckMsg { instance: 1, step, kind: 99 }).unwrap();
        }
        outboxes.push(outbox);
    }
    finish(recorder, &mut rover, &mut viewer);
    for (who, log) in [("rover", rover.log()), ("viewer", viewer.log())] {
        let (summaries, written): (Vec<&str>, Vec<&str>) = log
            .lines()
            .filter(|l| l.contains("ignoring a malformed acknowledgement"))
            .partition(|l| l.contains(" more in the last 10 s like: "));
        assert!(!summaries.is_empty(), "{who} did not say what it left out:\n{log}");
        let left_out: usize =
            summaries.iter().filter_map(|l| l.split("… ").nth(1)?.split(' ').next()?.parse::<usize>().ok()).sum();
        assert!(left_out >= 1 && written.len() + left_out <= 40, "{who}: {written:#?} {summaries:#?}");
    }
}

/// A mission process killed while creating a topic leaves it half made; the next
/// process to open the topic removes the remains and opens it.
#[test]
fn a_topic_a_killed_creator_left_half_made_opens() {
    use dyfos_mission::mission::topics::{Topics, TopicsConfig};
    use dyfos_shared::wire::mission::{RENDEZVOUS_TOPIC, RendezvousStateMsg, topic_name};
    use iceoryx2::service::messaging_pattern::MessagingPattern;
    let sandbox = Sandbox::new("half-made-topic");
    let config =
        TopicsConfig { prefix: sandbox.prefix.clone(), domain: Some(sandbox.domain.clone()), mission: "m".into() };
    let name = topic_name(&config.prefix, "mission", &config.mission, RENDEZVOUS_TOPIC);
    let pubsub = sandbox.leave_half_created(&name, MessagingPattern::PublishSubscribe);
    let event = sandbox.leave_half_created(&format!("{name}.event"), MessagingPattern::Event);
    let topics = Topics::open(&config).expect("node");
    let inbox = topics.inbox::<RendezvousStateMsg>("mission", RENDEZVOUS_TOPIC, 4);
    assert!(inbox.is_ok(), "{:?}", inbox.err());
    drop(inbox);
    drop(topics);
    assert!(!pubsub.exists() && !event.exists(), "the topic is removed when its last user leaves");
}
