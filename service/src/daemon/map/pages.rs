//! A map's snapshot, in pages: each page a self-contained chunk of records
//! (`MapRequest::Snapshot`), made once per world and kept while clients page it.

use dyfos_shared::limits::SNAPSHOT_PAGE_RECORDS;
use dyfos_shared::wire::map::{WireDelta, world_chunks_of};
use dyfos_shared::world::World;
use std::sync::Arc;

/// A map's snapshot pages, each a self-contained chunk of records.
pub(crate) type Pages = Arc<Vec<Vec<WireDelta>>>;

/// The snapshot pages of the last map paged, tied to the very world they were made
/// from: a map deleted and made again under its id starts again at version 0, so an
/// id and a version do not name one content.
#[derive(Default)]
pub(crate) struct PageCache(Option<(std::sync::Weak<World>, Pages)>);

impl PageCache {
    /// The pages of `world`, made now unless it was the last world paged.
    pub(crate) fn get(&mut self, world: &Arc<World>) -> Pages {
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

#[cfg(test)]
mod tests {
    use super::*;
    use dyfos_shared::world::{Bounds, Sun};

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
