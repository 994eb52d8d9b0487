//! The client's errors: one enum per operation, each saying what to do.

use dyfos_shared::wire::{PrefixError, Rejection, Status};
use std::sync::Arc;
use std::time::Duration;

/// An iceoryx2 failure: iceoryx2's error, kept as the [source](std::error::Error::source),
/// and its text.
#[derive(Debug, Clone, thiserror::Error)]
#[error("{text}")]
pub struct IpcFailure {
    text: String,
    #[source]
    source: Arc<dyn std::error::Error + Send + Sync>,
}

impl IpcFailure {
    /// iceoryx2 failed with `e`.
    pub(crate) fn new(e: impl std::error::Error + Send + Sync + 'static) -> Self {
        IpcFailure { text: format!("{e:?}"), source: Arc::new(e) }
    }

    /// iceoryx2 failed with `e` on `service`.
    pub(crate) fn on(service: &str, e: impl std::error::Error + Send + Sync + 'static) -> Self {
        IpcFailure { text: format!("{service}: {e:?}"), source: Arc::new(e) }
    }
}

/// Two failures are equal when they say the same (iceoryx2's errors are compared
/// by their text).
impl PartialEq for IpcFailure {
    fn eq(&self, other: &Self) -> bool {
        self.text == other.text
    }
}

/// Why [`crate::Client::connect`] failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ClientOpenError {
    /// The prefix cannot name services.
    #[error(transparent)]
    InvalidPrefix(#[from] PrefixError),
    /// The iceoryx2 domain is not a valid file-name prefix.
    #[error("iceoryx2 domain `{0}` is not a valid file-name prefix; use letters, digits and `_`")]
    InvalidDomain(String),
    /// No daemon serves this prefix.
    #[error("{}, or pass the prefix and domain it uses", no_daemon(service, prefix, domain.as_deref(), Some(*waited)))]
    NoDaemon {
        /// The service tried.
        service: String,
        /// The prefix.
        prefix: String,
        /// The iceoryx2 domain looked in (`None`: iceoryx2's default).
        domain: Option<String>,
        /// How long the client waited for it.
        waited: Duration,
    },
    /// The service exists with other payload types: a daemon of another version.
    #[error(
        "`{service}` is served with different message types ({reason}); run a dyfosd of the same version as this client"
    )]
    Incompatible {
        /// The service.
        service: String,
        /// iceoryx2's reason.
        reason: String,
    },
    /// Any other iceoryx2 failure.
    #[error("iceoryx2: {0}")]
    Ipc(#[source] IpcFailure),
}

/// What both errors of a missing daemon say first: no dyfosd serves `service` in
/// the domain (waited how long, if given), and the `dyfosd` command that would.
fn no_daemon(service: &str, prefix: &str, domain: Option<&str>, waited: Option<Duration>) -> String {
    let in_domain =
        domain.map_or_else(|| "the default iceoryx2 domain".to_string(), |d| format!("iceoryx2 domain `{d}`"));
    let waited = waited.map_or_else(String::new, |w| format!(" (waited {w:?})"));
    let domain_flag = domain.map_or_else(String::new, |d| format!(" --domain {d}"));
    format!(
        "no dyfosd serves `{service}` in {in_domain}{waited}; start one with `dyfosd --prefix {prefix}{domain_flag}`"
    )
}

/// A request's failure, before it is named by operation.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum CallError {
    Connect(ClientOpenError),
    NoDaemon { service: String, prefix: String, domain: Option<String> },
    DaemonGone,
    Timeout(Duration),
    Rejected(Rejection),
    Local(Rejection),
    Ipc(IpcFailure),
    Interrupted,
}

impl From<ClientOpenError> for CallError {
    fn from(e: ClientOpenError) -> Self {
        CallError::Connect(e)
    }
}

macro_rules! request_error {
    ($(#[$doc:meta])* $name:ident, $what:literal) => {
        $(#[$doc])*
        #[derive(Debug, Clone, PartialEq, thiserror::Error)]
        pub enum $name {
            /// Connecting (or reconnecting) to the daemon failed.
            #[error(transparent)]
            Connect(#[from] ClientOpenError),
            /// No daemon serves the prefix: it is not running or is restarting.
            #[error("{} (retryable)", no_daemon(service, prefix, domain.as_deref(), None))]
            NoDaemon {
                /// The service.
                service: String,
                /// The prefix.
                prefix: String,
                /// The iceoryx2 domain (`None`: iceoryx2's default).
                domain: Option<String>,
            },
            /// The daemon stopped or restarted while the request was in flight.
            #[error("dyfosd went away while the {what} request was in flight (stopped or restarted); retry, the client reconnects by itself", what = $what)]
            DaemonGone,
            /// No reply in time; the daemon may be overloaded or the query too long.
            #[error("no reply to the {what} request within {0:?}; raise the timeout, or give the request a shorter deadline or budget", what = $what)]
            Timeout(Duration),
            /// The daemon refused the request; nothing changed.
            #[error("dyfosd rejected the request: {0}")]
            Rejected(Rejection),
            /// The client refused to send it (too large, not encodable).
            #[error("not sent: {0}")]
            Invalid(Rejection),
            /// Any other iceoryx2 failure.
            #[error("iceoryx2: {0}")]
            Ipc(#[source] IpcFailure),
            /// The caller's interrupt check ended the wait
            /// ([`Client::set_interrupt_check`](crate::Client::set_interrupt_check)):
            /// no answer; a running search is abandoned.
            #[error("the {what} request was interrupted by the caller (e.g. Ctrl-C) before its reply", what = $what)]
            Interrupted,
        }

        impl $name {
            /// Whether sending the same request again may succeed: the daemon was
            /// missing, restarting or busy.
            pub fn is_retryable(&self) -> bool {
                match self {
                    $name::NoDaemon { .. } | $name::DaemonGone => true,
                    $name::Connect(ClientOpenError::NoDaemon { .. }) => true,
                    $name::Rejected(r) => r.status.is_retryable(),
                    _ => false,
                }
            }

            /// The map's version as the refused request left it, if the daemon said
            /// (rendezvous replies): after the request's inline deltas when they were
            /// applied before the search failed, else the version it already had.
            pub fn map_version(&self) -> Option<u64> {
                match self {
                    $name::Rejected(r) => r.map_version,
                    _ => None,
                }
            }

            /// The daemon's (or the client's) status code, if it refused the request.
            pub fn status(&self) -> Option<Status> {
                match self {
                    $name::Rejected(r) | $name::Invalid(r) => Some(r.status),
                    _ => None,
                }
            }
        }

        impl From<CallError> for $name {
            fn from(e: CallError) -> Self {
                match e {
                    CallError::Connect(e) => $name::Connect(e),
                    CallError::NoDaemon { service, prefix, domain } => $name::NoDaemon { service, prefix, domain },
                    CallError::DaemonGone => $name::DaemonGone,
                    CallError::Timeout(t) => $name::Timeout(t),
                    CallError::Rejected(r) => $name::Rejected(r),
                    CallError::Local(r) => $name::Invalid(r),
                    CallError::Ipc(s) => $name::Ipc(s),
                    CallError::Interrupted => $name::Interrupted,
                }
            }
        }
    };
}

request_error!(
    /// Why a rendezvous query failed.
    RendezvousError,
    "rendezvous"
);
request_error!(
    /// Why a map operation (create, apply, upload, snapshot, delete, list) failed.
    MapRequestError,
    "map"
);
request_error!(
    /// Why a stats request failed.
    StatsRequestError,
    "stats"
);
