//! The C and C++ programs of this crate, compiled with the system `cc` / `c++`
//! against the built library (found through `install.sh` and pkg-config), run
//! against a real `dyfosd`: their answers equal `dyfos solve`'s bit for bit, and
//! every error family comes back with its code.
//!
//! `cargo test` builds this crate's cdylib and staticlib before its tests (the lib
//! target is built with all its crate types), next to the test executable in
//! `target/<profile>/deps/`; `dyfosd` and `dyfos` from `dyfos_tests::bin`, which
//! builds them if they are missing.

use dyfos_tests::{Sandbox, Scratch, bin, data};
use std::io::{BufRead, BufReader, Write};
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};

fn crate_dir() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// `target/<profile>/deps`, where cargo wrote libdyfos.so and libdyfos.a for this test.
fn lib_dir() -> PathBuf {
    let exe = std::env::current_exe().expect("the test executable's path");
    let deps = exe.parent().expect("deps dir").to_path_buf();
    for lib in ["libdyfos.so", "libdyfos.a"] {
        assert!(deps.join(lib).exists(), "{} is missing: run `cargo build -p dyfos-ffi`", deps.join(lib).display());
    }
    deps
}

fn run(cmd: &mut Command) -> Output {
    let output = cmd.output().unwrap_or_else(|e| panic!("cannot run {cmd:?}: {e}"));
    assert!(
        output.status.success(),
        "{cmd:?} failed ({}):\n{}\n{}",
        output.status,
        String::from_utf8_lossy(&output.stdout),
        String::from_utf8_lossy(&output.stderr)
    );
    output
}

/// Installs the library under `prefix` with `install.sh` (linking the built libraries).
fn install(prefix: &Path) {
    run(Command::new("bash")
        .arg(crate_dir().join("install.sh"))
        .arg("--lib-dir")
        .arg(lib_dir())
        .arg("--symlink")
        .arg(prefix));
}

/// `pkg-config ARGS dyfos` for the installation under `prefix`, split into flags.
fn pkg_config(prefix: &Path, args: &[&str]) -> Vec<String> {
    assert!(
        Command::new("pkg-config").arg("--version").output().is_ok(),
        "pkg-config is not installed: run client/ffi/test.sh --deps (or apt-get install -y pkg-config)"
    );
    let out =
        run(Command::new("pkg-config").args(args).arg("dyfos").env("PKG_CONFIG_PATH", prefix.join("lib/pkgconfig")));
    String::from_utf8(out.stdout).expect("UTF-8 flags").split_whitespace().map(str::to_string).collect()
}

/// How to link the program.
enum Link {
    /// `$(pkg-config --cflags --libs dyfos)`, libdyfos.so found through an rpath.
    Shared,
    /// libdyfos.a and `$(pkg-config --static --libs dyfos)`'s private libraries.
    Static,
}

/// Compiles `source` (C or C++ by its extension) into `out` with the system compiler.
fn compile(prefix: &Path, source: &Path, out: &Path, link: Link) {
    let cpp = source.extension().is_some_and(|e| e == "cpp");
    let mut cmd = Command::new(if cpp { "c++" } else { "cc" });
    // The warnings a careful user turns on: the headers must compile clean with them.
    cmd.arg(if cpp { "-std=c++17" } else { "-std=c11" });
    cmd.args(["-Wall", "-Wextra", "-Wconversion", "-Wsign-conversion", "-Werror", "-O1"]);
    cmd.arg(source).arg("-o").arg(out);
    cmd.args(pkg_config(prefix, &["--cflags"]));
    match link {
        Link::Shared => {
            cmd.args(pkg_config(prefix, &["--libs"]));
            cmd.arg(format!("-Wl,-rpath,{}", prefix.join("lib").display()));
        }
        Link::Static => {
            cmd.arg(prefix.join("lib/libdyfos.a"));
            cmd.args(pkg_config(prefix, &["--static", "--libs-only-l"]).into_iter().filter(|f| f != "-ldyfos"));
        }
    }
    run(&mut cmd);
}

/// `dyfos solve --algo ALGORITHM --seed SEED SCENARIO`'s output.
fn dyfos_solve(scenario: &Path, algorithm: &str, seed: &str) -> String {
    let out = run(Command::new(bin("dyfos")).args(["solve", "--algo", algorithm, "--seed", seed]).arg(scenario));
    String::from_utf8(out.stdout).expect("UTF-8")
}

