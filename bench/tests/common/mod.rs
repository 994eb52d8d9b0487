//! What every smoke run of a `dyfos-bench` command does: run it into a folder, check
//! it succeeded and printed its tables.

use std::path::Path;
use std::process::Command;

/// Runs `command` with `--out OUT`; fails the test, with what it printed, unless it
/// succeeds. Returns its standard output.
pub fn succeeds(command: &mut Command, out: &Path) -> String {
    let output = command.arg("--out").arg(out).output().expect("dyfos-bench runs");
    let stdout = String::from_utf8_lossy(&output.stdout).into_owned();
    assert!(output.status.success(), "{stdout}\n{}", String::from_utf8_lossy(&output.stderr));
    stdout
}

/// Fails the test, naming the first one missing, unless `stdout` holds every one of
/// `lines`.
pub fn assert_holds(stdout: &str, lines: &[&str]) {
    for line in lines {
        assert!(stdout.contains(line), "missing `{line}` in\n{stdout}");
    }
}
