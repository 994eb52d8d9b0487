//! Status codes, the thread's last error message, and the panic boundary every
//! `extern "C"` function runs inside.

use dyfos_client::{ClientOpenError, MapRequestError, Rejection, RendezvousError, StatsRequestError, Status};
use std::cell::RefCell;
use std::panic::{AssertUnwindSafe, catch_unwind};

/// What every fallible function returns: `DYFOS_STATUS_OK` (0), one of the daemon's
/// wire status codes (1 to 21, the same numbers as `dyfos_shared::wire::Status`), or
/// a client-side code (1000 and up). The numbers are stable. On any code but OK,
/// `dyfos_last_error` gives a sentence saying what went wrong and what to do.
pub type dyfos_status = u32;

/// Success.
pub const DYFOS_STATUS_OK: dyfos_status = 0u32;
/// The daemon could not decode a header field of the request (a code outside its
/// set). A request made by this library never gets it from the daemon; dyfos.hpp
/// uses it for a `budget` of 0 evaluations, which can find nothing (in the C
/// struct, `budget` = 0 means no budget).
pub const DYFOS_STATUS_MALFORMED_REQUEST: dyfos_status = 1u32;
/// The request's `algorithm` is not one of the `DYFOS_ALGORITHM_*` codes.
pub const DYFOS_STATUS_INVALID_ALGORITHM: dyfos_status = 2u32;
/// The belief's mean is not finite or its covariance is not symmetric positive definite.
pub const DYFOS_STATUS_INVALID_BELIEF: dyfos_status = 3u32;
/// A parameter is out of its SPEC §11 range; the message names it.
pub const DYFOS_STATUS_INVALID_PARAMS: dyfos_status = 4u32;
/// The requested SDSMM model cannot run in the daemon (`learned` without weights).
pub const DYFOS_STATUS_UNSUPPORTED_MODEL: dyfos_status = 5u32;
/// The deadline is longer than the daemon accepts (one hour).
pub const DYFOS_STATUS_INVALID_DEADLINE: dyfos_status = 6u32;
/// Map deltas that cannot be read: `deltas_json` that is not a JSON array of
/// deltas (the message says where), or, from the daemon, a record it cannot decode.
pub const DYFOS_STATUS_MALFORMED_DELTA: dyfos_status = 7u32;
/// A delta or map content was refused (unknown id to remove, bad geometry, bounds or
/// sun, an unreadable OctoMap): the batch is refused whole and the map is unchanged.
/// Bounds and sun given as arguments (`dyfos_client_create_map`,
/// `dyfos_client_upload_octomap`) get this code too, as the daemon gives them.
pub const DYFOS_STATUS_INVALID_DELTA: dyfos_status = 8u32;
/// No map has this id: upload or create it first.
pub const DYFOS_STATUS_UNKNOWN_MAP: dyfos_status = 9u32;
/// The map's version is not the one the request expected: re-read the map and retry.
pub const DYFOS_STATUS_MAP_VERSION_MISMATCH: dyfos_status = 10u32;
/// The map id is taken (by other content, for an upload).
pub const DYFOS_STATUS_MAP_EXISTS: dyfos_status = 11u32;
/// Too many records (see `DYFOS_MAX_BATCH_RECORDS`, `DYFOS_MAX_INLINE_RECORDS`),
/// chunks, maps, uploads, obstacles or voxel cells for the daemon's limits. Not
/// retryable as it is: send less (split the batch) or make room (delete maps).
pub const DYFOS_STATUS_OVER_CAPACITY: dyfos_status = 12u32;
/// An upload chunk arrived before the chunks that precede it.
pub const DYFOS_STATUS_CHUNK_OUT_OF_ORDER: dyfos_status = 13u32;
/// An upload chunk arrived twice.
pub const DYFOS_STATUS_CHUNK_DUPLICATE: dyfos_status = 14u32;
/// The upload this chunk belongs to was abandoned.
pub const DYFOS_STATUS_CHUNK_INCOMPLETE: dyfos_status = 15u32;
/// No candidate pose passed the constraints (SPEC §8).
pub const DYFOS_STATUS_NO_FEASIBLE_POSE: dyfos_status = 16u32;
/// The deadline passed before any feasible pose was found.
pub const DYFOS_STATUS_DEADLINE_EXCEEDED: dyfos_status = 17u32;
/// The daemon's queue is full; retry shortly.
pub const DYFOS_STATUS_BUSY: dyfos_status = 18u32;
/// The map change could not be written to the daemon's state directory; retry.
pub const DYFOS_STATUS_STORAGE_FAILED: dyfos_status = 19u32;
/// The daemon is shutting down; retry once it is back.
pub const DYFOS_STATUS_SHUTTING_DOWN: dyfos_status = 20u32;
/// The daemon hit a bug handling the request (its log says where); please report it.
pub const DYFOS_STATUS_INTERNAL_ERROR: dyfos_status = 21u32;
/// A required pointer (a handle, an input or an output) is NULL, or a handle was
/// already freed (or never came from `dyfos_client_connect`).
pub const DYFOS_STATUS_NULL_PARAMETER: dyfos_status = 1000u32;
/// An argument cannot be used: text that is not UTF-8, a scenario or parameter JSON
/// text that does not parse or has an unknown field, a scenario that `dyfos solve`
/// would refuse (the message names the field), a flag other than 0 or 1, a timeout
/// of 0 in `dyfos_client_connect`. A value the daemon checks gets the daemon's code
/// wherever it is checked (parameters: `INVALID_PARAMS`; bounds, sun: `INVALID_DELTA`;
/// deltas JSON: `MALFORMED_DELTA`).
pub const DYFOS_STATUS_INVALID_ARGUMENT: dyfos_status = 1001u32;
/// No `dyfosd` serves the prefix in the domain (not running, or restarting): start
/// it, or retry after a pause. `dyfos_client_connect` waits up to its timeout for
/// one; a handle whose daemon went away tries once to reconnect at each call and
/// answers this at once while none serves.
pub const DYFOS_STATUS_NO_DAEMON: dyfos_status = 1002u32;
/// The daemon stopped or restarted while the request was in flight; retry (the
/// handle reconnects by itself at its next call).
pub const DYFOS_STATUS_DAEMON_GONE: dyfos_status = 1003u32;
/// No reply within the call's timeout: raise it, or give the request a deadline.
pub const DYFOS_STATUS_TIMEOUT: dyfos_status = 1004u32;
/// Any other shared-memory (iceoryx2) failure.
pub const DYFOS_STATUS_IPC: dyfos_status = 1005u32;
/// A bug in this library was caught at the C boundary (no panic crosses it); please
/// report it with the message.
pub const DYFOS_STATUS_PANIC: dyfos_status = 1006u32;
/// The daemon serves the prefix with other message types: run a `dyfosd` of the
/// same version as this library.
pub const DYFOS_STATUS_INCOMPATIBLE_DAEMON: dyfos_status = 1007u32;

