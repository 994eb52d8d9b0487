//! The typed opening of each of the daemon's iceoryx2 services: the one place that
//! says which payload and header types a service carries, and the limits the daemon
//! creates it with. The daemon, the client, the tests and the benchmarks all open
//! their services here; nothing here opens a port or creates a node: every function
//! takes a [`Node`] the caller owns and gives back a builder, which the caller opens
//! (a client), creates (the daemon) or tunes (a test).
//!
//! ```no_run
//! use dyfos_shared::wire::ServiceNames;
//! use dyfos_shared::wire::services::{Ipc, Services, iceoryx_config};
//! use iceoryx2::prelude::*;
//!
//! let node = NodeBuilder::new().config(&iceoryx_config(None)?).create::<Ipc>()?;
//! let names = ServiceNames::new("dyfos/")?;
//! let stats = Services::new(&node, &names).stats()?.open()?;
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use super::ServiceNames;
use super::map::{MapReplyHeader, MapRequestHeader, WireDelta};
use super::rendezvous::{RendezvousReply, RendezvousRequestHeader};
use super::stats::{StatsReply, StatsRequest};
use iceoryx2::prelude::*;
use iceoryx2::service::builder::{event, request_response};
use iceoryx2::service::port_factory;
use std::fmt::Debug;

/// The iceoryx2 service variant of the daemon's and the client's ports:
/// thread-safe, so a request can move to a worker thread and a client can be
/// shared. It shares memory with `ipc::Service` peers.
pub type Ipc = ipc_threadsafe::Service;

/// The rendezvous service: deltas with a [`RendezvousRequestHeader`], answered by a
/// [`RendezvousReply`].
pub type RendezvousBuilder<S = Ipc> =
    request_response::Builder<[WireDelta], RendezvousRequestHeader, RendezvousReply, (), S>;
/// The map service: deltas both ways, with [`MapRequestHeader`] and [`MapReplyHeader`].
pub type MapBuilder<S = Ipc> = request_response::Builder<[WireDelta], MapRequestHeader, [WireDelta], MapReplyHeader, S>;
/// The stats service.
pub type StatsBuilder<S = Ipc> = request_response::Builder<StatsRequest, (), StatsReply, (), S>;

/// The opened rendezvous service.
pub type RendezvousService<S = Ipc> =
    port_factory::request_response::PortFactory<S, [WireDelta], RendezvousRequestHeader, RendezvousReply, ()>;
/// The opened map service.
pub type MapService<S = Ipc> =
    port_factory::request_response::PortFactory<S, [WireDelta], MapRequestHeader, [WireDelta], MapReplyHeader>;
/// The opened stats service.
pub type StatsService<S = Ipc> = port_factory::request_response::PortFactory<S, StatsRequest, (), StatsReply, ()>;

/// A service name iceoryx2 refuses (a prefix that passed [`ServiceNames::new`]
/// always makes valid names).
#[derive(Debug, Clone, thiserror::Error)]
#[error("`{name}` cannot name an iceoryx2 service: {source:?}")]
pub struct BadServiceName {
    /// The name.
    pub name: String,
    /// iceoryx2's reason.
    pub source: iceoryx2::service::service_name::ServiceNameError,
}

/// An `--domain` (iceoryx2 file prefix) that is not a valid file-name prefix.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("iceoryx2 domain `{0}` is not a valid file-name prefix; use letters, digits and `_`, at most 32")]
pub struct InvalidDomain(pub String);

/// The iceoryx2 configuration of a domain (`None`: iceoryx2's default `iox2_`):
/// processes see each other only within one domain.
pub fn iceoryx_config(domain: Option<&str>) -> Result<iceoryx2::config::Config, InvalidDomain> {
    let mut config = iceoryx2::config::Config::default();
    if let Some(d) = domain {
        let valid = !d.is_empty() && d.len() <= 32 && d.bytes().all(|b| b.is_ascii_alphanumeric() || b == b'_');
        config.global.prefix = match FileName::new(d.as_bytes()) {
            Ok(name) if valid => name,
            _ => return Err(InvalidDomain(d.to_string())),
        };
    }
    Ok(config)
}

/// The daemon's services on one node, under one prefix.
#[derive(Debug)]
pub struct Services<'a, S: Service = Ipc> {
    node: &'a Node<S>,
    names: &'a ServiceNames,
}

impl<'a, S: Service> Services<'a, S> {
    /// The services named by `names`, opened through `node`.
    pub fn new(node: &'a Node<S>, names: &'a ServiceNames) -> Self {
        Services { node, names }
    }

