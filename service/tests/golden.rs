//! The golden vectors of an independent SPEC implementation (`tests/data/golden`):
//! constraint verdicts, R, Σ⁺ and E for 40 candidates per scenario, and the brute
//! force optimum on the default grid with SPEC's tie rule.

use dyfos_service::lupp::{Evaluation, Lupp};
use dyfos_service::search::{Brute, Search, SearchControl};
use dyfos_shared::prelude::*;
use serde_json::Value;
use std::path::{Path, PathBuf};

fn data() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/data/golden")
}

fn cases() -> Vec<(String, Scenario, Value)> {
    let golden: Value = serde_json::from_str(&std::fs::read_to_string(data().join("golden.json")).unwrap()).unwrap();
    golden["cases"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| {
            let name = c["scenario"].as_str().unwrap().to_string();
            let json = std::fs::read_to_string(data().join("scenarios").join(&name)).unwrap();
            (name, Scenario::from_json(&json).unwrap(), c.clone())
        })
        .collect()
}

fn close(a: f64, b: f64, rel: f64) -> bool {
    (a - b).abs() <= rel * a.abs().max(b.abs()).max(1e-300) || (a - b).abs() < 1e-15
}

fn x_of(v: &Value) -> SensorState {
    let a: Vec<f64> = v.as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect();
    SensorState::from_array([a[0], a[1], a[2], a[3]])
}

#[test]
fn candidates_match_the_golden_vectors() {
    let mut checked = 0;
    for (name, s, case) in cases() {
        let model = NoiseModel::from_params(&s.params).unwrap();
        let lupp = Lupp::new(&s.world, &s.belief, &s.params, &model);
        for (i, c) in case["candidates"].as_array().unwrap().iter().enumerate() {
            let p = lupp.predict(&x_of(&c["x"]));
            let reason = match p.evaluation {
                Evaluation::Feasible { .. } => None,
                Evaluation::Rejected(r) => Some(r.name()),
            };
            assert_eq!(reason, c["reason"].as_str(), "{name} candidate {i}: verdict");
            if let Evaluation::Feasible { cost } = p.evaluation {
                let want = c["cost"].as_f64().unwrap();
                assert!(close(cost, want, 1e-9), "{name} candidate {i}: cost {cost} vs {want}");
                for r in 0..2 {
                    for k in 0..2 {
                        let want = c["R"][r][k].as_f64().unwrap();
                        assert!(close(p.r.matrix()[(r, k)], want, 1e-9), "{name} #{i} R[{r}][{k}]");
                    }
                }
                for r in 0..3 {
                    for k in 0..3 {
                        let want = c["posterior"][r][k].as_f64().unwrap();
                        assert!(
                            close(p.posterior[(r, k)], want, 1e-9),
                            "{name} #{i} Σ⁺[{r}][{k}]: {} vs {want}",
                            p.posterior[(r, k)]
                        );
                    }
                }
            }
            checked += 1;
        }
    }
    assert_eq!(checked, 200);
}

#[test]
fn brute_matches_the_golden_optimum() {
    for (name, s, case) in cases() {
        let model = NoiseModel::from_params(&s.params).unwrap();
        let lupp = Lupp::new(&s.world, &s.belief, &s.params, &model);
        let grid: Vec<usize> =
            case["brute"]["grid"].as_array().unwrap().iter().map(|v| v.as_u64().unwrap() as usize).collect();
        let brute = Brute { grid: [grid[0], grid[1], grid[2], grid[3]] };
        let best = brute.search(&lupp, &SearchControl::seeded(0)).best.unwrap();
        let want = case["brute"]["cost"].as_f64().unwrap();
        assert!((best.cost - want).abs() <= 1e-8, "{name}: brute cost {} vs {want}", best.cost);
        let want_x = x_of(&case["brute"]["x"]);
        assert_eq!(best.x.to_array(), want_x.to_array(), "{name}: tie rule picked another point");
    }
}
