//! The map service and the maps themselves: create, apply, chunked upload,
//! paged snapshot, delete, list. Every accepted change is written to the store before
//! it is visible; a failed write leaves the map as it was.

use super::record::{ChangeCause, Record, Recorder, unix_ns, unix_ns_of};
use super::{Daemon, Ipc};
use crate::store::{Store, StoreSaveError};
use dyfos_shared::limits::{
    MAX_MAPS, MAX_OBSTACLES, MAX_OCCUPIED_VOXELS, MAX_PENDING_UPLOADS, MAX_TOTAL_VOXELS, SNAPSHOT_PAGE_RECORDS,
};
use dyfos_shared::wire::map::{
    MapId, MapReplyHeader, MapRequest, MapRequestHeader, WireDelta, world_chunks_of, world_from_content,
};
use dyfos_shared::wire::{Detail, Rejection, Status, join_u128};
use dyfos_shared::world::{Bounds, MapDelta, MapDeltaError, MapDeltaErrorKind, Sun, VoxelError, World};
use iceoryx2::active_request::ActiveRequest;
use std::collections::{BTreeMap, VecDeque};
use std::sync::Arc;
use std::time::{Duration, Instant, SystemTime};
use tracing::{debug, error, info, warn};

type MapActive = ActiveRequest<Ipc, [WireDelta], MapRequestHeader, [WireDelta], MapReplyHeader>;

/// Abandoned uploads remembered, so their late chunks get `chunk_incomplete`.
const ABANDONED_MEMORY: usize = 64;

pub(crate) fn unknown_map(id: MapId) -> Rejection {
    Rejection::new(
        Status::UnknownMap,
        format!("no map {id}; create it (`dyfos map create`, Client::create_map) or upload it first"),
    )
}

/// Runs `handle` (the handling of one request); a panic in it, a bug, becomes an
/// `internal_error` reply instead of taking the daemon (or a worker) down or
/// leaving the client without an answer. What `handle` changes is committed last
/// (`Maps::commit`), so a panic before that leaves every map as it was.
pub(crate) fn guarded<T>(what: &str, handle: impl FnOnce() -> Result<T, Rejection>) -> Result<T, Rejection> {
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(handle)).unwrap_or_else(|_| {
        error!("handling a {what} request panicked; it was answered with internal_error");
        Err(Rejection::new(
            Status::Internal,
            format!("dyfosd hit a bug handling this {what} request (see its log); nothing changed, please report it"),
        ))
    })
}

pub(crate) fn check_version(id: MapId, world: &World, expected: Option<u64>) -> Result<(), Rejection> {
    match expected {
        Some(v) if v != world.version() => Err(Rejection::new(
            Status::MapVersionMismatch,
            format!(
                "map {id} is at version {}, the request expected {v}; read the map again and retry",
                world.version()
            ),
        )),
        _ => Ok(()),
    }
}

/// The code of a delta the map refused: a map past its obstacle or cell limits is a
/// capacity refusal (`over_capacity`), anything else an invalid change.
fn delta_status(kind: &MapDeltaErrorKind) -> Status {
    match kind {
        MapDeltaErrorKind::Voxels(VoxelError::TooManyCells { .. } | VoxelError::GridTooLarge { .. })
        | MapDeltaErrorKind::TooManyObstacles { .. } => Status::OverCapacity,
        _ => Status::InvalidDelta,
    }
}

/// The refusal of a batch one of whose deltas the map refused, naming that delta
/// (`error_index`), with `over_capacity` too: the delta that passed the limit.
pub(crate) fn invalid_delta(e: MapDeltaError) -> Rejection {
    Rejection::at_delta(delta_status(&e.kind), format!("{e}; nothing was applied"), e.index as u64)
}

/// A map's snapshot pages, each a self-contained chunk of records.
type Pages = Arc<Vec<Vec<WireDelta>>>;

/// An upload in progress.
struct Upload {
    upload_id: u64,
    chunk_count: u32,
    next: u32,
    replace: bool,
    expected_version: Option<u64>,
    bounds: Bounds,
    sun: Sun,
    deltas: Vec<MapDelta>,
    /// Where each chunk's deltas start in `deltas`, to name a delta's chunk.
    starts: Vec<usize>,
    /// Obstacle upserts and voxel cells buffered so far, bounded by what one map
    /// may hold, so that chunks cannot grow the daemon's memory without limit
    /// before the upload completes.
    obstacles: usize,
    cells: usize,
    last_chunk: Instant,
}

