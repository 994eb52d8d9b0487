//! The rover and the viewer on two hosts: two network namespaces made
//! by the test, joined by a veth pair, each host with its own iceoryx2 domain and
//! a `dyfos-link`; `dyfosd`, the viewer and the evaluation's recorder on the
//! viewer's host. Needs root (CI runs as root); otherwise each test prints a loud
//! SKIPPED line and passes.
//!
//! - across two hosts the APE and the rover's event log equal the one-host run;
//! - a 3 s outage costs at most the step it hits; a 12 s one is noticed by both
//!   sides and the mission resumes after it;
//! - killed and restarted link and viewer-host processes: the mission resumes and
//!   every process exits cleanly;
//! - long legs at the fastest time scale (a burst of samples) lose no step;
//! - a third host without the credentials cannot publish into the mission;
//! - a two-host mission ends as promptly as a one-host one, without a warning;
//! - the finish reaches a viewer that was away when the rover got to its goal;
//! - connections held open by a stranger do not keep a restarted link out, and are
//!   counted in the log; a stranger's garbage costs a bounded log;
//! - a link says when it cannot reach its peer, and when the peer serves another
//!   mission; no link warns about Zenoh's gossip.

use dyfos_mission::eval::{MissionTrace, Recorder};
use dyfos_mission::mission::Mission;
use dyfos_mission::mission::topics::{Topics, TopicsConfig};
use dyfos_shared::wire::mission::{MEASUREMENT_TOPIC, Measurement, MeasurementMsg, Observation};
use dyfos_tests::hosts::{Hosts, INTRUDER, ROVER, Stranger, VIEWER};
use dyfos_tests::mission::{MissionFiles, Robot, small_mission, steps_of};
use dyfos_tests::{DaemonProcess, PATIENCE, Sandbox};
use std::process::ExitStatus;
use std::time::{Duration, Instant};

/// Two hosts (and the intruder's, if asked) for `test`, and a sandbox named
/// `sandbox`; `None` where the hosts cannot be made.
fn hosts_and_sandbox(test: &str, sandbox: &str, intruder: bool) -> Option<(Hosts, Sandbox)> {
    Some((Hosts::create(test, intruder)?, Sandbox::new(sandbox)))
}

/// [`hosts_and_sandbox`] with a daemon in the sandbox, on the viewer's host.
fn hosts_with_daemon(test: &str, sandbox: &str, intruder: bool) -> Option<(Hosts, Sandbox, DaemonProcess)> {
    let (hosts, sandbox) = hosts_and_sandbox(test, sandbox, intruder)?;
    let daemon = sandbox.start_daemon(&[]);
    Some((hosts, sandbox, daemon))
}

/// The links of mission `name` on the rover's and the viewer's host.
fn links(hosts: &Hosts, files: &MissionFiles, name: &str) -> [Robot; 2] {
    [files.link_on(hosts, ROVER, name, &[]), files.link_on(hosts, VIEWER, name, &[])]
}

/// Stops each link; each must exit cleanly.
fn stop_links(links: &mut [Robot]) {
    for link in links {
        stop_link(link);
    }
}

/// Stops a link, which must exit cleanly; returns its log.
fn stop_link(link: &mut Robot) -> String {
    let status = link.terminate();
    let log = link.log();
    assert!(status.success(), "the link did not stop cleanly:\n{log}");
    log
}

/// Records the mission until the rover exits; returns its status and the trace.
fn record_until_exit(recorder: &mut Recorder, rover: &mut Robot, patience: Duration) -> ExitStatus {
    let start = Instant::now();
    loop {
        recorder.poll();
        if let Some(status) = rover.try_exit() {
            recorder.poll();
            return status;
        }
        assert!(start.elapsed() < patience, "the rover did not finish:\n{}", rover.log());
        recorder.wait(Duration::from_millis(20));
    }
}

/// Polls the recorder until `done` holds for its trace.
fn record_until(recorder: &mut Recorder, rover: &mut Robot, what: &str, done: impl Fn(&MissionTrace) -> bool) {
    let start = Instant::now();
    while !done(recorder.trace()) {
        assert!(start.elapsed() < PATIENCE * 2, "waited in vain for {what}:\n{}", rover.log());
        assert!(rover.try_exit().is_none(), "the rover ended before {what}:\n{}", rover.log());
        recorder.wait(Duration::from_millis(20));
        recorder.poll();
    }
}

