//! Property tests (proptest, shrinking to the smallest failing input) over what a
//! client controls: request decoding (`RendezvousRequest::decode`,
//! `MapRequest::decode`, `decode_deltas`) and map-delta application
//! (`World::apply`), plus the search on valid but extreme requests.
//!
//! Properties: decoding never panics, whatever the bytes; a non-finite number is
//! always refused; what decodes re-encodes to the same request; a rejected batch
//! leaves the world as it was and names the first delta that fails on its own; an
//! accepted batch raises the version by its length and equals the batch applied in
//! two parts; a map survives the trip through upload chunks; a valid request is
//! answered with a finite cost or `no_feasible_pose`, never a panic.
//!
//! `PROPTEST_CASES=N` runs more cases than the default.

use dyfos_client::prelude::*;
use dyfos_service::search::SearchControl;
use dyfos_shared::wire::ANY_VERSION;
use dyfos_shared::wire::map::{
    MapRequest, MapRequestHeader, WireDelta, decode_deltas, encode_deltas, record_count, world_chunks,
    world_from_content,
};
use dyfos_shared::wire::rendezvous::{Mode, RendezvousRequestHeader, WireParams};
use dyfos_shared::world::{AxisBox, VerticalCylinder};
use dyfos_tests::param_floats_mut;
use proptest::prelude::*;

/// Any f64, weighted towards the values that break things.
fn any_f64() -> impl Strategy<Value = f64> {
    prop_oneof![
        3 => -20.0..20.0f64,
        1 => Just(f64::NAN),
        1 => Just(f64::INFINITY),
        1 => Just(f64::NEG_INFINITY),
        1 => Just(-0.0f64),
        1 => Just(1e-300f64),
        1 => Just(f64::MAX),
        2 => any::<f64>(),
    ]
}

fn any_i64() -> impl Strategy<Value = i64> {
    prop_oneof![3 => -4i64..6, 1 => Just(i64::MIN), 1 => Just(i64::MAX), 1 => any::<i64>()]
}

fn any_record() -> impl Strategy<Value = WireDelta> {
    // Flat vectors rather than nested tuples and arrays: their value trees live on
    // the heap (a deep tree of nested strategies overflows a test thread's stack).
    (prop::collection::vec(0u32..10, 4), prop::collection::vec(any_f64(), 6), prop::collection::vec(any_i64(), 3))
        .prop_map(|(tags, values, cell)| WireDelta {
            tag: tags[0],
            flag: tags[1] % 3,
            id: tags[2] % 8,
            reserved: u32::from(tags[3] == 9),
            values: std::array::from_fn(|i| values[i]),
            cell: std::array::from_fn(|i| cell[i]),
        })
}

fn wire_params(f: &[f64], perimeter_points: u32, model: u32) -> WireParams {
    WireParams {
        rover_radius: f[0],
        marker_size: f[1],
        marker_height: f[2],
        viewer_radius: f[3],
        safety_margin: f[4],
        z_min: f[5],
        z_max: f[6],
        camera_pitch: f[7],
        t_vs: [f[8], f[9], f[10]],
        f_h: f[11],
        f_v: f[12],
        rho_min: f[13],
        rho_max: f[14],
        kappa: f[15],
        lambda: f[16],
        perimeter_points,
        model,
        set: WireParams::ALL_SET,
        reserved: 0,
    }
}

fn any_header() -> impl Strategy<Value = RendezvousRequestHeader> {
    (
        prop::collection::vec(any::<u64>(), 8),
        prop::collection::vec(any_f64(), 29),
        any::<bool>(),
        prop::collection::vec(0u32..7, 4),
    )
        .prop_map(|(n, f, default_params, tags)| {
            let params = if default_params {
                WireParams::from(&Params::default())
            } else {
                wire_params(&f[12..], if tags[3] < 3 { 8 } else { n[7] as u32 }, tags[2] % 4)
            };
            RendezvousRequestHeader {
                request_id: n[0],
                map_id: n[1] % 3,
                expected_version: if n[2] % 2 == 0 { ANY_VERSION } else { n[2] % 3 },
                seed: n[3],
                budget: n[4],
                deadline_micros: n[5] >> (n[5] % 64),
                mean: [f[0], f[1], f[2]],
                cov: [[f[3], f[4], f[5]], [f[6], f[7], f[8]], [f[9], f[10], f[11]]],
                params,
                algorithm: tags[0],
                mode: tags[1] % 3,
                reply_to: [n[6], n[7]],
            }
        })
}