impl Upload {
    /// Counts `deltas` into the buffer's totals; an error if they pass a map's
    /// limits (the upload can never complete).
    fn count(&mut self, deltas: &[MapDelta]) -> Result<(), Rejection> {
        for d in deltas {
            match d {
                MapDelta::SetVoxels { cells, .. } => self.cells += cells.len(),
                MapDelta::SetVoxelBlocks { blocks, .. } => {
                    self.cells += blocks.iter().map(|b| b.mask.count_ones() as usize).sum::<usize>()
                }
                _ => self.obstacles += 1,
            }
        }
        if self.obstacles > MAX_OBSTACLES || self.cells > MAX_OCCUPIED_VOXELS {
            return Err(Rejection::new(
                Status::OverCapacity,
                format!(
                    "upload {} carries {} obstacles and {} voxel cells so far, more than a map holds ({MAX_OBSTACLES} and {MAX_OCCUPIED_VOXELS}); the upload is abandoned",
                    self.upload_id, self.obstacles, self.cells
                ),
            ));
        }
        Ok(())
    }

    /// Takes in a chunk's `deltas`, counted already.
    fn take(&mut self, deltas: Vec<MapDelta>) {
        self.starts.push(self.deltas.len());
        self.deltas.extend(deltas);
    }

    /// The refusal of an upload whose map cannot be built from its content, found
    /// when its last chunk arrived: the detail names the chunk and the delta in it.
    /// `error_index` is none, as the delta may be in another chunk than the one
    /// this replies to.
    fn content_error(&self, map: MapId, e: MapDeltaError) -> Rejection {
        let status = delta_status(&e.kind);
        let message = if status == Status::OverCapacity {
            // The cells of all chunks together: no one delta is at fault.
            format!("upload {} of map {map}: {}; nothing changed", self.upload_id, e.kind)
        } else {
            let chunk = self.starts.partition_point(|start| *start <= e.index).saturating_sub(1);
            let within = e.index - self.starts.get(chunk).copied().unwrap_or(0);
            format!(
                "upload {} of map {map}, chunk {chunk}, delta #{within}: {}; nothing changed",
                self.upload_id, e.kind
            )
        };
        Rejection::new(status, message)
    }
}

/// The snapshot pages of the last map paged, tied to the very world they were made
/// from: a map deleted and made again under its id starts again at version 0, so an
/// id and a version do not name one content.
#[derive(Default)]
struct PageCache(Option<(std::sync::Weak<World>, Pages)>);

impl PageCache {
    /// The pages of `world`, made now unless it was the last world paged.
    fn get(&mut self, world: &Arc<World>) -> Pages {
        if let Some((made_from, pages)) = &self.0 {
            // The Weak keeps the allocation, so its address names that world alone.
            if std::ptr::eq(made_from.as_ptr(), Arc::as_ptr(world)) {
                return Arc::clone(pages);
            }
        }
        let pages: Pages = Arc::new(world_chunks_of(world, SNAPSHOT_PAGE_RECORDS));
        self.0 = Some((Arc::downgrade(world), Arc::clone(&pages)));
        pages
    }
}

/// The maps, their store, uploads in progress and recent snapshots' pages.
pub(crate) struct Maps {
    maps: BTreeMap<MapId, Arc<World>>,
    /// Each map's generation (`MapReplyHeader::generation`): a map deleted and made
    /// again starts again at version 0, so its snapshot pages tell the two apart by this.
    generations: BTreeMap<MapId, u32>,
    /// The generation the next map made gets.
    next_generation: u32,
    store: Store,
    uploads: BTreeMap<MapId, Upload>,
    abandoned: VecDeque<(MapId, u64)>,
    pages: PageCache,
    upload_idle_timeout: Duration,
    /// Where changes are recorded (`--record`).
    pub(crate) recorder: Option<Arc<Recorder>>,
}

