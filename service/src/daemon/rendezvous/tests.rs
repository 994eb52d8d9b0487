//! [`accept`], the admission of a rendezvous request, over a [`State`] without
//! ports: each refusal gets its status and changes nothing; a check tries its
//! inline deltas on a copy, a query to solve commits them.

use super::{Accepted, accept};
use crate::daemon::state::Scratch;
use dyfos_shared::params::ModelKind;
use dyfos_shared::posterior::Belief;
use dyfos_shared::wire::Status;
use dyfos_shared::wire::rendezvous::{Mode, RendezvousRequest};
use dyfos_shared::world::{Bounds, MapDelta, Obstacle, Sun, VerticalCylinder, World};

/// Map 1 at version 2 (two pillars).
fn scratch(name: &str) -> Scratch {
    let world = World::empty(Bounds::new([-10.0, -10.0, 10.0, 10.0]).unwrap(), Sun::new(0.5, 0.0).unwrap())
        .apply(&[pillar(1), pillar(2)])
        .unwrap();
    Scratch::new(name, [(1, world)])
}

fn pillar(id: u32) -> MapDelta {
    let center = nalgebra::Point2::new(f64::from(id) * 3.0, 4.0);
    MapDelta::UpsertObstacle { id, obstacle: Obstacle::Cylinder(VerticalCylinder { center, radius: 0.3, height: 2.0 }) }
}

fn request() -> RendezvousRequest {
    let belief = Belief::new([0.0, 0.0, 0.3], [[0.2, 0.05, 0.0], [0.05, 0.1, 0.0], [0.0, 0.0, 0.05]]).unwrap();
    RendezvousRequest::new(1, belief)
}

/// `accept` of `request` in `mode`: the outcome, as the map's version it would
/// search, or the refusal's status.
fn admit(s: &mut Scratch, request: &RendezvousRequest, mode: Mode) -> Result<u64, Status> {
    match accept(&mut s.state, &request.header(mode, 1, [0, 0]), &request.records()) {
        Ok(Accepted::Checked(version, recorded)) => {
            assert!(mode == Mode::Check && recorded.is_none(), "no recorder: nothing kept to record");
            Ok(version)
        }
        Ok(Accepted::Queued(queued, world)) => {
            assert_eq!(mode, Mode::Solve);
            assert_eq!(format!("{queued:?}"), format!("{request:?}"), "the job is the request as sent");
            Ok(world.version())
        }
        Err(rejection) => {
            assert!(!rejection.message.is_empty(), "{:?}: a refusal says why", rejection.status);
            Err(rejection.status)
        }
    }
}

fn map_version(s: &Scratch) -> u64 {
    s.state.maps.get(1).expect("map 1").version()
}

/// Every refusal of `accept`, by name: its status, and map 1 unchanged.
#[test]
fn each_refusal_has_its_status_and_changes_nothing() {
    let with_delta = RendezvousRequest { deltas: vec![pillar(3)], ..request() };
    let cases: [(&str, RendezvousRequest, Mode, Status); 6] = [
        ("unknown map", RendezvousRequest { map: 9, ..with_delta.clone() }, Mode::Solve, Status::UnknownMap),
        (
            "stale version",
            RendezvousRequest { expected_version: Some(1), ..with_delta.clone() },
            Mode::Solve,
            Status::MapVersionMismatch,
        ),
        (
            "learned model, no weights",
            RendezvousRequest {
                params: dyfos_shared::params::Params { model: ModelKind::Learned, ..Default::default() },
                ..with_delta.clone()
            },
            Mode::Check,
            Status::UnsupportedModel,
        ),
        (
            "removing an obstacle that is not there",
            RendezvousRequest { deltas: vec![pillar(3), MapDelta::RemoveObstacle { id: 99 }], ..request() },
            Mode::Solve,
            Status::InvalidDelta,
        ),
        (
            "the same in check mode",
            RendezvousRequest { deltas: vec![MapDelta::RemoveObstacle { id: 99 }], ..request() },
            Mode::Check,
            Status::InvalidDelta,
        ),
        ("a valid request while closing", with_delta.clone(), Mode::Solve, Status::ShuttingDown),
    ];
    for (case, request, mode, status) in cases {
        let mut s = scratch("rv-refusals");
        s.state.closing = case.ends_with("while closing");
        assert_eq!(admit(&mut s, &request, mode), Err(status), "{case}");
        assert_eq!(map_version(&s), 2, "{case}: the map changed");
    }
}

#[test]
fn a_header_the_decoder_refuses_is_refused_with_its_status() {
    let mut s = scratch("rv-decode");
    let request = RendezvousRequest { deltas: vec![pillar(3)], ..request() };
    let mut header = request.header(Mode::Solve, 1, [0, 0]);
    header.mode = 9;
    let refused = accept(&mut s.state, &header, &request.records()).err().expect("refused");
    assert_eq!(refused.status, Status::MalformedRequest);
    assert_eq!(map_version(&s), 2);
}

#[test]
fn a_full_queue_refuses_queries_to_solve_not_checks() {
    let mut s = scratch("rv-busy");
    s.state.max_queued = 0;
    let request = RendezvousRequest { deltas: vec![pillar(3)], ..request() };
    assert_eq!(admit(&mut s, &request, Mode::Solve), Err(Status::Busy));
    assert_eq!(map_version(&s), 2, "a busy refusal commits no inline delta");
    assert_eq!(admit(&mut s, &request, Mode::Check), Ok(3), "a check never waits for a worker");
}

#[test]
fn a_check_tries_its_deltas_on_a_copy_and_a_query_commits_them() {
    let mut s = scratch("rv-deltas");
    let request = RendezvousRequest { expected_version: Some(2), deltas: vec![pillar(3), pillar(4)], ..request() };
    assert_eq!(admit(&mut s, &request, Mode::Check), Ok(4), "searched after its two deltas");
    assert_eq!(map_version(&s), 2, "a check changes no map");
    assert_eq!(admit(&mut s, &request, Mode::Solve), Ok(4));
    assert_eq!(map_version(&s), 4, "a query to solve commits its deltas before it is queued");
    assert_eq!(s.state.maps.get(1).unwrap().obstacles().len(), 4);
    // The same request again: the map moved on, so its expected version is stale.
    assert_eq!(admit(&mut s, &request, Mode::Solve), Err(Status::MapVersionMismatch));
    assert_eq!(map_version(&s), 4);
    // Without deltas, the map's own version.
    assert_eq!(admit(&mut s, &self::request(), Mode::Solve), Ok(4));
}
