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