/// One run's outcome: the rover's events (without wall-clock-dependent fields)
/// and the APE RMSE bits.
#[derive(Debug, PartialEq)]
struct Outcome {
    rover_events: Vec<serde_json::Value>,
    ape_rmse_bits: u64,
    ape_max_bits: u64,
    measurements: usize,
}

fn outcome(rover: &Robot, trace: &MissionTrace) -> Outcome {
    let ape = trace.ape().expect("samples were recorded");
    Outcome {
        rover_events: rover.events(),
        ape_rmse_bits: ape.rmse.to_bits(),
        ape_max_bits: ape.max.to_bits(),
        measurements: trace.measurements.len(),
    }
}

/// The mission on one host, as the existing mission tests run it.
fn one_host(files: &MissionFiles, name: &str, seed: u64) -> Outcome {
    let mut recorder = files.recorder(name);
    let mut viewer = files.viewer(name, "dyfos", seed, &[]);
    let mut rover = files.rover(name, seed, "0", &[]);
    let status = record_until_exit(&mut recorder, &mut rover, PATIENCE * 2);
    assert!(status.success(), "rover failed:\n{}", rover.log());
    assert!(viewer.wait_exit().success(), "viewer failed:\n{}", viewer.log());
    outcome(&rover, &recorder.finish())
}

/// The same mission across the two hosts.
fn two_hosts(hosts: &Hosts, files: &MissionFiles, name: &str, seed: u64) -> Outcome {
    let mut links = links(hosts, files, name);
    let mut recorder = files.recorder(name);
    let mut viewer = files.viewer_on(hosts, name, "dyfos", seed, &[]);
    let mut rover = files.rover_on(hosts, name, seed, "0", &[]);
    let status = record_until_exit(&mut recorder, &mut rover, PATIENCE * 2);
    assert!(status.success(), "rover failed:\n{}\nlinks:\n{}\n{}", rover.log(), links[0].log(), links[1].log());
    assert!(viewer.wait_exit().success(), "viewer failed:\n{}", viewer.log());
    for link in &mut links {
        assert_quiet_start(&stop_link(link));
    }
    outcome(&rover, &recorder.finish())
}

/// A link's log has no warning about Zenoh's own configuration at start.
fn assert_quiet_start(log: &str) {
    assert!(!log.contains("Gossip is disabled"), "{log}");
    assert!(!log.contains("Scouting delay elapsed"), "{log}");
}

/// The lines of `log` with a warning or error.
fn warnings(log: &str) -> Vec<&str> {
    log.lines().filter(|l| l.contains(" WARN ") || l.contains(" ERROR ")).collect()
}

/// Seconds of the day of a log line's timestamp (`2026-11-22T00:45:41.898640Z  INFO …`).
fn stamp(line: &str) -> Option<f64> {
    let time = line.split_whitespace().next()?.split('T').nth(1)?.trim_end_matches('Z');
    let mut parts = time.split(':');
    let (h, m, s) = (parts.next()?.parse::<f64>().ok()?, parts.next()?.parse::<f64>().ok()?, parts.next()?);
    Some(h * 3600.0 + m * 60.0 + s.parse::<f64>().ok()?)
}

/// The time of the first line of `log` containing `text`.
fn stamp_of(log: &str, text: &str) -> Option<f64> {
    log.lines().find(|l| l.contains(text)).and_then(stamp)
}

/// Waits (at most [`PATIENCE`]) until `robot`'s log contains `text`.
fn wait_for_log(robot: &Robot, text: &str) {
    let start = Instant::now();
    while !robot.log().contains(text) {
        assert!(start.elapsed() < PATIENCE, "waited in vain for `{text}` in:\n{}", robot.log());
        std::thread::sleep(Duration::from_millis(50));
    }
}

fn compare(one: &Outcome, two: &Outcome) {
    assert_eq!(one.rover_events.len(), two.rover_events.len(), "{:#?}\n{:#?}", one.rover_events, two.rover_events);
    for (a, b) in one.rover_events.iter().zip(&two.rover_events) {
        assert_eq!(a, b, "the rover's event logs differ");
    }
    assert_eq!(one, two);
}

