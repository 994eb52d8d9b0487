//! The daemon's map persistence: per map, a base file and a journal of changes.
//!
//! `map-<id>.bin` holds the whole map at some version (bincode 2 over serde), written
//! to `map-<id>.bin.tmp`, synced and renamed over the old one, so a crash at any moment
//! leaves either the old or the new base, never half of one. Creating, uploading or
//! replacing a map writes a new base. Applying deltas appends one record to
//! `map-<id>.log` and syncs it: the version before, the deltas, framed by length and
//! checksum. So an update costs what it changes, not what the map holds (a 10 000-cell
//! update of a 50 M-cell map appends ~100 KB, it does not rewrite 100 MB). When the
//! journal outgrows the base (and 16 MiB), the next change writes a new base and
//! removes the journal.
//!
//! On start every `map-*.bin` is read back with its journal replayed on top and
//! validated. A journal whose last record is torn (a crash while appending, before
//! the change was acknowledged) is cut back to its last whole record and reported; a
//! base or journal that cannot be read is renamed to `*.corrupt-<unix seconds>` and
//! reported, and the start goes on. Files of format 1 (whole map with a cell list,
//! before journals) are still read.
//!
//! ```
//! use dyfos_service::store::Store;
//! use dyfos_shared::world::{Bounds, MapDelta, Sun, World};
//!
//! let dir = std::env::temp_dir().join(format!("dyfos-store-doc-{}", std::process::id()));
//! let store = Store::open(&dir).unwrap();
//! let world = World::empty(Bounds::new([-5.0, -5.0, 5.0, 5.0]).unwrap(), Sun::new(0.4, 1.0).unwrap());
//! store.save(7, &world).unwrap();
//! let deltas = vec![MapDelta::SetSun(Sun::new(0.5, 1.0).unwrap())];
//! let next = world.apply(&deltas).unwrap();
//! store.append(7, world.version(), &deltas, &next).unwrap();
//! let loaded = store.load_all();
//! assert_eq!(loaded.maps, vec![(7, next)]);
//! assert!(loaded.quarantined.is_empty());
//! # std::fs::remove_dir_all(&dir).unwrap();
//! ```

use dyfos_shared::math::Point3;
use dyfos_shared::wire::map::MapId;
use dyfos_shared::world::{Bounds, MapDelta, Obstacle, Sun, VoxelBlock, VoxelGrid, World};
use std::fs;
use std::io::Write;
use std::path::{Path, PathBuf};

/// Format tag written first in every base file; bump when [`StoredMap`] changes.
const FORMAT: u32 = 2;

/// Largest base file read back (bincode refuses to allocate beyond it).
const MAX_FILE_BYTES: usize = 1 << 30;

/// Largest journal record: a batch of inline or applied deltas (4096 records of at
/// most 64 cells each, as bincode), with room to spare.
const MAX_RECORD_BYTES: usize = 64 << 20;

/// A journal longer than this and than its base is folded into a new base.
const COMPACT_AFTER_BYTES: u64 = 16 << 20;

/// A map as written to a base file; `V` is how its format writes the voxels.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
struct StoredMap<V = StoredVoxels> {
    format: u32,
    id: MapId,
    version: u64,
    bounds: Bounds,
    sun: Sun,
    obstacles: Vec<(u32, Obstacle)>,
    voxels: Option<V>,
}

#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
struct StoredVoxels {
    resolution: f64,
    origin: Point3<f64>,
    blocks: Vec<VoxelBlock>,
}

/// Format 1: the voxels as a cell list.
type StoredMapV1 = StoredMap<StoredVoxelsV1>;

#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
struct StoredVoxelsV1 {
    resolution: f64,
    origin: Point3<f64>,
    cells: Vec<[i64; 3]>,
}

/// One journal record's payload: `deltas` applied to the map at `version`.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
struct JournalEntry {
    id: MapId,
    version: u64,
    deltas: Vec<MapDelta>,
}