/// A valid delta (for some world): obstacles with ids 1..12 in ±9 m, voxels of one
/// grid, a sun, bounds, clear.
fn valid_delta() -> impl Strategy<Value = MapDelta> {
    prop_oneof![
        4 => (1u32..12, -9.0..9.0f64, -9.0..9.0f64, 0.1..2.0f64, 0.1..6.0f64).prop_map(|(id, x, y, r, h)| {
            MapDelta::UpsertObstacle {
                id,
                obstacle: Obstacle::Cylinder(VerticalCylinder { center: na::Point2::new(x, y), radius: r, height: h }),
            }
        }),
        2 => (1u32..12, -9.0..8.0f64, -9.0..8.0f64, 0.1..1.0f64).prop_map(|(id, x, y, s)| MapDelta::UpsertObstacle {
            id,
            obstacle: Obstacle::Box(AxisBox {
                min: na::Point3::new(x, y, 0.0),
                max: na::Point3::new(x + s, y + s, 2.0 * s),
            }),
        }),
        2 => (1u32..12).prop_map(|id| MapDelta::RemoveObstacle { id }),
        2 => (prop::collection::vec([0i64..20, 0i64..20, 0i64..6], 1..6), any::<bool>()).prop_map(|(cells, occupied)| {
            MapDelta::SetVoxels { resolution: 0.5, origin: na::Point3::new(-5.0, -5.0, 0.0), cells, occupied }
        }),
        1 => (-1.5..1.5f64, -3.0..3.0f64).prop_map(|(e, a)| MapDelta::SetSun(Sun::new(e, a).unwrap())),
        1 => (-20.0..-1.0f64, 1.0..20.0f64).prop_map(|(lo, hi)| MapDelta::SetBounds(Bounds::new([lo, lo, hi, hi]).unwrap())),
        1 => Just(MapDelta::Clear),
    ]
}

/// Deltas that may be invalid anywhere: bad numbers, a different voxel grid,
/// extreme cell indices, impossible suns and bounds.
fn any_delta() -> impl Strategy<Value = MapDelta> {
    prop_oneof![
        6 => valid_delta(),
        1 => (1u32..12, any_f64(), any_f64(), any_f64(), any_f64()).prop_map(|(id, x, y, r, h)| {
            MapDelta::UpsertObstacle {
                id,
                obstacle: Obstacle::Cylinder(VerticalCylinder { center: na::Point2::new(x, y), radius: r, height: h }),
            }
        }),
        1 => (any_f64(), prop::array::uniform3(any_f64()), prop::collection::vec([any_i64(), any_i64(), any_i64()], 0..4), any::<bool>())
            .prop_map(|(resolution, o, cells, occupied)| MapDelta::SetVoxels {
                resolution,
                origin: na::Point3::from(o),
                cells,
                occupied,
            }),
        1 => (any_f64(), any_f64()).prop_map(|(elevation, azimuth)| MapDelta::SetSun(Sun { elevation, azimuth })),
        1 => prop::array::uniform4(any_f64()).prop_map(|b| MapDelta::SetBounds(Bounds {
            min: na::Point2::new(b[0], b[1]),
            max: na::Point2::new(b[2], b[3]),
        })),
    ]
}

fn base_world() -> World {
    World::empty(Bounds::new([-10.0, -10.0, 10.0, 10.0]).unwrap(), Sun::new(0.5, 1.0).unwrap())
}

/// A world reached by valid deltas.
fn any_world() -> impl Strategy<Value = World> {
    prop::collection::vec(valid_delta(), 0..12)
        .prop_map(|deltas| deltas.iter().fold(base_world(), |w, d| w.apply(std::slice::from_ref(d)).unwrap_or(w)))
}