#[test]
fn across_two_hosts_the_ape_and_the_rover_log_equal_one_host() {
    let Some((hosts, sandbox, _daemon)) = hosts_with_daemon("two-hosts-equal", "hosts-equal", false) else { return };
    let files = MissionFiles::new(&sandbox, &small_mission());
    for seed in [1, 2] {
        let one = one_host(&files, &format!("one-{seed}"), seed);
        let two = two_hosts(&hosts, &files, &format!("two-{seed}"), seed);
        assert_eq!(one.measurements, 4, "every step measured on one host");
        compare(&one, &two);
    }
}

/// Long legs across the whole map at time scale 0: hundreds of samples per leg
/// arrive at once.
#[test]
fn long_legs_at_the_fastest_time_scale_lose_no_step() {
    let Some((hosts, sandbox, _daemon)) = hosts_with_daemon("two-hosts-burst", "hosts-burst", false) else { return };
    let mission = Mission { waypoints: vec![[6.5, -6.5], [6.5, 6.5], [-6.5, 6.5], [-6.5, -6.5]], ..small_mission() };
    let legs = mission.path_length() / mission.waypoints.len() as f64;
    assert!(legs > 10.0, "legs of {legs} m");
    let files = MissionFiles::new(&sandbox, &mission);
    let one = one_host(&files, "one", 3);
    let two = two_hosts(&hosts, &files, "two", 3);
    assert_eq!(two.measurements, mission.waypoints.len(), "a measurement (or why not) for every step");
    let reasons: Vec<String> = steps_of(&two.rover_events, "dead_reckoning")
        .iter()
        .map(|(_, e)| e["reason"].as_str().unwrap_or_default().to_string())
        .collect();
    assert!(
        reasons
            .iter()
            .all(|r| !r.contains("viewer gone") && !r.contains("no measurement") && !r.contains("rover_left")),
        "steps lost to the link: {reasons:?}"
    );
    compare(&one, &two);
}

/// Small mission, there and back: 8 legs, so that an outage leaves steps after it.
fn there_and_back() -> Mission {
    let mut m = small_mission();
    let mut back: Vec<[f64; 2]> = m.waypoints.iter().rev().skip(1).copied().collect();
    back.push([m.initial_belief.mean.x, m.initial_belief.mean.y]);
    m.waypoints.extend(back);
    m
}

/// Runs `there_and_back` at time scale `scale` across the hosts, calling
/// `disturb` once the first measurement is in; returns the rover's and viewer's events.
fn disturbed_mission(
    test: &str,
    scale: &str,
    disturb: impl FnOnce(&Hosts, &MissionFiles, &mut Recorder, &mut Robot, &mut [Robot; 3]),
) -> Option<(Vec<serde_json::Value>, Vec<serde_json::Value>, MissionTrace)> {
    let (hosts, sandbox, _daemon) = hosts_with_daemon(test, test, false)?;
    let mission = there_and_back();
    let files = MissionFiles::new(&sandbox, &mission);
    let name = "m";
    // Generous timeouts: the rover must not give up on a viewer that comes back,
    // nor the viewer on the rover.
    let mut procs = [
        files.link_on(&hosts, ROVER, name, &[]),
        files.link_on(&hosts, VIEWER, name, &[]),
        files.viewer_on(&hosts, name, "dyfos", 5, &["--rover-timeout", "120"]),
    ];
    let mut recorder = files.recorder(name);
    let mut rover = files.rover_on(&hosts, name, 5, scale, &["--measurement-timeout", "120"]);
    record_until(&mut recorder, &mut rover, "the first update", |t| t.updates() >= 1);
    disturb(&hosts, &files, &mut recorder, &mut rover, &mut procs);
    let status = record_until_exit(&mut recorder, &mut rover, PATIENCE * 6);
    assert!(status.success(), "rover failed:\n{}", rover.log());
    let [rover_link, viewer_link, viewer] = &mut procs;
    assert!(viewer.wait_exit().success(), "viewer failed:\n{}", viewer.log());
    stop_link(rover_link);
    stop_link(viewer_link);
    let trace = recorder.finish();
    assert!(trace.finished(), "the goal was never reported");
    let n = mission.waypoints.len();
    let events = rover.events();
    let updated = steps_of(&events, "updated").len();
    let dead = steps_of(&events, "dead_reckoning").len();
    assert_eq!(updated + dead, n, "each step updated or dead-reckoned: {events:#?}");
    Some((events, viewer.events(), trace))
}