/// Why the state directory cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum StoreOpenError {
    /// It cannot be created or written.
    #[error("state directory {path}: {source}; pick a writable directory with --state-dir")]
    Io {
        /// The directory.
        path: PathBuf,
        /// The cause.
        #[source]
        source: std::io::Error,
    },
}

/// Why a map could not be written.
#[derive(Debug, thiserror::Error)]
pub enum StoreSaveError {
    /// Encoding failed (cannot happen for valid maps).
    #[error("encoding map {id}: {source}")]
    Encode {
        /// The map.
        id: MapId,
        /// The cause.
        #[source]
        source: bincode::error::EncodeError,
    },
    /// Writing, syncing or renaming failed (disk full, permissions).
    #[error("writing {path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        #[source]
        source: std::io::Error,
    },
}

/// A file that could not be loaded and was moved aside.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Quarantined {
    /// Where the file was.
    pub file: PathBuf,
    /// Where it is now (`None` if even the rename failed).
    pub moved_to: Option<PathBuf>,
    /// What was wrong.
    pub reason: String,
}

/// What [`Store::load_all`] found.
#[derive(Debug, Default)]
pub struct Loaded {
    /// Valid maps, by id.
    pub maps: Vec<(MapId, World)>,
    /// Files moved aside.
    pub quarantined: Vec<Quarantined>,
    /// Journals whose torn last record was cut off: (file, what was dropped).
    pub repaired: Vec<(PathBuf, String)>,
}

/// The state directory.
#[derive(Debug, Clone)]
pub struct Store {
    dir: PathBuf,
}

fn config() -> impl bincode::config::Config {
    bincode::config::standard().with_limit::<MAX_FILE_BYTES>()
}

/// FNV-1a, 64 bit: the journal records' checksum (torn writes, not attackers).
fn checksum(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf29ce484222325u64, |h, b| (h ^ u64::from(*b)).wrapping_mul(0x100000001b3))
}

fn sync_dir(dir: &Path) {
    if let Ok(d) = fs::File::open(dir) {
        let _ = d.sync_all();
    }
}

impl Store {
    /// Opens (creating if needed) the state directory and removes leftover
    /// temporary files of an interrupted write.
    pub fn open(dir: &Path) -> Result<Store, StoreOpenError> {
        let io = |source| StoreOpenError::Io { path: dir.to_path_buf(), source };
        fs::create_dir_all(dir).map_err(io)?;
        for entry in fs::read_dir(dir).map_err(io)?.flatten() {
            if entry.file_name().to_string_lossy().ends_with(".bin.tmp") {
                let _ = fs::remove_file(entry.path());
            }
        }
        // Fail now, not at the first map change, if the directory is read-only.
        let probe = dir.join(".write-probe");
        fs::write(&probe, b"").map_err(io)?;
        let _ = fs::remove_file(&probe);
        Ok(Store { dir: dir.to_path_buf() })
    }

    /// The directory.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// The base file of map `id`.
    pub fn path_of(&self, id: MapId) -> PathBuf {
        self.dir.join(format!("map-{id}.bin"))
    }

    /// The journal of map `id`.
    pub fn journal_of(&self, id: MapId) -> PathBuf {
        self.dir.join(format!("map-{id}.log"))
    }

