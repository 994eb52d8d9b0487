//! The `dyfos` command line: output shape and exit codes (0 ok, 2 invalid input,
//! 3 no feasible pose).

use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn dyfos(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_dyfos")).args(args).output().expect("dyfos runs")
}

fn example() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/data/example.json")
}

/// Writes `json` to a fresh file in the target dir and returns its path.
fn scenario_file(name: &str, json: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("cli");
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join(name);
    std::fs::write(&path, json).unwrap();
    path
}

fn edited(from: &str, to: &str) -> String {
    let text = std::fs::read_to_string(example()).unwrap();
    assert!(text.contains(from), "edit `{from}` does not apply");
    text.replacen(from, to, 1)
}

#[test]
fn solve_prints_every_field_of_an_answer() {
    let out = dyfos(&["solve", example().to_str().unwrap(), "--algo", "dyfos", "--seed", "5"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: Value = serde_json::from_slice(&out.stdout).unwrap();
    for key in [
        "algorithm",
        "x",
        "cost",
        "sensor_position",
        "sensor_quaternion",
        "viewer_position",
        "R",
        "posterior",
        "evaluations",
        "micros",
    ] {
        assert!(v.get(key).is_some(), "missing {key}");
    }
    assert_eq!(v["algorithm"], "dyfos");
    assert_eq!(v["x"].as_array().unwrap().len(), 4);
    let ev = &v["evaluations"];
    let total = ev["total"].as_u64().unwrap();
    assert!(
        ev["workspace"].as_u64().unwrap() + ev["collision"].as_u64().unwrap() + ev["occlusion"].as_u64().unwrap()
            < total
    );
    let q: Vec<f64> = v["sensor_quaternion"].as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect();
    assert!((q.iter().map(|x| x * x).sum::<f64>() - 1.0).abs() < 1e-12 && q[3] >= 0.0);

    // Same seed, same answer (every field but the time).
    let again: Value = serde_json::from_slice(
        &dyfos(&["solve", example().to_str().unwrap(), "--algo", "dyfos", "--seed", "5"]).stdout,
    )
    .unwrap();
    for key in ["x", "cost", "sensor_position", "R", "posterior", "evaluations"] {
        assert_eq!(again[key], v[key], "{key}");
    }
}

#[test]
fn eval_reports_the_verdict_and_its_reason() {
    let ok = dyfos(&["eval", example().to_str().unwrap(), "--x", "2", "0", "0", "0.3"]);
    assert!(ok.status.success());
    let v: Value = serde_json::from_slice(&ok.stdout).unwrap();
    assert_eq!(v["feasible"], true);
    assert!(v["reason"].is_null() && v["cost"].is_f64());

    // Facing the pole at (2, 1) from the far side: the marker is hidden behind it.
    let hidden = dyfos(&["eval", example().to_str().unwrap(), "--x", "6", "0", "0", "-2.677945"]);
    let v: Value = serde_json::from_slice(&hidden.stdout).unwrap();
    assert_eq!(v["feasible"], false);
    assert_eq!(v["reason"], "occlusion", "{v}");
    assert_eq!(v["blockers"], serde_json::json!([1]));
    assert!(v["cost"].is_null());

    // Far outside the map.
    let outside = edited("[-10.0, -10.0, 10.0, 10.0]", "[-1.0, -1.0, 1.0, 1.0]");
    let path = scenario_file("small_bounds.json", &outside);
    let v: Value =
        serde_json::from_slice(&dyfos(&["eval", path.to_str().unwrap(), "--x", "6", "0", "0", "0"]).stdout).unwrap();
    assert_eq!(v["reason"], "workspace");
}

#[test]
fn invalid_scenarios_exit_2_naming_the_field() {
    let cases = [
        ("\"model\": \"paper\"", "\"rho_min\": 7", "params.rho_min = 7 must be < rho_max = 6"),
        ("\"model\": \"paper\"", "\"kapa\": 1", "did you mean `kappa`?"),
        ("[0.05, 0.1, 0.0]", "[0.06, 0.1, 0.0]", "rover.cov"),
        ("\"radius\": 0.5", "\"radius\": 0", "obstacles[0].cylinder"),
        ("{\"id\": 2,", "{\"id\": 1,", "duplicate obstacle id 1"),
        ("\"bounds\"", "\"bounds\": [0, 0, 1, 1], \"oops\"", "unknown field `oops`"),
        ("{\"model\": \"paper\"}", "[]", "params: invalid type: sequence, expected a JSON object"),
        ("\"params\": {\"model\": \"paper\"}\n}", "\"params\": {}\n} {}", "trailing characters"),
    ];
    for (i, (from, to, needle)) in cases.into_iter().enumerate() {
        let path = scenario_file(&format!("bad_{i}.json"), &edited(from, to));
        let out = dyfos(&["solve", path.to_str().unwrap()]);
        assert_eq!(out.status.code(), Some(2), "{to}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(needle), "`{to}`: {err}");
        assert_eq!(err.trim_end().lines().count(), 1, "one line: {err}");
        assert!(out.stdout.is_empty());
    }
    let out = dyfos(&["solve", "/nonexistent/scenario.json"]);
    assert_eq!(out.status.code(), Some(2));
    let path = scenario_file("not_json.json", "{\"bounds\": [");
    assert_eq!(dyfos(&["solve", path.to_str().unwrap()]).status.code(), Some(2));
}

#[test]
fn no_feasible_pose_exits_3() {
    // A slab over the whole map up to 9 m: nowhere to fly, nothing to see.
    let buried =
        edited("{\"id\": 2,", "{\"id\": 3, \"box\": {\"min\": [-10, -10, 0], \"max\": [10, 10, 9]}}, {\"id\": 2,");
    let path = scenario_file("buried.json", &buried);
    let out = dyfos(&["solve", path.to_str().unwrap(), "--algo", "random", "--budget", "2000"]);
    assert_eq!(out.status.code(), Some(3));
    assert!(String::from_utf8_lossy(&out.stderr).contains("no_feasible_pose"));
}

/// Regression: `dyfos solve` printed `"x": [1.0, 3.94e-05, -7.08e-06, 2.85]`
/// and `dyfos eval --x` refused it (clap took `-7.08e-06` for a flag). Every number a
/// command prints is now taken back by every numeric flag.
#[test]
fn numbers_solve_prints_are_taken_back_by_eval() {
    let path = example();
    let path = path.to_str().unwrap();
    for (algo, seed) in [("dyfos", "0"), ("dyfos", "3"), ("random", "1"), ("center", "0"), ("dyfos-scipy", "2")] {
        let solved = dyfos(&["solve", path, "--algo", algo, "--seed", seed]);
        assert!(solved.status.success(), "{}", String::from_utf8_lossy(&solved.stderr));
        let answer: Value = serde_json::from_slice(&solved.stdout).unwrap();
        // The numbers as printed, character for character.
        let x: Vec<String> = answer["x"].as_array().unwrap().iter().map(Value::to_string).collect();
        let mut args = vec!["eval", path, "--x"];
        args.extend(x.iter().map(String::as_str));
        let evaluated = dyfos(&args);
        assert!(evaluated.status.success(), "eval --x {x:?}: {}", String::from_utf8_lossy(&evaluated.stderr));
        let v: Value = serde_json::from_slice(&evaluated.stdout).unwrap();
        assert_eq!(v["cost"], answer["cost"], "{algo} seed {seed}: the same x gives the same E");
    }
    // Printed forms the search may not have produced here: negative exponents, -0.0,
    // the extremes of f64.
    let printed = ["-7.08e-06", "-0.0", "-5e-324", "-1.7976931348623157e308", "1e300", "-2.2250738585072014e-308"];
    for value in printed {
        let evaluated = dyfos(&["eval", path, "--x", "1.0", "3.94e-05", value, "2.85"]);
        assert!(evaluated.status.success(), "--x ... {value}: {}", String::from_utf8_lossy(&evaluated.stderr));
        let v: Value = serde_json::from_slice(&evaluated.stdout).unwrap();
        assert_eq!(v["x"][2].as_f64().unwrap().to_bits(), value.parse::<f64>().unwrap().to_bits(), "{v}");
    }
    // The other numeric flags parse such numbers too (the daemon is absent here, so
    // the command fails later, with exit 1, not on its arguments with exit 2).
    for args in [
        vec!["map", "create", "7", "--bounds", "-1e1", "-1.0e+01", "1e1", "10", "--sun", "-0.0", "-2.1e-3"],
        vec!["stats", "--timeout", "1e-3"],
    ] {
        let mut full = args.clone();
        full.extend(["--prefix", "dyfos-cli-test-nodaemon/"]);
        let out = dyfos(&full);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{args:?}: {stderr}");
        assert!(stderr.contains("no dyfosd"), "{args:?}: {stderr}");
    }
}

/// SPEC §11 `octomap`: a scenario naming a `.bt` file (relative to the scenario)
/// gives the same answers, bit for bit, as the same scenario with the OctoMap's
/// occupied cells listed as `voxels` (OctoMap's real building map geb079).
#[test]
fn an_octomap_scenario_answers_as_its_cells_listed_as_voxels() {
    use dyfos_shared::world::octomap::Octomap;
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/data/octomap");
    let octomap_scenario = dir.join("geb079-scenario.json");
    let map = Octomap::from_bt(&std::fs::read(dir.join("geb079.bt")).unwrap()).unwrap();
    let cells: Vec<[i64; 3]> = map.occupied().iter().flat_map(|c| c.cells().collect::<Vec<_>>()).collect();
    let mut listed: Value = serde_json::from_str(&std::fs::read_to_string(&octomap_scenario).unwrap()).unwrap();
    let origin = listed["octomap"]["origin"].clone();
    listed.as_object_mut().unwrap().remove("octomap");
    listed["voxels"] = serde_json::json!({"resolution": map.resolution(), "origin": origin, "occupied": cells});
    let voxel_scenario = scenario_file("geb079-voxels.json", &listed.to_string());
    let (a, b) = (octomap_scenario.to_str().unwrap(), voxel_scenario.to_str().unwrap());
    let without_micros = |out: &Output| {
        let mut v: Value = serde_json::from_slice(&out.stdout).unwrap_or(Value::Null);
        if let Some(o) = v.as_object_mut() {
            o.remove("micros");
        }
        (out.status.code(), v)
    };
    let runs: [&[&str]; 4] = [
        &["solve", "--seed", "1"],
        &["solve", "--algo", "random", "--seed", "2"],
        &["eval", "--x", "2.0", "0.0", "0.0", "3.0"],
        &["eval", "--x", "3.0", "0.1", "-0.1", "0.0"],
    ];
    let mut feasible = 0;
    for args in runs {
        let run = |scenario: &str| {
            let mut full = vec![args[0], scenario];
            full.extend(&args[1..]);
            dyfos(&full)
        };
        let (octo, vox) = (run(a), run(b));
        assert_eq!(octo.status.code(), Some(0), "{args:?}: {}", String::from_utf8_lossy(&octo.stderr));
        assert_eq!(without_micros(&octo), without_micros(&vox), "{args:?}");
        feasible += usize::from(without_micros(&octo).1["cost"].is_f64());
    }
    assert!(feasible > 0, "every run was infeasible: the comparison says little");
    // Both forms at once, and a file that is not there, are errors naming the field.
    let both = listed.as_object().unwrap().clone();
    let mut both = Value::Object(both);
    both["octomap"] = serde_json::json!({"file": "geb079.bt"});
    let out = dyfos(&["solve", scenario_file("both.json", &both.to_string()).to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("not both"), "{}", String::from_utf8_lossy(&out.stderr));
    let mut missing: Value = serde_json::from_str(&std::fs::read_to_string(&octomap_scenario).unwrap()).unwrap();
    missing["octomap"]["file"] = "nowhere.bt".into();
    let out = dyfos(&["solve", scenario_file("missing.json", &missing.to_string()).to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("octomap.file"), "{}", String::from_utf8_lossy(&out.stderr));
}
