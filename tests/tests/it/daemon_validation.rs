//! Every kind of bad request gets its own code, and the map is left as it was.
//! Requests are sent raw, as a buggy or hostile client in another language could.

use dyfos_client::prelude::*;
use dyfos_shared::limits::{MAX_DELTAS_PER_MESSAGE, MAX_INLINE_DELTAS, MAX_UPLOAD_CHUNKS};
use dyfos_shared::wire::Rejection;
use dyfos_shared::wire::map::{MapReplyHeader, MapRequest, MapRequestHeader, WireDelta, encode_deltas, tag};
use dyfos_shared::wire::rendezvous::{Mode, RendezvousRequestHeader, WireParams};
use dyfos_shared::world::{AxisBox, VerticalCylinder};
use dyfos_tests::{PATIENCE, RawFixture, Sandbox, create_test_map};

fn pole(x: f64) -> Obstacle {
    Obstacle::Cylinder(VerticalCylinder { center: na::Point2::new(x, 1.0), radius: 0.5, height: 10.0 })
}

fn rejection(h: &MapReplyHeader) -> Rejection {
    Rejection::from_wire(h.status, &h.detail, h.error_index)
}

/// A daemon with map 1 (two obstacles, version 2), a client, a raw client, and
/// the map as it is before any bad request.
struct Fixture {
    io: RawFixture,
    bounds: Bounds,
    before: World,
}

impl Fixture {
    fn new(name: &str) -> Fixture {
        let mut io = RawFixture::new(name);
        let crate_ =
            Obstacle::Box(AxisBox { min: na::Point3::new(4.0, 4.0, 0.0), max: na::Point3::new(5.0, 6.0, 3.0) });
        let (bounds, before) = io.test_map_with(
            1,
            &[
                MapDelta::UpsertObstacle { id: 1, obstacle: pole(2.0) },
                MapDelta::UpsertObstacle { id: 2, obstacle: crate_ },
            ],
        );
        Fixture { io, bounds, before }
    }

    /// Fails, naming the case, if the map changed.
    fn assert_unchanged(&mut self, what: &str) {
        assert_eq!(self.io.client.snapshot(1, PATIENCE).unwrap(), self.before, "{what} changed the map");
    }

    /// How many errors with `status` the daemon counted.
    fn errors(&mut self, status: Status) -> u64 {
        let stats = self.io.client.stats(PATIENCE).unwrap();
        stats.errors.iter().find(|(c, _)| *c == status).map_or(0, |(_, n)| *n)
    }
}

fn belief() -> Belief {
    Belief::new([0.0, 0.0, 0.3], [[0.2, 0.05, 0.0], [0.05, 0.1, 0.0], [0.0, 0.0, 0.05]]).unwrap()
}

/// Delta records every service must refuse, by name.
fn bad_records() -> (Vec<WireDelta>, Vec<WireDelta>, Vec<WireDelta>) {
    let remove_unknown = encode_deltas(&[MapDelta::RemoveObstacle { id: 1 }, MapDelta::RemoveObstacle { id: 99 }]);
    let nan_pole = encode_deltas(&[MapDelta::UpsertObstacle { id: 3, obstacle: pole(f64::NAN) }]);
    let truncated_run = vec![WireDelta {
        tag: tag::VOXEL_RUN,
        flag: 1,
        values: [0.5, 0.0, 0.0, 0.0, 0.0, 0.0],
        cell: [3, 0, 0],
        ..Default::default()
    }];
    (remove_unknown, nan_pole, truncated_run)
}