    /// Writes `world` as map `id`'s new base, atomically, and drops its journal.
    pub fn save(&self, id: MapId, world: &World) -> Result<(), StoreSaveError> {
        let stored = StoredMap {
            format: FORMAT,
            id,
            version: world.version(),
            bounds: *world.bounds(),
            sun: *world.sun(),
            obstacles: world.obstacles().iter().map(|(i, o)| (*i, *o)).collect(),
            voxels: world.voxels().map(|v| StoredVoxels {
                resolution: v.resolution(),
                origin: v.origin(),
                blocks: v.blocks().collect(),
            }),
        };
        let bytes =
            bincode::serde::encode_to_vec(&stored, config()).map_err(|source| StoreSaveError::Encode { id, source })?;
        let path = self.path_of(id);
        let tmp = path.with_extension("bin.tmp");
        let io = |source| StoreSaveError::Io { path: path.clone(), source };
        let mut file = fs::File::create(&tmp).map_err(io)?;
        file.write_all(&bytes).map_err(io)?;
        file.sync_all().map_err(io)?;
        drop(file);
        fs::rename(&tmp, &path).map_err(io)?;
        // The journal's records are in the new base now; a crash before it is gone
        // leaves records older than the base, which loading skips.
        match fs::remove_file(self.journal_of(id)) {
            Ok(()) => {}
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
            Err(source) => return Err(StoreSaveError::Io { path: self.journal_of(id), source }),
        }
        // Make the rename and the removal durable.
        sync_dir(&self.dir);
        Ok(())
    }

    /// Records that `deltas`, applied to map `id` at `version`, made `next`: one
    /// synced journal record, or a new base when the journal has outgrown it.
    pub fn append(&self, id: MapId, version: u64, deltas: &[MapDelta], next: &World) -> Result<(), StoreSaveError> {
        let journal = self.journal_of(id);
        let base_len = fs::metadata(self.path_of(id)).map_or(0, |m| m.len());
        let journal_len = fs::metadata(&journal).map_or(0, |m| m.len());
        if base_len == 0 || (journal_len > COMPACT_AFTER_BYTES && journal_len > base_len) {
            return self.save(id, next);
        }
        let entry = JournalEntry { id, version, deltas: deltas.to_vec() };
        let payload =
            bincode::serde::encode_to_vec(&entry, config()).map_err(|source| StoreSaveError::Encode { id, source })?;
        if payload.len() > MAX_RECORD_BYTES {
            return self.save(id, next);
        }
        let mut record = Vec::with_capacity(payload.len() + 12);
        record.extend_from_slice(&(payload.len() as u32).to_le_bytes());
        record.extend_from_slice(&checksum(&payload).to_le_bytes());
        record.extend_from_slice(&payload);
        let io = |source| StoreSaveError::Io { path: journal.clone(), source };
        let mut file = fs::OpenOptions::new().create(true).append(true).open(&journal).map_err(io)?;
        if let Err(e) = file.write_all(&record).and_then(|()| file.sync_data()) {
            // Leave no partial record behind for the next append to follow.
            let _ = file.set_len(journal_len);
            return Err(io(e));
        }
        if journal_len == 0 {
            sync_dir(&self.dir);
        }
        Ok(())
    }

    /// Removes map `id`'s files.
    pub fn remove(&self, id: MapId) -> Result<(), StoreSaveError> {
        for path in [self.journal_of(id), self.path_of(id)] {
            match fs::remove_file(&path) {
                Ok(()) => {}
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
                Err(source) => return Err(StoreSaveError::Io { path, source }),
            }
        }
        Ok(())
    }

    /// Reads every map (base, then journal); unreadable files are quarantined.
    pub fn load_all(&self) -> Loaded {
        let mut loaded = Loaded::default();
        let Ok(entries) = fs::read_dir(&self.dir) else {
            return loaded;
        };
        let mut files: Vec<(MapId, PathBuf)> = entries
            .flatten()
            .filter_map(|e| {
                let name = e.file_name().to_string_lossy().into_owned();
                let id = name.strip_prefix("map-")?.strip_suffix(".bin")?.parse::<MapId>().ok()?;
                Some((id, e.path()))
            })
            .collect();
        files.sort();
        let stamp = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_secs());
        let quarantine = |file: PathBuf, reason: String, loaded: &mut Loaded| {
            let name = file.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
            let target = file.with_file_name(format!("{name}.corrupt-{stamp}"));
            let moved_to = fs::rename(&file, &target).ok().map(|()| target);
            loaded.quarantined.push(Quarantined { file, moved_to, reason });
        };
        for (id, file) in files {
            let journal = self.journal_of(id);
            match read_map(&file, id) {
                Ok(world) => match replay(&journal, id, world) {
                    Ok((world, torn)) => {
                        if let Some(torn) = torn {
                            loaded.repaired.push((journal, torn));
                        }
                        loaded.maps.push((id, world));
                    }
                    Err(reason) => {
                        quarantine(journal, reason.clone(), &mut loaded);
                        quarantine(file, format!("its journal is unusable: {reason}"), &mut loaded);
                    }
                },
                Err(reason) => {
                    quarantine(file, reason, &mut loaded);
                    if journal.exists() {
                        quarantine(journal, "its base file is unusable".into(), &mut loaded);
                    }
                }
            }
        }
        loaded
    }
}