/// [`disturbed_mission`] with the link between the hosts down for `seconds`.
fn outage(
    test: &str,
    scale: &str,
    seconds: u64,
) -> Option<(Vec<serde_json::Value>, Vec<serde_json::Value>, MissionTrace)> {
    disturbed_mission(test, scale, |hosts, _, _, _, _| {
        hosts.set_link(false);
        std::thread::sleep(Duration::from_secs(seconds));
        hosts.set_link(true);
    })
}

#[test]
fn a_3_s_outage_costs_at_most_the_step_it_hits() {
    // Time scale 1: legs of 6 s or more, longer than the outage and the reconnection.
    let Some((events, _, _)) = outage("outage-3s", "1", 3) else { return };
    let dead = steps_of(&events, "dead_reckoning");
    assert!(dead.len() <= 1, "more than the step the outage hit was lost: {dead:#?}");
}

#[test]
fn a_12_s_outage_is_noticed_by_both_sides_and_the_mission_resumes() {
    let Some((rover_events, viewer_events, _)) = outage("outage-12s", "2", 12) else { return };
    let kinds = |events: &[serde_json::Value]| -> Vec<String> {
        events.iter().filter_map(|e| e["event"].as_str().map(str::to_string)).collect()
    };
    let rover = kinds(&rover_events);
    let lost = rover.iter().position(|e| e == "viewer_lost").expect("the rover noticed the outage");
    let back = rover.iter().position(|e| e == "viewer_back").expect("the rover saw the viewer come back");
    assert!(lost < back);
    assert!(rover[lost..back].iter().any(|e| e == "dead_reckoning"), "the rover dead-reckoned meanwhile: {rover:?}");
    assert!(rover[back..].iter().any(|e| e == "updated"), "measurements resumed after the outage: {rover:?}");
    let viewer = kinds(&viewer_events);
    let lost = viewer.iter().position(|e| e == "rover_lost").expect("the viewer noticed the outage");
    assert!(viewer[lost..].iter().any(|e| e == "rover_back"), "the viewer saw the rover come back: {viewer:?}");
    let silent: Vec<f64> =
        steps_of(&rover_events, "viewer_back").iter().filter_map(|(_, e)| e["silent_s"].as_f64()).collect();
    eprintln!("12 s outage: the rover heard nothing for {silent:?} s; events {rover:?}");
}

#[test]
fn killed_link_and_viewer_host_processes_restart_and_the_mission_resumes() {
    let Some((rover_events, _, _)) = disturbed_mission("restart", "2", |hosts, files, recorder, rover, procs| {
        // The rover's link dies and comes back.
        procs[0].kill9();
        procs[0] = files.link_on(hosts, ROVER, "m", &[]);
        let before = recorder.trace().updates();
        record_until(recorder, rover, "an update after the rover's link restarted", |t| t.updates() > before);
        // Then the viewer's host: its link and the viewer.
        procs[1].kill9();
        procs[2].kill9();
        procs[1] = files.link_on(hosts, VIEWER, "m", &[]);
        procs[2] = files.viewer_on(hosts, "m", "dyfos", 5, &["--rover-timeout", "120"]);
        let before = recorder.trace().updates();
        record_until(recorder, rover, "an update from the restarted viewer", |t| t.updates() > before);
    }) else {
        return;
    };
    assert!(
        steps_of(&rover_events, "viewer_back").iter().any(|(_, e)| e["instance"].is_u64()),
        "the rover saw a new viewer"
    );
}

