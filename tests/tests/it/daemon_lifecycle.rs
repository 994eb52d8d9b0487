//! Crashes, restarts, dying clients and clean shutdown.

use dyfos_client::prelude::*;
use dyfos_shared::answer::StopReason;
use dyfos_shared::world::VerticalCylinder;
use dyfos_tests::{KillOnDrop, PATIENCE, Sandbox, bin, data, scenario, signal, wait_for_stats, without_micros};
use std::io::Read;
use std::process::Command;
use std::time::Duration;

#[test]
fn kill_9_and_restart_keeps_the_maps_and_clients_reconnect() {
    let sandbox = Sandbox::new("restart");
    let s = scenario("golden/scenarios/numerical/map_00.json");
    let (mut daemon, mut client) = sandbox.start_serving(1, &s.world);
    let pole = Obstacle::Cylinder(VerticalCylinder { center: na::Point2::new(0.0, 5.0), radius: 0.3, height: 2.0 });
    client.apply(1, Some(0), &[MapDelta::UpsertObstacle { id: 500, obstacle: pole }], PATIENCE).unwrap();
    let bounds = Bounds::new([0.0, 0.0, 30.0, 30.0]).unwrap();
    client.create_map(2, bounds, Sun::new(-0.2, 0.0).unwrap(), PATIENCE).unwrap();
    let map1 = client.snapshot(1, PATIENCE).unwrap();
    let map2 = client.snapshot(2, PATIENCE).unwrap();
    assert_eq!(map1.version(), 1);

    daemon.kill9();
    let err = client.stats(Duration::from_secs(10)).unwrap_err();
    assert!(err.is_retryable(), "a dead daemon is a retryable error, got: {err}");

    // A corrupt map file must not stop the next start.
    std::fs::write(sandbox.state_dir.join("map-9.bin"), b"not a map").unwrap();
    let daemon = sandbox.start_daemon(&[]);
    // The same client reconnects by itself, and the maps came back.
    assert_eq!(client.snapshot(1, PATIENCE).unwrap(), map1);
    assert_eq!(client.snapshot(2, PATIENCE).unwrap(), map2);
    let request = RendezvousRequest { seed: 4, params: s.params, ..RendezvousRequest::new(1, s.belief) };
    assert_eq!(client.rendezvous(&request, PATIENCE).unwrap().map_version, 1);
    let err = client.snapshot(9, PATIENCE).unwrap_err();
    assert_eq!(err.status(), Some(Status::UnknownMap));
    let quarantined: Vec<_> = std::fs::read_dir(&sandbox.state_dir)
        .unwrap()
        .flatten()
        .filter(|e| e.file_name().to_string_lossy().starts_with("map-9.bin.corrupt-"))
        .collect();
    assert_eq!(quarantined.len(), 1);
    assert!(daemon.log().contains("quarantined"), "{}", daemon.log());

    // The new daemon holds the only server port: the killed one's was cleaned up,
    // and a clean stop now leaves nothing of either behind.
    drop(client);
    let mut daemon = daemon;
    assert!(daemon.terminate().success());
    assert_eq!(sandbox.shm_leftovers(), Vec::<String>::new());
}

