//! [`handle`] beyond uploads (those are tested beside the upload state machine):
//! snapshot pages, the list cursor, delete, and every refusal leaving the maps as
//! they were.

use super::{Reply, handle};
use crate::daemon::state::Scratch;
use dyfos_shared::limits::SNAPSHOT_PAGE_RECORDS;
use dyfos_shared::wire::Status;
use dyfos_shared::wire::map::{MapId, MapRequest, decode_deltas, world_from_content};
use dyfos_shared::world::{Bounds, MapDelta, Obstacle, Sun, VerticalCylinder, World};

fn bounds() -> Bounds {
    Bounds::new([-10.0, -10.0, 10.0, 10.0]).unwrap()
}

fn sun() -> Sun {
    Sun::new(0.5, 0.25).unwrap()
}

fn pillar(id: u32) -> MapDelta {
    let center = nalgebra::Point2::new(f64::from(id % 19) - 9.0, f64::from(id / 19 % 19) - 9.0);
    MapDelta::UpsertObstacle { id, obstacle: Obstacle::Cylinder(VerticalCylinder { center, radius: 0.3, height: 2.0 }) }
}

/// Maps 1 (version 2, two pillars), 4 (version 0, empty) and 6 (more obstacles than
/// a snapshot page holds, and voxels).
fn scratch(name: &str) -> Scratch {
    let empty = World::empty(bounds(), sun());
    let two = empty.apply(&[pillar(1), pillar(2)]).unwrap();
    let mut many: Vec<MapDelta> = (1..=SNAPSHOT_PAGE_RECORDS as u32 + 60).map(pillar).collect();
    let cells: Vec<[i64; 3]> = (0..200).map(|i| [4 * (i % 20), 4 * (i / 20), i % 3]).collect();
    many.push(MapDelta::SetVoxels {
        resolution: 0.25,
        origin: nalgebra::Point3::new(-5.0, -5.0, 0.0),
        cells,
        occupied: true,
    });
    let big = empty.apply(&many).unwrap();
    Scratch::new(name, [(1, two), (4, empty), (6, big)])
}

fn ok(s: &mut Scratch, request: MapRequest) -> Reply {
    handle(&mut s.state.maps, request).unwrap_or_else(|r| panic!("refused: {:?}: {}", r.status, r.message))
}

/// Every map's version and content, to see that a refusal changed nothing.
fn maps(s: &Scratch) -> Vec<(MapId, World)> {
    s.state.maps.iter().map(|(id, w)| (id, w.clone())).collect()
}

#[test]
fn snapshot_pages_rebuild_the_map_and_a_page_past_the_end_is_refused() {
    let mut s = scratch("map-pages");
    let world = s.state.maps.get(6).unwrap();
    let first = ok(&mut s, MapRequest::Snapshot { map: 6, page: 0 });
    let count = first.header.chunk_count;
    assert!(count > 1, "the big map takes more than one page");
    assert_eq!((first.header.map_id, first.header.version), (6, world.version()));
    assert_eq!(first.header.bounds, bounds().to_array());
    assert_eq!(first.header.sun, [sun().elevation, sun().azimuth]);
    assert_ne!(first.header.generation, 0, "a snapshot carries the map's generation");
    let mut deltas = Vec::new();
    for page in 0..count {
        let reply = ok(&mut s, MapRequest::Snapshot { map: 6, page });
        assert_eq!((reply.header.chunk_index, reply.header.chunk_count), (page, count));
        assert_eq!(reply.header.generation, first.header.generation);
        let (pages, i) = reply.records.expect("a page");
        deltas.extend(decode_deltas(&pages[i]).expect("a page decodes"));
    }
    let rebuilt = world_from_content(world.version(), bounds(), sun(), &deltas).unwrap();
    assert!(rebuilt.same_content(&world), "the pages hold the whole map");

    let before = maps(&s);
    for (case, request, status) in [
        ("page past the end", MapRequest::Snapshot { map: 6, page: count }, Status::ChunkOutOfOrder),
        ("unknown map", MapRequest::Snapshot { map: 9, page: 0 }, Status::UnknownMap),
    ] {
        assert_eq!(handle(&mut s.state.maps, request).err().map(|r| r.status), Some(status), "{case}");
    }
    assert_eq!(maps(&s), before);
}

