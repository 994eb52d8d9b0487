//! Chunked uploads: a map too large for one message arrives in chunks, in order,
//! and is made only once its last chunk is in ([`Maps::upload`]). Until then the
//! chunks wait in an [`Uploads`] session per map, bounded by what one map may hold;
//! a session is abandoned when a new upload of its map starts, its map is deleted,
//! it passes a map's limits or no chunk comes for `upload_idle_timeout`.

use super::registry::Maps;
use crate::daemon::record::ChangeCause;
use crate::daemon::reject::{check_version, delta_status};
use dyfos_shared::limits::{MAX_OBSTACLES, MAX_OCCUPIED_VOXELS, MAX_PENDING_UPLOADS};
use dyfos_shared::wire::map::{MapId, world_from_content};
use dyfos_shared::wire::{Rejection, Status};
use dyfos_shared::world::{Bounds, MapDelta, MapDeltaError, Sun};
use std::collections::{BTreeMap, VecDeque};
use std::time::{Duration, Instant};
use tracing::warn;

/// Abandoned uploads remembered, so their late chunks get `chunk_incomplete`.
const ABANDONED_MEMORY: usize = 64;

/// One chunk of an upload, as decoded (`MapRequest::Upload`).
#[derive(Debug, Clone)]
pub(crate) struct Chunk {
    pub(crate) upload_id: u64,
    pub(crate) chunk_index: u32,
    pub(crate) chunk_count: u32,
    pub(crate) replace: bool,
    pub(crate) expected_version: Option<u64>,
    pub(crate) bounds: Bounds,
    pub(crate) sun: Sun,
    pub(crate) deltas: Vec<MapDelta>,
}

impl Maps {
    /// One upload chunk. Returns the map's version: the new one once the last chunk
    /// made the map, else the current one (0 for a map not there yet).
    pub(crate) fn upload(&mut self, map: MapId, chunk: Chunk) -> Result<u64, Rejection> {
        let Some(u) = self.uploads.take(map, chunk)? else {
            return Ok(self.get(map).map_or(0, |w| w.version()));
        };
        let version = match self.get(map) {
            Some(_) if !u.replace => {
                return Err(Rejection::new(
                    Status::MapExists,
                    format!("map {map} exists; upload with replace (`--replace`) to overwrite it, or pick another id"),
                ));
            }
            Some(w) => {
                check_version(map, &w, u.expected_version)?;
                w.version() + 1
            }
            None => 0,
        };
        let world = world_from_content(version, u.bounds, u.sun, &u.deltas).map_err(|e| u.content_error(map, e))?;
        let what = format!("uploaded ({} chunks)", u.chunk_count);
        Ok(self.commit(map, world, &what, ChangeCause::Upload)?.version())
    }
}

/// The uploads in progress, one per map at most, and the last ones abandoned.
pub(crate) struct Uploads {
    open: BTreeMap<MapId, Upload>,
    abandoned: VecDeque<(MapId, u64)>,
    idle_timeout: Duration,
}

impl Uploads {
    /// None in progress; an upload with no chunk for `idle_timeout` is abandoned.
    pub(crate) fn new(idle_timeout: Duration) -> Self {
        Uploads { open: BTreeMap::new(), abandoned: VecDeque::new(), idle_timeout }
    }