impl Maps {
    pub(crate) fn new(
        store: Store,
        maps: impl IntoIterator<Item = (MapId, World)>,
        upload_idle_timeout: Duration,
    ) -> Self {
        let mut this = Maps {
            generations: BTreeMap::new(),
            // Random, so that a client paging across a daemon restart does not see
            // the generations of the maps it reads again.
            next_generation: rand::random(),
            maps: BTreeMap::new(),
            store,
            uploads: BTreeMap::new(),
            abandoned: VecDeque::new(),
            pages: PageCache::default(),
            upload_idle_timeout,
            recorder: None,
        };
        for (id, world) in maps {
            this.made(id);
            this.maps.insert(id, Arc::new(world));
        }
        this
    }

    /// Map `id` is made anew (created, uploaded or loaded): it gets the next
    /// generation. Never 0, which replies other than a snapshot carry.
    fn made(&mut self, id: MapId) {
        self.next_generation = self.next_generation.wrapping_add(1).max(1);
        self.generations.insert(id, self.next_generation);
    }

    /// Map `id`'s generation (0 if no map has the id).
    pub(crate) fn generation(&self, id: MapId) -> u32 {
        self.generations.get(&id).copied().unwrap_or(0)
    }

    pub(crate) fn len(&self) -> usize {
        self.maps.len()
    }

    pub(crate) fn iter(&self) -> impl Iterator<Item = (MapId, &World)> {
        self.maps.iter().map(|(id, w)| (*id, w.as_ref()))
    }