#[test]
fn a_third_host_without_the_credentials_cannot_publish_a_measurement() {
    let Some((hosts, sandbox)) = hosts_and_sandbox("intruder", "hosts-intruder", true) else { return };
    let files = MissionFiles::new(&sandbox, &small_mission());
    let name = "m";
    let mut rover_link = files.link_on(&hosts, ROVER, name, &[]);
    // The rover's host listens for measurements (as the rover would).
    let rover_topics =
        TopicsConfig { prefix: sandbox.prefix.clone(), domain: Some(files.rover_domain()), mission: name.into() };
    let topics = Topics::open(&rover_topics).unwrap();
    let inbox = topics.inbox::<MeasurementMsg>("mission", MEASUREMENT_TOPIC, 64).unwrap();
    // The intruder: a link of its own, wrong credentials, and a fake measurement
    // published on its host again and again.
    let wrong = sandbox.state_dir.with_extension("wrong-credentials");
    std::fs::write(&wrong, "crew:not-the-password\n").unwrap();
    let intruder_domain = sandbox.host_domain('i');
    let mut intruders = Vec::new();
    for credentials in [Some(&wrong), None] {
        let mut cmd = hosts.command(INTRUDER, &dyfos_tests::bin("dyfos-link"));
        cmd.args([
            "--side",
            "viewer",
            "--prefix",
            &sandbox.prefix,
            "--domain",
            &intruder_domain,
            "--mission-name",
            name,
        ])
        .args(["--connect", &hosts.rover_endpoint(INTRUDER, 7447)]);
        match credentials {
            Some(c) => cmd.arg("--credentials").arg(c),
            None => cmd.arg("--insecure"),
        };
        let log = sandbox.state_dir.with_extension(format!("intruder-{}.log", intruders.len()));
        cmd.stderr(std::fs::File::create(&log).unwrap()).stdout(std::process::Stdio::null());
        intruders.push((cmd.spawn().unwrap(), log));
        let fake_topics = TopicsConfig {
            prefix: sandbox.prefix.clone(),
            domain: Some(intruder_domain.clone()),
            mission: name.into(),
        };
        let fake = Topics::open(&fake_topics).unwrap();
        let outbox = fake.outbox::<MeasurementMsg>("mission", MEASUREMENT_TOPIC).unwrap();
        let forged = Measurement {
            step: 1,
            sim_time: 0.0,
            observation: Observation::Observed {
                position: [0.0, 0.0],
                r: dyfos_shared::math::Cov2::from_rows(&[[1e-4, 0.0], [0.0, 1e-4]]).unwrap(),
            },
            viewer: None,
            predicted_cost: None,
        };
        // Until the rover's link has logged two refused attempts of this intruder
        // (Zenoh's user/password authentication says why, through our rate-limited log).
        let seen = rover_link.log().len();
        let start = Instant::now();
        while rover_link.log()[seen..].matches("UsrPwd extension").count() < 2 {
            outbox.send(MeasurementMsg::from(&forged)).unwrap();
            assert!(inbox.try_recv().is_none(), "a forged measurement reached the rover's host");
            std::thread::sleep(Duration::from_millis(100));
            assert!(start.elapsed() < PATIENCE, "the rover's link logged no refusal:\n{}", rover_link.log());
        }
        assert!(inbox.try_recv().is_none(), "a forged measurement reached the rover's host");
    }
    for (mut child, log) in intruders {
        let _ = child.kill();
        let _ = child.wait();
        let text = std::fs::read_to_string(&log).unwrap_or_default();
        assert!(!text.contains("the other host is connected"), "the intruder connected:\n{text}");
        let _ = std::fs::remove_file(&log);
    }
    let _ = std::fs::remove_file(&wrong);
    let log = stop_link(&mut rover_link);
    assert!(log.contains("received=0"), "the rover's link handed nothing on:\n{log}");
}

#[test]
fn demo_on_two_hosts_prints_the_one_host_table() {
    // Only to print SKIPPED when not root; the demo makes its own namespaces.
    let Some(_probe) = Hosts::create("demo-hosts-2", false) else { return };
    let sandbox = Sandbox::new("hosts-demo");
    let files = MissionFiles::new(&sandbox, &small_mission());
    let table = |hosts: &str| {
        let out_dir = sandbox.state_dir.with_extension(format!("demo-{hosts}"));
        let stdout = files.demo(&out_dir, &["--seed", "2", "--hosts", hosts]);
        let _ = std::fs::remove_dir_all(&out_dir);
        let start = stdout.find("APE (cm)").expect("a table");
        stdout[start..].lines().take(6).map(str::to_string).collect::<Vec<_>>()
    };
    let (one, two) = (table("1"), table("2"));
    assert_eq!(one.len(), 6);
    assert_eq!(one, two, "the two-host demo's table differs from the one-host one");
}

