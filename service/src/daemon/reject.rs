//! How the daemon refuses a request: the refusals both the rendezvous and the map
//! paths give (an unknown map, a stale version, a delta the map refuses) and the
//! guard that turns a bug in a handler into an `internal_error` reply.

use dyfos_shared::wire::map::MapId;
use dyfos_shared::wire::{Rejection, Status};
use dyfos_shared::world::{MapDeltaError, MapDeltaErrorKind, VoxelError, World};
use tracing::error;

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

pub(crate) fn unknown_map(id: MapId) -> Rejection {
    Rejection::new(
        Status::UnknownMap,
        format!("no map {id}; create it (`dyfos map create`, Client::create_map) or upload it first"),
    )
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
pub(crate) fn delta_status(kind: &MapDeltaErrorKind) -> Status {
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
}
