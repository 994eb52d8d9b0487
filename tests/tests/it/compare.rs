//! `dyfos-bench compare`: two builds' `dyfos solve` (or daemons) interleaved. Here
//! the workspace's own build is its own baseline, so every answer must be identical.

use dyfos_tests::{bin, bin_dir};
use std::process::Command;
use std::sync::atomic::{AtomicU32, Ordering};

#[test]
fn a_build_against_itself_gives_identical_answers_and_a_ratio() {
    let (stdout, report) = compare_itself(&["--models", "paper"]);
    let row = stdout.lines().find(|l| l.starts_with("| dyfos | numerical | paper | 2 |")).expect("a group line");
    assert!(row.ends_with("| identical |"), "{row}");
    // The evaluation floor is measured and each query is set against it.
    assert!(stdout.contains("floor (paper): "), "{stdout}");
    let floor_column = row.split('|').nth(10).unwrap().trim();
    assert!(floor_column.contains(" / ") && !floor_column.contains("NaN"), "{row}");
    assert!(
        stdout.contains("2 queries, 1 rounds, through `dyfos solve` --threads 1: every answer identical"),
        "{stdout}"
    );
    let queries = report["queries"].as_array().unwrap();
    assert_eq!(queries.len(), 2);
    for q in queries {
        let (base, new) = (&q["baseline"][0], &q["new"][0]);
        assert_eq!(base["answer"], new["answer"]);
        assert!(base["answer"]["evaluations"]["total"].as_u64().unwrap() > 0);
        assert!(new["micros"].as_f64().unwrap() > 0.0);
    }
    let ratio = report["groups"][0]["ratio"].as_f64().unwrap();
    assert!(ratio.is_finite() && ratio > 0.0, "{ratio}");
}

#[test]
fn a_baseline_without_dyfos_is_a_clear_error() {
    let empty = std::env::temp_dir().join(format!("dyfos-compare-empty-{}", std::process::id()));
    std::fs::create_dir_all(&empty).unwrap();
    let out = Command::new(bin("dyfos-bench"))
        .args(["compare", "--rounds", "1", "--count", "1", "--maps", "numerical", "--models", "paper"])
        .arg("--baseline")
        .arg(&empty)
        .output()
        .expect("dyfos-bench runs");
    let _ = std::fs::remove_dir(&empty);
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("has no `dyfos` binary"), "{stderr}");
}

/// `dyfos-bench compare` of this build against itself on two SPEC maps, one round,
/// `dyfos` only, with `extra` flags: what it printed and its JSON report.
fn compare_itself(extra: &[&str]) -> (String, serde_json::Value) {
    static RUNS: AtomicU32 = AtomicU32::new(0);
    let run = RUNS.fetch_add(1, Ordering::Relaxed);
    let json = std::env::temp_dir().join(format!("dyfos-compare-{}-{run}.json", std::process::id()));
    let out = Command::new(bin("dyfos-bench"))
        .args(["compare", "--rounds", "1", "--count", "2", "--maps", "numerical", "--algos", "dyfos", "--threads", "1"])
        .args(extra)
        .arg("--baseline")
        .arg(bin_dir())
        .arg("--new")
        .arg(bin_dir())
        .arg("--data")
        .arg(dyfos_tests::data(""))
        .arg("--json")
        .arg(&json)
        .output()
        .expect("dyfos-bench runs");
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(out.status.success(), "{stdout}\n{}", String::from_utf8_lossy(&out.stderr));
    let report = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let _ = std::fs::remove_file(&json);
    (stdout, report)
}

#[test]
fn through_each_builds_daemon_the_answers_are_those_of_dyfos_solve() {
    let (_, daemon) = compare_itself(&["--models", "paper,learned", "--no-floor", "--through", "dyfosd"]);
    let (_, solve) = compare_itself(&["--models", "paper,learned", "--no-floor", "--through", "solve"]);
    assert_eq!(daemon["through"], "dyfosd");
    let (d, s) = (daemon["queries"].as_array().unwrap(), solve["queries"].as_array().unwrap());
    assert_eq!(d.len(), 4, "two maps, two models");
    assert_eq!(d.len(), s.len());
    for (d, s) in d.iter().zip(s) {
        assert_eq!((&d["name"], &d["model"]), (&s["name"], &s["model"]));
        assert!(d["new"][0]["answer"]["x"].is_array(), "{d}");
        // The daemon's answer is `dyfos solve`'s, bit for bit, for both models.
        assert_eq!(d["new"][0]["answer"], s["new"][0]["answer"], "{}", d["name"]);
        assert_eq!(d["baseline"][0]["answer"], d["new"][0]["answer"]);
        assert!(d["new"][0]["micros"].as_f64().unwrap() > 0.0);
    }
}
