//! The learned SDSMM end to end: the committed model file fits the synthetic camera
//! it was trained on, `dyfos solve/eval --model` use it, bad model files are exit
//! code 2 before any search, `dyfos train-data` writes a data set, and `dyfos train`
//! either trains (with the `train` feature) or says how to rebuild (without).

use dyfos_service::learned::{DataSet, DataSpec, generate, load_model, mean_nll};
use dyfos_service::lupp::Lupp;
use dyfos_shared::prelude::*;
use dyfos_shared::sdsmm::{Paper, Synthetic};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn dyfos(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_dyfos")).args(args).output().expect("dyfos runs")
}

fn data(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/data").join(name)
}

fn committed_model() -> PathBuf {
    data("learned/model.bin")
}

fn scratch(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("learned");
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

#[test]
fn committed_model_fits_the_reference_camera() {
    // Held-out data (the model was trained on seed 0).
    let held_out = generate(&DataSpec { samples: 20_000, seed: 99, ..DataSpec::default() });
    let learned = load_model(&committed_model()).unwrap();
    let truth = mean_nll(&Synthetic::default(), &held_out.samples);
    let fit = mean_nll(learned.as_ref(), &held_out.samples);
    let paper = mean_nll(&Paper, &held_out.samples);
    // The learned model's goal: within 5 % of the true model's NLL, and far below the
    // linear model's (a model that fits no better than `paper` was not learned).
    assert!((fit - truth).abs() <= 0.05 * truth.abs(), "learned {fit}, true {truth}");
    assert!(paper - truth > 10.0 * (fit - truth).abs(), "learned {fit}, true {truth}, paper {paper}");
}

#[test]
fn eval_with_model_uses_the_file() {
    let scenario_path = data("example.json");
    let out = dyfos(&[
        "eval",
        scenario_path.to_str().unwrap(),
        "--x",
        "2.0",
        "0.1",
        "-0.1",
        "0.3",
        "--model",
        committed_model().to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let v: Value = serde_json::from_slice(&out.stdout).unwrap();
    let got: Vec<f64> = v["R"]
        .as_array()
        .unwrap()
        .iter()
        .flat_map(|r| r.as_array().unwrap().clone())
        .map(|x| x.as_f64().unwrap())
        .collect();
    // The same prediction in this process.
    let scenario = Scenario::from_json(&std::fs::read_to_string(&scenario_path).unwrap()).unwrap();
    let params = Params { model: ModelKind::Learned, ..scenario.params };
    let model = NoiseModel::from_params_and_weights(&params, Some(&load_model(&committed_model()).unwrap())).unwrap();
    let lupp = Lupp::new(&scenario.world, &scenario.belief, &params, &model);
    let want = lupp.predict(&SensorState::new(2.0, 0.1, -0.1, 0.3)).r.to_rows();
    let want: Vec<f64> = want.iter().flatten().copied().collect();
    assert_eq!(got, want);
    // And not the paper model's (isotropic) noise.
    assert!((got[0] - got[3]).abs() > 1e-6 && got[1].abs() > 1e-9, "{got:?}");
}

#[test]
fn solve_with_model_is_seeded_and_answers() {
    let scenario = data("example.json");
    let run =
        || dyfos(&["solve", scenario.to_str().unwrap(), "--seed", "3", "--model", committed_model().to_str().unwrap()]);
    let (a, b) = (run(), run());
    assert!(a.status.success(), "{}", stderr(&a));
    let (va, vb): (Value, Value) =
        (serde_json::from_slice(&a.stdout).unwrap(), serde_json::from_slice(&b.stdout).unwrap());
    assert_eq!(va["x"], vb["x"]);
    assert_eq!(va["cost"], vb["cost"]);
    let paper = dyfos(&["solve", scenario.to_str().unwrap(), "--seed", "3"]);
    let vp: Value = serde_json::from_slice(&paper.stdout).unwrap();
    assert_ne!(va["R"], vp["R"], "--model must change the noise model");
}

#[test]
fn bad_model_files_are_exit_code_2() {
    let scenario = data("example.json");
    let scenario = scenario.to_str().unwrap();
    let missing = scratch("does-not-exist.bin");
    let out = dyfos(&["solve", scenario, "--model", missing.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(2));
    assert!(
        stderr(&out).contains("cannot read model file") && stderr(&out).contains("does-not-exist.bin"),
        "{}",
        stderr(&out)
    );

    let bytes = std::fs::read(committed_model()).unwrap();
    let truncated = scratch("truncated.bin");
    std::fs::write(&truncated, &bytes[..bytes.len() / 2]).unwrap();
    let out = dyfos(&["solve", scenario, "--model", truncated.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(2));
    assert!(stderr(&out).contains("is truncated"), "{}", stderr(&out));

    let mut flipped = bytes.clone();
    flipped[200] ^= 0x40;
    let corrupt = scratch("corrupt.bin");
    std::fs::write(&corrupt, &flipped).unwrap();
    let out = dyfos(&["eval", scenario, "--x", "2", "0", "0", "0", "--model", corrupt.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(2));
    assert!(stderr(&out).contains("is corrupt"), "{}", stderr(&out));

    let out = dyfos(&["solve", scenario, "--model", scenario]);
    assert_eq!(out.status.code(), Some(2));
    assert!(stderr(&out).contains("not a dyfos model file"), "{}", stderr(&out));
}

#[test]
fn learned_scenario_without_a_model_file_says_what_to_pass() {
    let text = std::fs::read_to_string(data("example.json")).unwrap();
    let v: Value = serde_json::from_str(&text).unwrap();
    let mut v = v.as_object().unwrap().clone();
    v.insert("params".into(), serde_json::json!({"model": "learned"}));
    let path = scratch("learned-scenario.json");
    std::fs::write(&path, serde_json::to_string(&v).unwrap()).unwrap();
    let out = dyfos(&["solve", path.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(2));
    assert!(stderr(&out).contains("--model"), "{}", stderr(&out));
}

#[test]
fn train_data_writes_the_requested_samples() {
    let path = scratch("small-data.bin");
    let out = dyfos(&["train-data", "--out", path.to_str().unwrap(), "--samples", "321", "--seed", "4"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let data = DataSet::from_bytes(&std::fs::read(&path).unwrap()).unwrap();
    assert_eq!(data, generate(&DataSpec { samples: 321, seed: 4, ..DataSpec::default() }));
}

#[cfg(not(feature = "train"))]
#[test]
fn train_without_the_feature_says_how_to_rebuild() {
    let out = dyfos(&["train", "--data", "d.bin", "--out", "m.bin"]);
    assert!(!out.status.success());
    assert!(stderr(&out).contains("--features train"), "{}", stderr(&out));
}

#[cfg(feature = "train")]
#[test]
fn train_writes_a_loadable_model_and_reports_every_epoch() {
    let data = scratch("train-data.bin");
    let model = scratch("trained.bin");
    let out = dyfos(&["train-data", "--out", data.to_str().unwrap(), "--samples", "3000", "--seed", "8"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let out = dyfos(&[
        "train",
        "--data",
        data.to_str().unwrap(),
        "--out",
        model.to_str().unwrap(),
        "--epochs",
        "3",
        "--hidden",
        "8",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let err = stderr(&out);
    assert_eq!(err.matches("validation NLL").count(), 3 + 1, "{err}");
    let loaded = load_model(&model).unwrap();
    assert_eq!(loaded.hidden(), 8);
    assert!(loaded.note().contains("seed 0"), "{}", loaded.note());
    let missing =
        dyfos(&["train", "--data", scratch("nothing.bin").to_str().unwrap(), "--out", model.to_str().unwrap()]);
    assert_eq!(missing.status.code(), Some(2));
}