/// An answer's JSON text without its compute-time line (the one number that
/// differs between two runs); every other byte must match.
fn without_micros_line(text: &str) -> String {
    let lines: Vec<&str> = text.trim_end().lines().filter(|l| !l.trim_start().starts_with("\"micros\":")).collect();
    assert!(lines.len() > 10, "not an answer:\n{text}");
    lines.join("\n")
}

#[test]
fn the_c_and_cpp_examples_print_what_dyfos_solve_prints() {
    let scratch = Scratch::new("ffi-examples");
    let prefix = scratch.0.join("prefix");
    install(&prefix);
    let examples = crate_dir().join("examples");
    let programs = [
        (examples.join("query.c"), scratch.0.join("query_c"), Link::Shared),
        (examples.join("query.c"), scratch.0.join("query_c_static"), Link::Static),
        (examples.join("query.cpp"), scratch.0.join("query_cpp"), Link::Shared),
    ];
    for (source, out, link) in programs {
        compile(&prefix, &source, &out, link);
    }
    let sandbox = Sandbox::new("ffi-examples");
    let _daemon = sandbox.start_daemon(&[]);
    let scenario = data("example.json");
    let expected = without_micros_line(&dyfos_solve(&scenario, "dyfos", "7"));
    for program in ["query_c", "query_c_static", "query_cpp"] {
        let out =
            run(Command::new(scratch.0.join(program)).arg(&scenario).args([&sandbox.prefix, &sandbox.domain, "7"]));
        let got = String::from_utf8(out.stdout).expect("UTF-8");
        assert_eq!(without_micros_line(&got), expected, "{program}");
    }
    // Their error path: no daemon serves this prefix.
    for program in ["query_c", "query_cpp"] {
        let out = Command::new(scratch.0.join(program))
            .arg(&scenario)
            .args(["dyfos-ffi-nobody/", &sandbox.domain])
            .output()
            .expect("run the example");
        assert_eq!(out.status.code(), Some(1), "{program}");
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(stderr.contains("no_daemon") && stderr.contains("dyfosd --prefix"), "{program}: {stderr}");
    }
}

/// What `dyfos` printed at a check program's `--- kill`, before the daemon was killed.
#[derive(Default)]
struct AtKill {
    /// `dyfos map snapshot` of the map of the `snapshot MAP` section, if any.
    snapshot: Option<String>,
    /// `dyfos map list`, if the program printed a `maps` section.
    list: Option<String>,
}

/// Builds the check `tests/c/SOURCE` against an installed tree and runs it as
/// `program SCENARIO PREFIX DOMAIN`, on the example scenario, against a fresh daemon
/// (sandbox `ffi-NAME`) as the checks expect: their `--- SECTION` output is returned;
/// at `--- kill` the daemon's snapshot of the named map and its list of maps are
/// taken with `dyfos`, the daemon is killed, and the program told to go on.
fn run_check(source: &str, name: &str) -> (Vec<(String, String)>, AtKill) {
    let scratch = Scratch::new(&format!("ffi-check-{name}"));
    let prefix = scratch.0.join("prefix");
    install(&prefix);
    let program = scratch.0.join(format!("check-{name}"));
    compile(&prefix, &crate_dir().join("tests/c").join(source), &program, Link::Shared);
    let sandbox = Sandbox::new(&format!("ffi-{name}"));
    let scenario = data("example.json");
    let mut daemon = sandbox.start_daemon(&[]);
    let mut child = Command::new(&program)
        .env("DYFOS_TEST_OCTOMAP", data("octomap/geb079.bt"))
        .env("DYFOS_TEST_DELTAS", data("deltas-every-kind.json"))
        .arg(&scenario)
        .args([&sandbox.prefix, &sandbox.domain])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start the check program");
    let mut stdin = child.stdin.take().expect("stdin");
    let stdout = BufReader::new(child.stdout.take().expect("stdout"));
    let mut sections: Vec<(String, String)> = Vec::new();
    let mut at_kill = AtKill::default();
    for line in stdout.lines() {
        let line = line.expect("a line of output");
        if let Some(name) = line.strip_prefix("--- ") {
            if name == "kill" {
                let dyfos_map = |args: &[&str]| {
                    let out = run(Command::new(bin("dyfos")).arg("map").args(args).args(sandbox.dyfos_flags()));
                    String::from_utf8(out.stdout).expect("UTF-8")
                };
                let snapshot_map = sections.iter().find_map(|(n, _)| n.strip_prefix("snapshot ").map(str::to_string));
                if let Some(map) = snapshot_map {
                    at_kill.snapshot = Some(dyfos_map(&["snapshot", &map]));
                }
                if sections.iter().any(|(n, _)| n == "maps") {
                    at_kill.list = Some(dyfos_map(&["list"]));
                }
                daemon.kill9();
                writeln!(stdin, "go on").expect("tell the program to go on");
            }
            sections.push((name.to_string(), String::new()));
        } else if let Some((_, text)) = sections.last_mut() {
            text.push_str(&line);
            text.push('\n');
        }
    }
    let output = child.wait_with_output().expect("the check program ends");
    assert!(
        output.status.success(),
        "{} failed ({}):\n{}",
        program.display(),
        output.status,
        String::from_utf8_lossy(&output.stderr)
    );
    assert_eq!(sections.last().map(|s| s.0.as_str()), Some("done"), "{sections:?}");
    (sections, at_kill)
}