#[test]
fn every_bad_rendezvous_request_gets_its_code_and_leaves_the_map_unchanged() {
    let mut f = Fixture::new("bad-rendezvous");
    let raw = &f.io.raw;
    let good = RendezvousRequest { expected_version: Some(2), ..RendezvousRequest::new(1, belief()) };
    let h = good.header(Mode::Solve, 1, [0, 0]);
    assert_eq!(raw.rendezvous(h, &[]).status, Status::Ok as u32, "the unmodified request is fine");
    let params = |f: fn(&mut WireParams)| {
        let mut p = h.params;
        f(&mut p);
        RendezvousRequestHeader { params: p, ..h }
    };
    let with_cov = |f: fn(&mut [[f64; 3]; 3])| {
        let mut c = h.cov;
        f(&mut c);
        RendezvousRequestHeader { cov: c, ..h }
    };
    let (remove_unknown, nan_pole, truncated_run) = bad_records();
    let bad_tag = vec![WireDelta { tag: 42, ..Default::default() }];
    let too_many = vec![WireDelta { tag: tag::CLEAR, ..Default::default() }; MAX_INLINE_DELTAS + 1];
    let cases: Vec<(&str, RendezvousRequestHeader, Vec<WireDelta>, Status)> = vec![
        ("mode", RendezvousRequestHeader { mode: 9, ..h }, vec![], Status::MalformedRequest),
        ("algorithm", RendezvousRequestHeader { algorithm: 5, ..h }, vec![], Status::InvalidAlgorithm),
        ("NaN mean", RendezvousRequestHeader { mean: [f64::NAN, 0.0, 0.0], ..h }, vec![], Status::InvalidBelief),
        ("inf mean", RendezvousRequestHeader { mean: [0.0, f64::INFINITY, 0.0], ..h }, vec![], Status::InvalidBelief),
        ("asymmetric", with_cov(|c| c[0][1] = 0.07), vec![], Status::InvalidBelief),
        ("not SPD", with_cov(|c| c[2][2] = -0.05), vec![], Status::InvalidBelief),
        ("NaN cov", with_cov(|c| c[2][2] = f64::NAN), vec![], Status::InvalidBelief),
        ("rho_min", params(|p| p.rho_min = 9.0), vec![], Status::InvalidParams),
        ("f_h", params(|p| p.f_h = 4.0), vec![], Status::InvalidParams),
        ("kappa NaN", params(|p| p.kappa = f64::NAN), vec![], Status::InvalidParams),
        ("perimeter", params(|p| p.perimeter_points = 5000), vec![], Status::InvalidParams),
        ("model tag", params(|p| p.model = 7), vec![], Status::InvalidParams),
        ("learned", params(|p| p.model = 2), vec![], Status::UnsupportedModel),
        ("deadline", RendezvousRequestHeader { deadline_micros: u64::MAX, ..h }, vec![], Status::InvalidDeadline),
        ("unknown map", RendezvousRequestHeader { map_id: 9, ..h }, vec![], Status::UnknownMap),
        ("version", RendezvousRequestHeader { expected_version: 1, ..h }, vec![], Status::MapVersionMismatch),
        ("delta tag", h, bad_tag, Status::MalformedDelta),
        ("truncated run", h, truncated_run.clone(), Status::MalformedDelta),
        ("remove unknown", h, remove_unknown.clone(), Status::InvalidDelta),
        ("NaN obstacle", h, nan_pole.clone(), Status::InvalidDelta),
        ("too many deltas", h, too_many, Status::OverCapacity),
    ];
    for (what, header, records, expected) in cases {
        let reply = f.io.raw.rendezvous(header, &records);
        let got = Status::try_from(reply.status).unwrap();
        assert_eq!(got, expected, "{what}: {}", reply.detail.text());
        assert!(!reply.detail.text().is_empty(), "{what}: an error says why");
        f.assert_unchanged(what);
    }
    // A delta error names the failing delta.
    let reply = f.io.raw.rendezvous(h, &remove_unknown);
    assert_eq!(reply.error_index, 1);
    assert!(reply.detail.text().contains("no obstacle with id 99"), "{}", reply.detail.text());
    // The daemon counted every error by its code and is still serving.
    assert_eq!(f.errors(Status::InvalidBelief), 5);
    assert_eq!(f.io.client.check(&RendezvousRequest::new(1, belief()), PATIENCE).unwrap().map_version, 2);
}

