//! `dyfosd --model`: the daemon answers `learned` queries as the offline library
//! does with the same model file, refuses them without one, and will not start
//! with a bad model file (exit code 2).

use dyfos_client::prelude::*;
use dyfos_service::learned::load_model;
use dyfos_service::search::SearchControl;
use dyfos_tests::{PATIENCE, Sandbox, bin, data, scenario, without_micros};
use std::process::Command;

fn model_file() -> String {
    data("learned/model.bin").to_str().unwrap().to_string()
}

#[test]
fn learned_queries_match_the_offline_library_bit_for_bit() {
    let sandbox = Sandbox::new("learned");
    let _daemon = sandbox.start_daemon(&["--model", &model_file()]);
    let mut client = sandbox.client();
    let s = scenario("example.json");
    client.upload_map(1, &s.world, false, PATIENCE).unwrap();
    let weights = load_model(&data("learned/model.bin")).unwrap();
    for seed in [0, 5] {
        let params = Params { model: ModelKind::Learned, ..s.params };
        let request = RendezvousRequest { seed, params, ..RendezvousRequest::new(1, s.belief) };
        let daemon = client.rendezvous(&request, PATIENCE).unwrap();
        let model = NoiseModel::from_params_and_weights(&params, Some(&weights)).unwrap();
        let offline =
            dyfos_service::solve(&s.world, &s.belief, &params, &model, request.algorithm, &SearchControl::seeded(seed))
                .unwrap();
        assert_eq!(without_micros(daemon.to_json()), without_micros(offline.to_json()), "seed {seed}");
    }
}

#[test]
fn without_a_model_file_learned_is_refused() {
    let sandbox = Sandbox::new("nolearned");
    let s = scenario("example.json");
    let (_daemon, mut client) = sandbox.start_serving(1, &s.world);
    let params = Params { model: ModelKind::Learned, ..s.params };
    let err = client.rendezvous(&RendezvousRequest { params, ..RendezvousRequest::new(1, s.belief) }, PATIENCE);
    let err = err.unwrap_err();
    assert_eq!(err.status(), Some(Status::UnsupportedModel), "{err}");
}

#[test]
fn a_bad_model_file_stops_the_start_with_exit_code_2() {
    let sandbox = Sandbox::new("badmodel");
    let missing = sandbox.state_dir.with_extension("missing-model.bin");
    let out = Command::new(bin("dyfosd"))
        .args(["--prefix", &sandbox.prefix, "--domain", &sandbox.domain, "--state-dir"])
        .arg(&sandbox.state_dir)
        .arg("--model")
        .arg(&missing)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("cannot read model file") && stderr.contains("missing-model.bin"), "{stderr}");
    let _ = std::fs::remove_dir_all(&sandbox.state_dir);
}