/// docs/cross-host.md's two-host setup, without an evaluation: at the goal the rover waits
/// for every reader of its estimates, and on the rover's host that is the link.
/// The viewer's link acknowledges for the (no) evaluations on its host, so the
/// rover ends as soon as the viewer has the finish, with no warning.
#[test]
fn a_two_host_mission_ends_as_promptly_as_a_one_host_one() {
    let Some((hosts, sandbox, _daemon)) = hosts_with_daemon("prompt-end", "hosts-prompt", false) else { return };
    let files = MissionFiles::new(&sandbox, &small_mission());
    let name = "m";
    let mut links = links(&hosts, &files, name);
    let mut viewer = files.viewer_on(&hosts, name, "dyfos", 6, &[]);
    let started = Instant::now();
    let mut rover = files.rover_on(&hosts, name, 6, "0", &[]);
    // When each exits: the viewer once it has the finish, the rover once the
    // finish and its last sample are acknowledged.
    let (mut viewer_done, mut rover_done) = (None, None);
    while viewer_done.is_none() || rover_done.is_none() {
        if viewer_done.is_none()
            && let Some(status) = viewer.try_exit()
        {
            assert!(status.success(), "viewer failed:\n{}", viewer.log());
            viewer_done = Some(Instant::now());
        }
        if rover_done.is_none()
            && let Some(status) = rover.try_exit()
        {
            assert!(status.success(), "rover failed:\n{}", rover.log());
            rover_done = Some((Instant::now(), started.elapsed()));
        }
        assert!(started.elapsed() < PATIENCE * 2, "the mission did not end:\n{}\n{}", rover.log(), viewer.log());
        std::thread::sleep(Duration::from_millis(5));
    }
    let (Some(viewer_done), Some((rover_done, ran))) = (viewer_done, rover_done) else { unreachable!() };
    let after_viewer = rover_done.saturating_duration_since(viewer_done);
    eprintln!("two-host mission: the rover ran {ran:?} and ended {after_viewer:?} after the viewer");
    assert!(
        after_viewer < Duration::from_millis(1500),
        "the rover lingered {after_viewer:?}:\n{}\nlinks:\n{}\n{}",
        rover.log(),
        links[0].log(),
        links[1].log()
    );
    let rover_log = rover.log();
    assert!(warnings(&rover_log).is_empty(), "the rover warned:\n{rover_log}");
    stop_links(&mut links);
}

/// The viewer's host is cut off while the rover drives its last leg, so that the
/// viewer counts as gone at the goal; it comes back a moment later and must still
/// hear the finish (and both exit 0), because the rover keeps offering it.
#[test]
fn the_finish_reaches_a_viewer_that_was_away_at_the_goal() {
    let Some((hosts, sandbox, _daemon)) = hosts_with_daemon("away-at-goal", "hosts-away", false) else { return };
    let mission = small_mission();
    let n = mission.waypoints.len() as u64;
    let files = MissionFiles::new(&sandbox, &mission);
    let name = "m";
    let mut links = links(&hosts, &files, name);
    let mut viewer = files.viewer_on(&hosts, name, "dyfos", 8, &[]);
    // Paced, so that the last leg lasts long enough to cut the link during it.
    let mut rover = files.rover_on(&hosts, name, 8, "2", &["--measurement-timeout", "60"]);
    let wait_event = |rover: &mut Robot, event: &str| {
        let start = Instant::now();
        while !steps_of(&rover.events(), event).iter().any(|(k, _)| *k == n) {
            assert!(start.elapsed() < PATIENCE * 2, "no {event} for step {n}:\n{}", rover.log());
            assert!(rover.try_exit().is_none(), "the rover ended early:\n{}", rover.log());
            std::thread::sleep(Duration::from_millis(20));
        }
    };
    wait_event(&mut rover, "rendezvous_sent");
    hosts.set_link(false);
    // The rover at the goal, without the viewer: it dead-reckons the last step
    // once the viewer counts as gone, then offers the finish.
    wait_event(&mut rover, "dead_reckoning");
    std::thread::sleep(Duration::from_secs(1));
    hosts.set_link(true);
    let back = Instant::now();
    let status = rover.wait_exit();
    // The rover's last samples were lost on the link, so it waits out its linger
    // for an acknowledgement of them (and says so).
    eprintln!("the rover ended {:?} after the link came back: {:#?}", back.elapsed(), warnings(&rover.log()));
    assert!(status.success(), "rover failed:\n{}", rover.log());
    let viewer_status = viewer.wait_exit();
    assert!(viewer_status.success(), "the viewer did not hear the finish:\n{}", viewer.log());
    let events = rover.events();
    assert!(
        !events.iter().any(|e| e["event"] == "finish_unacknowledged"),
        "the finish was not acknowledged: {events:#?}"
    );
    let viewer_events = viewer.events();
    assert!(viewer_events.iter().any(|e| e["event"] == "finished"), "{viewer_events:#?}");
    stop_links(&mut links);
}