fn read_map(file: &Path, id: MapId) -> Result<World, String> {
    let bytes = fs::read(file).map_err(|e| format!("cannot read: {e}"))?;
    let (format, _): (u32, usize) =
        bincode::serde::decode_from_slice(&bytes, config()).map_err(|e| format!("not a map file: {e}"))?;
    let (stored_id, version, bounds, sun, obstacles, voxels) = match format {
        FORMAT => {
            let stored: StoredMap = decode_whole(&bytes)?;
            let voxels = match stored.voxels {
                None => None,
                Some(v) => Some(
                    VoxelGrid::empty(v.resolution, v.origin)
                        .and_then(|g| g.with_blocks(&v.blocks, true))
                        .map_err(|e| e.to_string())?,
                ),
            };
            (stored.id, stored.version, stored.bounds, stored.sun, stored.obstacles, voxels)
        }
        1 => {
            let stored: StoredMapV1 = decode_whole(&bytes)?;
            let voxels = match stored.voxels {
                None => None,
                Some(v) => Some(VoxelGrid::new(v.resolution, v.origin, v.cells).map_err(|e| e.to_string())?),
            };
            (stored.id, stored.version, stored.bounds, stored.sun, stored.obstacles, voxels)
        }
        f => return Err(format!("format {f} is not a supported one (1 or {FORMAT})")),
    };
    if stored_id != id {
        return Err(format!("the file holds map {stored_id}, its name says {id}"));
    }
    let bounds = Bounds::new(bounds.to_array()).map_err(|e| e.to_string())?;
    let sun = Sun::new(sun.elevation, sun.azimuth).map_err(|e| e.to_string())?;
    World::new(version, bounds, sun, obstacles, voxels).map_err(|e| e.to_string())
}

fn decode_whole<T: serde::de::DeserializeOwned>(bytes: &[u8]) -> Result<T, String> {
    let (value, used): (T, usize) =
        bincode::serde::decode_from_slice(bytes, config()).map_err(|e| format!("not a map file: {e}"))?;
    if used != bytes.len() {
        return Err(format!("{} trailing bytes after the map", bytes.len() - used));
    }
    Ok(value)
}

