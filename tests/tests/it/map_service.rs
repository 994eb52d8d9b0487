//! The map service's behaviour as `docs/wire.md` §9 states it, through raw wire
//! messages: uploads against deletes, where an upload's content errors are
//! reported, what a batch may carry, and the order of the checks.

use dyfos_client::prelude::*;
use dyfos_shared::wire::map::{MapReplyHeader, MapRequest, MapRequestHeader, WireDelta, encode_deltas, tag};
use dyfos_shared::wire::rendezvous::Mode;
use dyfos_shared::world::{VerticalCylinder, VoxelBlock};
use dyfos_tests::{PATIENCE, RawFixture, Sandbox, create_test_map};

fn pole(id: u32, x: f64) -> MapDelta {
    MapDelta::UpsertObstacle {
        id,
        obstacle: Obstacle::Cylinder(VerticalCylinder { center: na::Point2::new(x, 1.0), radius: 0.5, height: 10.0 }),
    }
}

fn bounds() -> Bounds {
    Bounds::new([-10.0, -10.0, 10.0, 10.0]).unwrap()
}

fn sun() -> Sun {
    Sun::new(0.7, 2.1).unwrap()
}

fn status(reply: &MapReplyHeader) -> Status {
    Status::try_from(reply.status).unwrap()
}

/// The header of chunk `index` of `count` of upload `upload_id` of `map`.
fn chunk(map: MapId, upload_id: u64, index: u32, count: u32, expected_version: Option<u64>) -> MapRequestHeader {
    MapRequest::Upload {
        map,
        upload_id,
        chunk_index: index,
        chunk_count: count,
        replace: true,
        expected_version,
        bounds: bounds(),
        sun: sun(),
        deltas: vec![],
    }
    .header(u64::from(index), [0, 0])
}

/// Regression: a delete did not touch an upload of the map in progress, so the
/// upload's last chunk made the deleted map again.
#[test]
fn deleting_a_map_abandons_its_upload_in_progress() {
    let RawFixture { sandbox: _sandbox, daemon: _daemon, mut client, raw } = RawFixture::new("delup");
    create_test_map(&mut client, 1);
    let (reply, _) = raw.map(chunk(1, 7, 0, 2, None), &encode_deltas(&[pole(1, 1.0)]));
    assert_eq!(status(&reply), Status::Ok);
    client.delete_map(1, None, PATIENCE).unwrap();
    let (reply, _) = raw.map(chunk(1, 7, 1, 2, None), &encode_deltas(&[pole(2, 3.0)]));
    assert_eq!(status(&reply), Status::ChunkIncomplete, "{}", reply.detail.text());
    assert!(reply.detail.text().contains("start again from chunk 0"), "{}", reply.detail.text());
    let err = client.snapshot(1, PATIENCE).unwrap_err();
    assert_eq!(err.status(), Some(Status::UnknownMap), "the deleted map came back: {err}");
    // Uploading again from chunk 0 works as for any new map.
    client.upload_map(1, &World::empty(bounds(), sun()), false, PATIENCE).unwrap();
}

/// An upload's content is checked when its last chunk arrives; the error names the
/// chunk and the delta within it, not an index into a batch the reply is not about.
#[test]
fn an_uploads_bad_content_is_named_by_chunk_at_the_last_chunk() {
    let RawFixture { sandbox: _sandbox, daemon: _daemon, mut client, raw } = RawFixture::new("upbad");
    let bad = MapDelta::UpsertObstacle {
        id: 9,
        obstacle: Obstacle::Cylinder(VerticalCylinder { center: na::Point2::new(0.0, 0.0), radius: -1.0, height: 2.0 }),
    };
    let chunks = [vec![pole(1, 1.0), pole(2, 2.0)], vec![pole(3, 3.0), bad], vec![pole(4, 4.0)]];
    let mut replies = Vec::new();
    for (i, deltas) in chunks.iter().enumerate() {
        replies.push(raw.map(chunk(5, 3, i as u32, 3, None), &encode_deltas(deltas)).0);
    }
    assert_eq!(replies[..2].iter().map(status).collect::<Vec<_>>(), [Status::Ok, Status::Ok]);
    let last = &replies[2];
    assert_eq!(status(last), Status::InvalidDelta, "{}", last.detail.text());
    assert_eq!(last.error_index, u64::MAX, "the bad delta is not in the last chunk's records");
    assert!(last.detail.text().contains("chunk 1, delta #1"), "{}", last.detail.text());
    assert!(last.detail.text().contains("radius"), "{}", last.detail.text());
    assert_eq!(client.snapshot(5, PATIENCE).unwrap_err().status(), Some(Status::UnknownMap));
}

