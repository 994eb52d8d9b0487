//! `dyfosd`'s configuration as an operator meets it: a TOML file, `--set`, the
//! flags, `--print-config`, and the errors for a bad key, a bad value and a flag of
//! an earlier version (docs/daemon.md).

use dyfos_service::daemon::DaemonConfig;
use dyfos_tests::{PATIENCE, Sandbox, bin};
use std::path::PathBuf;
use std::process::{Command, Output};

/// A file of this test's own, removed on drop.
struct File(PathBuf);

impl File {
    fn new(name: &str, text: &str) -> File {
        let path = std::env::temp_dir().join(format!("dyfosd-config-test-{}-{name}.toml", std::process::id()));
        std::fs::write(&path, text).expect("write the file");
        File(path)
    }

    fn path(&self) -> &str {
        self.0.to_str().expect("a UTF-8 temporary path")
    }
}

impl Drop for File {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.0);
    }
}

fn dyfosd(args: &[&str]) -> Output {
    Command::new(bin("dyfosd")).args(args).output().expect("run dyfosd")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

#[test]
fn print_config_shows_the_file_under_the_sets_under_the_flags() {
    let file =
        File::new("layers", "prefix = \"file/\"\nworkers = 3\n[limits]\nmax_queued = 9\n[scheduling]\npoll_us = 70\n");
    let out = dyfosd(&[
        "--config",
        file.path(),
        "--set",
        "scheduling.poll_us=80",
        "--set",
        "prefix=set/",
        "--prefix",
        "flag/",
        "--print-config",
    ]);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    let printed = File::new("printed", &String::from_utf8_lossy(&out.stdout));
    let c = DaemonConfig::load(Some(&printed.0), &[] as &[&str]).expect("the printed configuration reads back");
    assert_eq!((c.prefix.as_str(), c.workers, c.limits.max_queued, c.scheduling.poll_us), ("flag/", 3, 9, 80));
    assert_eq!(c.limits.max_clients, DaemonConfig::default().limits.max_clients);
}

#[test]
fn a_started_daemon_runs_with_its_file() {
    let file = File::new("start", "workers = 3\n[limits]\nmax_clients = 8\n");
    let sandbox = Sandbox::new("config-file");
    let _daemon = sandbox.start_daemon(&["--config", file.path()]);
    assert_eq!(sandbox.client().stats(PATIENCE).unwrap().workers, 3);
}

/// Each mistake stops the start with exit code 2 and says what to write.
#[test]
fn bad_keys_values_and_former_flags_are_refused_with_what_to_write() {
    let old = File::new("old", "max_queued = 3\n");
    let typo = File::new("typo", "[scheduling]\npoll_uss = 3\n");
    let old_flag = "was replaced by the key `scheduling.poll_us`: write `--set scheduling.poll_us=VALUE`";
    for (args, want) in [
        (&["--spin-us", "50"][..], old_flag),
        (&["--workers", "2", "--max-queued=3"], "--max-queued=3 was replaced by the key `limits.max_queued`"),
        (&["--queue", "fifo"], "--queue was removed: the search queue is always fair across clients"),
        (&["--set", "limits.max_queued=0"], "limits.max_queued = 0 must be at least 1"),
        (&["--set", "scheduling.worker_slice_us=99"], "scheduling.worker_slice_us = 99 must be 100–100000"),
        (&["--set", "scheduling.cpu_latency_us=soon"], "expected a number of µs or \"off\""),
        (&["--set", "limits.max_clientz=3"], "did you mean `max_clients`?"),
        (&["--config", old.path()], "`max_queued`: is now `limits.max_queued`"),
        (&["--config", typo.path()], "`scheduling.poll_uss`: is not a key"),
        (&["--prefix", "a b"], "prefix = \"a b\" is refused"),
    ] {
        let out = dyfosd(args);
        let err = stderr(&out);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
        assert!(err.contains(want), "{args:?}: `{want}` not in: {err}");
    }
}

#[test]
fn help_shows_at_most_ten_flags() {
    let out = dyfosd(&["--help"]);
    let help = String::from_utf8_lossy(&out.stdout);
    let flags = help.lines().filter(|l| l.trim_start().starts_with("--")).count();
    assert!((1..=10).contains(&flags), "{flags} flags:\n{help}");
    for flag in ["--prefix", "--state-dir", "--domain", "--workers", "--model", "--config", "--record", "--set"] {
        assert!(help.contains(flag), "{flag} missing:\n{help}");
    }
}