/// A valid belief: mean in the map, covariance L·Lᵀ + εI.
fn any_belief() -> impl Strategy<Value = Belief> {
    ([-9.0..9.0f64, -9.0..9.0f64, -3.0..3.0f64], prop::array::uniform6(-0.6..0.6f64), 1e-4..0.1f64).prop_map(
        |(mean, l, eps)| {
            let l = na::Matrix3::new(l[0], 0.0, 0.0, l[1], l[2], 0.0, l[3], l[4], l[5]);
            let cov = l * l.transpose() + na::Matrix3::identity() * eps;
            let rows = std::array::from_fn(|r| std::array::from_fn(|c| (cov[(r, c)] + cov[(c, r)]) / 2.0));
            Belief::new(mean, rows).expect("L·Lᵀ + εI is SPD")
        },
    )
}

proptest! {
    #![proptest_config(ProptestConfig::default())]

    #[test]
    fn rendezvous_decode_never_panics_refuses_non_finite_numbers_and_round_trips(
        header in any_header(),
        records in prop::collection::vec(any_record(), 0..6),
    ) {
        match dyfos_shared::wire::rendezvous::RendezvousRequest::decode(&header, &records) {
            Ok((request, mode)) => {
                let numbers = header.mean.iter().chain(header.cov.iter().flatten()).copied()
                    .chain(param_floats_mut(&mut { header.params }).map(|f| *f));
                prop_assert!(numbers.into_iter().all(f64::is_finite), "accepted a non-finite number");
                prop_assert!(header.mode <= 1 && header.algorithm < 5);
                let again = request.header(mode, header.request_id, header.reply_to);
                let decoded = dyfos_shared::wire::rendezvous::RendezvousRequest::decode(&again, &request.records());
                // Debug text: inline deltas may carry a NaN (refused when applied).
                prop_assert_eq!(format!("{decoded:?}"), format!("{:?}", Ok::<_, ()>((request, mode))));
            }
            Err(rejection) => {
                prop_assert!(rejection.status != Status::Ok);
                prop_assert!(!rejection.message.is_empty());
            }
        }
    }

    #[test]
    fn valid_rendezvous_requests_round_trip(
        belief in any_belief(),
        deltas in prop::collection::vec(valid_delta(), 0..5),
        algorithm in 0usize..5,
        (seed, budget, deadline_ms) in (any::<u64>(), prop::option::of(1u64..1_000_000), prop::option::of(1u64..3_600_000)),
        expected_version in prop::option::of(0u64..1000),
        check in any::<bool>(),
    ) {
        let request = RendezvousRequest {
            expected_version,
            deltas,
            algorithm: Algorithm::ALL[algorithm],
            seed,
            budget,
            deadline: deadline_ms.map(std::time::Duration::from_millis),
            ..RendezvousRequest::new(7, belief)
        };
        let mode = if check { Mode::Check } else { Mode::Solve };
        let header = request.header(mode, 3, [1, 2]);
        let decoded = dyfos_shared::wire::rendezvous::RendezvousRequest::decode(&header, &request.records());
        prop_assert_eq!(decoded, Ok((request, mode)));
    }

    #[test]
    fn map_request_decode_never_panics_and_round_trips(
        (op, flags, map_id, expected_version, upload_id, chunk_index, chunk_count) in
            (0u32..7, 0u32..3, 0u64..4, prop_oneof![Just(ANY_VERSION), 0u64..4], any::<u64>(), 0u32..4, 0u32..5),
        bounds in prop::array::uniform4(any_f64()),
        sun in prop::array::uniform2(any_f64()),
        records in prop::collection::vec(any_record(), 0..8),
    ) {
        let header = MapRequestHeader {
            op, flags, map_id, expected_version, request_id: 5, upload_id, chunk_index, chunk_count, bounds, sun,
            reply_to: [0, 0],
        };
        if let Ok(request) = MapRequest::decode(&header, &records) {
            let again = request.header(5, [0, 0]);
            // Debug text: a NaN (refused later, when applied) is not equal to itself.
            let text = |r: &MapRequest| format!("{r:?}");
            prop_assert_eq!(MapRequest::decode(&again, &request.records()).map(|r| text(&r)), Ok(text(&request)));
        }
    }

    #[test]
    fn deltas_round_trip_through_records(deltas in prop::collection::vec(any_delta(), 0..8)) {
        let records = encode_deltas(&deltas);
        prop_assert_eq!(records.len(), deltas.iter().map(record_count).sum::<usize>());
        let decoded = decode_deltas(&records).expect("encoded deltas decode");
        // Bit-level equality: NaN != NaN, so compare the records they make.
        prop_assert_eq!(format!("{:?}", encode_deltas(&decoded)), format!("{:?}", records));
    }

    #[test]
    fn decode_deltas_never_panics_and_names_a_record_in_the_batch(
        records in prop::collection::vec(any_record(), 0..10),
    ) {
        match decode_deltas(&records) {
            Ok(deltas) => prop_assert_eq!(deltas.iter().map(record_count).sum::<usize>(), records.len()),
            Err(e) => prop_assert!(e.index.is_some_and(|i| (i as usize) < records.len().max(1)), "{e:?}"),
        }
    }

    #[test]
    fn world_apply_is_atomic_and_counts_versions(
        world in any_world(),
        batch in prop::collection::vec(any_delta(), 0..8),
        split in 0usize..8,
    ) {
        let before = world.clone();
        match world.apply(&batch) {
            Ok(next) => {
                prop_assert_eq!(next.version(), world.version() + batch.len() as u64);
                let split = split.min(batch.len());
                let in_two = world.apply(&batch[..split]).and_then(|w| w.apply(&batch[split..]));
                prop_assert_eq!(in_two.as_ref(), Ok(&next));
                let chunks = world_chunks(&next);
                let content: Vec<MapDelta> = chunks.iter().flat_map(|c| decode_deltas(c).unwrap()).collect();
                let rebuilt = world_from_content(next.version(), *next.bounds(), *next.sun(), &content);
                prop_assert_eq!(rebuilt.as_ref(), Ok(&next));
            }
            Err(e) => {
                prop_assert!(e.index < batch.len());
                let prefix = world.apply(&batch[..e.index]);
                prop_assert!(prefix.is_ok(), "the deltas before #{} apply", e.index);
                let failing = prefix.unwrap().apply(&batch[e.index..=e.index]);
                // Debug text: a NaN in the error is not equal to itself.
                let kind = |k: &dyfos_shared::world::MapDeltaErrorKind| format!("{k:?}");
                prop_assert_eq!(failing.map(|_| ()).map_err(|f| kind(&f.kind)), Err(kind(&e.kind)));
            }
        }
        prop_assert_eq!(world, before, "apply changed the world it was called on");
    }

    #[test]
    fn valid_extreme_requests_get_a_finite_answer_or_no_feasible_pose(
        world in any_world(),
        belief in any_belief(),
        algorithm in 0usize..5,
        seed in any::<u64>(),
        budget in 1u64..300,
        scale in prop_oneof![Just(1.0f64), 1e-6..1e-3f64, 10.0..1e3f64],
        (kappa, lambda, perimeter_points) in (prop_oneof![Just(1.0f64), 1e-3..1e3f64], 0.0..100.0f64, 0u32..64),
        model in prop_oneof![Just(ModelKind::Paper), Just(ModelKind::Anisotropic)],
    ) {
        let d = Params::default();
        let params = Params {
            rover_radius: d.rover_radius * scale,
            marker_size: d.marker_size * scale,
            viewer_radius: d.viewer_radius * scale,
            safety_margin: d.safety_margin * scale,
            rho_min: d.rho_min * scale,
            rho_max: d.rho_max * scale,
            z_max: d.z_max * scale.max(1.0),
            kappa,
            lambda,
            perimeter_points,
            model,
            ..d
        };
        prop_assume!(params.validate().is_ok());
        let noise = NoiseModel::from_params(&params).expect("paper or anisotropic");
        let control = SearchControl { budget: Some(budget), threads: 2, ..SearchControl::seeded(seed) };
        match dyfos_service::solve(&world, &belief, &params, &noise, Algorithm::ALL[algorithm], &control) {
            Ok(answer) => {
                prop_assert!(answer.cost.is_finite(), "cost {}", answer.cost);
                prop_assert!(answer.evaluations.total <= budget);
                prop_assert!(answer.posterior.iter().all(|v| v.is_finite()));
            }
            Err(dyfos_service::SearchError::NoFeasiblePose { .. }) => {}
        }
    }
}