#[test]
fn a_second_daemon_on_the_same_prefix_refuses_to_start() {
    let (sandbox, _daemon) = Sandbox::with_daemon("twice");
    let out = Command::new(bin("dyfosd"))
        .args(["--prefix", &sandbox.prefix, "--domain", &sandbox.domain, "--state-dir"])
        .arg(sandbox.state_dir.join("second"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("another dyfosd already serves prefix"), "{stderr}");
}

#[test]
fn killing_a_client_mid_query_does_not_disturb_the_others() {
    let sandbox = Sandbox::new("clientkill");
    let file = data("golden/scenarios/hard/hard_01.json");
    let s = scenario("golden/scenarios/hard/hard_01.json");
    let (daemon, mut client) = sandbox.start_serving(1, &s.world);
    let mut child = KillOnDrop::new(sandbox.brute_query(&file, &["--map", "1"]));
    wait_for_stats(&mut client, "the doomed brute query to run", |s| s.running >= 1);
    child.kill(); // SIGKILL, and reap

    // Others are served while (and after) the orphaned query runs.
    let request = RendezvousRequest { seed: 2, params: s.params, ..RendezvousRequest::new(1, s.belief) };
    let first = client.rendezvous(&request, PATIENCE);
    assert!(first.is_ok() || first.as_ref().unwrap_err().status() == Some(Status::NoFeasiblePose), "{first:?}");
    wait_for_stats(&mut client, "the orphaned query to end", |s| s.running == 0);
    let mut other = sandbox.client();
    let again = other.rendezvous(&request, PATIENCE);
    assert_eq!(format!("{first:?}").replace(char::is_numeric, ""), format!("{again:?}").replace(char::is_numeric, ""));
    assert!(daemon.log().contains("dyfosd ready"));
}

#[test]
fn sigterm_finishes_in_flight_queries_and_leaves_no_shared_memory() {
    let sandbox = Sandbox::new("sigterm");
    let s = scenario("golden/scenarios/numerical/map_02.json");
    let (mut daemon, mut client) = sandbox.start_serving(1, &s.world);
    let in_flight = {
        let mut slow = sandbox.client();
        let request =
            RendezvousRequest { algorithm: Algorithm::Brute, params: s.params, ..RendezvousRequest::new(1, s.belief) };
        std::thread::spawn(move || slow.rendezvous(&request, PATIENCE))
    };
    wait_for_stats(&mut client, "the brute query to run", |s| s.running >= 1);
    drop(client);
    assert!(daemon.terminate().success(), "{}", daemon.log());
    let answer = in_flight.join().unwrap().expect("the query in flight is answered before the daemon exits");
    assert_eq!(answer.stop, StopReason::Finished);
    let log = daemon.log();
    assert!(log.contains("shutting down") && log.contains("dyfosd stopped"), "{log}");
    assert_eq!(sandbox.shm_leftovers(), Vec::<String>::new());
}

/// Regression (found by the soak): iceoryx2 handed the connection of a client
/// killed mid-query to the next client, and the daemon's reply to the killed
/// client's query arrived there. Request ids started at 1 in every client, so the
/// next client, at the same point of the same sequence of calls, took that reply
/// for its own answer (another map, another algorithm). Now ids start at random
/// and the stale reply is dropped. Its own query waits behind
/// the orphaned one (one worker takes `brute`), so it is pending when that reply is
/// sent.
#[test]
fn a_reply_meant_for_a_killed_client_never_reaches_the_next_one() {
    let sandbox = Sandbox::new("stale");
    let _daemon = sandbox.start_daemon(&["--workers", "2"]);
    let mut admin = sandbox.client();
    let doomed_file = data("golden/scenarios/hard/hard_01.json");
    let next_file = data("golden/scenarios/numerical/map_00.json");
    admin.upload_map(1, &scenario("golden/scenarios/hard/hard_01.json").world, false, PATIENCE).unwrap();
    admin.upload_map(2, &scenario("golden/scenarios/numerical/map_00.json").world, false, PATIENCE).unwrap();
    let query = |file: &std::path::Path, map: &str, extra: &[&str]| {
        sandbox.brute_query(file, &[["--map", map].as_slice(), extra].concat())
    };
    for seed in ["1", "2"] {
        let mut doomed = KillOnDrop::new(query(&doomed_file, "1", &[]));
        wait_for_stats(&mut admin, "the doomed brute query to run", |s| s.running >= 1);
        doomed.kill(); // SIGKILL, and reap
        let mut next = query(&next_file, "2", &["--budget", "20000", "--seed", seed]).wait_with_output().unwrap();
        if !next.status.success() {
            // The orphaned reply is dropped; iceoryx2 may still close the channel it
            // reused, which the next client reports as a retryable error. Retried,
            // it must get its own answer.
            let stderr = String::from_utf8_lossy(&next.stderr);
            assert!(stderr.contains("retry"), "{stderr}");
            next = query(&next_file, "2", &["--budget", "20000", "--seed", seed]).wait_with_output().unwrap();
            assert!(next.status.success(), "{}", String::from_utf8_lossy(&next.stderr));
        }
        let offline = Command::new(bin("dyfos"))
            .arg("solve")
            .arg(&next_file)
            .args(["--algo", "brute", "--budget", "20000", "--seed", seed])
            .output()
            .unwrap();
        let json = |out: &[u8]| without_micros(serde_json::from_slice(out).expect("an answer"));
        assert_eq!(json(&next.stdout), json(&offline.stdout), "the next client got another client's answer");
        wait_for_stats(&mut admin, "the orphaned query to end", |s| s.running == 0);
    }
}

/// Bytes of `/dev/shm` (allocated, not apparent: what a container's `/dev/shm`
/// limit counts) that the sandbox's processes hold.
fn shm_allocated(sandbox: &Sandbox) -> u64 {
    use std::os::unix::fs::MetadataExt;
    std::fs::read_dir("/dev/shm")
        .unwrap()
        .flatten()
        .filter(|e| e.file_name().to_string_lossy().starts_with(&sandbox.domain))
        .filter_map(|e| e.metadata().ok())
        .map(|m| m.blocks() * 512)
        .sum()
}

/// A map at version 0 of more records than one snapshot page holds: 40 000 cells,
/// 1 250 blocks, `dz` cells up.
fn grid_of_several_pages(dz: i64) -> World {
    let cells = (0..40_000i64).map(move |i| [i % 200, (i / 200) % 50, i / 10_000 + dz]);
    let voxels = dyfos_shared::world::VoxelGrid::new(0.1, na::Point3::new(0.0, 0.0, 0.0), cells).unwrap();
    World::new(0, Bounds::new([-1.0, -1.0, 30.0, 30.0]).unwrap(), Sun::new(0.5, 0.0).unwrap(), [], Some(voxels))
        .unwrap()
}

#[test]
fn clients_cost_the_daemon_little_shared_memory_and_snapshots_come_in_pages() {
    let (sandbox, _daemon) = Sandbox::with_daemon("shmclients");
    let mut first = sandbox.client();
    let world = grid_of_several_pages(0);
    let pages = dyfos_shared::wire::map::world_chunks_of(&world, dyfos_shared::limits::SNAPSHOT_PAGE_RECORDS).len();
    assert!(pages > 2, "{pages} pages");
    first.upload_map(1, &world, false, PATIENCE).unwrap();
    let back = first.snapshot(1, PATIENCE).unwrap();
    assert!(back.same_content(&world), "the paged snapshot is the uploaded map");

    // Each client holds a connection to each of the daemon's services. iceoryx2
    // 0.10 gave every one to a resizable segment bookkeeping for 255 segments:
    // 8 MB of /dev/shm a client (Docker's default /dev/shm is 64 MB).
    let before = shm_allocated(&sandbox);
    let mut more: Vec<Client> = (0..4).map(|_| sandbox.client()).collect();
    for c in &mut more {
        c.stats(PATIENCE).unwrap();
    }
    let per_client = shm_allocated(&sandbox).saturating_sub(before) / 4;
    assert!(per_client < 1 << 20, "{per_client} bytes of /dev/shm per connected client");
}

#[test]
fn a_map_deleted_and_made_again_is_snapshot_with_its_new_content() {
    let (sandbox, _daemon) = Sandbox::with_daemon("remade");
    let mut client = sandbox.client();
    let bounds = Bounds::new([0.0, 0.0, 30.0, 30.0]).unwrap();
    let sun = Sun::new(0.5, 0.0).unwrap();
    let pole =
        |x: f64| Obstacle::Cylinder(VerticalCylinder { center: na::Point2::new(x, 5.0), radius: 0.3, height: 2.0 });
    let old = World::new(0, bounds, sun, [(1, pole(3.0))], None).unwrap();
    let new = World::new(0, bounds, sun, [(1, pole(7.0))], None).unwrap();
    client.upload_map(1, &old, false, PATIENCE).unwrap();
    assert!(client.snapshot(1, PATIENCE).unwrap().same_content(&old));
    client.delete_map(1, None, PATIENCE).unwrap();
    // Same id, same version (0), other content.
    client.upload_map(1, &new, false, PATIENCE).unwrap();
    let back = client.snapshot(1, PATIENCE).unwrap();
    assert_eq!(back.version(), 0);
    assert!(back.same_content(&new), "got the deleted map's content: {:?}", back.obstacles());
}

#[test]
fn snapshot_pages_of_a_map_deleted_and_made_again_carry_another_generation() {
    use dyfos_shared::wire::map::MapRequest;
    let (sandbox, _daemon) = Sandbox::with_daemon("generation");
    let mut client = sandbox.client();
    let raw = dyfos_tests::RawClient::open(&sandbox);
    // Two maps of several snapshot pages each, both at version 0, other content.
    let grid = grid_of_several_pages;
    let page = |p: u32| raw.map(MapRequest::Snapshot { map: 1, page: p }.header(u64::from(p), [0, 0]), &[]);
    client.upload_map(1, &grid(0), false, PATIENCE).unwrap();
    let (first, _) = page(0);
    assert!(first.chunk_count > 1 && first.generation != 0, "{first:?}");
    assert_eq!(page(1).0.generation, first.generation, "pages of one map share its generation");

    // Deleted and made again between two page requests: the version alone cannot tell.
    client.delete_map(1, None, PATIENCE).unwrap();
    client.upload_map(1, &grid(10), false, PATIENCE).unwrap();
    let (second, _) = page(1);
    assert_eq!((second.status, second.version), (0, first.version));
    assert_ne!(second.generation, first.generation, "a reader would mix two maps' pages");
    assert!(client.snapshot(1, PATIENCE).unwrap().same_content(&grid(10)));
    // Other replies carry no generation.
    let (deleted, _) = raw.map(MapRequest::Delete { map: 1, expected_version: None }.header(9, [0, 0]), &[]);
    assert_eq!((deleted.status, deleted.generation), (0, 0));
}

/// Stops a process as Ctrl-Z does and continues it as `fg` does (a debugger or
/// `strace` attaching does the same to it), after `settle` to let it reach its wait.
fn stop_and_continue(pid: u32, settle: Duration) {
    std::thread::sleep(settle);
    signal(pid, "STOP");
    std::thread::sleep(Duration::from_millis(50));
    signal(pid, "CONT");
}

/// A daemon stopped and continued keeps serving: the SIGCONT ends its wait as any
/// signal does, and only SIGINT and SIGTERM stop it. Regression: it took every
/// interrupted wait for a Ctrl-C and shut down.
#[test]
fn a_stopped_and_continued_daemon_keeps_serving_and_sigint_stops_it() {
    let sandbox = Sandbox::new("stop-cont");
    let s = scenario("golden/scenarios/numerical/map_02.json");
    let (mut daemon, mut client) = sandbox.start_serving(1, &s.world);
    let request = RendezvousRequest { params: s.params, ..RendezvousRequest::new(1, s.belief) };
    for round in 0..3 {
        // The settling time lets the daemon go from polling to sleeping in its wait.
        stop_and_continue(daemon.pid(), Duration::from_millis(20));
        let answer = client.rendezvous(&request, PATIENCE);
        assert!(answer.is_ok(), "round {round}: {answer:?}\n{}", daemon.log());
    }
    assert!(daemon.is_running(), "{}", daemon.log());
    assert!(!daemon.log().contains("shutting down"), "{}", daemon.log());

    drop(client);
    assert!(daemon.stop_with("INT").success(), "{}", daemon.log());
    assert!(daemon.log().contains("dyfosd stopped"), "{}", daemon.log());
    assert_eq!(sandbox.shm_leftovers(), Vec::<String>::new());
}

/// A client stopped and continued while it waits for its answer still gets it: the
/// interrupted wait goes on (`dyfos query` sets no interrupt check). Regression: the
/// query failed with `iceoryx2: InterruptSignal`.
#[test]
fn a_client_stopped_and_continued_mid_query_still_gets_its_answer() {
    let (sandbox, _daemon) = Sandbox::with_daemon("client-stop-cont");
    let mut admin = sandbox.client();
    let file = sandbox.state_dir.with_extension("slow.json");
    std::fs::write(&file, dyfos_tests::slow_search_scenario().to_json()).unwrap();
    // A search that ends at its deadline, so the client waits that long.
    let mut child = KillOnDrop::new(sandbox.brute_query(&file, &["--deadline-ms", "1500"]));
    wait_for_stats(&mut admin, "the query to run", |s| s.running == 1);
    stop_and_continue(child.id(), Duration::from_millis(50));
    let (mut stdout, mut stderr) = (String::new(), String::new());
    let process = child.child_mut().expect("not reaped");
    process.stdout.take().unwrap().read_to_string(&mut stdout).unwrap();
    process.stderr.take().unwrap().read_to_string(&mut stderr).unwrap();
    let status = process.wait().unwrap();
    let _ = std::fs::remove_file(&file);
    assert!(status.success(), "{stderr}");
    let answer: serde_json::Value = serde_json::from_str(&stdout).expect("the answer as JSON");
    assert_eq!(answer["stop"], "deadline", "{answer}");
}

/// `Daemon::wait` says `Work` when a client's request wakes it, as `dyfosd`'s loop
/// expects (it starts its polling window then). Regression: the wake-up was told
/// apart by an iceoryx2 attachment id that holds the wait set's address, and the
/// wait set moved into the daemon after attaching, so every wake-up read `Idle`.
#[test]
fn a_request_that_wakes_the_daemon_is_reported_as_work() {
    use dyfos_service::daemon::{Daemon, DaemonConfig, Scheduling, WaitOutcome};
    let sandbox = Sandbox::new("wait-work");
    let config = DaemonConfig {
        prefix: sandbox.prefix.clone(),
        domain: Some(sandbox.domain.clone()),
        state_dir: sandbox.state_dir.clone(),
        // This test's thread is the IPC thread: keep it out of real-time scheduling.
        scheduling: Scheduling { ipc_priority: 0, ..Scheduling::default() },
        ..DaemonConfig::default()
    };
    let mut daemon = Daemon::create(&config).unwrap();
    let config = sandbox.client_config();
    let client = std::thread::spawn(move || {
        let mut client = Client::connect(&config).unwrap();
        // Long enough for the daemon to be asleep in its wait.
        std::thread::sleep(Duration::from_millis(300));
        client.stats(PATIENCE).map(|s| s.workers)
    });
    assert_eq!(daemon.wait(PATIENCE), WaitOutcome::Work);
    // Answer until the client has its reply.
    while !client.is_finished() {
        daemon.spin();
        std::thread::sleep(Duration::from_millis(1));
    }
    assert!(client.join().unwrap().unwrap() >= 2);
    daemon.shutdown();
}

/// A daemon killed while creating its services leaves them half made; the next one
/// removes the remains and serves instead of failing for good.
#[test]
fn a_daemon_starts_over_services_a_killed_creator_left_half_made() {
    use iceoryx2::service::messaging_pattern::MessagingPattern;
    let sandbox = Sandbox::new("half-made");
    let (_, names) = sandbox.ipc_node();
    let rendezvous = sandbox.leave_half_created(&names.rendezvous, MessagingPattern::RequestResponse);
    let wake = sandbox.leave_half_created(&names.wake, MessagingPattern::Event);
    let mut daemon = sandbox.start_daemon(&[]);
    let answer = sandbox.client().stats(PATIENCE);
    assert!(answer.is_ok(), "{answer:?}");
    let log = daemon.log();
    assert_eq!(
        log.matches("removed what a process killed while creating this service left behind").count(),
        2,
        "{log}"
    );
    assert!(daemon.terminate().success(), "{}", daemon.log());
    assert!(!rendezvous.exists() && !wake.exists(), "the daemon's own services are removed at exit");
}
