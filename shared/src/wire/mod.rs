//! Wire types of the daemon's iceoryx2 services (see `dyfosd`).
//!
//! Every service name lives under one prefix (default [`DEFAULT_PREFIX`], `dyfos/`):
//!
//! | service | pattern | request | response |
//! |---|---|---|---|
//! | `<prefix>rendezvous` | request-response | [`rendezvous::RendezvousRequestHeader`] + `[`[`map::WireDelta`]`]` | [`rendezvous::RendezvousReply`] |
//! | `<prefix>map` | request-response | [`map::MapRequestHeader`] + `[WireDelta]` | [`map::MapReplyHeader`] + `[WireDelta]` |
//! | `<prefix>stats` | request-response | [`stats::StatsRequest`] | [`stats::StatsReply`] |
//! | `<prefix>wake` | event | clients notify after sending a request | the daemon listens |
//! | `<prefix>reply` | event | the daemon notifies the requesting client's listener | |
//!
//! Payloads are `#[repr(C)]` plain numbers with a stable `#[type_name]`, so C, C++
//! and Python clients can join later. Tags, codes and flags are integers: a peer
//! can write any bits into shared memory, so nothing is read as a Rust `enum` or
//! `bool`; every message is decoded with `TryFrom` (or a `decode` function) into a
//! validated type before use. The daemon creates the services with its own limits;
//! clients only open them.
//!
//! For clients in other languages, `docs/wire.md` in the repository documents every
//! type's name, size and field offsets, every code and default, and the protocol
//! rules; `tests/tests/it/wire_doc.rs` checks it against these definitions.
//!
//! ```
//! use dyfos_shared::wire::{ServiceNames, Status};
//!
//! let names = ServiceNames::new("dyfos/").unwrap();
//! assert_eq!(names.rendezvous, "dyfos/rendezvous");
//! assert_eq!(Status::try_from(10).unwrap(), Status::MapVersionMismatch);
//! assert_eq!(Status::MapVersionMismatch.name(), "map_version_mismatch");
//! assert!(Status::try_from(999).is_err());
//! assert!(ServiceNames::new("bad prefix/").is_err());
//! ```

pub mod map;
pub mod mission;
pub mod rendezvous;
pub mod services;
pub mod stats;

use crate::codes::codes;
use crate::limits::{DETAIL_LEN, MAX_PREFIX_LEN};
use iceoryx2::prelude::ZeroCopySend;

/// The service-name prefix used when none is given.
pub const DEFAULT_PREFIX: &str = "dyfos/";

/// The `expected_version` that accepts any map version.
pub const ANY_VERSION: u64 = u64::MAX;

/// The full names of the daemon's services under one prefix.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ServiceNames {
    /// The prefix they share, e.g. `dyfos/`.
    pub prefix: String,
    /// Rendezvous queries (request-response).
    pub rendezvous: String,
    /// Map deltas, uploads and snapshots (request-response).
    pub map: String,
    /// Health and statistics (request-response).
    pub stats: String,
    /// Event: a client sent a request (the daemon listens).
    pub wake: String,
    /// Event: the daemon answered (each client listens).
    pub reply: String,
}

/// A prefix that cannot name iceoryx2 services.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "service prefix `{prefix}` {problem}; use letters, digits and `_ - . /`, at most {MAX_PREFIX_LEN} bytes, e.g. `dyfos/`"
)]
pub struct PrefixError {
    /// The rejected prefix.
    pub prefix: String,
    /// What is wrong.
    pub problem: &'static str,
}

impl ServiceNames {
    /// The service names under `prefix` (used verbatim: `dyfos/` gives `dyfos/rendezvous`).
    pub fn new(prefix: &str) -> Result<Self, PrefixError> {
        let fail = |problem| Err(PrefixError { prefix: prefix.to_string(), problem });
        if prefix.is_empty() {
            return fail("is empty");
        }
        if prefix.len() > MAX_PREFIX_LEN {
            return fail("is too long");
        }
        if !prefix.bytes().all(|b| b.is_ascii_alphanumeric() || b"_-./".contains(&b)) {
            return fail("contains a character other than letters, digits and `_ - . /`");
        }
        let name = |s: &str| format!("{prefix}{s}");
        Ok(ServiceNames {
            prefix: prefix.to_string(),
            rendezvous: name("rendezvous"),
            map: name("map"),
            stats: name("stats"),
            wake: name("wake"),
            reply: name("reply"),
        })
    }
}