#[test]
fn the_c_api_answers_like_dyfos_solve_and_returns_every_error_family() {
    let (sections, at_kill) = run_check("ffi_check.c", "c");
    let scenario = data("example.json");
    let mut compared = 0;
    for (name, text) in &sections {
        if let Some(rest) = name.strip_prefix("answer ") {
            let (algorithm, seed) = rest.split_once(' ').expect("answer ALGORITHM SEED");
            let expected = dyfos_solve(&scenario, algorithm, seed);
            assert_eq!(without_micros_line(text), without_micros_line(&expected), "{name}");
            compared += 1;
        }
    }
    assert_eq!(compared, 3, "{sections:?}");
    // The OctoMap map, replaced once (origin NULL: OctoMap's frame).
    assert!(sections.contains(&("octomap".to_string(), "version=1\n".to_string())), "{sections:?}");
    // The snapshot equals `dyfos map snapshot`'s, but for the CLI's `map` field.
    let snapshot = sections.iter().find(|(n, _)| n.starts_with("snapshot ")).expect("a snapshot").1.clone();
    let ours: serde_json::Value = serde_json::from_str(&snapshot).expect("snapshot JSON");
    let mut cli: serde_json::Value =
        serde_json::from_str(&at_kill.snapshot.expect("the CLI's snapshot")).expect("JSON");
    cli.as_object_mut().expect("an object").remove("map");
    assert_eq!(ours, cli);
    // The map after `[{"clear": {}}]` and the file of every delta kind: what the same
    // deltas make in Rust.
    use dyfos_shared::world::{Bounds, MapDelta, Sun, World};
    let text = std::fs::read_to_string(data("deltas-every-kind.json")).expect("the deltas file");
    let deltas = dyfos_shared::map_json::deltas_from_json(&text).expect("the deltas file reads");
    let tiny = World::empty(Bounds::new([-0.2, -0.2, 0.2, 0.2]).unwrap(), Sun::new(0.7, 2.1).unwrap());
    let expected = tiny.apply(&[MapDelta::Clear]).and_then(|w| w.apply(&deltas)).expect("the deltas apply");
    let (_, got) = dyfos_shared::map_json::map_from_json(&snapshot).expect("the snapshot reads back");
    assert_eq!(got, expected, "{snapshot}");
    // The maps listed through C are those `dyfos map list` prints, number for number.
    let listed = &sections.iter().find(|(n, _)| n == "maps").expect("a list of maps").1;
    let cli_list = at_kill.list.expect("the CLI's list");
    let cli_maps: Vec<serde_json::Value> =
        cli_list.lines().map(|l| serde_json::from_str(l).expect("a JSON object a line")).collect();
    assert!(cli_maps.len() >= 3, "the scenario's, the OctoMap and the small map: {cli_list}");
    let as_cli = |line: &str| {
        let f: Vec<&str> = line.split(' ').collect();
        let number = |i: usize| f[i].parse::<f64>().expect("a number");
        serde_json::json!({
            "map": f[0].parse::<u64>().expect("an id"),
            "version": f[1].parse::<u64>().expect("a version"),
            "generation": f[2].parse::<u32>().expect("a generation"),
            "bounds": [number(3), number(4), number(5), number(6)],
            "sun": {"elevation": number(7), "azimuth": number(8)},
        })
    };
    assert_eq!(listed.lines().map(as_cli).collect::<Vec<_>>(), cli_maps, "{listed}");
}