/// `upload(id, index, count)`: chunk `index` of `count` of upload `id` of map 1,
/// replacing it with one pole (id 9).
fn upload(bounds: Bounds, id: u64, index: u32, count: u32) -> MapRequestHeader {
    MapRequest::Upload {
        map: 1,
        upload_id: id,
        chunk_index: index,
        chunk_count: count,
        replace: true,
        expected_version: None,
        bounds,
        sun: Sun::new(0.1, 0.0).unwrap(),
        deltas: vec![MapDelta::UpsertObstacle { id: 9, obstacle: pole(-3.0) }],
    }
    .header(2, [0, 0])
}

fn one_pole() -> Vec<WireDelta> {
    encode_deltas(&[MapDelta::UpsertObstacle { id: 9, obstacle: pole(-3.0) }])
}

#[test]
fn every_bad_map_request_gets_its_code_and_leaves_the_map_unchanged() {
    let mut f = Fixture::new("bad-map");
    let bounds = f.bounds;
    let (remove_unknown, nan_pole, truncated_run) = bad_records();
    let apply = MapRequest::Apply { map: 1, expected_version: Some(2), deltas: vec![] }.header(1, [0, 0]);
    let upload = |id, index, count| upload(bounds, id, index, count);
    let one_pole = one_pole();
    let over = vec![WireDelta { tag: tag::CLEAR, ..Default::default() }; MAX_DELTAS_PER_MESSAGE + 1];
    let create = MapRequest::Create { map: 1, bounds, sun: Sun::new(0.1, 0.0).unwrap() }.header(3, [0, 0]);
    let map_cases: Vec<(&str, MapRequestHeader, Vec<WireDelta>, Status)> = vec![
        ("op", MapRequestHeader { op: 77, ..apply }, vec![], Status::MalformedRequest),
        ("flags", MapRequestHeader { flags: 4, ..apply }, vec![], Status::MalformedRequest),
        ("create existing", create, vec![], Status::MapExists),
        (
            "create NaN bounds",
            MapRequestHeader { map_id: 2, bounds: [0.0, 0.0, f64::NAN, 1.0], ..create },
            vec![],
            Status::InvalidDelta,
        ),
        ("apply unknown map", MapRequestHeader { map_id: 5, ..apply }, one_pole.clone(), Status::UnknownMap),
        (
            "apply old version",
            MapRequestHeader { expected_version: 0, ..apply },
            one_pole.clone(),
            Status::MapVersionMismatch,
        ),
        ("apply remove unknown", apply, remove_unknown, Status::InvalidDelta),
        ("apply NaN", apply, nan_pole, Status::InvalidDelta),
        ("apply truncated run", apply, truncated_run, Status::MalformedDelta),
        ("apply too many", apply, over, Status::OverCapacity),
        ("chunk count 0", upload(5, 0, 0), one_pole.clone(), Status::OverCapacity),
        ("chunk count huge", upload(5, 0, MAX_UPLOAD_CHUNKS + 1), one_pole.clone(), Status::OverCapacity),
        ("chunk past count", upload(5, 3, 3), one_pole.clone(), Status::ChunkOutOfOrder),
        ("first chunk missing", upload(5, 1, 3), one_pole.clone(), Status::ChunkOutOfOrder),
        ("upload clear", upload(5, 0, 3), encode_deltas(&[MapDelta::Clear]), Status::MalformedDelta),
        ("snapshot page", MapRequest::Snapshot { map: 1, page: 5 }.header(4, [0, 0]), vec![], Status::ChunkOutOfOrder),
        ("snapshot unknown", MapRequest::Snapshot { map: 8, page: 0 }.header(4, [0, 0]), vec![], Status::UnknownMap),
        (
            "delete version",
            MapRequest::Delete { map: 1, expected_version: Some(7) }.header(5, [0, 0]),
            vec![],
            Status::MapVersionMismatch,
        ),
        (
            "delete unknown",
            MapRequest::Delete { map: 6, expected_version: None }.header(5, [0, 0]),
            vec![],
            Status::UnknownMap,
        ),
    ];
    for (what, header, records, expected) in map_cases {
        let (reply, _) = f.io.raw.map(header, &records);
        let r = rejection(&reply);
        assert_eq!(Status::try_from(reply.status).unwrap(), expected, "{what}: {r}");
        assert!(!r.message.is_empty(), "{what}");
        f.assert_unchanged(what);
    }
}