/// The content of an upload is a set: upserts and voxel runs (cells and blocks)
/// may come in any order, within and across chunks, and make the same map.
#[test]
fn an_uploads_content_may_come_in_any_order() {
    let RawFixture { sandbox: _sandbox, daemon: _daemon, mut client, raw } = RawFixture::new("uporder");
    let origin = na::Point3::new(-1.0, -1.0, 0.0);
    let cells = |c: Vec<[i64; 3]>| MapDelta::SetVoxels { resolution: 0.25, origin, cells: c, occupied: true };
    let blocks = |b: Vec<VoxelBlock>| MapDelta::SetVoxelBlocks { resolution: 0.25, origin, blocks: b, occupied: true };
    let chunks = [
        vec![cells(vec![[1, 2, 3]]), pole(1, 1.0), blocks(vec![VoxelBlock { min: [8, 0, 4], mask: 0b1011 }])],
        vec![pole(2, -2.0), cells(vec![[40, 2, 0], [1, 2, 3]]), pole(1, 5.0)],
        vec![blocks(vec![VoxelBlock { min: [-4, -8, 0], mask: 1 << 63 }]), pole(3, 0.0)],
    ];
    for (i, deltas) in chunks.iter().enumerate() {
        let (reply, _) = raw.map(chunk(2, 11, i as u32, 3, None), &encode_deltas(deltas));
        assert_eq!(status(&reply), Status::Ok, "chunk {i}: {}", reply.detail.text());
    }
    let all: Vec<MapDelta> = chunks.concat();
    let expected = World::empty(bounds(), sun()).apply(&all).unwrap().at_version(0);
    let got = client.snapshot(2, PATIENCE).unwrap();
    assert_eq!(got, expected);
    assert_eq!(
        got.obstacles()[&1],
        match pole(1, 5.0) {
            MapDelta::UpsertObstacle { obstacle, .. } => obstacle,
            _ => unreachable!(),
        },
        "an id upserted twice keeps the later obstacle"
    );
}

/// `expected_version` of an upload is checked when its last chunk arrives: a
/// version that was right at chunk 0 and went stale meanwhile is reported there.
#[test]
fn an_uploads_stale_version_is_reported_at_its_last_chunk() {
    let RawFixture { sandbox: _sandbox, daemon: _daemon, mut client, raw } = RawFixture::new("upstale");
    create_test_map(&mut client, 3);
    let (reply, _) = raw.map(chunk(3, 1, 0, 2, Some(0)), &encode_deltas(&[pole(1, 1.0)]));
    assert_eq!((status(&reply), reply.version), (Status::Ok, 0));
    client.apply(3, Some(0), &[pole(7, -4.0)], PATIENCE).unwrap();
    let (reply, _) = raw.map(chunk(3, 1, 1, 2, Some(0)), &encode_deltas(&[pole(2, 2.0)]));
    assert_eq!((status(&reply), reply.version), (Status::MapVersionMismatch, 1), "{}", reply.detail.text());
    // The upload is over: its chunks are refused, and the map is as the apply left it.
    let (reply, _) = raw.map(chunk(3, 1, 1, 2, Some(0)), &encode_deltas(&[pole(2, 2.0)]));
    assert_eq!(status(&reply), Status::ChunkOutOfOrder, "{}", reply.detail.text());
    let map = client.snapshot(3, PATIENCE).unwrap();
    assert_eq!((map.version(), map.obstacles().keys().copied().collect::<Vec<_>>()), (1, vec![7]));
}