#[test]
fn the_cpp_wrapper_answers_like_dyfos_solve_and_throws_each_family() {
    let (sections, _) = run_check("cpp_check.cpp", "cpp");
    let scenario = data("example.json");
    let answers: Vec<_> = sections.iter().filter(|(n, _)| n.starts_with("answer ")).collect();
    assert_eq!(answers.len(), 2, "{sections:?}");
    for (name, text) in answers {
        let rest = name.strip_prefix("answer ").expect("answer");
        let (algorithm, seed) = rest.split_once(' ').expect("answer ALGORITHM SEED");
        assert_eq!(without_micros_line(text), without_micros_line(&dyfos_solve(&scenario, algorithm, seed)), "{name}");
    }
}

/// `readelf -d FILE`'s dynamic section.
fn dynamic_section(file: &Path) -> String {
    String::from_utf8(run(Command::new("readelf").arg("-d").arg(file)).stdout).expect("UTF-8")
}

/// The installed tree: libdyfos.so.<ABI> is the SONAME programs record, and the tree
/// still works after it is moved (pkg-config's prefix comes from where dyfos.pc lies).
#[test]
fn the_installed_library_has_a_soname_and_a_relocatable_pkg_config_file() {
    let scratch = Scratch::new("ffi-relocate");
    let first = scratch.0.join("first");
    run(Command::new("bash").arg(crate_dir().join("install.sh")).arg("--lib-dir").arg(lib_dir()).arg(&first));
    let soname = format!("libdyfos.so.{}", dyfos::DYFOS_ABI_VERSION);
    assert!(first.join("lib").join(&soname).is_file(), "{soname} is installed");
    assert_eq!(std::fs::read_link(first.join("lib/libdyfos.so")).expect("a link"), Path::new(&soname));
    let library = dynamic_section(&first.join("lib").join(&soname));
    assert!(library.contains(&format!("Library soname: [{soname}]")), "{library}");

    let moved = scratch.0.join("moved");
    std::fs::rename(&first, &moved).expect("move the installed tree");
    let cflags = pkg_config(&moved, &["--cflags"]).join(" ");
    let libs = pkg_config(&moved, &["--libs"]).join(" ");
    for flags in [&cflags, &libs] {
        assert!(flags.contains(&moved.display().to_string()), "{flags}");
        assert!(!flags.contains(&first.display().to_string()), "{flags}");
    }
    let program = scratch.0.join("query_c");
    compile(&moved, &crate_dir().join("examples/query.c"), &program, Link::Shared);
    let needed = dynamic_section(&program);
    assert!(needed.contains(&format!("Shared library: [{soname}]")), "{needed}");
    // It loads the moved library and runs: here it finds no daemon.
    let out = Command::new(&program)
        .arg(data("example.json"))
        .args(["dyfos-ffi-nobody/", &format!("dyt{}_reloc_", std::process::id())])
        .output()
        .expect("run the example");
    assert_eq!(out.status.code(), Some(1), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(String::from_utf8_lossy(&out.stderr).contains("no_daemon"), "{}", String::from_utf8_lossy(&out.stderr));
}

/// Without `--lib-dir`, install.sh installs the workspace's built release library as
/// it is: it never runs cargo (which would rebuild it with other features and
/// replace the workspace's), so a `cargo` that fails does not matter.
#[test]
fn install_takes_the_built_library_without_running_cargo() {
    let scratch = Scratch::new("ffi-no-rebuild");
    let target = scratch.0.join("target");
    let release = target.join("release");
    std::fs::create_dir_all(&release).expect("release dir");
    for lib in ["libdyfos.so", "libdyfos.a"] {
        std::fs::copy(lib_dir().join(lib), release.join(lib)).expect("copy the built library");
    }
    let bin = scratch.0.join("bin");
    std::fs::create_dir_all(&bin).expect("bin dir");
    let marker = scratch.0.join("cargo-ran");
    let fake_cargo = bin.join("cargo");
    std::fs::write(&fake_cargo, format!("#!/bin/sh\ntouch '{}'\nexit 1\n", marker.display())).expect("fake cargo");
    run(Command::new("chmod").arg("+x").arg(&fake_cargo));
    let path = format!("{}:{}", bin.display(), std::env::var("PATH").unwrap_or_default());
    let prefix = scratch.0.join("prefix");
    let installed = |cmd: &mut Command| {
        cmd.env("CARGO_TARGET_DIR", &target).env("PATH", &path).env_remove("DYFOS_LIB_DIR");
        run(cmd)
    };
    installed(Command::new("bash").arg(crate_dir().join("install.sh")).arg(&prefix));
    assert!(!marker.exists(), "install.sh ran cargo although a built library was there");
    let soname = format!("libdyfos.so.{}", dyfos::DYFOS_ABI_VERSION);
    for (built, copy) in [("libdyfos.so", soname.as_str()), ("libdyfos.a", "libdyfos.a")] {
        let same = std::fs::read(release.join(built)).ok() == std::fs::read(prefix.join("lib").join(copy)).ok();
        assert!(same, "{copy} is not the built {built}");
    }
    // An explicit library directory that lacks the library is an error, not a build.
    let missing = Command::new("bash")
        .arg(crate_dir().join("install.sh"))
        .args(["--lib-dir", "/nonexistent-dyfos-libs"])
        .arg(&prefix)
        .env("PATH", &path)
        .output()
        .expect("run install.sh");
    assert!(!missing.status.success());
    assert!(String::from_utf8_lossy(&missing.stderr).contains("/nonexistent-dyfos-libs/libdyfos.so does not exist"));
    assert!(!marker.exists());
}

/// The CMake package: `find_package(dyfos)` finds the installed library, and the C++
/// example (shared) and the C example (static) build and run against a daemon.
/// Needs cmake, which the CI machine lacks: `client/ffi/test.sh --cmake` installs it
/// and runs this test.
#[test]
#[ignore = "needs cmake: run client/ffi/test.sh --cmake"]
fn the_cmake_package_finds_the_library() {
    let scratch = Scratch::new("ffi-cmake");
    let prefix = scratch.0.join("prefix");
    install(&prefix);
    let app = scratch.0.join("app");
    std::fs::create_dir_all(&app).expect("app dir");
    for file in ["query.c", "query.cpp"] {
        std::fs::copy(crate_dir().join("examples").join(file), app.join(file)).expect("copy the example");
    }
    // A version this package is not (another major) is refused; 0.1 is found.
    std::fs::write(
        app.join("CMakeLists.txt"),
        "cmake_minimum_required(VERSION 3.16)\nproject(dyfos_query C CXX)\n\
         find_package(dyfos 1.0 QUIET)\nif(dyfos_FOUND)\n  message(FATAL_ERROR \"dyfos 1.0 found\")\nendif()\n\
         find_package(dyfos 0.1 REQUIRED)\n\
         add_executable(query_cpp query.cpp)\nset_target_properties(query_cpp PROPERTIES CXX_STANDARD 17)\n\
         target_link_libraries(query_cpp PRIVATE dyfos::dyfos)\n\
         add_executable(query_c_static query.c)\ntarget_link_libraries(query_c_static PRIVATE dyfos::dyfos_static)\n",
    )
    .expect("CMakeLists.txt");
    let build = app.join("build");
    run(Command::new("cmake")
        .arg("-S")
        .arg(&app)
        .arg("-B")
        .arg(&build)
        .arg(format!("-DCMAKE_PREFIX_PATH={}", prefix.display())));
    run(Command::new("cmake").arg("--build").arg(&build));
    let sandbox = Sandbox::new("ffi-cmake");
    let _daemon = sandbox.start_daemon(&[]);
    let scenario = data("example.json");
    let expected = without_micros_line(&dyfos_solve(&scenario, "dyfos", "3"));
    for program in ["query_cpp", "query_c_static"] {
        let out = run(Command::new(build.join(program)).arg(&scenario).args([&sandbox.prefix, &sandbox.domain, "3"]));
        assert_eq!(without_micros_line(&String::from_utf8(out.stdout).expect("UTF-8")), expected, "{program}");
    }
}