    /// Every map, shared.
    pub(crate) fn arcs(&self) -> impl Iterator<Item = (MapId, Arc<World>)> + '_ {
        self.maps.iter().map(|(id, w)| (*id, Arc::clone(w)))
    }

    pub(crate) fn get(&self, id: MapId) -> Option<Arc<World>> {
        self.maps.get(&id).cloned()
    }

    /// Persists `world` as map `id` (a new base file), then makes it current.
    /// `cause` is `Create` or `Upload`, for the recording.
    pub(crate) fn commit(
        &mut self,
        id: MapId,
        world: World,
        what: &str,
        cause: ChangeCause,
    ) -> Result<Arc<World>, Rejection> {
        self.check_room(id, &world)?;
        let saved = self.store.save(id, &world);
        let world = self.publish(id, world, what, saved)?;
        self.made(id);
        self.record(id, cause, None, Vec::new(), Some(&world), world.version());
        Ok(world)
    }

    /// Hands a change to the recorder, if recording.
    fn record(
        &self,
        map: MapId,
        cause: ChangeCause,
        from: Option<u64>,
        deltas: Vec<MapDelta>,
        world: Option<&Arc<World>>,
        version: u64,
    ) {
        if let Some(r) = &self.recorder {
            let at = unix_ns(SystemTime::now());
            r.record(Record::MapChange { at, map, cause, deltas, world: world.cloned(), from, version });
        }
    }

    /// Persists `deltas`, which made `next` from `world`, as a journal record of map
    /// `id`, then makes `next` current: an update costs what it changes. `cause`
    /// is `Apply` or `Inline`, for the recording.
    pub(crate) fn commit_deltas(
        &mut self,
        id: MapId,
        world: &World,
        deltas: &[MapDelta],
        next: World,
        what: &str,
        cause: ChangeCause,
    ) -> Result<Arc<World>, Rejection> {
        self.check_room(id, &next)?;
        let saved = self.store.append(id, world.version(), deltas, &next);
        let next = self.publish(id, next, what, saved)?;
        if self.recorder.is_some() {
            self.record(id, cause, Some(world.version()), deltas.to_vec(), Some(&next), next.version());
        }
        Ok(next)
    }

    /// Whether the daemon may hold `world` as map `id`: the map count, and the
    /// occupied cells of all maps together.
    fn check_room(&self, id: MapId, world: &World) -> Result<(), Rejection> {
        if !self.maps.contains_key(&id) && self.maps.len() >= MAX_MAPS {
            return Err(Rejection::new(
                Status::OverCapacity,
                format!("the daemon holds {MAX_MAPS} maps, its limit; delete one first"),
            ));
        }
        let cells = |w: &World| w.voxels().map_or(0, |v| v.len());
        let others: u64 = self.maps.iter().filter(|(m, _)| **m != id).map(|(_, w)| cells(w)).sum();
        if others + cells(world) > MAX_TOTAL_VOXELS {
            return Err(Rejection::new(
                Status::OverCapacity,
                format!(
                    "map {id} would bring the daemon's maps to {} occupied voxel cells, more than its limit of {MAX_TOTAL_VOXELS}; delete a map or use a coarser resolution",
                    others + cells(world)
                ),
            ));
        }
        Ok(())
    }

    fn publish(
        &mut self,
        id: MapId,
        world: World,
        what: &str,
        saved: Result<(), StoreSaveError>,
    ) -> Result<Arc<World>, Rejection> {
        if let Err(e) = saved {
            warn!(map = id, "could not persist map: {e}");
            return Err(Rejection::new(
                Status::StorageFailed,
                format!("could not write map {id} to the state directory ({e}); the map is unchanged"),
            ));
        }
        info!(map = id, version = world.version(), "map changed: {what}");
        let world = Arc::new(world);
        self.maps.insert(id, Arc::clone(&world));
        Ok(world)
    }

    fn abandon(&mut self, map: MapId, upload: &Upload, why: &str) {
        warn!(
            map,
            upload_id = upload.upload_id,
            received = upload.next,
            of = upload.chunk_count,
            "upload abandoned: {why}"
        );
        if self.abandoned.len() == ABANDONED_MEMORY {
            self.abandoned.pop_front();
        }
        self.abandoned.push_back((map, upload.upload_id));
    }

    /// Abandons uploads idle for longer than the timeout.
    pub(crate) fn expire_uploads(&mut self) {
        let timeout = self.upload_idle_timeout;
        let stale: Vec<MapId> =
            self.uploads.iter().filter(|(_, u)| u.last_chunk.elapsed() > timeout).map(|(id, _)| *id).collect();
        for id in stale {
            if let Some(u) = self.uploads.remove(&id) {
                self.abandon(id, &u, "no chunk for too long");
            }
        }
    }

    fn incomplete_or_out_of_order(&self, map: MapId, upload_id: u64, chunk_index: u32) -> Rejection {
        if self.abandoned.contains(&(map, upload_id)) {
            Rejection::new(
                Status::ChunkIncomplete,
                format!(
                    "upload {upload_id} of map {map} was abandoned before it completed (superseded or idle); start again from chunk 0"
                ),
            )
        } else {
            Rejection::new(
                Status::ChunkOutOfOrder,
                format!(
                    "chunk {chunk_index} of upload {upload_id}: no such upload of map {map} in progress; start with chunk 0"
                ),
            )
        }
    }

    /// One upload chunk. Returns the map's version (the new one when complete).
    #[allow(clippy::too_many_arguments)]
    fn upload(
        &mut self,
        map: MapId,
        upload_id: u64,
        chunk_index: u32,
        chunk_count: u32,
        replace: bool,
        expected_version: Option<u64>,
        bounds: Bounds,
        sun: Sun,
        deltas: Vec<MapDelta>,
    ) -> Result<u64, Rejection> {
        match self.uploads.get_mut(&map) {
            Some(u) if u.upload_id == upload_id => {
                if chunk_count != u.chunk_count {
                    return Err(Rejection::new(
                        Status::MalformedRequest,
                        format!(
                            "chunk_count = {chunk_count} differs from the {} this upload began with",
                            u.chunk_count
                        ),
                    ));
                }
                if chunk_index < u.next {
                    return Err(Rejection::new(
                        Status::ChunkDuplicate,
                        format!(
                            "chunk {chunk_index} of upload {upload_id} was already received; send chunk {} next",
                            u.next
                        ),
                    ));
                }
                if chunk_index > u.next {
                    return Err(Rejection::new(
                        Status::ChunkOutOfOrder,
                        format!(
                            "chunk {chunk_index} of upload {upload_id} arrived before chunk {}; send chunk {} next",
                            u.next, u.next
                        ),
                    ));
                }
                if let Err(e) = u.count(&deltas) {
                    let u = self.uploads.remove(&map).expect("present");
                    self.abandon(map, &u, "past a map's limits");
                    return Err(e);
                }
                u.take(deltas);
                u.next += 1;
                u.last_chunk = Instant::now();
            }
            Some(_) if chunk_index == 0 => {
                let old = self.uploads.remove(&map).expect("present");
                self.abandon(map, &old, "superseded by a new upload of the same map");
                self.start_upload(map, upload_id, chunk_count, replace, expected_version, bounds, sun, deltas)?;
            }
            Some(_) => return Err(self.incomplete_or_out_of_order(map, upload_id, chunk_index)),
            None if chunk_index == 0 => {
                self.start_upload(map, upload_id, chunk_count, replace, expected_version, bounds, sun, deltas)?;
            }
            None => return Err(self.incomplete_or_out_of_order(map, upload_id, chunk_index)),
        }
        let u = self.uploads.get(&map).expect("upload in progress");
        if u.next < u.chunk_count {
            return Ok(self.maps.get(&map).map_or(0, |w| w.version()));
        }
        let u = self.uploads.remove(&map).expect("upload in progress");
        let current = self.maps.get(&map).cloned();
        let version = match &current {
            Some(_) if !u.replace => {
                return Err(Rejection::new(
                    Status::MapExists,
                    format!("map {map} exists; upload with replace (`--replace`) to overwrite it, or pick another id"),
                ));
            }
            Some(w) => {
                check_version(map, w, u.expected_version)?;
                w.version() + 1
            }
            None => 0,
        };
        let world = world_from_content(version, u.bounds, u.sun, &u.deltas).map_err(|e| u.content_error(map, e))?;
        let what = format!("uploaded ({} chunks)", u.chunk_count);
        Ok(self.commit(map, world, &what, ChangeCause::Upload)?.version())
    }

    #[allow(clippy::too_many_arguments)]
    fn start_upload(
        &mut self,
        map: MapId,
        upload_id: u64,
        chunk_count: u32,
        replace: bool,
        expected_version: Option<u64>,
        bounds: Bounds,
        sun: Sun,
        deltas: Vec<MapDelta>,
    ) -> Result<(), Rejection> {
        if self.uploads.len() >= MAX_PENDING_UPLOADS {
            return Err(Rejection::new(
                Status::OverCapacity,
                format!("{MAX_PENDING_UPLOADS} uploads are in progress, the limit; retry when one completes"),
            ));
        }
        let mut upload = Upload {
            upload_id,
            chunk_count,
            next: 1,
            replace,
            expected_version,
            bounds,
            sun,
            deltas: Vec::new(),
            starts: Vec::new(),
            obstacles: 0,
            cells: 0,
            last_chunk: Instant::now(),
        };
        upload.count(&deltas)?;
        upload.take(deltas);
        self.uploads.insert(map, upload);
        Ok(())
    }

    /// The snapshot pages of `world` (a map's current world).
    fn pages(&mut self, world: &Arc<World>) -> Pages {
        self.pages.get(world)
    }
}