/// Regression: a voxel run of no cells in a batch was accepted and fixed a map
/// without voxels to its resolution and origin, so the next real run at another
/// resolution was refused.
#[test]
fn a_voxel_run_of_no_cells_is_refused_in_a_batch() {
    let RawFixture { sandbox: _sandbox, daemon: _daemon, mut client, raw } = RawFixture::new("emptyrun");
    create_test_map(&mut client, 4);
    let empty_cells =
        MapDelta::SetVoxels { resolution: 0.5, origin: na::Point3::origin(), cells: vec![], occupied: true };
    let empty_blocks =
        MapDelta::SetVoxelBlocks { resolution: 0.5, origin: na::Point3::origin(), blocks: vec![], occupied: false };
    let apply = MapRequest::Apply { map: 4, expected_version: None, deltas: vec![] }.header(1, [0, 0]);
    let belief = Belief::new([0.0, 0.0, 0.3], [[0.2, 0.05, 0.0], [0.05, 0.1, 0.0], [0.0, 0.0, 0.05]]).unwrap();
    let query = RendezvousRequest::new(4, belief).header(Mode::Check, 2, [0, 0]);
    for empty in [&empty_cells, &empty_blocks] {
        let records = encode_deltas(&[pole(1, 1.0), empty.clone()]);
        let (reply, _) = raw.map(apply, &records);
        assert_eq!((status(&reply), reply.error_index), (Status::MalformedDelta, 1), "{}", reply.detail.text());
        assert!(reply.detail.text().contains("0 cells"), "{}", reply.detail.text());
        let reply = raw.rendezvous(query, &records);
        assert_eq!(Status::try_from(reply.status).unwrap(), Status::MalformedDelta, "{}", reply.detail.text());
        assert_eq!(reply.error_index, 1);
    }
    let map = client.snapshot(4, PATIENCE).unwrap();
    assert_eq!((map.version(), map.voxels().is_none()), (0, true), "the map did not change");
    // So the map's grid is still free to be any resolution.
    let real =
        MapDelta::SetVoxels { resolution: 0.1, origin: na::Point3::origin(), cells: vec![[1, 1, 1]], occupied: true };
    assert_eq!(client.apply(4, Some(0), &[real], PATIENCE).unwrap(), 1);
}

/// Where two checks fail at once, the one docs/wire.md §9 lists first answers.
#[test]
fn map_requests_are_checked_in_the_documented_order() {
    let RawFixture { sandbox: _sandbox, daemon: _daemon, mut client, raw } = RawFixture::new("maporder");
    create_test_map(&mut client, 1);
    let one = encode_deltas(&[pole(1, 1.0)]);
    let bad_tag = vec![WireDelta { tag: 99, ..Default::default() }];
    let clear = encode_deltas(&[MapDelta::Clear]);
    let too_many =
        vec![WireDelta { tag: tag::CLEAR, ..Default::default() }; dyfos_shared::limits::MAX_DELTAS_PER_MESSAGE + 1];
    let create = MapRequest::Create { map: 2, bounds: bounds(), sun: sun() }.header(1, [0, 0]);
    let apply = MapRequest::Apply { map: 1, expected_version: None, deltas: vec![] }.header(2, [0, 0]);
    let snapshot = MapRequest::Snapshot { map: 1, page: 0 }.header(3, [0, 0]);
    let delete = MapRequest::Delete { map: 1, expected_version: None }.header(4, [0, 0]);
    let nan = [f64::NAN; 4];
    let first = chunk(1, 1, 0, 1, None);
    // (what, header, records, status, a word of the detail telling the check apart)
    let cases: Vec<(&str, MapRequestHeader, Vec<WireDelta>, Status, &str)> = vec![
        (
            "records past the limit, then the op",
            MapRequestHeader { op: 0, ..apply },
            too_many,
            Status::OverCapacity,
            "limit",
        ),
        (
            "flags, then records",
            MapRequestHeader { flags: 1, ..snapshot },
            one.clone(),
            Status::MalformedRequest,
            "flags",
        ),
        (
            "create: records, then bounds",
            MapRequestHeader { bounds: nan, ..create },
            one.clone(),
            Status::MalformedRequest,
            "records",
        ),
        (
            "create: bounds, then a taken id",
            MapRequestHeader { map_id: 1, bounds: [1.0, 0.0, 0.0, 1.0], ..create },
            vec![],
            Status::InvalidDelta,
            "bounds",
        ),
        (
            "delete: records, then the map",
            MapRequestHeader { map_id: 9, ..delete },
            one.clone(),
            Status::MalformedRequest,
            "records",
        ),
        (
            "apply: records, then the map",
            MapRequestHeader { map_id: 9, ..apply },
            bad_tag.clone(),
            Status::MalformedDelta,
            "tag",
        ),
        (
            "apply: the map, then its version",
            MapRequestHeader { map_id: 9, expected_version: 5, ..apply },
            one.clone(),
            Status::UnknownMap,
            "no map 9",
        ),
        (
            "apply: the version, then the deltas",
            MapRequestHeader { expected_version: 5, ..apply },
            encode_deltas(&[MapDelta::RemoveObstacle { id: 8 }]),
            Status::MapVersionMismatch,
            "version",
        ),
        (
            "upload: chunk count, then index",
            MapRequestHeader { chunk_count: 0, chunk_index: 3, ..first },
            one.clone(),
            Status::OverCapacity,
            "chunk_count",
        ),
        ("upload: index, then records", chunk(1, 1, 3, 2, None), bad_tag, Status::ChunkOutOfOrder, "chunk_index"),
        (
            "upload: record kinds, then bounds",
            MapRequestHeader { bounds: nan, ..first },
            clear,
            Status::MalformedDelta,
            "upload chunks",
        ),
        (
            "upload: bounds, then the upload state",
            MapRequestHeader { bounds: nan, ..chunk(1, 1, 1, 2, None) },
            one.clone(),
            Status::InvalidDelta,
            "bounds",
        ),
        (
            "snapshot: the map, then the page",
            MapRequestHeader { map_id: 9, chunk_index: 7, ..snapshot },
            vec![],
            Status::UnknownMap,
            "no map 9",
        ),
    ];
    for (what, header, records, expected, word) in cases {
        let (reply, _) = raw.map(header, &records);
        assert_eq!(status(&reply), expected, "{what}: {}", reply.detail.text());
        assert!(reply.detail.text().contains(word), "{what}: {}", reply.detail.text());
    }
    assert_eq!(client.snapshot(1, PATIENCE).unwrap().version(), 0, "nothing changed the map");
}

