//! The daemon's iceoryx2 ports: a server per request-response service, the wake-up
//! listener the IPC thread sleeps on, and the reply notifier ([`Replies`]) the IPC
//! thread and the workers wake clients with. The services themselves are opened as
//! `dyfos_shared::wire::services` says, with the daemon's limits.

use super::error::{DaemonCreateError, IpcError};
use super::rendezvous::Connected;
use dyfos_process::abandoned::recover;
use dyfos_shared::limits::SNAPSHOT_PAGE_RECORDS;
use dyfos_shared::wire::ServiceNames;
use dyfos_shared::wire::map::{MapReplyHeader, MapRequestHeader, WireDelta};
use dyfos_shared::wire::rendezvous::{RendezvousReply, RendezvousRequestHeader};
use dyfos_shared::wire::services::{Ipc, ServiceLimits, Services};
use dyfos_shared::wire::stats::{StatsReply, StatsRequest};
use iceoryx2::active_request::ActiveRequest;
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::server::Server;
use iceoryx2::prelude::*;
use iceoryx2::service::messaging_pattern::MessagingPattern;
use iceoryx2::service::port_factory::server::ServerCreateError;
use tracing::{debug, info};

type RendezvousServer = Server<Ipc, [WireDelta], RendezvousRequestHeader, RendezvousReply, ()>;
type MapServer = Server<Ipc, [WireDelta], MapRequestHeader, [WireDelta], MapReplyHeader>;
type StatsServer = Server<Ipc, StatsRequest, (), StatsReply, ()>;

/// A rendezvous request taken from the port, answered through it.
pub(crate) type RendezvousActive = ActiveRequest<Ipc, [WireDelta], RendezvousRequestHeader, RendezvousReply, ()>;
/// A map request taken from the port.
pub(crate) type MapActive = ActiveRequest<Ipc, [WireDelta], MapRequestHeader, [WireDelta], MapReplyHeader>;
/// A stats request taken from the port.
pub(crate) type StatsActive = ActiveRequest<Ipc, StatsRequest, (), StatsReply, ()>;

impl Connected for RendezvousActive {
    fn is_connected(&self) -> bool {
        ActiveRequest::is_connected(self)
    }
}

/// The ports only the IPC thread uses.
pub(crate) struct Ports {
    pub(crate) node: Node<Ipc>,
    pub(crate) rendezvous: RendezvousServer,
    pub(crate) map: MapServer,
    pub(crate) stats: StatsServer,
    pub(crate) wake: Listener<Ipc>,
    /// Where the IPC thread sleeps: on `wake`, attached once, and on SIGINT/SIGTERM.
    pub(crate) waitset: WaitSet<Ipc>,
}

/// Wakes clients once their reply is sent; used by the IPC thread and the workers.
pub(crate) struct Replies(Notifier<Ipc>);

impl Replies {
    /// Wakes the client whose reply listener has id `listener`.
    pub(crate) fn notify(&self, listener: u128) {
        self.0.for_each_listener(|m, details| {
            if details.listener_id.value() == listener {
                if let Err(e) = m.notify() {
                    debug!("reply notification failed: {e:?}");
                }
                CallbackProgression::Stop
            } else {
                CallbackProgression::Continue
            }
        });
    }
}

/// Opens a service with `open`; if that fails because a process killed while
/// creating the service left it half made (see `dyfos_process::abandoned`), removes
/// the remains and opens once more. A daemon restarted after such a death would
/// otherwise find the name unusable for good.
fn recovering<T, E>(
    node: &Node<Ipc>,
    name: &str,
    pattern: MessagingPattern,
    open: impl Fn() -> Result<Result<T, E>, DaemonCreateError>,
) -> Result<Result<T, E>, DaemonCreateError> {
    let first = open()?;
    if first.is_ok() {
        return Ok(first);
    }
    match ServiceName::new(name) {
        Ok(service) if recover(node, &service, pattern) => open(),
        _ => Ok(first),
    }
}