/// `world` with the journal's records applied. A torn last record (short, or its
/// checksum wrong) is cut off the file and described in the second value; records
/// older than the base (a crash between a new base and the journal's removal) are
/// skipped. Anything else wrong is an error.
fn replay(journal: &Path, id: MapId, mut world: World) -> Result<(World, Option<String>), String> {
    let bytes = match fs::read(journal) {
        Ok(b) => b,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok((world, None)),
        Err(e) => return Err(format!("cannot read {}: {e}", journal.display())),
    };
    let mut at = 0usize;
    let mut torn = None;
    while at < bytes.len() {
        let rest = &bytes[at..];
        let whole = rest.len() >= 12 && {
            let len = u32::from_le_bytes(rest[..4].try_into().expect("4 bytes")) as usize;
            len <= MAX_RECORD_BYTES
                && rest.len() - 12 >= len
                && checksum(&rest[12..12 + len]) == u64::from_le_bytes(rest[4..12].try_into().expect("8 bytes"))
        };
        if !whole {
            torn = Some(format!("{} bytes of a torn last record after {at} good bytes", rest.len()));
            break;
        }
        let len = u32::from_le_bytes(rest[..4].try_into().expect("4 bytes")) as usize;
        let payload = &rest[12..12 + len];
        let (entry, used): (JournalEntry, usize) = bincode::serde::decode_from_slice(payload, config())
            .map_err(|e| format!("record at byte {at}: not a journal record: {e}"))?;
        if used != len || entry.id != id {
            return Err(format!("record at byte {at}: names map {} or has stray bytes", entry.id));
        }
        let end_version = entry.version.saturating_add(entry.deltas.len() as u64);
        if end_version <= world.version() && entry.version < world.version() {
            // Already in the base.
        } else if entry.version == world.version() {
            world = world.apply(&entry.deltas).map_err(|e| format!("record at byte {at}: {e}"))?;
        } else {
            return Err(format!(
                "record at byte {at} applies to version {}, the map is at {}: a record is missing",
                entry.version,
                world.version()
            ));
        }
        at += 12 + len;
    }
    if torn.is_some() {
        let cut = fs::OpenOptions::new().write(true).open(journal).and_then(|f| f.set_len(at as u64));
        cut.map_err(|e| format!("cannot cut the torn record off {}: {e}", journal.display()))?;
    }
    Ok((world, torn))
}

#[cfg(test)]
mod tests {
    use super::*;
    use dyfos_shared::math::Point2;
    use dyfos_shared::world::VerticalCylinder;