/// The reply to a map request, with the records to send.
struct Reply {
    header: MapReplyHeader,
    records: Option<(Arc<Vec<Vec<WireDelta>>>, usize)>,
}

fn handle(daemon: &mut Daemon, request: MapRequest) -> Result<Reply, Rejection> {
    let ok = |map: MapId, version: u64| Reply {
        header: MapReplyHeader { map_id: map, version, error_index: u64::MAX, ..Default::default() },
        records: None,
    };
    let maps = &mut daemon.maps;
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
            let version =
                maps.upload(map, upload_id, chunk_index, chunk_count, replace, expected_version, bounds, sun, deltas)?;
            let mut reply = ok(map, version);
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
        MapRequest::Delete { map, expected_version } => {
            let world = maps.get(map).ok_or_else(|| unknown_map(map))?;
            check_version(map, &world, expected_version)?;
            maps.store.remove(map).map_err(|e| {
                Rejection::new(
                    Status::StorageFailed,
                    format!("could not remove map {map}'s file ({e}); the map is unchanged"),
                )
            })?;
            maps.maps.remove(&map);
            maps.generations.remove(&map);
            // An upload in progress would otherwise make the map again at its last
            // chunk, undoing the delete: its later chunks get `chunk_incomplete`.
            if let Some(upload) = maps.uploads.remove(&map) {
                maps.abandon(map, &upload, "its map was deleted");
            }
            maps.record(map, ChangeCause::Delete, None, Vec::new(), None, world.version());
            info!(map, version = world.version(), "map deleted");
            Ok(ok(map, world.version()))
        }
        MapRequest::List { from } => {
            // No map at or after the cursor is the end of a listing, not an error.
            let mut at_or_after = maps.maps.range(from..);
            let mut reply = ok(from, 0);
            reply.header.chunk_count = u32::try_from(at_or_after.clone().count()).unwrap_or(u32::MAX);
            if let Some((id, world)) = at_or_after.next() {
                reply.header.map_id = *id;
                reply.header.version = world.version();
                reply.header.generation = maps.generation(*id);
                reply.header.bounds = world.bounds().to_array();
                reply.header.sun = [world.sun().elevation, world.sun().azimuth];
            }
            Ok(reply)
        }
    }
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

