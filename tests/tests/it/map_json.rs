//! Map deltas and snapshots in JSON through `dyfos map …` (docs/deltas.md): the
//! delta file of every kind applies as the same deltas do in Rust, a snapshot
//! reads back as the map it shows and uploads as it is, and a malformed file is
//! refused with the field and a valid example of its kind.

use dyfos_shared::map_json::{deltas_from_json, map_from_json};
use dyfos_shared::scenario::Scenario;
use dyfos_shared::world::{Bounds, Sun, World};
use dyfos_tests::{Sandbox, bin, data};
use std::ffi::OsStr;
use std::process::{Command, Output};

/// `dyfos map ARGS…` against the sandbox's daemon.
fn map<S: AsRef<OsStr>>(sandbox: &Sandbox, args: impl IntoIterator<Item = S>) -> Output {
    Command::new(bin("dyfos")).arg("map").args(args).args(sandbox.dyfos_flags()).output().unwrap()
}

fn ok(out: Output) -> serde_json::Value {
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    serde_json::from_slice(&out.stdout).expect("JSON on stdout")
}

/// `dyfos map snapshot ID`, read back.
fn snapshot(sandbox: &Sandbox, id: &str) -> (String, World) {
    let out = map(sandbox, ["snapshot", id]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let text = String::from_utf8(out.stdout).unwrap();
    let (map, world) = map_from_json(&text).unwrap_or_else(|e| panic!("{e}: {text}"));
    assert_eq!(map.map(|m| m.to_string()).as_deref(), Some(id));
    (text, world)
}

#[test]
fn every_delta_kind_applies_and_a_snapshot_reads_back_as_its_map() {
    let (sandbox, _daemon) = Sandbox::with_daemon("map-json");
    ok(map(&sandbox, ["create", "7", "--bounds", "-10", "-10", "10", "10", "--sun", "0.7", "2.1"]));
    let file = data("deltas-every-kind.json");
    let applied = ok(map(
        &sandbox,
        [OsStr::new("apply"), "7".as_ref(), file.as_ref(), "--expected-version".as_ref(), "0".as_ref()],
    ));

    // The daemon's map is what the same deltas make in Rust.
    let deltas = deltas_from_json(&std::fs::read_to_string(&file).unwrap()).unwrap();
    let expected = World::empty(Bounds::new([-10.0, -10.0, 10.0, 10.0]).unwrap(), Sun::new(0.7, 2.1).unwrap())
        .apply(&deltas)
        .unwrap();
    let (text, got) = snapshot(&sandbox, "7");
    assert!(got.same_content(&expected), "{text}");
    assert_eq!(Some(got.version()), applied["version"].as_u64());
    assert!(got.voxels().is_some() && got.obstacles().len() == 1, "the file leaves a cylinder and cells: {text}");

    // A scenario's map reads back as the scenario's world.
    let example = data("example.json");
    ok(map(&sandbox, [OsStr::new("upload"), "8".as_ref(), example.as_ref()]));
    let scenario = Scenario::from_json(&std::fs::read_to_string(&example).unwrap()).unwrap();
    let (_, uploaded) = snapshot(&sandbox, "8");
    assert_eq!(uploaded, scenario.world);

    // A snapshot uploads as it is.
    let copy = sandbox.state_dir.with_extension("snapshot-7.json");
    std::fs::write(&copy, &text).unwrap();
    ok(map(&sandbox, [OsStr::new("upload"), "9".as_ref(), copy.as_ref()]));
    let (_, copied) = snapshot(&sandbox, "9");
    assert!(copied.same_content(&expected));
    let _ = std::fs::remove_file(&copy);

    // `dyfos map list`: one JSON object a line, in id order, each map as its snapshot
    // shows it; a deleted map is gone from it.
    let list = || {
        let out = map(&sandbox, ["list"]);
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        let text = String::from_utf8(out.stdout).unwrap();
        text.lines()
            .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("{e}: {l}")))
            .collect::<Vec<serde_json::Value>>()
    };
    let listed: Vec<serde_json::Value> = list();
    assert_eq!(listed.iter().map(|m| m["map"].as_u64().unwrap()).collect::<Vec<_>>(), [7, 8, 9]);
    for (m, world) in listed.iter().zip([&got, &uploaded, &copied]) {
        let shown = dyfos_shared::map_json::map_to_json(None, world);
        assert_eq!((&m["version"], &m["bounds"], &m["sun"]), (&shown["version"], &shown["bounds"], &shown["sun"]));
        assert_ne!(m["generation"], 0, "{m}");
    }
    ok(map(&sandbox, ["delete", "8"]));
    assert_eq!(list().iter().map(|m| m["map"].as_u64().unwrap()).collect::<Vec<_>>(), [7, 9]);
}

#[test]
fn a_malformed_delta_file_names_the_field_and_shows_a_valid_example() {
    let (sandbox, _daemon) = Sandbox::with_daemon("map-json-bad");
    ok(map(&sandbox, ["create", "7", "--bounds", "-10", "-10", "10", "10", "--sun", "0.7", "2.1"]));
    let file = sandbox.state_dir.with_extension("bad-deltas.json");
    let cases = [
        // The spelling before docs/deltas.md.
        (
            r#"[{"RemoveObstacle": {"id": 3}}]"#,
            "deltas[0]",
            r#"(did you mean `remove_obstacle`?)"#,
            r#"a valid remove_obstacle: {"remove_obstacle": {"id": 2}}"#,
        ),
        (
            r#"[{"set_sun": {"elevation": 0.5, "azimuth": 1.0}}, {"upsert_obstacle": {"id": 1, "cylinder": {"x": 0, "y": 0, "radius": 1, "heigth": 2}}}]"#,
            "deltas[1].upsert_obstacle.cylinder",
            "(did you mean `height`?)",
            r#"a valid upsert_obstacle: {"upsert_obstacle": {"id": 1, "cylinder": {"x": 2.0"#,
        ),
        (r#"{"clear": {}}"#, "deltas", "expected a sequence", "write a JSON array of deltas"),
    ];
    for (text, path, reason, example) in cases {
        std::fs::write(&file, text).unwrap();
        let out = map(&sandbox, [OsStr::new("apply"), "7".as_ref(), file.as_ref()]);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{text}: {stderr}");
        assert!(stderr.contains(&format!("{}: {path}: ", file.display())), "{text}: {stderr}");
        assert!(stderr.contains(reason) && stderr.contains(example), "{text}: {stderr}");
    }
    let _ = std::fs::remove_file(&file);
    let (_, map) = snapshot(&sandbox, "7");
    assert_eq!(map.version(), 0, "nothing was applied");
}