#[test]
fn the_list_cursor_walks_the_maps_in_id_order_and_ends_empty() {
    let mut s = scratch("map-list");
    let mut seen = Vec::new();
    let mut from = 0;
    loop {
        let reply = ok(&mut s, MapRequest::List { from });
        let h = reply.header;
        assert!(reply.records.is_none(), "a list reply has no records");
        if h.chunk_count == 0 {
            assert_eq!((h.map_id, h.version), (from, 0), "the end of a listing names the cursor");
            break;
        }
        let world = s.state.maps.get(h.map_id).expect("a listed map exists");
        assert_eq!(h.version, world.version());
        assert_eq!(h.generation, s.state.maps.generation(h.map_id));
        assert_eq!(h.chunk_count as usize, 3 - seen.len(), "maps at or after the cursor");
        seen.push(h.map_id);
        from = h.map_id + 1;
    }
    assert_eq!(seen, [1, 4, 6]);
}

#[test]
fn delete_takes_the_expected_version_and_frees_the_id() {
    let mut s = scratch("map-delete");
    let before = maps(&s);
    let stale = MapRequest::Delete { map: 1, expected_version: Some(1) };
    assert_eq!(handle(&mut s.state.maps, stale).err().map(|r| r.status), Some(Status::MapVersionMismatch));
    assert_eq!(maps(&s), before, "a stale delete deletes nothing");
    assert_eq!(ok(&mut s, MapRequest::Delete { map: 1, expected_version: Some(2) }).header.version, 2);
    assert!(s.state.maps.get(1).is_none());
    let again = MapRequest::Delete { map: 1, expected_version: None };
    assert_eq!(handle(&mut s.state.maps, again).err().map(|r| r.status), Some(Status::UnknownMap));
    // The id is free again, at version 0.
    assert_eq!(ok(&mut s, MapRequest::Create { map: 1, bounds: bounds(), sun: sun() }).header.version, 0);
}

/// Every refusal of a request that would change a map, by name: its status, and
/// every map as it was.
#[test]
fn refused_changes_leave_every_map_as_it_was() {
    let mut s = scratch("map-refusals");
    let before = maps(&s);
    let cases = [
        ("create over a map", MapRequest::Create { map: 4, bounds: bounds(), sun: sun() }, Status::MapExists),
        (
            "apply at a stale version",
            MapRequest::Apply { map: 1, expected_version: Some(0), deltas: vec![pillar(3)] },
            Status::MapVersionMismatch,
        ),
        (
            "apply with a bad delta last",
            MapRequest::Apply {
                map: 1,
                expected_version: None,
                deltas: vec![pillar(3), MapDelta::RemoveObstacle { id: 99 }],
            },
            Status::InvalidDelta,
        ),
        (
            "apply to no map",
            MapRequest::Apply { map: 9, expected_version: None, deltas: vec![pillar(3)] },
            Status::UnknownMap,
        ),
        ("delete no map", MapRequest::Delete { map: 9, expected_version: None }, Status::UnknownMap),
    ];
    for (case, request, status) in cases {
        let refused = handle(&mut s.state.maps, request).err().unwrap_or_else(|| panic!("{case}: accepted"));
        assert_eq!(refused.status, status, "{case}: {}", refused.message);
        assert_eq!(maps(&s), before, "{case}: a map changed");
    }
    // And an accepted apply does change it.
    ok(&mut s, MapRequest::Apply { map: 1, expected_version: Some(2), deltas: vec![pillar(3)] });
    assert_eq!(s.state.maps.get(1).unwrap().version(), 3);
}