/// A list request describes the map with the smallest id at or after its cursor and
/// counts the maps from there; walking the cursor from 0 lists every map in id
/// order (docs/wire.md §9). Listing is never an error, so it moves no failure
/// counter; a list request with flags or records is refused.
#[test]
fn listing_walks_the_maps_in_id_order_and_is_never_an_error() {
    let RawFixture { sandbox: _sandbox, daemon: _daemon, mut client, raw } = RawFixture::new("maplist");
    let list = |from: MapId| {
        let (reply, records) = raw.map(MapRequest::List { from }.header(from ^ 0x5a5a, [0, 0]), &[]);
        assert_eq!((status(&reply), reply.request_id), (Status::Ok, from ^ 0x5a5a), "{}", reply.detail.text());
        assert!(records.is_empty());
        reply
    };
    // Every map, by the walk: from 0, then from the id described + 1.
    let walk = || {
        let mut described = Vec::new();
        let mut from = 0;
        loop {
            let reply = list(from);
            if reply.chunk_count == 0 {
                return described;
            }
            assert!(reply.map_id >= from, "{reply:?}");
            described.push(reply);
            from = reply.map_id + 1;
        }
    };
    let nothing = |reply: &MapReplyHeader, from: MapId| {
        assert_eq!((reply.chunk_count, reply.map_id, reply.version, reply.generation), (0, from, 0, 0));
        assert_eq!((reply.bounds, reply.sun), ([0.0; 4], [0.0; 2]));
    };
    nothing(&list(0), 0);
    assert!(walk().is_empty(), "no maps yet");

    let big = u64::MAX - 1;
    let wide = Bounds::new([-20.0, -5.0, 20.0, 5.0]).unwrap();
    client.create_map(big, wide, sun(), PATIENCE).unwrap();
    client.create_map(0, bounds(), sun(), PATIENCE).unwrap();
    client.create_map(77, bounds(), sun(), PATIENCE).unwrap();
    client.apply(77, Some(0), &[pole(1, 1.0), MapDelta::SetSun(Sun::new(0.4, -1.0).unwrap())], PATIENCE).unwrap();

    let before = client.stats(PATIENCE).unwrap();
    let maps = walk();
    let seen: Vec<_> = maps.iter().map(|r| (r.map_id, r.chunk_count, r.version)).collect();
    assert_eq!(seen, [(0, 3, 0), (77, 2, 2), (big, 1, 0)]);
    assert_eq!((maps[1].bounds, maps[1].sun), (bounds().to_array(), [0.4, -1.0]));
    assert_eq!((maps[2].bounds, maps[2].sun), (wide.to_array(), [0.7, 2.1]));
    let generations: Vec<u32> = maps.iter().map(|r| r.generation).collect();
    assert!(generations.iter().all(|g| *g != 0), "{generations:?}");
    // A cursor between ids, and past the last: no error either.
    let between = list(1);
    assert_eq!((between.map_id, between.chunk_count, between.version), (77, 2, 2));
    assert_eq!(list(78).map_id, big);
    nothing(&list(u64::MAX), u64::MAX);
    let after = client.stats(PATIENCE).unwrap();
    assert_eq!((after.requests_failed, &after.errors), (before.requests_failed, &before.errors));
    assert_eq!(after.map_requests, before.map_requests + 4 + 3, "every list step is a map request served");

    // Deleted, the map is no longer listed; made again, it has another generation.
    client.delete_map(77, None, PATIENCE).unwrap();
    assert_eq!(walk().iter().map(|r| r.map_id).collect::<Vec<_>>(), [0, big]);
    assert_eq!((list(1).map_id, list(1).chunk_count), (big, 1));
    client.create_map(77, bounds(), sun(), PATIENCE).unwrap();
    let again = list(1);
    assert_eq!((again.map_id, again.version), (77, 0));
    assert_ne!(again.generation, generations[1], "a map made again under its id");

    // Flags or records: refused, and counted as failures (the counter does move).
    let header = MapRequest::List { from: 0 }.header(9, [0, 0]);
    let (flagged, _) = raw.map(MapRequestHeader { flags: 1, ..header }, &[]);
    assert_eq!(status(&flagged), Status::MalformedRequest, "{}", flagged.detail.text());
    assert!(flagged.detail.text().contains("list: flags"), "{}", flagged.detail.text());
    let (carrying, _) = raw.map(header, &encode_deltas(&[MapDelta::Clear]));
    assert_eq!(status(&carrying), Status::MalformedRequest, "{}", carrying.detail.text());
    assert!(carrying.detail.text().contains("list carries no records"), "{}", carrying.detail.text());
    assert_eq!(client.stats(PATIENCE).unwrap().requests_failed, before.requests_failed + 2);
}