    fn temp_dir(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("dyfos-store-{name}-{}", std::process::id()));
        let _ = fs::remove_dir_all(&dir);
        dir
    }

    #[test]
    fn saves_reloads_and_quarantines_corrupt_files() {
        let dir = temp_dir("roundtrip");
        let store = Store::open(&dir).unwrap();
        let pole = Obstacle::Cylinder(VerticalCylinder { center: Point2::new(1.0, 2.0), radius: 0.5, height: 3.0 });
        let voxels = VoxelGrid::new(0.5, Point3::origin(), [[1, 2, 3], [4, 5, 6]]).unwrap();
        let world = World::new(
            9,
            Bounds::new([-5.0, -5.0, 5.0, 5.0]).unwrap(),
            Sun::new(0.4, 1.0).unwrap(),
            [(3, pole)],
            Some(voxels),
        )
        .unwrap();
        store.save(1, &world).unwrap();
        store.save(2, &world).unwrap();
        // Corrupt map 2: truncate it. Also a file whose content names another map.
        let bytes = fs::read(store.path_of(2)).unwrap();
        fs::write(store.path_of(2), &bytes[..bytes.len() / 2]).unwrap();
        fs::copy(store.path_of(1), store.path_of(5)).unwrap();
        fs::write(dir.join("map-3.bin.tmp"), b"half written").unwrap();
        let store = Store::open(&dir).unwrap();
        assert!(!dir.join("map-3.bin.tmp").exists());
        let loaded = store.load_all();
        assert_eq!(loaded.maps, vec![(1, world)]);
        assert_eq!(loaded.quarantined.len(), 2, "{:?}", loaded.quarantined);
        assert!(loaded.quarantined.iter().all(|q| q.moved_to.as_ref().is_some_and(|p| p.exists())));
        assert!(!store.path_of(2).exists() && !store.path_of(5).exists());
        store.remove(1).unwrap();
        assert!(store.load_all().maps.is_empty());
        fs::remove_dir_all(&dir).unwrap();
    }

    /// Deltas go to the journal and come back on load; a torn last record is cut
    /// off and reported; records already in a newer base are skipped; a base of
    /// format 1 (a cell list) is still read; a journal with a gap is quarantined.
    #[test]
    fn journal_replays_repairs_and_skips() {
        let dir = temp_dir("journal");
        let store = Store::open(&dir).unwrap();
        let base = World::empty(Bounds::new([-5.0, -5.0, 5.0, 5.0]).unwrap(), Sun::new(0.4, 1.0).unwrap());
        store.save(1, &base).unwrap();
        let mut world = base.clone();
        let mut sizes = Vec::new();
        for i in 0..5i64 {
            let deltas = vec![MapDelta::SetVoxels {
                resolution: 0.5,
                origin: Point3::origin(),
                cells: (0..100).map(|k| [i, k, 0]).collect(),
                occupied: true,
            }];
            let next = world.apply(&deltas).unwrap();
            store.append(1, world.version(), &deltas, &next).unwrap();
            world = next;
            sizes.push(fs::metadata(store.journal_of(1)).unwrap().len());
        }
        let loaded = store.load_all();
        assert_eq!(loaded.maps, vec![(1, world.clone())]);
        assert!(loaded.repaired.is_empty() && loaded.quarantined.is_empty());
        assert_eq!(world.voxels().unwrap().len(), 500);

        // A crash in the middle of the last append: cut back to four records.
        let journal = store.journal_of(1);
        let bytes = fs::read(&journal).unwrap();
        fs::write(&journal, &bytes[..(sizes[3] as usize + 7)]).unwrap();
        let loaded = store.load_all();
        assert_eq!(loaded.maps[0].1.version(), 4);
        assert_eq!(loaded.repaired.len(), 1, "{:?}", loaded.repaired);
        assert_eq!(fs::metadata(&journal).unwrap().len(), sizes[3]);

        // A new base at version 4 written, the crash before the journal went: the
        // journal's records are older than the base and skipped.
        let at4 = loaded.maps[0].1.clone();
        fs::write(&journal, &bytes[..sizes[3] as usize]).unwrap();
        let stale = fs::read(&journal).unwrap();
        store.save(1, &at4).unwrap();
        assert!(!journal.exists());
        fs::write(&journal, &stale).unwrap();
        let loaded = store.load_all();
        assert_eq!(loaded.maps, vec![(1, at4.clone())]);

        // A record whose version does not follow: quarantined with its base.
        // A journal of another map: quarantined too.
        store.save(1, &base).unwrap();
        fs::write(&journal, &bytes[sizes[3] as usize..]).unwrap();
        store.save(2, &base).unwrap();
        fs::write(store.journal_of(2), &bytes[..sizes[0] as usize]).unwrap();
        let loaded = store.load_all();
        assert!(loaded.maps.is_empty(), "{:?}", loaded.maps);
        let reasons: Vec<&str> = loaded.quarantined.iter().map(|q| q.reason.as_str()).collect();
        assert!(reasons.iter().any(|r| r.contains("version 4, the map is at 0: a record is missing")), "{reasons:?}");
        assert!(reasons.iter().any(|r| r.contains("names map 1")), "{reasons:?}");
        assert_eq!(reasons.len(), 4, "{reasons:?}");

        // Format 1, as earlier releases wrote it.
        let v1 = StoredMapV1 {
            format: 1,
            id: 3,
            version: 9,
            bounds: *base.bounds(),
            sun: *base.sun(),
            obstacles: vec![],
            voxels: Some(StoredVoxelsV1 {
                resolution: 0.5,
                origin: Point3::origin(),
                cells: vec![[1, 2, 3], [-4, 5, 6]],
            }),
        };
        fs::write(store.path_of(3), bincode::serde::encode_to_vec(&v1, config()).unwrap()).unwrap();
        let loaded = store.load_all();
        let (_, map3) = loaded.maps.iter().find(|(id, _)| *id == 3).expect("format 1 read");
        assert_eq!((map3.version(), map3.voxels().unwrap().cells_sorted()), (9, vec![[-4, 5, 6], [1, 2, 3]]));
        fs::remove_dir_all(&dir).unwrap();
    }
}
