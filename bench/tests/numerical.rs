//! The numerical evaluation as tests: `dyfos` against `brute` on generated SPEC §10
//! maps (the evidence that the search reaches the grid optimum), and a smoke run of
//! `dyfos-bench numerical` so the command cannot rot. No timing is asserted; speed is
//! in `bench/RESULTS.md`.

mod common;

use dyfos_bench::evaluation::{Contender, evaluate};
use dyfos_bench::numerical::{NumericalConfig, numerical_maps};
use dyfos_shared::answer::Algorithm;
use dyfos_shared::params::ModelKind;
use std::process::Command;

/// Maps per model. The benchmark uses 20; 8 keep this test to a few seconds in a
/// debug build (each `brute` query is 397 800 candidates).
const MAPS: usize = 8;

fn dyfos_against_brute(model: ModelKind) {
    let maps = numerical_maps(2024, MAPS, &NumericalConfig::paper().model(model));
    let contenders = [
        Contender::algorithm(Algorithm::Dyfos, 1),
        Contender::algorithm(Algorithm::DyfosScipy, 1),
        Contender::algorithm(Algorithm::Brute, 2),
    ];
    let run = evaluate(&maps, &contenders, 2024, 1);
    for (c, name) in run.names.iter().enumerate() {
        for (m, q) in run.queries[c].iter().enumerate() {
            assert!(q.feasible(), "{name} on map {m}: {q:?} (no pose, or a pose the constraints reject)");
        }
    }
    let brute = run.index("brute").unwrap();
    let median = run.median_map(brute).unwrap();
    for name in ["dyfos", "dyfos-scipy"] {
        let gap = run.gaps(run.index(name).unwrap(), brute)[median].unwrap();
        assert!(
            gap <= 0.1,
            "{model:?}: {name} is {gap} above brute on brute's median map {median}\n{}",
            run.cost_table()
        );
    }
    // The polished default is no worse than SciPy's search on any map (it polishes
    // SciPy's answer, and the polish only accepts improvements).
    let (d, s) = (run.index("dyfos").unwrap(), run.index("dyfos-scipy").unwrap());
    for (m, gap) in run.gaps(d, s).iter().enumerate() {
        assert!(gap.unwrap() <= 0.0, "map {m}: dyfos {gap:?} above dyfos-scipy");
    }
}

#[test]
fn dyfos_lands_near_brute_on_the_median_map_paper_model() {
    dyfos_against_brute(ModelKind::Paper);
}

#[test]
fn dyfos_lands_near_brute_on_the_median_map_anisotropic_model() {
    dyfos_against_brute(ModelKind::Anisotropic);
}

#[test]
fn numerical_command_smoke_run() {
    let out = std::env::temp_dir().join(format!("dyfos-bench-smoke-{}", std::process::id()));
    let stdout = common::succeeds(
        Command::new(env!("CARGO_BIN_EXE_dyfos-bench"))
            .args([
                "numerical",
                "--maps",
                "2",
                "--repeats",
                "1",
                "--algos",
                "dyfos,brute,random,center",
                "--threads",
                "2",
            ])
            .args(["--obstacles", "25,100", "--scaling-maps", "1", "--voxel-resolution", "0.5"]),
        &out,
    );
    common::assert_holds(&stdout, &["| dyfos | ", "| brute | 2 |", "(median)", "| 100 | 40 × 40 m | voxels 0.5 m |"]);
    for file in ["numerical-paper-cost.svg", "numerical-paper.json", "numerical-paper.md", "scaling.svg", "scaling.md"]
    {
        let text = std::fs::read_to_string(out.join(file)).unwrap_or_else(|e| panic!("{file}: {e}"));
        assert!(text.len() > 200, "{file} is nearly empty");
    }
    let raw: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("numerical-paper.json")).unwrap()).unwrap();
    assert_eq!(raw["contenders"].as_array().unwrap().len(), 4);
    let bad = Command::new(env!("CARGO_BIN_EXE_dyfos-bench"))
        .args(["numerical", "--model", "neural", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(!bad.status.success() && String::from_utf8_lossy(&bad.stderr).contains("use `paper` or `anisotropic`"));
    let _ = std::fs::remove_dir_all(&out);
}