impl Ports {
    /// Cleans up after dead processes (a daemon killed by SIGKILL leaves its shared
    /// memory behind), then opens (or creates) the services named by `names` with
    /// `limits` and makes the daemon's ports on them.
    pub(crate) fn open(
        iox: &iceoryx2::config::Config,
        names: &ServiceNames,
        limits: ServiceLimits,
    ) -> Result<(Ports, Replies), DaemonCreateError> {
        let node = NodeBuilder::new().config(iox).create::<Ipc>().map_err(|e| IpcError::new("node", e))?;
        let cleanup = node.try_cleanup_dead_nodes();
        if cleanup.cleanups > 0 || cleanup.failed_cleanups > 0 {
            info!(cleaned = cleanup.cleanups, failed = cleanup.failed_cleanups, "removed resources of dead processes");
        }
        let services = Services::new(&node, names);
        let incompatible = |service: &str, e: &dyn std::fmt::Debug| DaemonCreateError::Incompatible {
            service: service.to_string(),
            reason: format!("{e:?}"),
        };
        let named = |e| IpcError::new("service name", e);
        // Each service opened or created with the daemon's limits, through
        // `recovering`; one that exists with other payload types is `Incompatible`.
        macro_rules! open {
            ($service:ident, $limits:ident, $pattern:ident) => {
                recovering(&node, &names.$service, MessagingPattern::$pattern, || {
                    Ok(limits.$limits(services.$service().map_err(named)?).open_or_create())
                })?
                .map_err(|e| incompatible(&names.$service, &e))?
            };
        }
        let rendezvous = open!(rendezvous, request_response, RequestResponse);
        let map = open!(map, request_response, RequestResponse);
        let stats = open!(stats, request_response, RequestResponse);
        let wake_service = open!(wake, event, Event);
        let reply_service = open!(reply, event, Event);
        // A service serves one daemon: another's server there means it runs.
        let server = |e: ServerCreateError| match e {
            ServerCreateError::ExceedsMaxSupportedServers => DaemonCreateError::AlreadyRunning(names.prefix.clone()),
            e => IpcError::new("server", e).into(),
        };
        // The daemon sends exactly one response to every request, so a client port
        // holds at most one response per request it may have in flight or have
        // dropped unanswered (2 × `max_requests_per_client`); iceoryx2 would otherwise
        // preallocate for every response buffer and borrow slot as well (6× more).
        let responses = limits.max_clients * 2 * limits.max_requests_per_client + 1;
        // Each server with the service's own settings, then the daemon's one loan
        // and `responses` per request.
        macro_rules! server {
            ($service:ident $(, $setting:ident($value:expr))*) => {
                $service
                    .server_builder()
                    $(.$setting($value))*
                    .max_loaned_responses_per_request(1)
                    .override_response_preallocation(move |_| responses)
                    .create()
                    .map_err(server)?
            };
        }
        let rendezvous = server!(rendezvous);
        // A fixed-size segment of snapshot-page-sized replies: iceoryx2 keeps the
        // bookkeeping of a resizable segment for all of its 255 possible segments per
        // connected client (8 MB of /dev/shm per client, written and swept by this
        // thread each time one connects or leaves, stalling every other client's
        // requests).
        let map =
            server!(map, initial_max_slice_len(SNAPSHOT_PAGE_RECORDS), allocation_strategy(AllocationStrategy::Static));
        let stats = server!(stats);
        let wake = wake_service.listener_builder().create().map_err(|e| IpcError::new("wake listener", e))?;
        let reply = reply_service.notifier_builder().create().map_err(|e| IpcError::new("reply notifier", e))?;
        let waitset = WaitSetBuilder::new().create::<Ipc>().map_err(|e| IpcError::new("wait set", e))?;
        // Attached once, for the daemon's life. iceoryx2 0.10's `attach` reads
        // /proc/sys/fs/epoll/max_user_watches every time, so attaching and detaching
        // around each sleep made 6 of the 10 system calls of a wake-up, at real-time
        // priority, on a core whose client may be waiting for it to sleep again.
        // Forgetting the guard only skips its detach: the wait set and the listener
        // go together when the daemon is dropped. It is the wait set's only
        // attachment, so any event it reports is a wake-up (an attachment id would
        // not do: iceoryx2's ids hold the wait set's address, which changes when the
        // daemon moves).
        std::mem::forget(waitset.attach_notification(&wake).map_err(|e| IpcError::new("wait set", e))?);
        Ok((Ports { node, rendezvous, map, stats, wake, waitset }, Replies(reply)))
    }
}