/// The client-side codes and their names, in code order.
pub(crate) const CLIENT_CODES: [(dyfos_status, &str); 8] = [
    (DYFOS_STATUS_NULL_PARAMETER, "null_parameter"),
    (DYFOS_STATUS_INVALID_ARGUMENT, "invalid_argument"),
    (DYFOS_STATUS_NO_DAEMON, "no_daemon"),
    (DYFOS_STATUS_DAEMON_GONE, "daemon_gone"),
    (DYFOS_STATUS_TIMEOUT, "timeout"),
    (DYFOS_STATUS_IPC, "ipc"),
    (DYFOS_STATUS_PANIC, "panic"),
    (DYFOS_STATUS_INCOMPATIBLE_DAEMON, "incompatible_daemon"),
];

/// The snake_case name of a code: the wire name (`map_version_mismatch`) for 0..=21,
/// `null_parameter` etc. for the client's codes, `None` for an unknown code.
pub(crate) fn status_name(code: dyfos_status) -> Option<&'static str> {
    if let Ok(s) = Status::try_from(code) {
        return Some(s.name());
    }
    CLIENT_CODES.iter().find(|(c, _)| *c == code).map(|(_, n)| *n)
}

/// A failed call: its code and the sentence for `dyfos_last_error`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct Failure {
    pub code: dyfos_status,
    pub message: String,
}

impl Failure {
    pub fn new(code: dyfos_status, message: impl Into<String>) -> Self {
        Failure { code, message: message.into() }
    }

    pub fn null(what: &str) -> Self {
        Failure::new(DYFOS_STATUS_NULL_PARAMETER, format!("`{what}` is NULL; pass a valid pointer"))
    }

    pub fn invalid(message: impl Into<String>) -> Self {
        Failure::new(DYFOS_STATUS_INVALID_ARGUMENT, message)
    }
}

impl From<Rejection> for Failure {
    fn from(r: Rejection) -> Self {
        let message = r.to_string();
        Failure::new(r.status as u32, message)
    }
}

