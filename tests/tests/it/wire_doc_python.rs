//! `docs/wire.md` §8 is a Python client over iceoryx2's own PyPI binding, in three
//! code blocks. This test runs exactly those blocks against a `dyfosd` and checks
//! that they print what `dyfos solve` prints for the same scenario and seed, bit
//! for bit: so every call the document shows is the binding's real API, and a user
//! who copies it gets the daemon's answer.
//!
//! The binding is installed the first time into a virtual environment beside the
//! build (`target/wire-doc-venv`), with the `pip install` command the document
//! gives; later runs reuse it. Needs Python ≥ 3.9 with venv and pip (`$PYTHON`,
//! default `python3`) and, the first time, PyPI.

use dyfos_tests::{PATIENCE, Sandbox, bin, bin_dir, data};
use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Instant;

const DOC: &str = include_str!("../../../docs/wire.md");

/// The Python code blocks of §8, in order, as one program.
fn section_8_python() -> String {
    let start = DOC.find("\n## 8. ").expect("docs/wire.md has a §8");
    let end = DOC[start..].find("\n## 9. ").map_or(DOC.len(), |e| start + e);
    let mut code = String::new();
    let mut rest = &DOC[start..end];
    while let Some(open) = rest.find("```python\n") {
        let body = &rest[open + "```python\n".len()..];
        let close = body.find("```").expect("a closed code block");
        code.push_str(&body[..close]);
        code.push('\n');
        rest = &body[close..];
    }
    assert!(code.contains("class Connection"), "§8 has no Python client");
    code
}

/// The `pip install iceoryx2==…` requirement the document tells Python users.
fn pip_requirement() -> String {
    let at = DOC.find("pip install iceoryx2==").expect("docs/wire.md says which binding to install");
    let spec = &DOC[at + "pip install ".len()..];
    spec[..spec.find('`').expect("in a code span")].to_string()
}

fn run(cmd: &mut Command, what: &str) {
    let out = cmd.output().unwrap_or_else(|e| panic!("{what}: {e}"));
    assert!(
        out.status.success(),
        "{what} failed: {}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}

/// A Python with the document's binding installed, made once per build directory.
fn python_with_binding() -> PathBuf {
    let venv = bin_dir().parent().expect("the target directory").join("wire-doc-venv");
    let python = venv.join("bin/python");
    let requirement = pip_requirement();
    let has_it = |python: &Path| {
        let check =
            format!("import importlib.metadata as m; assert '{requirement}' == 'iceoryx2==' + m.version('iceoryx2')");
        Command::new(python).args(["-c", &check]).stderr(Stdio::null()).status().is_ok_and(|s| s.success())
    };
    if !has_it(&python) {
        let system = std::env::var("PYTHON").unwrap_or_else(|_| "python3".to_string());
        if !python.exists() {
            run(
                Command::new(&system).args(["-m", "venv"]).arg(&venv),
                &format!("{system} -m venv (Python with venv is needed)"),
            );
        }
        run(
            Command::new(&python).args([
                "-m",
                "pip",
                "install",
                "--quiet",
                "--disable-pip-version-check",
                &requirement,
            ]),
            &format!("pip install {requirement}"),
        );
    }
    python
}

#[test]
fn the_documents_python_client_gets_the_answer_of_dyfos_solve() {
    let python = python_with_binding();
    let sandbox = Sandbox::new("wire-doc-py");
    let daemon = sandbox.start_daemon(&[]);
    let mut child = Command::new(&python)
        .args(["-c", &section_8_python()])
        .env("DYFOS_PREFIX", &sandbox.prefix)
        .env("DYFOS_DOMAIN", &sandbox.domain)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start the document's Python client");
    let started = Instant::now();
    let status = loop {
        if let Some(status) = child.try_wait().expect("wait for the client") {
            break status;
        }
        if started.elapsed() > PATIENCE {
            let _ = child.kill();
            panic!("the document's Python client did not finish within {PATIENCE:?}");
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    };
    let (mut stdout, mut stderr) = (String::new(), String::new());
    child.stdout.take().expect("stdout").read_to_string(&mut stdout).expect("its output");
    child.stderr.take().expect("stderr").read_to_string(&mut stderr).expect("its errors");
    assert!(status.success(), "the document's Python client failed:\n{stderr}\n{}", daemon.log());
    let printed: serde_json::Value = serde_json::from_str(stdout.trim()).unwrap_or_else(|e| panic!("{e}: {stdout}"));

    let solve = Command::new(bin("dyfos"))
        .arg("solve")
        .arg(data("example.json"))
        .args(["--seed", "7"])
        .output()
        .expect("dyfos solve");
    assert!(solve.status.success(), "{}", String::from_utf8_lossy(&solve.stderr));
    let mut expected: serde_json::Value = serde_json::from_slice(&solve.stdout).expect("dyfos solve prints JSON");
    // The same numbers in the shapes the Python client prints them.
    let e = &expected["evaluations"];
    let evaluations = serde_json::json!([e["total"], e["workspace"], e["collision"], e["occlusion"]]);
    let stop = ["finished", "max_generations", "budget", "deadline", "abandoned"]
        .iter()
        .position(|s| expected["stop"] == *s)
        .expect("a known stop reason");
    expected["evaluations"] = evaluations;
    expected["stop"] = serde_json::json!(stop);
    for key in ["x", "cost", "sensor_position", "sensor_quaternion", "viewer_position", "viewer_yaw", "R", "posterior"]
    {
        // Both sides print the shortest round-trip form, so equal text is equal bits.
        assert_eq!(printed[key], expected[key], "{key}: Python printed {stdout}");
    }
    for key in ["evaluations", "map_version", "stop"] {
        assert_eq!(printed[key], expected[key], "{key}: Python printed {stdout}");
    }
}
