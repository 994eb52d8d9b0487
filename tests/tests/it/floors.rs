//! The floors of the workspace (ARCHITECTURE.md) as cargo resolves them: what each
//! crate compiles in, by `cargo tree -e normal` (dependencies a user of the crate
//! links, with the features that crate alone turns on; no dev- or build-
//! dependencies).

use std::collections::BTreeSet;
use std::path::Path;
use std::process::Command;

/// Every package `package` compiles in through its normal dependencies, itself
/// included, by name.
fn normal_dependencies(package: &str) -> BTreeSet<String> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".to_string());
    let out = Command::new(cargo)
        .current_dir(&root)
        .args(["tree", "--offline", "-e", "normal", "--prefix", "none", "--format", "{p}", "-p", package])
        .output()
        .expect("cargo tree runs");
    assert!(out.status.success(), "cargo tree -p {package}: {}", String::from_utf8_lossy(&out.stderr));
    let names: BTreeSet<String> = String::from_utf8_lossy(&out.stdout)
        .lines()
        .filter_map(|line| line.split_whitespace().next())
        .map(str::to_string)
        .collect();
    assert!(names.contains(package), "cargo tree -p {package} does not list {package}: {names:?}");
    names
}

fn assert_links_none_of(package: &str, forbidden: &[&str], why: &str) {
    let names = normal_dependencies(package);
    let found: Vec<&str> = forbidden.iter().copied().filter(|f| names.contains(*f)).collect();
    assert!(found.is_empty(), "{package} compiles in {found:?} ({why})");
}

#[test]
fn the_daemon_does_not_depend_on_the_client() {
    assert_links_none_of(
        "dyfos-service",
        &["dyfos-client", "dyfos-mission", "dyfos-cli", "dyfos-link"],
        "the optimizer and daemon sit below the client; what both need is in dyfos-process or dyfos-shared",
    );
}

#[test]
fn the_client_robots_link_holds_no_optimizer_simulator_or_command_line() {
    assert_links_none_of(
        "dyfos-client",
        &["dyfos-service", "dyfos-mission", "mcap", "clap", "anyhow", "rand", "tracing-subscriber"],
        "robots link it: the request, the answer and the errors, nothing of the daemon, the missions or the binaries",
    );
}

#[test]
fn the_bottom_floors_depend_on_no_other_dyfos_crate() {
    for bottom in ["dyfos-process", "dyfos-shared"] {
        let names = normal_dependencies(bottom);
        let dyfos: Vec<&String> = names.iter().filter(|n| n.starts_with("dyfos-") && *n != bottom).collect();
        assert!(dyfos.is_empty(), "{bottom} depends on {dyfos:?}");
    }
}

#[test]
fn the_missions_link_no_optimizer() {
    assert_links_none_of("dyfos-mission", &["dyfos-service"], "the viewer asks the daemon through dyfos-client");
}
