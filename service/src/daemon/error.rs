//! Why the daemon could not start.

use super::config::ConfigError;
use crate::store::StoreOpenError;
use dyfos_shared::wire::PrefixError;
use dyfos_shared::wire::services::InvalidDomain;
use std::path::PathBuf;

/// Why the daemon could not start.
#[derive(Debug, thiserror::Error)]
pub enum DaemonCreateError {
    /// `--prefix` cannot name services.
    #[error(transparent)]
    InvalidPrefix(#[from] PrefixError),
    /// `--domain` is not a valid file-name prefix.
    #[error(transparent)]
    InvalidDomain(#[from] InvalidDomain),
    /// A configuration value is out of its range.
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// The state directory is unusable.
    #[error(transparent)]
    Store(#[from] StoreOpenError),
    /// Another daemon serves this prefix: its server holds the service's one
    /// server slot.
    #[error("another dyfosd already serves prefix `{0}`; stop it, or start this one with another --prefix")]
    AlreadyRunning(String),
    /// A service exists with other types or smaller limits (a daemon of another
    /// version or configuration, kept alive by its clients).
    #[error(
        "service `{service}` exists with other types or limits ({reason}); stop the clients of the old daemon, or use another --prefix"
    )]
    Incompatible {
        /// The service.
        service: String,
        /// iceoryx2's reason.
        reason: String,
    },
    /// Any other iceoryx2 failure.
    #[error(transparent)]
    Ipc(#[from] IpcError),
    /// A thread of the daemon (a worker, the cleanup) could not be started.
    #[error("cannot start the {what} thread: {source}")]
    Thread {
        /// Which thread.
        what: &'static str,
        /// Why.
        source: std::io::Error,
    },
    /// The learned model file is missing, corrupt or of the wrong shape.
    #[error(transparent)]
    Model(#[from] crate::learned::ModelLoadError),
    /// The recording file (`--record`) cannot be created.
    #[error("cannot record to {path}: {source}; check the directory exists and is writable, or drop --record")]
    Record {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
}

/// An iceoryx2 call that failed, with iceoryx2's error as its source.
#[derive(Debug, thiserror::Error)]
#[error("iceoryx2: {what}: {source:?}")]
pub struct IpcError {
    /// What the daemon was making (`node`, `wait set`, …).
    pub what: &'static str,
    /// iceoryx2's error.
    #[source]
    pub source: Box<dyn std::error::Error + Send + Sync>,
}

impl IpcError {
    /// `what` failed with `source`.
    pub fn new(what: &'static str, source: impl std::error::Error + Send + Sync + 'static) -> Self {
        IpcError { what, source: Box::new(source) }
    }
}