/// 300 connections held open without a word by a host without the credentials:
/// the viewer's link, restarted, reconnects within 2 s and the mission completes;
/// the rover's link counts the handshakes it gave up on and reports them, at most
/// once per 10 s.
#[test]
fn silent_connections_do_not_keep_a_restarted_link_out() {
    let Some((hosts, sandbox, _daemon)) = hosts_with_daemon("silent-connections", "hosts-silent", true) else { return };
    let mission = there_and_back();
    let files = MissionFiles::new(&sandbox, &mission);
    let name = "m";
    let mut rover_link = files.link_on(&hosts, ROVER, name, &[]);
    let mut viewer_link = files.link_on(&hosts, VIEWER, name, &[]);
    let mut viewer = files.viewer_on(&hosts, name, "dyfos", 9, &["--rover-timeout", "120"]);
    let mut recorder = files.recorder(name);
    let mut rover = files.rover_on(&hosts, name, 9, "2", &["--measurement-timeout", "120"]);
    record_until(&mut recorder, &mut rover, "the first update", |t| t.updates() >= 1);

    let mut stranger = Stranger::start(&hosts, INTRUDER, 7447, "silent", "300");
    assert_eq!(stranger.line(), "holding 300");
    // Long enough for the rover's link to give up on the first of them.
    std::thread::sleep(Duration::from_secs(3));
    viewer_link.kill9();
    let restarted = time_of_day();
    viewer_link = files.link_on(&hosts, VIEWER, name, &[]);
    wait_for_log(&viewer_link, "the other host is connected");
    let log = viewer_link.log();
    let connected = stamp_of(&log, "the other host is connected").expect("a connected line") - restarted;
    let opened = stamp_of(&log, "Using ZID").expect("zenoh's first line") - restarted;
    eprintln!(
        "with 300 silent connections the restarted link connected {connected:.3} s after it was started (its Zenoh session opened at {opened:.3} s)"
    );
    assert!(connected <= 2.0, "the restarted link took {connected:.3} s to connect:\n{log}");
    let before = recorder.trace().updates();
    record_until(&mut recorder, &mut rover, "an update after the restart", |t| t.updates() > before);
    let status = record_until_exit(&mut recorder, &mut rover, PATIENCE * 4);
    assert!(status.success(), "rover failed:\n{}", rover.log());
    assert!(viewer.wait_exit().success(), "viewer failed:\n{}", viewer.log());
    wait_for_log(&rover_link, "given up (no handshake within 2s)");
    drop(stranger);
    for link in [&mut rover_link, &mut viewer_link] {
        assert_quiet_start(&stop_link(link));
    }
    let log = rover_link.log();
    let reports: Vec<&str> = log.lines().filter(|l| l.contains("incoming connections")).collect();
    eprintln!("{}", reports.join("\n"));
    // At most one report per 10 s (the first at once).
    let stamps: Vec<f64> = reports.iter().filter_map(|l| stamp(l)).collect();
    assert!(stamps.windows(2).all(|w| w[1] - w[0] >= 9.9), "{reports:#?}");
}