codes! {
    /// The outcome code of every reply. `Ok` is 0; every error has its own code,
    /// stable on the wire. The reply's detail text says what to change.
    #[derive(PartialOrd, Ord)]
    pub enum Status("status") {
        /// Success.
        Ok = 0, "ok";
        /// A header field is not one of its allowed codes (operation, mode, flags), or a
        /// reserved field is not zero.
        MalformedRequest = 1, "malformed_request";
        /// The algorithm tag is unknown.
        InvalidAlgorithm = 2, "invalid_algorithm";
        /// The rendezvous belief is not finite or its covariance is not SPD.
        InvalidBelief = 3, "invalid_belief";
        /// A parameter override is out of its range (SPEC §11).
        InvalidParams = 4, "invalid_params";
        /// The requested SDSMM model cannot run in the daemon (`learned` without weights).
        UnsupportedModel = 5, "unsupported_model";
        /// The deadline is longer than the daemon accepts (one hour).
        InvalidDeadline = 6, "invalid_deadline";
        /// A delta record has an unknown tag, a bad flag or a truncated voxel run.
        MalformedDelta = 7, "malformed_delta";
        /// A delta was rejected by the map (SPEC §1: unknown id to remove, invalid
        /// geometry, ...); the batch is rejected whole and the map is unchanged.
        InvalidDelta = 8, "invalid_delta";
        /// No map has this id.
        UnknownMap = 9, "unknown_map";
        /// The map's version is not the one the request expected.
        MapVersionMismatch = 10, "map_version_mismatch";
        /// Creating a map whose id is taken (or uploading without the replace flag).
        MapExists = 11, "map_exists";
        /// Too many records, chunks, maps or uploads for the daemon's limits.
        OverCapacity = 12, "over_capacity";
        /// An upload chunk arrived before the chunks that precede it.
        ChunkOutOfOrder = 13, "chunk_out_of_order";
        /// An upload chunk arrived twice.
        ChunkDuplicate = 14, "chunk_duplicate";
        /// The upload this chunk belongs to was abandoned (superseded by a new upload
        /// of the same map, or idle too long) and will never complete.
        ChunkIncomplete = 15, "chunk_incomplete";
        /// No candidate pose passed the constraints (SPEC §8 `no_feasible_pose`).
        NoFeasiblePose = 16, "no_feasible_pose";
        /// The deadline passed before any feasible pose was found.
        DeadlineExceeded = 17, "deadline_exceeded";
        /// The daemon's queue is full; retry shortly.
        Busy = 18, "busy";
        /// The map change could not be written to the state directory; the map is unchanged.
        StorageFailed = 19, "storage_failed";
        /// The daemon is shutting down and takes no new work.
        ShuttingDown = 20, "shutting_down";
        /// The daemon hit a bug while handling the request (its log says where); the
        /// request changed nothing and other requests are still served. Please report it.
        Internal = 21, "internal_error";
    }
}

impl Status {
    /// Whether the same request may succeed if simply sent again later.
    pub fn is_retryable(self) -> bool {
        matches!(self, Status::Busy | Status::ShuttingDown | Status::StorageFailed)
    }
}

pub use crate::codes::UnknownCode;

/// A short UTF-8 text carried by a reply (the error's detail), truncated at a
/// character boundary to fit.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ZeroCopySend)]
#[type_name("dyfos::Detail")]
#[repr(C)]
pub struct Detail {
    /// Bytes used in `bytes`.
    pub len: u32,
    /// UTF-8 text.
    pub bytes: [u8; DETAIL_LEN],
}

impl Default for Detail {
    fn default() -> Self {
        Detail { len: 0, bytes: [0; DETAIL_LEN] }
    }
}

