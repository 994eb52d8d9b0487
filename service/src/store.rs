//! The daemon's map persistence: one file per map in the state directory.
//!
//! Each accepted change writes the whole map (bincode 2 over serde) to
//! `map-<id>.bin.tmp`, syncs it and renames it over `map-<id>.bin`, so a crash at any
//! moment leaves either the old or the new map, never half of one. On start every
//! `map-*.bin` is read back and validated; a file that cannot be read is renamed to
//! `*.corrupt-<unix seconds>` and reported, and the start goes on.
//!
//! ```
//! use dyfos_service::store::Store;
//! use dyfos_shared::world::{Bounds, Sun, World};
//!
//! let dir = std::env::temp_dir().join(format!("dyfos-store-doc-{}", std::process::id()));
//! let store = Store::open(&dir).unwrap();
//! let world = World::empty(Bounds::new([-5.0, -5.0, 5.0, 5.0]).unwrap(), Sun::new(0.4, 1.0).unwrap());
//! store.save(7, &world).unwrap();
//! let loaded = store.load_all();
//! assert_eq!(loaded.maps, vec![(7, world)]);
//! assert!(loaded.quarantined.is_empty());
//! # std::fs::remove_dir_all(&dir).unwrap();
//! ```

use dyfos_shared::math::Point3;
use dyfos_shared::wire::map::MapId;
use dyfos_shared::world::{Bounds, Obstacle, Sun, VoxelGrid, World};
use std::fs;
use std::io::Write;
use std::path::{Path, PathBuf};

/// Format tag written first in every file; bump when [`StoredMap`] changes.
const FORMAT: u32 = 1;

/// Largest map file read back (bincode refuses to allocate beyond it).
const MAX_FILE_BYTES: usize = 1 << 30;

/// A map as written to disk.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
struct StoredMap {
    format: u32,
    id: MapId,
    version: u64,
    bounds: Bounds,
    sun: Sun,
    obstacles: Vec<(u32, Obstacle)>,
    voxels: Option<StoredVoxels>,
}

#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
struct StoredVoxels {
    resolution: f64,
    origin: Point3<f64>,
    cells: Vec<[i64; 3]>,
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
}

/// The state directory.
#[derive(Debug, Clone)]
pub struct Store {
    dir: PathBuf,
}

fn config() -> impl bincode::config::Config {
    bincode::config::standard().with_limit::<MAX_FILE_BYTES>()
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

    /// The file of map `id`.
    pub fn path_of(&self, id: MapId) -> PathBuf {
        self.dir.join(format!("map-{id}.bin"))
    }

    /// Writes `world` as map `id`, atomically.
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
                cells: v.occupied().copied().collect(),
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
        // Make the rename itself durable.
        if let Ok(d) = fs::File::open(&self.dir) {
            let _ = d.sync_all();
        }
        Ok(())
    }

    /// Removes map `id`'s file.
    pub fn remove(&self, id: MapId) -> Result<(), StoreSaveError> {
        let path = self.path_of(id);
        match fs::remove_file(&path) {
            Ok(()) => Ok(()),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(()),
            Err(source) => Err(StoreSaveError::Io { path, source }),
        }
    }

    /// Reads every map file; unreadable ones are quarantined.
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
        for (id, file) in files {
            match read_map(&file, id) {
                Ok(world) => loaded.maps.push((id, world)),
                Err(reason) => {
                    let stamp =
                        std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_secs());
                    let target = file.with_extension(format!("bin.corrupt-{stamp}"));
                    let moved_to = fs::rename(&file, &target).ok().map(|()| target);
                    loaded.quarantined.push(Quarantined { file, moved_to, reason });
                }
            }
        }
        loaded
    }
}

fn read_map(file: &Path, id: MapId) -> Result<World, String> {
    let bytes = fs::read(file).map_err(|e| format!("cannot read: {e}"))?;
    let (stored, used): (StoredMap, usize) =
        bincode::serde::decode_from_slice(&bytes, config()).map_err(|e| format!("not a map file: {e}"))?;
    if used != bytes.len() {
        return Err(format!("{} trailing bytes after the map", bytes.len() - used));
    }
    if stored.format != FORMAT {
        return Err(format!("format {} is not the supported {FORMAT}", stored.format));
    }
    if stored.id != id {
        return Err(format!("the file holds map {}, its name says {id}", stored.id));
    }
    let bounds = Bounds::new(stored.bounds.to_array()).map_err(|e| e.to_string())?;
    let sun = Sun::new(stored.sun.elevation, stored.sun.azimuth).map_err(|e| e.to_string())?;
    let voxels = match stored.voxels {
        None => None,
        Some(v) => Some(VoxelGrid::new(v.resolution, v.origin, v.cells).map_err(|e| e.to_string())?),
    };
    World::new(stored.version, bounds, sun, stored.obstacles, voxels).map_err(|e| e.to_string())
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
}
