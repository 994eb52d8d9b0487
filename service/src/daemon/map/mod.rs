//! The map service: create, apply, chunked upload, paged snapshot, delete, list.
//! [`on_request`] decodes a request, [`handle`] changes the maps (port-free, so its
//! rules are tested beside it) and [`deliver`] records and sends the one reply.

mod pages;
mod registry;
mod upload;

pub(crate) use registry::Maps;

use super::ports::{MapActive, Replies};
use super::record::{ChangeCause, Record, unix_ns, unix_ns_of};
use super::reject::{check_version, guarded, invalid_delta, unknown_map};
use super::state::State;
use dyfos_shared::wire::map::{MapId, MapReplyHeader, MapRequest, MapRequestHeader, WireDelta};
use dyfos_shared::wire::{Detail, Rejection, Status, join_u128};
use dyfos_shared::world::World;
use std::time::{Instant, SystemTime};
use tracing::{debug, warn};
use upload::Chunk;

/// Answers one map request.
pub(super) fn on_request(state: &mut State, replies: &Replies, active: MapActive) {
    let received = Instant::now();
    let header = *active.user_header();
    let recording = state.pool.recorder.is_some();
    let mut recorded: Option<(&'static str, serde_json::Value)> = None;
    let result = guarded("map", || {
        MapRequest::decode(&header, active.payload()).and_then(|request| {
            if recording {
                recorded = Some(request_json(&request));
            }
            handle(&mut state.maps, request)
        })
    });
    let reply = match result {
        Ok(reply) => {
            state.pool.stats().map_ok();
            reply
        }
        Err(rejection) => {
            debug!(request_id = header.request_id, map = header.map_id, status = %rejection.status, "map request rejected: {}", rejection.message);
            state.pool.stats().failed(rejection.status);
            // Only accepted requests are recorded.
            recorded = None;
            Reply {
                header: MapReplyHeader {
                    status: rejection.status as u32,
                    map_id: header.map_id,
                    version: state.maps.get(header.map_id).map_or(0, |w| w.version()),
                    error_index: rejection.wire_index(),
                    detail: Detail::new(&rejection.message),
                    ..Default::default()
                },
                records: None,
            }
        }
    };
    deliver(state, replies, &active, &header, reply, recorded.map(|r| (received, r)));
}

/// The reply to a map request, with the records to send.
struct Reply {
    header: MapReplyHeader,
    records: Option<(super::map::pages::Pages, usize)>,
}

/// Carries out `request` on `maps`.
fn handle(maps: &mut Maps, request: MapRequest) -> Result<Reply, Rejection> {
    let ok = |map: MapId, version: u64| Reply {
        header: MapReplyHeader { map_id: map, version, error_index: u64::MAX, ..Default::default() },
        records: None,
    };
    match request {
        MapRequest::Create { map, bounds, sun } => {
            if maps.get(map).is_some() {
                return Err(Rejection::new(
                    Status::MapExists,
                    format!("map {map} exists; pick another id or delete it first"),
                ));
            }
            let world = maps.commit(map, World::empty(bounds, sun), "created", ChangeCause::Create)?;
            Ok(ok(map, world.version()))
        }
        MapRequest::Apply { map, expected_version, deltas } => {
            let world = maps.get(map).ok_or_else(|| unknown_map(map))?;
            check_version(map, &world, expected_version)?;
            let next = world.apply(&deltas).map_err(invalid_delta)?;
            let what = format!("{} deltas applied", deltas.len());
            Ok(ok(map, maps.commit_deltas(map, &world, &deltas, next, &what, ChangeCause::Apply)?.version()))
        }
        MapRequest::Upload {
            map,
            upload_id,
            chunk_index,
            chunk_count,
            replace,
            expected_version,
            bounds,
            sun,
            deltas,
        } => {
            let chunk = Chunk { upload_id, chunk_index, chunk_count, replace, expected_version, bounds, sun, deltas };
            let mut reply = ok(map, maps.upload(map, chunk)?);
            reply.header.chunk_index = chunk_index;
            reply.header.chunk_count = chunk_count;
            Ok(reply)
        }
        MapRequest::Snapshot { map, page } => {
            let world = maps.get(map).ok_or_else(|| unknown_map(map))?;
            let pages = maps.pages(&world);
            let count = pages.len() as u32;
            if page >= count {
                return Err(Rejection::new(
                    Status::ChunkOutOfOrder,
                    format!(
                        "map {map} at version {} has {count} snapshot pages; page {page} does not exist",
                        world.version()
                    ),
                ));
            }
            let mut reply = ok(map, world.version());
            reply.header.chunk_index = page;
            reply.header.chunk_count = count;
            reply.header.generation = maps.generation(map);
            reply.header.bounds = world.bounds().to_array();
            reply.header.sun = [world.sun().elevation, world.sun().azimuth];
            reply.records = Some((pages, page as usize));
            Ok(reply)
        }
        MapRequest::Delete { map, expected_version } => Ok(ok(map, maps.delete(map, expected_version)?)),
        MapRequest::List { from } => {
            // No map at or after the cursor is the end of a listing, not an error.
            let mut at_or_after = maps.from(from);
            let mut reply = ok(from, 0);
            reply.header.chunk_count = u32::try_from(at_or_after.clone().count()).unwrap_or(u32::MAX);
            if let Some((id, world)) = at_or_after.next() {
                reply.header.map_id = id;
                reply.header.version = world.version();
                reply.header.generation = maps.generation(id);
                reply.header.bounds = world.bounds().to_array();
                reply.header.sun = [world.sun().elevation, world.sun().azimuth];
            }
            Ok(reply)
        }
    }
}

/// Records `reply` (if `recorded`: an accepted request, received then) and sends it.
fn deliver(
    state: &State,
    replies: &Replies,
    active: &MapActive,
    header: &MapRequestHeader,
    reply: Reply,
    recorded: Option<(Instant, (&'static str, serde_json::Value))>,
) {
    let mut reply_header = reply.header;
    reply_header.request_id = header.request_id;
    if let (Some(recorder), Some((received, (kind, request)))) = (&state.pool.recorder, recorded) {
        let h = &reply_header;
        let (received, replied) = (unix_ns_of(received), unix_ns(SystemTime::now()));
        let mut recorded_reply = serde_json::json!({
            "status": "ok", "version": h.version, "chunk_index": h.chunk_index, "chunk_count": h.chunk_count,
        });
        if kind == "list" {
            // The map described, which is not the request's (the cursor).
            recorded_reply["map"] = h.map_id.into();
        }
        let message = serde_json::json!({
            "kind": kind, "request_id": header.request_id, "map": header.map_id,
            "received_ns": received, "replied_ns": replied, "request": request,
            "reply": recorded_reply,
        });
        recorder.record(Record::Map { received, replied, message });
    }
    let records: &[WireDelta] = match &reply.records {
        Some((pages, i)) => &pages[*i],
        None => &[],
    };
    match active.loan_slice_uninit(records.len()) {
        Ok(mut loan) => {
            *loan.user_header_mut() = reply_header;
            if let Err(e) = loan.write_from_slice(records).send() {
                debug!("map reply not delivered (client gone?): {e:?}");
            }
        }
        Err(e) => warn!("map reply not delivered: {e:?}"),
    }
    replies.notify(join_u128(header.reply_to));
}

/// What the recording shows of a map request (its deltas are in the map change
/// they made, if any).
fn request_json(request: &MapRequest) -> (&'static str, serde_json::Value) {
    use serde_json::json;
    match request {
        MapRequest::Create { bounds, sun, .. } => ("create", json!({"bounds": bounds.to_array(), "sun": sun})),
        MapRequest::Apply { expected_version, deltas, .. } => {
            ("apply", json!({"expected_version": expected_version, "deltas": deltas.len()}))
        }
        MapRequest::Upload { upload_id, chunk_index, chunk_count, replace, expected_version, deltas, .. } => (
            "upload",
            json!({"upload_id": upload_id, "chunk_index": chunk_index, "chunk_count": chunk_count,
                   "replace": replace, "expected_version": expected_version, "deltas": deltas.len()}),
        ),
        MapRequest::Snapshot { page, .. } => ("snapshot", json!({"page": page})),
        MapRequest::Delete { expected_version, .. } => ("delete", json!({"expected_version": expected_version})),
        // The cursor is the message's `map`; the map described is in its reply.
        MapRequest::List { .. } => ("list", json!({})),
    }
}

#[cfg(test)]
mod tests;