/// Chunk sequences: duplicated, out of order, abandoned (incomplete), then a
/// completed upload replacing the map whole.
#[test]
fn upload_chunks_out_of_sequence_are_refused_and_only_a_complete_upload_changes_the_map() {
    let mut f = Fixture::new("bad-chunks");
    let (bounds, one_pole) = (f.bounds, one_pole());
    let upload = |id, index, count| upload(bounds, id, index, count);
    let raw = &f.io.raw;
    let status = |h: MapRequestHeader| Status::try_from(raw.map(h, &one_pole).0.status).unwrap();
    assert_eq!(status(upload(10, 0, 3)), Status::Ok);
    assert_eq!(status(upload(10, 0, 3)), Status::ChunkDuplicate);
    assert_eq!(status(upload(10, 2, 3)), Status::ChunkOutOfOrder);
    assert_eq!(status(MapRequestHeader { chunk_count: 4, ..upload(10, 1, 3) }), Status::MalformedRequest);
    assert_eq!(status(upload(10, 1, 3)), Status::Ok);
    // A new upload of the same map supersedes it: its remaining chunk is refused.
    assert_eq!(status(upload(11, 0, 2)), Status::Ok);
    assert_eq!(status(upload(10, 2, 3)), Status::ChunkIncomplete);
    f.assert_unchanged("an incomplete upload");
    // Completing the new one replaces the map whole, as one change.
    let raw = &f.io.raw;
    assert_eq!(Status::try_from(raw.map(upload(11, 1, 2), &one_pole).0.status).unwrap(), Status::Ok);
    let replaced = f.io.client.snapshot(1, PATIENCE).unwrap();
    assert_eq!(replaced.version(), f.before.version() + 1);
    assert_eq!(replaced.obstacles().keys().copied().collect::<Vec<_>>(), vec![9]);
    assert_eq!(f.errors(Status::ChunkIncomplete), 1);
    let check = f.io.client.check(&RendezvousRequest::new(1, belief()), PATIENCE).unwrap();
    assert_eq!(check.map_version, replaced.version());
}

#[test]
fn the_client_refuses_what_it_cannot_send() {
    let (sandbox, _daemon) = Sandbox::with_daemon("local");
    let mut client = sandbox.client();
    let bounds = create_test_map(&mut client, 1);
    let deltas = vec![MapDelta::Clear; MAX_DELTAS_PER_MESSAGE + 1];
    let err = client.apply(1, None, &deltas, PATIENCE).unwrap_err();
    assert_eq!(err.status(), Some(Status::OverCapacity), "{err}");
    let belief = Belief::new([0.0, 0.0, 0.3], [[0.2, 0.05, 0.0], [0.05, 0.1, 0.0], [0.0, 0.0, 0.05]]).unwrap();
    let zero_budget = RendezvousRequest { budget: Some(0), ..RendezvousRequest::new(1, belief) };
    let err = client.rendezvous(&zero_budget, PATIENCE).unwrap_err();
    assert!(matches!(err, RendezvousError::Invalid(_)), "{err}");
    let err = client.create_map(1, bounds, Sun::new(0.7, 2.1).unwrap(), PATIENCE).unwrap_err();
    assert_eq!(err.status(), Some(Status::MapExists));
    assert!(!err.is_retryable());
    assert!(err.to_string().contains("map 1 exists"), "{err}");
}
