//! The maps the daemon holds: each current world, its generation, the store that
//! persists it, and the daemon-wide limits on them. Every accepted change is written
//! to the store before it is visible; a failed write leaves the map as it was.

use super::pages::{PageCache, Pages};
use super::upload::Uploads;
use crate::daemon::record::{ChangeCause, Record, TrafficRecorder, unix_ns};
use crate::daemon::reject::{check_version, unknown_map};
use crate::store::{Store, StoreOpenError, StoreSaveError};
use dyfos_shared::limits::{MAX_MAPS, MAX_TOTAL_VOXELS};
use dyfos_shared::wire::map::MapId;
use dyfos_shared::wire::{Rejection, Status};
use dyfos_shared::world::{MapDelta, World};
use std::collections::BTreeMap;
use std::sync::Arc;
use std::time::{Duration, SystemTime};
use tracing::{info, warn};

/// The maps, their store, uploads in progress and recent snapshots' pages.
pub(crate) struct Maps {
    maps: BTreeMap<MapId, Arc<World>>,
    /// Each map's generation (`MapReplyHeader::generation`): a map deleted and made
    /// again starts again at version 0, so its snapshot pages tell the two apart by this.
    generations: BTreeMap<MapId, u32>,
    /// The generation the next map made gets.
    next_generation: u32,
    store: Store,
    pub(super) uploads: Uploads,
    pages: PageCache,
    /// Where changes are recorded (`--record`).
    pub(crate) recorder: Option<Arc<TrafficRecorder>>,
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
            uploads: Uploads::new(upload_idle_timeout),
            pages: PageCache::default(),
            recorder: None,
        };
        for (id, world) in maps {
            this.made(id);
            this.maps.insert(id, Arc::new(world));
        }
        this
    }

    /// The maps of the state directory `state_dir` (at most [`MAX_MAPS`]); a file
    /// that cannot be loaded is quarantined and logged, not fatal.
    pub(crate) fn load(state_dir: &std::path::Path, upload_idle_timeout: Duration) -> Result<Self, StoreOpenError> {
        let store = Store::open(state_dir)?;
        let loaded = store.load_all();
        for q in &loaded.quarantined {
            warn!(file = %q.file.display(), moved_to = ?q.moved_to, "map file could not be loaded and was quarantined: {}", q.reason);
        }
        for (journal, torn) in &loaded.repaired {
            warn!(file = %journal.display(), "map journal ended in a torn record (a crash while writing an unacknowledged change); cut off: {torn}");
        }
        if loaded.maps.len() > MAX_MAPS {
            warn!(
                "{} maps in the state directory, more than the limit of {MAX_MAPS}; only the first are served",
                loaded.maps.len()
            );
        }
        Ok(Maps::new(store, loaded.maps.into_iter().take(MAX_MAPS), upload_idle_timeout))
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

    /// The maps with ids from `from` on, in id order.
    pub(crate) fn from(&self, from: MapId) -> impl Iterator<Item = (MapId, &Arc<World>)> + Clone {
        self.maps.range(from..).map(|(id, w)| (*id, w))
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

    /// Deletes map `map` (at `expected_version`, if given) from the store, then from
    /// memory; returns the version deleted. An upload of it in progress is abandoned.
    pub(crate) fn delete(&mut self, map: MapId, expected_version: Option<u64>) -> Result<u64, Rejection> {
        let world = self.get(map).ok_or_else(|| unknown_map(map))?;
        check_version(map, &world, expected_version)?;
        self.store.remove(map).map_err(|e| {
            Rejection::new(
                Status::StorageFailed,
                format!("could not remove map {map}'s file ({e}); the map is unchanged"),
            )
        })?;
        self.maps.remove(&map);
        self.generations.remove(&map);
        // An upload in progress would otherwise make the map again at its last
        // chunk, undoing the delete: its later chunks get `chunk_incomplete`.
        self.uploads.abandon(map, "its map was deleted");
        self.record(map, ChangeCause::Delete, None, Vec::new(), None, world.version());
        info!(map, version = world.version(), "map deleted");
        Ok(world.version())
    }

    /// Abandons uploads idle for longer than the timeout.
    pub(crate) fn expire_uploads(&mut self) {
        self.uploads.expire();
    }

    /// The snapshot pages of `world` (a map's current world).
    pub(crate) fn pages(&mut self, world: &Arc<World>) -> Pages {
        self.pages.get(world)
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
}