impl From<ClientOpenError> for Failure {
    fn from(e: ClientOpenError) -> Self {
        let code = match &e {
            ClientOpenError::InvalidPrefix(_) | ClientOpenError::InvalidDomain(_) => DYFOS_STATUS_INVALID_ARGUMENT,
            ClientOpenError::NoDaemon { .. } => DYFOS_STATUS_NO_DAEMON,
            ClientOpenError::Incompatible { .. } => DYFOS_STATUS_INCOMPATIBLE_DAEMON,
            ClientOpenError::Ipc(_) => DYFOS_STATUS_IPC,
        };
        Failure::new(code, e.to_string())
    }
}

/// The three request errors have the same variants.
macro_rules! from_request_error {
    ($($error:ident),*) => {$(
        impl From<$error> for Failure {
            fn from(e: $error) -> Self {
                let message = e.to_string();
                match e {
                    $error::Connect(open) => Failure::from(open),
                    $error::NoDaemon { .. } => Failure::new(DYFOS_STATUS_NO_DAEMON, message),
                    $error::DaemonGone => Failure::new(DYFOS_STATUS_DAEMON_GONE, message),
                    $error::Timeout(_) => Failure::new(DYFOS_STATUS_TIMEOUT, message),
                    $error::Rejected(r) | $error::Invalid(r) => Failure::new(r.status as u32, message),
                    // The C ABI sets no interrupt check, so `Interrupted` never comes.
                    $error::Ipc(_) | $error::Interrupted => Failure::new(DYFOS_STATUS_IPC, message),
                }
            }
        }
    )*};
}

from_request_error!(RendezvousError, MapRequestError, StatsRequestError);

thread_local! {
    /// The message of this thread's last failed call (empty after a success).
    static LAST_ERROR: RefCell<String> = const { RefCell::new(String::new()) };
}

/// Records the message of this thread's last call (`None`: it succeeded).
fn set_last_error(message: Option<String>) {
    // `try_with`: a call made while the thread is being torn down keeps no message
    // rather than panicking.
    let _ = LAST_ERROR.try_with(|m| {
        if let Ok(mut m) = m.try_borrow_mut() {
            match message {
                Some(text) => *m = text,
                None => m.clear(),
            }
        }
    });
}

/// Runs `f` with this thread's last error message.
pub(crate) fn with_last_error<T>(f: impl FnOnce(&str) -> T) -> Option<T> {
    LAST_ERROR.try_with(|m| m.try_borrow().ok().map(|m| f(&m))).ok().flatten()
}

/// The panic boundary: runs `body`, records its error message for
/// `dyfos_last_error` and returns its code; a panic is caught and becomes
/// `DYFOS_STATUS_PANIC` (it never unwinds into C).
pub(crate) fn boundary(body: impl FnOnce() -> Result<(), Failure>) -> dyfos_status {
    match catch_unwind(AssertUnwindSafe(body)) {
        Ok(Ok(())) => {
            set_last_error(None);
            DYFOS_STATUS_OK
        }
        Ok(Err(failure)) => {
            set_last_error(Some(failure.message));
            failure.code
        }
        Err(payload) => {
            let text = format!(
                "bug in libdyfos, caught at the C boundary: {}; the call did nothing more, please report it",
                dyfos_process::panic::panic_text(payload.as_ref()).unwrap_or("no message")
            );
            // Dropping a payload can itself panic; never let that unwind into C.
            let _ = catch_unwind(AssertUnwindSafe(move || drop(payload)));
            set_last_error(Some(text));
            DYFOS_STATUS_PANIC
        }
    }
}