pub(super) fn on_request(daemon: &mut Daemon, active: MapActive) {
    let received = Instant::now();
    let header = *active.user_header();
    let reply_to = join_u128(header.reply_to);
    let recording = daemon.shared.recorder.is_some();
    let mut recorded: Option<(&'static str, serde_json::Value)> = None;
    let result = guarded("map", || {
        MapRequest::decode(&header, active.payload()).and_then(|request| {
            if recording {
                recorded = Some(request_json(&request));
            }
            handle(daemon, request)
        })
    });
    let reply = match result {
        Ok(reply) => {
            if let Ok(mut s) = daemon.shared.stats.lock() {
                s.map_ok();
            }
            if let (Some(recorder), Some((kind, request))) = (&daemon.shared.recorder, recorded.take()) {
                let h = &reply.header;
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
            reply
        }
        Err(rejection) => {
            debug!(request_id = header.request_id, map = header.map_id, status = %rejection.status, "map request rejected: {}", rejection.message);
            if let Ok(mut s) = daemon.shared.stats.lock() {
                s.failed(rejection.status);
            }
            Reply {
                header: MapReplyHeader {
                    status: rejection.status as u32,
                    map_id: header.map_id,
                    version: daemon.maps.get(header.map_id).map_or(0, |w| w.version()),
                    error_index: rejection.wire_index(),
                    detail: Detail::new(&rejection.message),
                    ..Default::default()
                },
                records: None,
            }
        }
    };
    let mut reply_header = reply.header;
    reply_header.request_id = header.request_id;
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
    daemon.shared.notify(reply_to);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_panic_while_handling_a_request_becomes_internal_error() {
        let answer: Result<u32, Rejection> = guarded("test", || panic!("a bug"));
        assert_eq!(answer.unwrap_err().status, Status::Internal);
        assert_eq!(guarded("test", || Ok(7)), Ok(7));
        let refused: Result<(), Rejection> = guarded("test", || Err(unknown_map(3)));
        assert_eq!(refused.unwrap_err().status, Status::UnknownMap);
    }

    fn grid_world(cells: i64) -> Arc<World> {
        let voxels = dyfos_shared::world::VoxelGrid::new(
            0.1,
            nalgebra::Point3::origin(),
            (0..cells).map(|i| [i % 256, (i / 256) % 256, i / 65_536]),
        )
        .unwrap();
        let bounds = Bounds::new([-1.0, -1.0, 30.0, 30.0]).unwrap();
        Arc::new(World::new(0, bounds, Sun::new(0.5, 0.0).unwrap(), std::iter::empty(), Some(voxels)).unwrap())
    }

    #[test]
    fn snapshot_pages_are_kept_for_the_world_they_were_made_from() {
        let mut cache = PageCache::default();
        let a = grid_world(19_200);
        let pages = cache.get(&a);
        assert!(pages.len() > 1 && Arc::ptr_eq(&pages, &cache.get(&a)), "kept");
        // Equal content, version and id, but another world (deleted and made again).
        let again = grid_world(19_200);
        assert_eq!(again.version(), a.version());
        assert!(!Arc::ptr_eq(&pages, &cache.get(&again)));
    }
}
