//! What the request handlers change: the maps (with their uploads) and the worker
//! pool's queue and counters; no iceoryx2 port, so the handlers' rules can be
//! tested without a daemon.

use super::map::Maps;
use super::pool::Pool;
use std::sync::Arc;

/// The state the IPC thread's handlers take.
pub(crate) struct State {
    pub(crate) maps: Maps,
    pub(crate) pool: Arc<Pool>,
    /// Queries of one class that may wait for a worker (`limits.max_queued`).
    pub(crate) max_queued: usize,
    /// Shutting down: new queries get `shutting_down`.
    pub(crate) closing: bool,
}

/// A [`State`] for the handlers' unit tests: maps in a fresh state directory
/// (removed on drop), two workers and no thread started, no recorder, no learned
/// weights.
#[cfg(test)]
pub(crate) struct Scratch {
    pub(crate) state: State,
    dir: std::path::PathBuf,
}

#[cfg(test)]
impl Scratch {
    /// `maps` held from the start (version as given), `max_queued` queries per class.
    pub(crate) fn new(
        name: &str,
        maps: impl IntoIterator<Item = (dyfos_shared::wire::map::MapId, dyfos_shared::world::World)>,
    ) -> Scratch {
        let dir = std::env::temp_dir().join(format!("dyfos-state-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let store = crate::store::Store::open(&dir).expect("a scratch state directory");
        let maps = Maps::new(store, maps, std::time::Duration::from_secs(60));
        let config = super::DaemonConfig { workers: 2, ..Default::default() };
        let pool = Arc::new(Pool::new(&config, None, None));
        Scratch { state: State { maps, pool, max_queued: 8, closing: false }, dir }
    }
}

#[cfg(test)]
impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}
