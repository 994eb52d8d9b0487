//! A short run of `dyfos-bench latency` so the command cannot rot: it starts its own
//! `dyfosd`, client processes of every workload in closed and open loop, merges
//! their samples, and stops the daemon cleanly. No timing is asserted; the numbers
//! are in `bench/RESULTS.md`.
//!
//! `dyfos-bench` starts the `dyfosd` built next to it (`dyfos_tests::bin` builds it
//! if it is missing).

mod common;

use std::process::Command;

#[test]
fn latency_command_smoke_run() {
    let exe = std::path::PathBuf::from(env!("CARGO_BIN_EXE_dyfos-bench"));
    assert_eq!(dyfos_tests::bin("dyfosd"), exe.with_file_name("dyfosd"), "dyfosd is built next to dyfos-bench");
    let out = std::env::temp_dir().join(format!("dyfos-bench-latency-smoke-{}", std::process::id()));
    let stdout = common::succeeds(
        Command::new(&exe)
            .args(["latency", "--seconds", "0.2", "--clients", "1,2", "--open-clients", "2", "--maps", "2"])
            .args([
                "--null-rates",
                "300",
                "--dyfos-rates",
                "30",
                "--mixed-null-rate",
                "300",
                "--mixed-dyfos-clients",
                "1",
            ])
            // A second daemon with another polling window, for the before/after table.
            .arg("--compare-daemon-arg=--set=scheduling.poll_us=50")
            // Clients with a shorter poll window than the library default.
            .args(["--client-poll-us", "100"])
            // The contention runs, short: one hog, 0.2 s idle.
            .args(["--hogs", "1", "--idle-seconds", "0.2"]),
        &out,
    );
    common::assert_holds(
        &stdout,
        &[
            "| floor | 1 | ",
            "| null | 1 | ",
            "| null | 2 | ",
            "| dyfos | 2 | ",
            "| null | 2 | 300 | ",
            "| dyfos | 2 | 30 | ",
        ],
    );
    assert!(stdout.contains("in-process `dyfos` query"), "{stdout}");
    assert!(stdout.contains("### Mixed"), "{stdout}");
    assert!(stdout.contains("(left) and dyfosd with `--set=scheduling.poll_us=50` (right)"), "{stdout}");
    // The contention runs, against both daemons.
    common::assert_holds(
        &stdout,
        &[
            "| stats open loop, 300/s over 1 client(s), beside dyfos closed loop",
            "| map open loop, 300/s over 1 client(s), beside dyfos closed loop",
            "| hog closed loop, 1 client(s), beside dyfos closed loop",
            "| greedy closed loop, 1 client(s), beside dyfos closed loop",
            "| null open loop, 300/s over 1 client(s), beside churn closed loop",
            "| null open loop, 300/s over 1 client(s), beside dyfos closed loop",
        ],
    );
    assert!(stdout.contains("Idle: dyfosd used ") && stdout.contains("; dyfosd with `--set"), "{stdout}");
    assert!(!stdout.contains("Targets"), "no acceptance table: {stdout}");
    assert!(stdout.contains("Daemon shutdown: clean (SIGTERM, exit 0)"), "{stdout}");
    assert!(stdout.contains("shared-memory files left in /dev/shm: none"), "{stdout}");

    let rows: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("latency.json")).expect("latency.json")).unwrap();
    let rows = rows.as_array().unwrap();
    // floor: 1 closed + 1 open; null and dyfos: 2 closed + 1 open each; the mixed
    // run's two groups; the contention runs: the hog alone, stats and map beside dyfos (2
    // each), dyfos alone, hog beside dyfos (2), greedy beside dyfos (2), null beside
    // a client that comes and goes (2); 2 in-process.
    assert_eq!(rows.len(), 24, "{rows:#?}");
    assert_eq!(rows.iter().filter(|r| !r["alongside"].is_null()).count(), 12);
    let churn = rows.iter().find(|r| r["workload"] == "churn").expect("the churn row");
    assert!(churn["latency"]["count"].as_u64().unwrap() > 0, "no visit: {churn}");
    for r in rows.iter().filter(|r| r["workload"] != "hog") {
        assert!(r["answered_per_s"].as_f64().unwrap() > 0.0, "nothing answered: {r}");
        assert!(r["errors"].as_object().unwrap().is_empty(), "errors: {r}");
        let l = &r["latency"];
        assert!(l["p50_us"].as_f64().unwrap() <= l["p99_us"].as_f64().unwrap(), "{r}");
        assert!(l["p99_us"].as_f64().unwrap() <= l["max_us"].as_f64().unwrap(), "{r}");
        if r["workload"] == "dyfos" {
            assert!(r["search"]["count"].as_u64().unwrap() > 0, "no search times: {r}");
        }
        // An open loop times each request from its send too, without the client's
        // own lateness: never longer than from its scheduled time.
        if !r["offered_per_s"].is_null() && r["path"] == "daemon" {
            let (sent, scheduled) = (&r["from_send"], &r["latency"]);
            assert_eq!(sent["count"], scheduled["count"], "{r}");
            assert!(sent["p50_us"].as_f64().unwrap() <= scheduled["p50_us"].as_f64().unwrap(), "{r}");
        }
        // Each configuration run through the daemon says how much of the machine the
        // hypervisor took meanwhile (a share, 0 on bare metal).
        if cfg!(target_os = "linux") && r["path"] == "daemon" {
            let steal = r["host_steal"].as_f64().unwrap_or_else(|| panic!("no host_steal: {r}"));
            assert!((0.0..=1.0).contains(&steal), "{r}");
        }
    }
    if cfg!(target_os = "linux") {
        assert!(stdout.contains("Host steal time (the hypervisor ran other guests"), "{stdout}");
    }
    for file in ["latency.md", "latency-null.svg", "latency-dyfos.svg", "latency-throughput.svg"] {
        let text = std::fs::read_to_string(out.join(file)).unwrap_or_else(|e| panic!("{file}: {e}"));
        assert!(text.len() > 200, "{file} is nearly empty");
    }
    let bad = Command::new(&exe).args(["latency", "--workloads", "nap", "--out"]).arg(&out).output().unwrap();
    assert!(!bad.status.success() && String::from_utf8_lossy(&bad.stderr).contains("use floor, null, dyfos"));
    let _ = std::fs::remove_dir_all(&out);
}