/// Now, as seconds of the (UTC) day, like [`stamp`].
fn time_of_day() -> f64 {
    let now = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).expect("after 1970");
    (now.as_secs() % 86_400) as f64 + f64::from(now.subsec_nanos()) * 1e-9
}

/// Random frames from a host without the credentials for `SECONDS`: Zenoh quotes
/// each in a line of its own (a new kind of line each time), yet the rover's link
/// writes at most 200 KB per minute, and says how many lines it left out, also
/// for the last window when it stops.
#[test]
fn a_strangers_garbage_costs_a_bounded_log() {
    const SECONDS: u64 = 30;
    let Some((hosts, sandbox)) = hosts_and_sandbox("garbage", "hosts-garbage", true) else { return };
    let files = MissionFiles::new(&sandbox, &small_mission());
    let mut rover_link = files.link_on(&hosts, ROVER, "m", &[]);
    wait_for_log(&rover_link, "link started");
    let mut stranger = Stranger::start(&hosts, INTRUDER, 7447, "garbage", &SECONDS.to_string());
    let sent = stranger.line();
    assert!(sent.starts_with("sent "), "{sent}");
    let log = stop_link(&mut rover_link);
    let bound = 200 * 1024 * SECONDS as usize / 60;
    eprintln!("{sent}: {} bytes of log in {SECONDS} s (bound {bound})", log.len());
    assert!(log.len() <= bound, "{} bytes of log:\n{}", log.len(), &log[..log.len().min(20_000)]);
    assert!(log.contains(" more in the last 10 s"), "nothing says what was left out:\n{log}");
    // The summary of the window open at the stop comes after the stop.
    let stopped = log.find("link stopped").expect("a stop line");
    assert!(log[stopped..].contains(" more in the last 10 s"), "no summary at exit:\n{}", &log[stopped..]);
    assert_quiet_start(&log);
}

/// A viewer's link whose peer is not there says so, with Zenoh's reason, and keeps
/// trying.
#[test]
fn a_link_that_cannot_reach_its_peer_says_so() {
    let Some((hosts, sandbox)) = hosts_and_sandbox("unreachable", "hosts-unreachable", false) else { return };
    let files = MissionFiles::new(&sandbox, &small_mission());
    let mut viewer_link = files.link_on(&hosts, VIEWER, "m", &[]);
    wait_for_log(&viewer_link, "cannot reach the other host");
    let log = viewer_link.log();
    let line = log.lines().find(|l| l.contains("cannot reach the other host")).unwrap_or_default();
    eprintln!("{line}");
    assert!(line.contains(&hosts.rover_endpoint(VIEWER, 7447)), "the endpoint is named:\n{log}");
    // Then the peer comes, and the link connects.
    let mut rover_link = files.link_on(&hosts, ROVER, "m", &[]);
    wait_for_log(&viewer_link, "the other host is connected");
    for link in [&mut viewer_link, &mut rover_link] {
        assert_quiet_start(&stop_link(link));
    }
}

/// Two links with the right credentials but different mission names: nothing
/// flows between them, and each says once which mission the other serves.
#[test]
fn a_peer_of_another_mission_is_named_once_on_both_sides() {
    let Some((hosts, sandbox)) = hosts_and_sandbox("other-mission", "hosts-other-mission", false) else { return };
    let files = MissionFiles::new(&sandbox, &small_mission());
    let mut rover_link = files.link_on(&hosts, ROVER, "field-1", &[]);
    let mut viewer_link = files.link_on(&hosts, VIEWER, "field-2", &[]);
    wait_for_log(&rover_link, "serves mission `field-2`, this one `field-1`");
    wait_for_log(&viewer_link, "serves mission `field-1`, this one `field-2`");
    // A restart of the other side says nothing new.
    viewer_link.kill9();
    viewer_link = files.link_on(&hosts, VIEWER, "field-2", &[]);
    wait_for_log(&viewer_link, "serves mission `field-1`");
    std::thread::sleep(Duration::from_secs(2));
    for link in [&mut rover_link, &mut viewer_link] {
        let log = stop_link(link);
        assert_eq!(log.matches("serves mission").count(), 1, "said more than once:\n{log}");
    }
}