    /// The names.
    pub fn names(&self) -> &ServiceNames {
        self.names
    }

    fn builder(&self, name: &str) -> Result<iceoryx2::service::builder::Builder<S>, BadServiceName> {
        builder(self.node, name)
    }

    /// `<prefix>rendezvous`.
    pub fn rendezvous(&self) -> Result<RendezvousBuilder<S>, BadServiceName> {
        rendezvous_named(self.node, &self.names.rendezvous)
    }

    /// `<prefix>map`.
    pub fn map(&self) -> Result<MapBuilder<S>, BadServiceName> {
        Ok(self
            .builder(&self.names.map)?
            .request_response::<[WireDelta], [WireDelta]>()
            .request_user_header::<MapRequestHeader>()
            .response_user_header::<MapReplyHeader>())
    }

    /// `<prefix>stats`.
    pub fn stats(&self) -> Result<StatsBuilder<S>, BadServiceName> {
        Ok(self.builder(&self.names.stats)?.request_response::<StatsRequest, StatsReply>())
    }

    /// `<prefix>wake`: a client sent a request (the daemon listens).
    pub fn wake(&self) -> Result<event::Builder<S>, BadServiceName> {
        Ok(self.builder(&self.names.wake)?.event())
    }

    /// `<prefix>reply`: the daemon answered (each client listens).
    pub fn reply(&self) -> Result<event::Builder<S>, BadServiceName> {
        Ok(self.builder(&self.names.reply)?.event())
    }
}

/// A service with the rendezvous service's types under any `name` (the benchmark's
/// floor: iceoryx2 alone, without a daemon behind it).
pub fn rendezvous_named<S: Service>(node: &Node<S>, name: &str) -> Result<RendezvousBuilder<S>, BadServiceName> {
    Ok(builder(node, name)?
        .request_response::<[WireDelta], RendezvousReply>()
        .request_user_header::<RendezvousRequestHeader>())
}

fn builder<S: Service>(node: &Node<S>, name: &str) -> Result<iceoryx2::service::builder::Builder<S>, BadServiceName> {
    let service = ServiceName::new(name).map_err(|source| BadServiceName { name: name.to_string(), source })?;
    Ok(node.service_builder(&service))
}

/// The limits the daemon creates its services with (`docs/wire.md`): one server,
/// `max_clients` clients, each with at most `max_requests_per_client` requests in
/// flight. A daemon that finds a service with smaller limits refuses to start.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ServiceLimits {
    /// Client ports at once.
    pub max_clients: usize,
    /// Requests one client port may have in flight.
    pub max_requests_per_client: usize,
}

impl ServiceLimits {
    /// Nodes that may use a service: every client's, the daemon's and one spare.
    pub fn max_nodes(&self) -> usize {
        self.max_clients + 2
    }

    /// A request-response service with these limits: no fire-and-forget requests
    /// (every request gets exactly one reply), two loans and two buffered responses.
    pub fn request_response<Req, ReqHeader, Res, ResHeader, S>(
        &self,
        builder: request_response::Builder<Req, ReqHeader, Res, ResHeader, S>,
    ) -> request_response::Builder<Req, ReqHeader, Res, ResHeader, S>
    where
        Req: Debug + IceoryxSend + ?Sized,
        ReqHeader: Debug + ZeroCopySend,
        Res: Debug + IceoryxSend + ?Sized,
        ResHeader: Debug + ZeroCopySend,
        S: Service,
    {
        builder
            .enable_fire_and_forget_requests(false)
            .max_servers(1)
            .max_clients(self.max_clients)
            .max_nodes(self.max_nodes())
            .max_active_requests_per_client(self.max_requests_per_client)
            .max_response_buffer_size(2)
            .max_loaned_requests(2)
            .max_borrowed_responses_per_pending_response(2)
    }

    /// An event service with these limits: a notifier and a listener per client,
    /// and the daemon's.
    pub fn event<S: Service>(&self, builder: event::Builder<S>) -> event::Builder<S> {
        builder.max_nodes(self.max_nodes()).max_notifiers(self.max_clients + 1).max_listeners(self.max_clients + 1)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_domain_is_a_short_file_name_prefix() {
        assert!(iceoryx_config(None).is_ok());
        assert_eq!(iceoryx_config(Some("dyfos_test_7")).unwrap().global.prefix.as_bytes(), b"dyfos_test_7");
        for bad in ["", "a/b", "a.b", &"x".repeat(33)] {
            assert_eq!(iceoryx_config(Some(bad)).unwrap_err(), InvalidDomain(bad.to_string()));
        }
    }
}