impl Detail {
    /// `text`, truncated to fit.
    pub fn new(text: &str) -> Self {
        let mut end = text.len().min(DETAIL_LEN);
        while !text.is_char_boundary(end) {
            end -= 1;
        }
        let mut d = Detail::default();
        d.bytes[..end].copy_from_slice(&text.as_bytes()[..end]);
        d.len = end as u32;
        d
    }

    /// The text (invalid UTF-8 or a bad length from a peer is repaired, never trusted).
    pub fn text(&self) -> String {
        let len = (self.len as usize).min(DETAIL_LEN);
        String::from_utf8_lossy(&self.bytes[..len]).into_owned()
    }
}

/// Why the daemon refused a request: the code, the text for people, and for
/// delta errors the index of the failing record.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{status}: {message}")]
pub struct Rejection {
    /// The code.
    pub status: Status,
    /// What is wrong and what to do.
    pub message: String,
    /// For delta errors, the failing delta's position in its batch.
    pub index: Option<u64>,
    /// For rendezvous replies, the map's version as this request left it: after its
    /// inline deltas if they were applied before the search failed
    /// (`no_feasible_pose`, `deadline_exceeded`, `internal_error`), else the version
    /// it had when the request was refused; `None` if no map has the id (or the
    /// reply did not say).
    pub map_version: Option<u64>,
}

impl Rejection {
    /// A rejection without an index.
    pub fn new(status: Status, message: impl Into<String>) -> Self {
        debug_assert!(status != Status::Ok);
        Rejection { status, message: message.into(), index: None, map_version: None }
    }

    /// A rejection of the delta at `index` of its batch.
    pub fn at_delta(status: Status, message: impl Into<String>, index: u64) -> Self {
        Rejection { index: Some(index), ..Rejection::new(status, message) }
    }

    /// `over_capacity` for `n` records of `what` over `limit`, as the daemon refuses
    /// a message that carries too many and a client refuses to send one; `advice`
    /// ends the message.
    pub fn at_most(n: usize, limit: usize, what: &str, advice: &str) -> Result<(), Rejection> {
        if n > limit {
            return Err(Rejection::new(
                Status::OverCapacity,
                format!("{n} {what} exceed the limit of {limit}{advice}"),
            ));
        }
        Ok(())
    }

    /// The wire form of `index` (`u64::MAX` for none).
    pub fn wire_index(&self) -> u64 {
        self.index.unwrap_or(u64::MAX)
    }

    /// Rebuilds a rejection from a reply's fields; an unknown code is kept as a
    /// malformed reply rather than trusted.
    pub fn from_wire(status: u32, detail: &Detail, index: u64) -> Self {
        let message = detail.text();
        match Status::try_from(status) {
            Ok(status) => Rejection { index: (index != u64::MAX).then_some(index), ..Rejection::new(status, message) },
            Err(e) => Rejection::new(Status::MalformedRequest, format!("reply {e}: {message}")),
        }
    }
}

/// A listener id (iceoryx2's `UniqueListenerId::value()`) as two `u64`s, so that
/// a reply can wake exactly the client that asked.
pub fn split_u128(v: u128) -> [u64; 2] {
    [v as u64, (v >> 64) as u64]
}

/// Inverse of [`split_u128`].
pub fn join_u128(v: [u64; 2]) -> u128 {
    u128::from(v[0]) | (u128::from(v[1]) << 64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn status_codes_round_trip() {
        for (i, s) in Status::ALL.iter().enumerate() {
            assert_eq!(*s as u32, i as u32);
            assert_eq!(Status::try_from(*s as u32), Ok(*s));
        }
        assert!(Status::try_from(Status::ALL.len() as u32).is_err());
    }

    #[test]
    fn detail_truncates_on_char_boundary() {
        let long = "é".repeat(DETAIL_LEN);
        let d = Detail::new(&long);
        assert!(d.len as usize <= DETAIL_LEN);
        assert_eq!(d.text(), "é".repeat(DETAIL_LEN / 2));
        let hostile = Detail { len: u32::MAX, bytes: [0xff; DETAIL_LEN] };
        assert_eq!(hostile.text().chars().count(), DETAIL_LEN);
        assert_eq!(join_u128(split_u128(u128::MAX - 5)), u128::MAX - 5);
    }
}