/// The panic boundary of a function that returns no status (`dyfos_string_free`):
/// runs `body` and catches a panic, leaving this thread's last error message as it
/// was, since the caller has no status telling it to look.
pub(crate) fn boundary_quiet(body: impl FnOnce()) {
    if let Err(payload) = catch_unwind(AssertUnwindSafe(body)) {
        // Dropping a payload can itself panic; never let that unwind into C.
        let _ = catch_unwind(AssertUnwindSafe(move || drop(payload)));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wire_codes_are_the_wire_status_numbers_and_names() {
        let ours = [
            (DYFOS_STATUS_OK, Status::Ok),
            (DYFOS_STATUS_MALFORMED_REQUEST, Status::MalformedRequest),
            (DYFOS_STATUS_INVALID_ALGORITHM, Status::InvalidAlgorithm),
            (DYFOS_STATUS_INVALID_BELIEF, Status::InvalidBelief),
            (DYFOS_STATUS_INVALID_PARAMS, Status::InvalidParams),
            (DYFOS_STATUS_UNSUPPORTED_MODEL, Status::UnsupportedModel),
            (DYFOS_STATUS_INVALID_DEADLINE, Status::InvalidDeadline),
            (DYFOS_STATUS_MALFORMED_DELTA, Status::MalformedDelta),
            (DYFOS_STATUS_INVALID_DELTA, Status::InvalidDelta),
            (DYFOS_STATUS_UNKNOWN_MAP, Status::UnknownMap),
            (DYFOS_STATUS_MAP_VERSION_MISMATCH, Status::MapVersionMismatch),
            (DYFOS_STATUS_MAP_EXISTS, Status::MapExists),
            (DYFOS_STATUS_OVER_CAPACITY, Status::OverCapacity),
            (DYFOS_STATUS_CHUNK_OUT_OF_ORDER, Status::ChunkOutOfOrder),
            (DYFOS_STATUS_CHUNK_DUPLICATE, Status::ChunkDuplicate),
            (DYFOS_STATUS_CHUNK_INCOMPLETE, Status::ChunkIncomplete),
            (DYFOS_STATUS_NO_FEASIBLE_POSE, Status::NoFeasiblePose),
            (DYFOS_STATUS_DEADLINE_EXCEEDED, Status::DeadlineExceeded),
            (DYFOS_STATUS_BUSY, Status::Busy),
            (DYFOS_STATUS_STORAGE_FAILED, Status::StorageFailed),
            (DYFOS_STATUS_SHUTTING_DOWN, Status::ShuttingDown),
            (DYFOS_STATUS_INTERNAL_ERROR, Status::Internal),
        ];
        // Every wire status has its constant, with its number.
        assert_eq!(ours.len(), Status::ALL.len());
        for (code, status) in ours {
            assert_eq!(code, status as u32, "{status}");
            assert_eq!(status_name(code), Some(status.name()));
        }
        for (code, name) in CLIENT_CODES {
            assert_eq!(status_name(code), Some(name));
            assert!(Status::try_from(code).is_err());
        }
        assert_eq!(status_name(999), None);
    }

    #[test]
    fn the_boundary_turns_a_panic_into_the_panic_code_with_its_message() {
        let code = boundary(|| panic!("boom at the boundary"));
        assert_eq!(code, DYFOS_STATUS_PANIC);
        let message = with_last_error(str::to_owned).unwrap();
        assert!(message.contains("boom at the boundary"), "{message}");
        let formatted = boundary(|| panic!("{} formatted", 42));
        assert_eq!(formatted, DYFOS_STATUS_PANIC);
        assert!(with_last_error(|m| m.contains("42 formatted")).unwrap());
    }

    #[test]
    fn the_boundary_records_failures_and_clears_them_on_success() {
        assert_eq!(boundary(|| Err(Failure::new(DYFOS_STATUS_UNKNOWN_MAP, "no map 7"))), DYFOS_STATUS_UNKNOWN_MAP);
        assert_eq!(with_last_error(str::to_owned).unwrap(), "no map 7");
        assert_eq!(boundary(|| Ok(())), DYFOS_STATUS_OK);
        assert_eq!(with_last_error(str::to_owned).unwrap(), "");
    }

    #[test]
    fn client_errors_map_to_their_codes() {
        let cases = [
            (Failure::from(RendezvousError::DaemonGone), DYFOS_STATUS_DAEMON_GONE),
            (Failure::from(MapRequestError::Timeout(std::time::Duration::from_secs(1))), DYFOS_STATUS_TIMEOUT),
            (
                Failure::from(StatsRequestError::NoDaemon { service: "s".into(), prefix: "p/".into(), domain: None }),
                DYFOS_STATUS_NO_DAEMON,
            ),
            (
                Failure::from(RendezvousError::Rejected(Rejection::new(Status::UnknownMap, "no map 3"))),
                DYFOS_STATUS_UNKNOWN_MAP,
            ),
            (
                Failure::from(RendezvousError::Invalid(Rejection::new(Status::OverCapacity, "too many"))),
                DYFOS_STATUS_OVER_CAPACITY,
            ),
            (Failure::from(ClientOpenError::InvalidDomain("a/b".into())), DYFOS_STATUS_INVALID_ARGUMENT),
            (
                Failure::from(MapRequestError::Connect(ClientOpenError::Incompatible {
                    service: "s".into(),
                    reason: "r".into(),
                })),
                DYFOS_STATUS_INCOMPATIBLE_DAEMON,
            ),
        ];
        for (failure, code) in cases {
            assert_eq!(failure.code, code, "{failure:?}");
            assert!(!failure.message.is_empty());
        }
    }
}