    /// Takes in one chunk of an upload of `map`: `None` while chunks are missing,
    /// the whole upload once its last chunk is in (and no longer in progress).
    pub(crate) fn take(&mut self, map: MapId, chunk: Chunk) -> Result<Option<Upload>, Rejection> {
        let Chunk { upload_id, chunk_index, chunk_count, .. } = chunk;
        match self.open.get_mut(&map) {
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
                if let Err(e) = u.count(&chunk.deltas) {
                    self.abandon(map, "past a map's limits");
                    return Err(e);
                }
                u.append(chunk.deltas);
                u.next += 1;
                u.last_chunk = Instant::now();
            }
            Some(_) if chunk_index == 0 => {
                self.abandon(map, "superseded by a new upload of the same map");
                self.start(map, chunk)?;
            }
            None if chunk_index == 0 => self.start(map, chunk)?,
            Some(_) | None => return Err(self.incomplete_or_out_of_order(map, upload_id, chunk_index)),
        }
        if self.open.get(&map).is_some_and(|u| u.next < u.chunk_count) {
            return Ok(None);
        }
        Ok(self.open.remove(&map))
    }

    fn start(&mut self, map: MapId, chunk: Chunk) -> Result<(), Rejection> {
        if self.open.len() >= MAX_PENDING_UPLOADS {
            return Err(Rejection::new(
                Status::OverCapacity,
                format!("{MAX_PENDING_UPLOADS} uploads are in progress, the limit; retry when one completes"),
            ));
        }
        let mut upload = Upload {
            upload_id: chunk.upload_id,
            chunk_count: chunk.chunk_count,
            next: 1,
            replace: chunk.replace,
            expected_version: chunk.expected_version,
            bounds: chunk.bounds,
            sun: chunk.sun,
            deltas: Vec::new(),
            starts: Vec::new(),
            obstacles: 0,
            cells: 0,
            last_chunk: Instant::now(),
        };
        upload.count(&chunk.deltas)?;
        upload.append(chunk.deltas);
        self.open.insert(map, upload);
        Ok(())
    }

    /// Abandons the upload of `map` in progress, if any.
    pub(crate) fn abandon(&mut self, map: MapId, why: &str) {
        let Some(upload) = self.open.remove(&map) else { return };
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
    pub(crate) fn expire(&mut self) {
        let timeout = self.idle_timeout;
        let stale: Vec<MapId> =
            self.open.iter().filter(|(_, u)| u.last_chunk.elapsed() > timeout).map(|(id, _)| *id).collect();
        for id in stale {
            self.abandon(id, "no chunk for too long");
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
}

/// An upload in progress.
pub(crate) struct Upload {
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
    fn append(&mut self, deltas: Vec<MapDelta>) {
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::store::Store;
    use dyfos_shared::world::{Obstacle, VerticalCylinder, World};

    fn bounds() -> Bounds {
        Bounds::new([-10.0, -10.0, 10.0, 10.0]).unwrap()
    }

    fn sun() -> Sun {
        Sun::new(0.5, 0.0).unwrap()
    }

    /// An obstacle upsert with id `id`.
    fn pillar(id: u32) -> MapDelta {
        let obstacle = Obstacle::Cylinder(VerticalCylinder {
            center: nalgebra::Point2::new(f64::from(id), 0.0),
            radius: 0.2,
            height: 1.0,
        });
        MapDelta::UpsertObstacle { id, obstacle }
    }

    fn chunk(upload_id: u64, chunk_index: u32, chunk_count: u32) -> Chunk {
        Chunk {
            upload_id,
            chunk_index,
            chunk_count,
            replace: false,
            expected_version: None,
            bounds: bounds(),
            sun: sun(),
            deltas: vec![pillar(chunk_index)],
        }
    }

    fn status(result: Result<Option<Upload>, Rejection>) -> Status {
        result.err().expect("refused").status
    }

    /// Maps in a fresh state directory, removed on drop.
    struct Scratch(std::path::PathBuf, Maps);

    impl Scratch {
        fn new(name: &str) -> Scratch {
            let dir = std::env::temp_dir().join(format!("dyfos-upload-{name}-{}", std::process::id()));
            let _ = std::fs::remove_dir_all(&dir);
            let maps = Maps::new(Store::open(&dir).unwrap(), std::iter::empty(), Duration::from_secs(60));
            Scratch(dir, maps)
        }
    }

    impl Drop for Scratch {
        fn drop(&mut self) {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }

    #[test]
    fn chunks_in_order_complete_the_upload_with_every_delta() {
        let mut uploads = Uploads::new(Duration::from_secs(60));
        assert!(uploads.take(1, chunk(7, 0, 3)).unwrap().is_none());
        assert!(uploads.take(1, chunk(7, 1, 3)).unwrap().is_none());
        let done = uploads.take(1, chunk(7, 2, 3)).unwrap().expect("complete");
        assert_eq!(done.deltas.len(), 3);
        assert_eq!(done.starts, [0, 1, 2]);
        // No longer in progress: a late chunk names no upload.
        assert_eq!(status(uploads.take(1, chunk(7, 2, 3))), Status::ChunkOutOfOrder);
    }

    #[test]
    fn a_chunk_out_of_order_or_twice_is_refused_and_the_upload_goes_on() {
        let mut uploads = Uploads::new(Duration::from_secs(60));
        // Nothing in progress: only a chunk 0 starts an upload.
        assert_eq!(status(uploads.take(1, chunk(7, 1, 3))), Status::ChunkOutOfOrder);
        uploads.take(1, chunk(7, 0, 3)).unwrap();
        assert_eq!(status(uploads.take(1, chunk(7, 2, 3))), Status::ChunkOutOfOrder, "chunk 1 is missing");
        uploads.take(1, chunk(7, 1, 3)).unwrap();
        assert_eq!(status(uploads.take(1, chunk(7, 1, 3))), Status::ChunkDuplicate);
        assert_eq!(status(uploads.take(1, chunk(7, 2, 4))), Status::MalformedRequest, "another chunk_count");
        let done = uploads.take(1, chunk(7, 2, 3)).unwrap().expect("complete");
        assert_eq!(done.deltas, [pillar(0), pillar(1), pillar(2)], "refused chunks left nothing behind");
    }

    #[test]
    fn a_new_upload_of_the_map_abandons_the_old_one() {
        let mut uploads = Uploads::new(Duration::from_secs(60));
        uploads.take(1, chunk(7, 0, 2)).unwrap();
        uploads.take(2, chunk(7, 0, 2)).unwrap(); // another map: independent
        uploads.take(1, chunk(8, 0, 2)).unwrap();
        assert_eq!(status(uploads.take(1, chunk(7, 1, 2))), Status::ChunkIncomplete, "superseded");
        assert!(uploads.take(1, chunk(8, 1, 2)).unwrap().is_some());
        assert!(uploads.take(2, chunk(7, 1, 2)).unwrap().is_some());
    }

    #[test]
    fn an_upload_past_a_maps_limits_is_abandoned() {
        let mut uploads = Uploads::new(Duration::from_secs(60));
        let full = |index| Chunk { deltas: (0..=MAX_OBSTACLES as u32 / 2).map(pillar).collect(), ..chunk(7, index, 3) };
        uploads.take(1, full(0)).unwrap();
        assert_eq!(status(uploads.take(1, full(1))), Status::OverCapacity);
        assert_eq!(status(uploads.take(1, chunk(7, 2, 3))), Status::ChunkIncomplete);
    }

    #[test]
    fn uploads_in_progress_are_limited_and_idle_ones_expire() {
        let mut uploads = Uploads::new(Duration::ZERO);
        for map in 0..MAX_PENDING_UPLOADS as MapId {
            uploads.take(map, chunk(7, 0, 2)).unwrap();
        }
        assert_eq!(status(uploads.take(MAX_PENDING_UPLOADS as MapId, chunk(7, 0, 2))), Status::OverCapacity);
        std::thread::sleep(Duration::from_millis(1));
        uploads.expire();
        assert_eq!(status(uploads.take(0, chunk(7, 1, 2))), Status::ChunkIncomplete);
        assert!(uploads.take(MAX_PENDING_UPLOADS as MapId, chunk(7, 0, 2)).is_ok());
    }

    #[test]
    fn a_completed_upload_makes_the_map_unless_its_version_is_stale() {
        let mut s = Scratch::new("stale");
        let maps = &mut s.1;
        maps.upload(1, chunk(7, 0, 2)).unwrap();
        assert!(maps.get(1).is_none(), "not before its last chunk");
        assert_eq!(maps.upload(1, chunk(7, 1, 2)).unwrap(), 0);
        assert_eq!(maps.get(1).unwrap().obstacles().len(), 2);
        // Without replace, an existing map stays.
        assert_eq!(maps.upload(1, chunk(9, 0, 1)).unwrap_err().status, Status::MapExists);
        // Replacing: only at the version expected.
        let stale = Chunk { replace: true, expected_version: Some(5), ..chunk(10, 0, 1) };
        assert_eq!(maps.upload(1, stale).unwrap_err().status, Status::MapVersionMismatch);
        assert_eq!(maps.get(1).unwrap().version(), 0, "nothing changed");
        let current = Chunk { replace: true, expected_version: Some(0), ..chunk(11, 0, 1) };
        assert_eq!(maps.upload(1, current).unwrap(), 1);
        assert_eq!(maps.get(1).unwrap().obstacles().len(), 1);
    }

    #[test]
    fn deleting_a_map_abandons_its_upload() {
        let mut s = Scratch::new("delete");
        let maps = &mut s.1;
        maps.commit(1, World::empty(bounds(), sun()), "created", ChangeCause::Create).unwrap();
        let replace = |index| Chunk { replace: true, ..chunk(7, index, 2) };
        maps.upload(1, replace(0)).unwrap();
        maps.delete(1, None).unwrap();
        // The last chunk must not make the deleted map again.
        assert_eq!(maps.upload(1, replace(1)).unwrap_err().status, Status::ChunkIncomplete);
        assert!(maps.get(1).is_none());
    }
}
