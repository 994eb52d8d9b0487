//! The daemon answers as the offline library does, to several processes at once.

use dyfos_client::prelude::*;
use dyfos_service::search::SearchControl;
use dyfos_shared::answer::StopReason;
use dyfos_shared::world::VerticalCylinder;
use dyfos_tests::{KillOnDrop, PATIENCE, Sandbox, bin, data, scenario, wait_for_stats, without_micros};
use std::io::Write;
use std::process::{Command, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

fn offline(world: &World, s: &Scenario, request: &RendezvousRequest) -> Result<Answer, dyfos_service::SearchError> {
    let model = NoiseModel::from_params(&request.params).expect("model");
    let control = SearchControl { budget: request.budget, ..SearchControl::seeded(request.seed) };
    dyfos_service::solve(world, &s.belief, &request.params, &model, request.algorithm, &control)
}

/// Bit for bit: the JSON text, where every f64 is printed exactly (and -0.0 ≠ 0.0).
fn text(answer: &Answer) -> String {
    without_micros(answer.to_json()).to_string()
}

#[test]
fn daemon_answers_equal_the_offline_library_bit_for_bit() {
    let (sandbox, _daemon) = Sandbox::with_daemon("bits");
    let mut client = sandbox.client();
    let mut compared = 0;
    for (map, file) in [(1, "example.json"), (2, "golden/scenarios/numerical/map_00.json")] {
        let s = scenario(file);
        assert_eq!(client.upload_map(map, &s.world, false, PATIENCE).unwrap(), 0);
        let cases = [
            (Algorithm::Dyfos, None),
            (Algorithm::DyfosScipy, None),
            (Algorithm::Random, None),
            (Algorithm::Center, None),
            (Algorithm::Brute, Some(20_000)),
        ];
        for (algorithm, budget) in cases {
            for seed in [0, 7] {
                for model in [ModelKind::Paper, ModelKind::Anisotropic] {
                    let params = Params { model, ..s.params };
                    let request =
                        RendezvousRequest { algorithm, seed, budget, params, ..RendezvousRequest::new(map, s.belief) };
                    let got = client.rendezvous(&request, PATIENCE);
                    match (got, offline(&s.world, &s, &request)) {
                        (Ok(d), Ok(o)) => {
                            assert_eq!(text(&d), text(&o), "{file} {algorithm} seed {seed} {model:?}");
                            compared += 1;
                        }
                        (Err(e), Err(_)) => assert_eq!(e.status(), Some(Status::NoFeasiblePose), "{e}"),
                        (d, o) => panic!("daemon {d:?} vs offline {o:?}"),
                    }
                }
            }
        }
    }
    assert!(compared >= 30, "only {compared} answers compared");
}

#[test]
fn inline_deltas_are_applied_before_the_search_and_kept() {
    let sandbox = Sandbox::new("inline");
    let s = scenario("example.json");
    let (_daemon, mut client) = sandbox.start_serving(5, &s.world);
    let pole = Obstacle::Cylinder(VerticalCylinder { center: na::Point2::new(-1.5, 0.5), radius: 0.4, height: 9.0 });
    let deltas =
        vec![MapDelta::UpsertObstacle { id: 77, obstacle: pole }, MapDelta::SetSun(Sun::new(0.4, -2.0).unwrap())];
    let request = RendezvousRequest {
        expected_version: Some(0),
        deltas: deltas.clone(),
        seed: 3,
        ..RendezvousRequest::new(5, s.belief)
    };
    // Check mode validates the deltas on a copy: nothing changes.
    assert_eq!(client.check(&request, PATIENCE).unwrap().map_version, 2);
    assert_eq!(client.snapshot(5, PATIENCE).unwrap().version(), 0);
    let answer = client.rendezvous(&request, PATIENCE).unwrap();
    assert_eq!(answer.map_version, 2);
    let changed = s.world.apply(&deltas).unwrap();
    assert_eq!(text(&answer), text(&offline(&changed, &s, &request).unwrap()));
    let stored = client.snapshot(5, PATIENCE).unwrap();
    assert_eq!(stored, changed);
    // The same request again now fails: the map moved on.
    let err = client.rendezvous(&request, PATIENCE).unwrap_err();
    assert_eq!(err.status(), Some(Status::MapVersionMismatch), "{err}");
}

#[test]
fn a_deadline_returns_the_best_pose_so_far_flagged() {
    let sandbox = Sandbox::new("deadline");
    let s = scenario("golden/scenarios/numerical/map_00.json");
    let (_daemon, mut client) = sandbox.start_serving(1, &s.world);
    // 4096 perimeter points: a `brute` of seconds, far beyond the deadline (with the
    // default 8 it can finish within it).
    let request = RendezvousRequest {
        algorithm: Algorithm::Brute,
        deadline: Some(Duration::from_millis(30)),
        params: Params { perimeter_points: 4096, ..s.params },
        ..RendezvousRequest::new(1, s.belief)
    };
    match client.rendezvous(&request, PATIENCE) {
        Ok(answer) => {
            assert_eq!(answer.stop, StopReason::Deadline);
            assert!(answer.cost.is_finite());
            assert!(answer.evaluations.total < 25 * 17 * 13 * 72);
        }
        Err(e) => assert_eq!(e.status(), Some(Status::DeadlineExceeded), "{e}"),
    }
}

#[test]
fn several_client_processes_at_once_and_the_examples() {
    let (sandbox, _daemon) = Sandbox::with_daemon("procs");
    let file = data("example.json");
    let seeds = [0u64, 1, 2, 3];
    let queries: Vec<KillOnDrop> = seeds
        .iter()
        .map(|seed| {
            let child = sandbox
                .dyfos("query")
                .arg(&file)
                .args(["--seed", &seed.to_string()])
                .stdout(Stdio::piped())
                .stderr(Stdio::piped())
                .spawn()
                .expect("start dyfos query");
            KillOnDrop::new(child)
        })
        .collect();
    let examples: Vec<(&str, KillOnDrop)> = ["rendezvous_once", "map_delta", "check_latency"]
        .into_iter()
        .map(|name| {
            let child = Command::new(bin(&format!("examples/{name}")))
                .args([&sandbox.prefix, &sandbox.domain, "50"])
                .stdout(Stdio::piped())
                .stderr(Stdio::piped())
                .spawn()
                .expect("start example");
            (name, KillOnDrop::new(child))
        })
        .collect();
    let s = scenario("example.json");
    for (seed, mut q) in seeds.into_iter().zip(queries) {
        let out = q.child_mut().expect("not reaped").wait_with_output_guarded();
        assert!(out.status.success(), "dyfos query --seed {seed}: {}", String::from_utf8_lossy(&out.stderr));
        let json: serde_json::Value = serde_json::from_slice(&out.stdout).expect("JSON answer");
        let request = RendezvousRequest { seed, params: s.params, ..RendezvousRequest::new(0, s.belief) };
        let expected = offline(&s.world, &s, &request).unwrap();
        assert_eq!(without_micros(json).to_string(), text(&expected), "seed {seed}");
    }
    for (name, mut child) in examples {
        let out = child.child_mut().expect("not reaped").wait_with_output_guarded();
        let stdout = String::from_utf8_lossy(&out.stdout);
        assert!(out.status.success(), "{name}: {}{stdout}", String::from_utf8_lossy(&out.stderr));
        match name {
            "rendezvous_once" => assert!(stdout.starts_with("viewer at ("), "{stdout}"),
            "check_latency" => {
                let json: serde_json::Value = serde_json::from_str(&stdout).expect("one JSON line");
                assert_eq!(json["count"], 50);
                assert!(json["p50_us"].as_f64().is_some_and(|p| p > 0.0), "{stdout}");
            }
            _ => {
                assert!(stdout.contains("rejected as expected: ") && stdout.contains("still at version 3"), "{stdout}")
            }
        }
    }
}

#[test]
fn dyfos_query_prints_what_dyfos_solve_prints() {
    let (sandbox, _daemon) = Sandbox::with_daemon("cli");
    let file = data("golden/scenarios/numerical/map_01.json");
    let run = |args: &[&str], online: bool| {
        let mut cmd = Command::new(bin("dyfos"));
        cmd.arg(if online { "query" } else { "solve" }).arg(&file).args(args);
        if online {
            cmd.args(sandbox.dyfos_flags());
        }
        let out = cmd.output().expect("run dyfos");
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        let json: serde_json::Value = serde_json::from_slice(&out.stdout).expect("JSON");
        without_micros(json).to_string()
    };
    for args in [&["--seed", "5"][..], &["--algo", "center", "--seed", "9"][..]] {
        assert_eq!(run(args, true), run(args, false), "{args:?}");
    }
    let stats = sandbox.dyfos("stats").output().unwrap();
    let stats: serde_json::Value = serde_json::from_slice(&stats.stdout).expect("stats JSON");
    assert_eq!(stats["queries_served"], 2);
    assert_eq!(stats["maps"], 1);
}

#[test]
fn a_slow_brute_query_does_not_hold_up_a_cheap_one() {
    let sandbox = Sandbox::new("fair");
    let s = scenario("golden/scenarios/hard/hard_00.json");
    let (_daemon, mut client) = sandbox.start_serving(1, &s.world);
    let brute_done = Arc::new(AtomicBool::new(false));
    let brute = {
        let mut slow = sandbox.client();
        let done = Arc::clone(&brute_done);
        let request = RendezvousRequest { algorithm: Algorithm::Brute, ..RendezvousRequest::new(1, s.belief) };
        std::thread::spawn(move || {
            let answer = slow.rendezvous(&request, PATIENCE);
            done.store(true, Ordering::SeqCst);
            answer
        })
    };
    wait_for_stats(&mut client, "the brute query to start", |s| s.running >= 1);
    let cheap = RendezvousRequest { algorithm: Algorithm::Center, seed: 1, ..RendezvousRequest::new(1, s.belief) };
    let answer = client.rendezvous(&cheap, PATIENCE);
    assert!(!brute_done.load(Ordering::SeqCst), "the cheap query waited for the brute one");
    assert!(answer.is_ok() || answer.as_ref().unwrap_err().status() == Some(Status::NoFeasiblePose), "{answer:?}");
    let brute = brute.join().unwrap().unwrap();
    assert_eq!(brute.algorithm, Algorithm::Brute);
}

/// `wait_with_output` for a child owned by a guard.
trait WaitGuarded {
    fn wait_with_output_guarded(&mut self) -> std::process::Output;
}

impl WaitGuarded for std::process::Child {
    fn wait_with_output_guarded(&mut self) -> std::process::Output {
        use std::io::Read;
        let mut stdout = Vec::new();
        let mut stderr = Vec::new();
        if let Some(mut o) = self.stdout.take() {
            o.read_to_end(&mut stdout).unwrap();
        }
        if let Some(mut e) = self.stderr.take() {
            e.read_to_end(&mut stderr).unwrap();
        }
        let status = self.wait().unwrap();
        std::process::Output { status, stdout, stderr }
    }
}

/// Regression (found by an independently written client): a query whose inline
/// deltas were committed but whose search then failed replied `map_version 0`, so a
/// client retrying with the version it was told got `map_version_mismatch`. Every
/// reply now carries the version the request left the map at.
#[test]
fn a_failed_query_reports_the_version_its_inline_deltas_made() {
    let (sandbox, _daemon) = Sandbox::with_daemon("inline-version");
    let mut client = sandbox.client();
    let s = scenario("example.json");
    assert_eq!(client.upload_map(1, &s.world, false, PATIENCE).unwrap(), 0);
    let pole = |id: u32| MapDelta::UpsertObstacle {
        id: 100 + id,
        obstacle: Obstacle::Cylinder(VerticalCylinder {
            center: na::Point2::new(-8.0, 8.0 - id as f64),
            radius: 0.2,
            height: 1.0,
        }),
    };
    // The viewer must fly at 7–8 m but see the rover within 2 m: no pose can do both.
    let impossible = Params { z_min: 7.0, z_max: 8.0, rho_min: 1.0, rho_max: 2.0, ..s.params };
    let request = RendezvousRequest {
        expected_version: Some(0),
        deltas: vec![pole(1), pole(2)],
        params: impossible,
        ..RendezvousRequest::new(1, s.belief)
    };
    let err = client.rendezvous(&request, PATIENCE).unwrap_err();
    assert_eq!(err.status(), Some(Status::NoFeasiblePose), "{err}");
    assert_eq!(err.map_version(), Some(2), "the two inline deltas were applied: {err:?}");
    assert_eq!(client.snapshot(1, PATIENCE).unwrap().version(), 2);

    // A deadline that passes at once: the deltas stay applied, and the reply says so
    // whether the daemon found nothing in time or answered with what it had.
    let rushed = RendezvousRequest {
        expected_version: err.map_version(),
        deltas: vec![pole(3)],
        algorithm: Algorithm::Brute,
        deadline: Some(Duration::from_micros(1)),
        ..RendezvousRequest::new(1, s.belief)
    };
    match client.rendezvous(&rushed, PATIENCE) {
        Ok(answer) => assert_eq!((answer.map_version, answer.stop), (3, StopReason::Deadline)),
        Err(e) => {
            assert_eq!(e.status(), Some(Status::DeadlineExceeded), "{e}");
            assert_eq!(e.map_version(), Some(3), "{e:?}");
        }
    }
    assert_eq!(client.snapshot(1, PATIENCE).unwrap().version(), 3);

    // Refused before the deltas: nothing changed, and the reply gives the version the
    // map has, so the retry below (with that version) is accepted.
    let stale =
        RendezvousRequest { expected_version: Some(0), deltas: vec![pole(4)], ..RendezvousRequest::new(1, s.belief) };
    let err = client.rendezvous(&stale, PATIENCE).unwrap_err();
    assert_eq!((err.status(), err.map_version()), (Some(Status::MapVersionMismatch), Some(3)), "{err}");
    assert_eq!(client.snapshot(1, PATIENCE).unwrap().version(), 3);
    let retried = RendezvousRequest { expected_version: err.map_version(), ..stale };
    assert_eq!(client.rendezvous(&retried, PATIENCE).unwrap().map_version, 4);
    let unknown = client.rendezvous(&RendezvousRequest::new(99, s.belief), PATIENCE).unwrap_err();
    assert_eq!((unknown.status(), unknown.map_version()), (Some(Status::UnknownMap), None), "{unknown}");
}

/// OctoMap's real building map through the client API: uploaded, queried,
/// updated in batches (cells set occupied as 4³ blocks, cells freed as a cell list),
/// the daemon killed (SIGKILL) with a torn record after its journal, restarted:
/// the map comes back at the same version with the same cells, answers the same
/// query bit for bit, and goes back out as the same occupied cells. A file whose
/// cells exceed the limit is refused with `over_capacity` before anything is sent.
#[test]
fn an_octomap_map_is_updated_in_batches_and_survives_a_crash() {
    let sandbox = Sandbox::new("octomap-journal");
    let mut daemon = sandbox.start_daemon(&[]);
    let mut client = sandbox.client();
    let bt = std::fs::read(data("octomap/geb079.bt")).unwrap();
    let (origin, bounds, sun) =
        (Point3::new(0.0, 0.0, 0.32), Bounds::new([-12.0, -8.0, 31.0, 10.0]).unwrap(), Sun::new(0.6, 2.4).unwrap());
    assert_eq!(client.upload_octomap(7, &bt, origin, bounds, sun, false, PATIENCE).unwrap(), 0);
    let scenario = dyfos_shared::scenario::Scenario::from_json_with_files(
        &std::fs::read_to_string(data("octomap/geb079-scenario.json")).unwrap(),
        |f| std::fs::read(data(&format!("octomap/{f}"))).map_err(|e| e.to_string()),
    )
    .unwrap();
    let mut world = scenario.world.clone();
    let request = RendezvousRequest { seed: 3, params: scenario.params, ..RendezvousRequest::new(7, scenario.belief) };
    client.rendezvous(&request, PATIENCE).unwrap();

    // A 1 m × 1 m × 0.1 m block of new cells near the rover, then the first 500 of
    // the file's cells freed.
    let resolution = world.voxels().unwrap().resolution();
    let new_cells: Vec<[i64; 3]> =
        (0..20).flat_map(|i| (0..20).flat_map(move |j| (0..2).map(move |k| [-100 + i, 100 + j, 10 + k]))).collect();
    let freed: Vec<[i64; 3]> = world.voxels().unwrap().cells_sorted()[..500].to_vec();
    let batches = [
        vec![MapDelta::SetVoxelBlocks {
            resolution,
            origin,
            blocks: dyfos_shared::world::VoxelBlock::from_cells(new_cells.iter().copied()),
            occupied: true,
        }],
        vec![MapDelta::SetVoxels { resolution, origin, cells: freed.clone(), occupied: false }],
    ];
    for (i, batch) in batches.iter().enumerate() {
        assert_eq!(client.apply(7, Some(i as u64), batch, PATIENCE).unwrap(), i as u64 + 1);
        world = world.apply(batch).unwrap();
    }
    assert_eq!(world.voxels().unwrap().len(), 185_673 + 800 - 500);
    let before = client.rendezvous(&request, PATIENCE).unwrap();
    assert_eq!(before.map_version, 2);

    // A crash, and a half-written record after the two whole ones.
    drop(client);
    daemon.kill9();
    let journal = sandbox.state_dir.join("map-7.log");
    let whole = std::fs::metadata(&journal).expect("updates go to the journal").len();
    std::fs::OpenOptions::new().append(true).open(&journal).unwrap().write_all(&[9, 0, 0, 0, 1, 2]).unwrap();
    let daemon = sandbox.start_daemon(&[]);
    let mut client = sandbox.client();
    let back = client.snapshot(7, PATIENCE).unwrap();
    assert_eq!(back.version(), 2);
    assert!(back.same_content(&world), "the map after the restart differs from the one before it");
    assert_eq!(std::fs::metadata(&journal).unwrap().len(), whole, "the torn record is cut off");
    assert!(daemon.log().contains("torn record"), "{}", daemon.log());
    let after = client.rendezvous(&request, PATIENCE).unwrap();
    assert_eq!(without_micros(after.to_json()), without_micros(before.to_json()));

    // Out as a .bt: the updated cells.
    let written = dyfos_shared::world::octomap::write_bt(resolution, back.voxels().unwrap().cells()).unwrap();
    let read = dyfos_shared::world::octomap::world_from_bt(&written, origin, bounds, sun).unwrap();
    assert_eq!(read.voxels().unwrap().cells_sorted(), world.voxels().unwrap().cells_sorted());

    // 32768³ cells: refused here, with the limit's code, and map 8 never made.
    let mut huge = b"# Octomap OcTree binary file\nid OcTree\nsize 2\nres 0.1\ndata\n".to_vec();
    huge.extend([0b0000_0010, 0b0000_0000]);
    let refused = client.upload_octomap(8, &huge, origin, bounds, sun, false, PATIENCE).unwrap_err();
    assert_eq!(refused.status(), Some(Status::OverCapacity), "{refused}");
    assert!(refused.to_string().contains("exceed the limit"), "{refused}");
    assert!(client.snapshot(8, PATIENCE).is_err());
}

/// occupied cells answers, through the daemon, as the scenario that names the same
/// `.bt` file does offline, bit for bit.
#[test]
fn an_octomap_uploaded_to_the_daemon_answers_as_its_scenario_offline() {
    let (sandbox, _daemon) = Sandbox::with_daemon("octomap-upload");
    let scenario = data("octomap/geb079-scenario.json");
    let upload = Command::new(bin("dyfos"))
        .args(["map", "upload", "5", "--octomap"])
        .arg(data("octomap/geb079.bt"))
        .args(["--origin", "0", "0", "0.32", "--bounds", "-12", "-8", "31", "10", "--sun", "0.6", "2.4"])
        .args(sandbox.dyfos_flags())
        .output()
        .unwrap();
    assert!(upload.status.success(), "{}", String::from_utf8_lossy(&upload.stderr));
    // The scenario's map has the same content, so the query reuses map 5 as it is.
    let query = sandbox.dyfos("query").arg(&scenario).args(["--map", "5", "--seed", "1"]).output().unwrap();
    assert!(query.status.success(), "{}", String::from_utf8_lossy(&query.stderr));
    let solve = Command::new(bin("dyfos")).arg("solve").arg(&scenario).args(["--seed", "1"]).output().unwrap();
    assert!(solve.status.success(), "{}", String::from_utf8_lossy(&solve.stderr));
    let json = |out: &[u8]| without_micros(serde_json::from_slice(out).unwrap());
    assert_eq!(json(&query.stdout), json(&solve.stdout));
    let map = sandbox.client().snapshot(5, PATIENCE).unwrap();
    assert_eq!((map.version(), map.voxels().unwrap().len()), (0, 185_673));
    // And back out as a .bt: the same occupied cells as the file uploaded.
    let written = sandbox.state_dir.with_extension("snapshot.bt");
    let snapshot = Command::new(bin("dyfos"))
        .args(["map", "snapshot", "5", "--bt"])
        .arg(&written)
        .args(sandbox.dyfos_flags())
        .output()
        .unwrap();
    assert!(snapshot.status.success(), "{}", String::from_utf8_lossy(&snapshot.stderr));
    let printed: serde_json::Value = serde_json::from_slice(&snapshot.stdout).unwrap();
    assert_eq!((printed["cells"].as_u64(), printed["origin"][2].as_f64()), (Some(185_673), Some(0.32)));
    let cells = |bytes: &[u8]| {
        let map = dyfos_shared::world::octomap::Octomap::from_bt(bytes).unwrap();
        let mut c: Vec<[i64; 3]> = map.occupied().iter().flat_map(|c| c.cells().collect::<Vec<_>>()).collect();
        c.sort_unstable();
        c
    };
    assert_eq!(cells(&std::fs::read(&written).unwrap()), cells(&std::fs::read(data("octomap/geb079.bt")).unwrap()));
    let _ = std::fs::remove_file(&written);
    // Without bounds and sun, or with a file that is not an OctoMap: exit 2, no map.
    let refused = Command::new(bin("dyfos"))
        .args(["map", "upload", "6", "--octomap"])
        .arg(&scenario)
        .args(["--bounds", "-12", "-8", "31", "10", "--sun", "0.6", "2.4"])
        .args(sandbox.dyfos_flags())
        .output()
        .unwrap();
    assert_eq!(refused.status.code(), Some(2), "{}", String::from_utf8_lossy(&refused.stderr));
    assert!(String::from_utf8_lossy(&refused.stderr).contains("not an OctoMap .bt file"));
    assert!(sandbox.client().snapshot(6, PATIENCE).is_err());
}
