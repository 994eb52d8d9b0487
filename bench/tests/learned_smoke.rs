//! A short run of `dyfos-bench learned` so the command cannot rot: held-out NLL of
//! every model, the std plots, planning on two maps with the per-map gaps. No
//! timing or quality is asserted here; the figures are in `bench/RESULTS.md`.

mod common;

use std::process::Command;

#[test]
fn learned_command_smoke_run() {
    let model = concat!(env!("CARGO_MANIFEST_DIR"), "/../tests/data/learned/model.bin");
    let out = std::env::temp_dir().join(format!("dyfos-bench-learned-smoke-{}", std::process::id()));
    let stdout = common::succeeds(
        Command::new(env!("CARGO_BIN_EXE_dyfos-bench"))
            .args(["learned", "--model", model, "--samples", "2000", "--maps", "2", "--repeats", "1"])
            .args(["--algos", "dyfos"]),
        &out,
    );
    common::assert_holds(
        &stdout,
        &["| learned | ", "| paper | ", "| map | true-planned E | learned | paper | anisotropic |", "| 1 | "],
    );
    for file in ["learned.md", "learned-std-u.svg", "learned-std-v.svg"] {
        let text = std::fs::read_to_string(out.join(file)).unwrap_or_else(|e| panic!("{file}: {e}"));
        assert!(text.len() > 200, "{file} is nearly empty");
    }
    let missing = Command::new(env!("CARGO_BIN_EXE_dyfos-bench"))
        .args(["learned", "--model", "/nonexistent/model.bin", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(!missing.status.success(), "a missing model file must fail");
    let _ = std::fs::remove_dir_all(&out);
}