/// `Client::list_maps` walks the whole id range, both ends included, and describes
/// each map as a snapshot shows it.
#[test]
fn the_client_lists_every_map_as_its_snapshot_shows_it() {
    let (sandbox, _daemon) = Sandbox::with_daemon("maplistc");
    let mut client = sandbox.client();
    assert_eq!(client.list_maps(PATIENCE).unwrap(), []);
    let ids = [u64::MAX, 0, u64::MAX - 1, 1 << 40];
    for (k, id) in ids.iter().enumerate() {
        let b = Bounds::new([-1.0 - k as f64, -1.0, 1.0, 1.0 + k as f64]).unwrap();
        client.create_map(*id, b, sun(), PATIENCE).unwrap();
    }
    client.apply(u64::MAX, None, &[pole(3, 0.5), MapDelta::SetSun(Sun::new(-0.1, 3.0).unwrap())], PATIENCE).unwrap();
    let listed = client.list_maps(PATIENCE).unwrap();
    assert_eq!(listed.iter().map(|m| m.id).collect::<Vec<_>>(), [0, 1 << 40, u64::MAX - 1, u64::MAX]);
    for m in &listed {
        let world = client.snapshot(m.id, PATIENCE).unwrap();
        assert_eq!((m.version, m.bounds, m.sun), (world.version(), *world.bounds(), *world.sun()), "map {}", m.id);
    }
    assert_eq!(listed[3].version, 2);
    client.delete_map(1 << 40, None, PATIENCE).unwrap();
    let left: Vec<MapId> = client.list_maps(PATIENCE).unwrap().iter().map(|m| m.id).collect();
    assert_eq!(left, [0, u64::MAX - 1, u64::MAX]);
}
