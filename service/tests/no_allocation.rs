//! Hot paths allocate nothing per candidate (STYLE §5): `Lupp::evaluate` over many
//! candidates of every verdict, on cylinders, boxes, voxels and a crowded map, makes
//! no heap allocation; a differential evolution search allocates a fixed amount
//! whatever the number of candidates it evaluates.
//!
//! Allocations are counted per thread by `allocation-counter`'s global allocator,
//! so tests running beside this one on other threads do not disturb the counts.

use allocation_counter::measure;
use dyfos_service::lupp::{Evaluation, Lupp, Violation};
use dyfos_service::search::{Brute, DifferentialEvolution, Search, SearchControl};
use dyfos_shared::prelude::*;
use dyfos_shared::world::{AxisBox, VerticalCylinder};
use std::path::Path;

fn scenario(relative: &str) -> Scenario {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/data").join(relative);
    Scenario::from_json(&std::fs::read_to_string(&path).unwrap()).unwrap()
}

/// The example with a voxel wall near the rover, and a map crowded with small
/// obstacles (more near one viewer than the BVH gathers on the stack).
fn worlds() -> Vec<(&'static str, Scenario)> {
    let mut out = vec![
        ("example", scenario("example.json")),
        ("numerical map_00", scenario("golden/scenarios/numerical/map_00.json")),
        ("hard_00", scenario("golden/scenarios/hard/hard_00.json")),
        ("hard_01", scenario("golden/scenarios/hard/hard_01.json")),
    ];
    let mut voxels = scenario("example.json");
    let wall: Vec<[i64; 3]> = (0..40).flat_map(|j| (0..30).map(move |k| [25, j, k])).collect();
    voxels.world = voxels
        .world
        .apply(&[MapDelta::SetVoxels {
            resolution: 0.1,
            origin: Point3::new(-1.0, -2.0, 0.0),
            cells: wall,
            occupied: true,
        }])
        .unwrap();
    out.push(("voxels", voxels));
    let mut crowded = scenario("example.json");
    let mut deltas = Vec::new();
    for i in 0..40u32 {
        for j in 0..40u32 {
            let (x, y) = (-10.0 + 0.5 * f64::from(i), -10.0 + 0.5 * f64::from(j));
            if x.hypot(y) < 1.2 {
                continue; // keep the rover's footprint clear
            }
            let obstacle = if (i + j) % 2 == 0 {
                Obstacle::Cylinder(VerticalCylinder { center: [x, y].into(), radius: 0.05, height: 3.0 })
            } else {
                Obstacle::Box(AxisBox { min: Point3::new(x, y, 2.0), max: Point3::new(x + 0.05, y + 0.05, 2.1) })
            };
            deltas.push(MapDelta::UpsertObstacle { id: 100 + i * 40 + j, obstacle });
        }
    }
    crowded.world = crowded.world.apply(&deltas).unwrap();
    out.push(("crowded", crowded));
    out
}

/// The committed learned model (tests/data/learned).
fn learned_weights() -> std::sync::Arc<dyfos_shared::sdsmm::Learned> {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/data/learned/model.bin");
    dyfos_service::learned::load_model(&path).unwrap()
}

#[test]
fn lupp_evaluate_allocates_nothing() {
    let grid = Brute { grid: [9, 7, 5, 24] };
    for (name, s) in worlds() {
        for model in [ModelKind::Paper, ModelKind::Anisotropic, ModelKind::Learned] {
            let params = Params { model, ..s.params };
            let noise = NoiseModel::from_params_and_weights(&params, Some(&learned_weights())).unwrap();
            let lupp = Lupp::new(&s.world, &s.belief, &params, &noise);
            let candidates: Vec<SensorState> = (0..grid.len()).map(|i| grid.point(lupp.space(), i)).collect();
            let mut verdicts = [0usize; 4];
            let info = measure(|| {
                for x in &candidates {
                    let slot = match lupp.evaluate(x) {
                        Evaluation::Feasible { .. } => 0,
                        Evaluation::Rejected(Violation::Workspace) => 1,
                        Evaluation::Rejected(Violation::Collision) => 2,
                        Evaluation::Rejected(Violation::Occlusion) => 3,
                    };
                    verdicts[slot] += 1;
                }
            });
            assert_eq!(
                info.count_total,
                0,
                "{name} ({model:?}): {} allocations over {} candidates",
                info.count_total,
                candidates.len()
            );
            // The candidates reach every branch of the pipeline, so the count covers them all.
            assert!(verdicts[0] > 0 && verdicts[2] > 0 && verdicts[3] > 0, "{name}: verdicts {verdicts:?}");
        }
    }
}

#[test]
fn differential_evolution_allocates_per_search_not_per_candidate() {
    let s = scenario("golden/scenarios/numerical/map_00.json");
    let noise = NoiseModel::from_params(&s.params).unwrap();
    let lupp = Lupp::new(&s.world, &s.belief, &s.params, &noise);
    for de in [DifferentialEvolution::dyfos(), DifferentialEvolution::scipy()] {
        let mut evaluations = Vec::new();
        let mut allocations = Vec::new();
        for budget in [60, 200, 5_000] {
            let control = SearchControl { budget: Some(budget), ..SearchControl::seeded(4) };
            let mut outcome = None;
            let info = measure(|| outcome = Some(de.search(&lupp, &control)));
            evaluations.push(outcome.unwrap().stats.total);
            allocations.push(info.count_total);
        }
        assert!(evaluations[2] > 4 * evaluations[0], "{evaluations:?}");
        assert!(allocations.iter().all(|a| *a == allocations[0]), "{de:?}: allocations {allocations:?}");
        assert!(allocations[0] >= 1, "the counter sees the population being allocated");
        assert!(allocations[0] <= 4, "{de:?}: {} allocations per search", allocations[0]);
    }
}
