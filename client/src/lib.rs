//! # dyfos-client
//!
//! The library robot processes link to ask the `dyfosd` daemon, over iceoryx2 shared
//! memory, where a viewer should put its camera to localize a rover (DyFOS). It hides
//! iceoryx2: connect, send a [`RendezvousRequest`], get the [`Answer`]. Every call
//! takes a timeout and never hangs; a daemon restart shows as a retryable error
//! ([`RendezvousError::is_retryable`]) and the next call reconnects by itself.
//!
//! ```no_run
//! use dyfos_client::prelude::*;
//! use std::time::Duration;
//!
//! let mut client = Client::connect(&ClientConfig::default())?;
//! let bounds = Bounds::new([-10.0, -10.0, 10.0, 10.0])?;
//! client.create_map(1, bounds, Sun::new(0.7, 2.1)?, Duration::from_secs(1))?;
//! let belief = Belief::new([0.0, 0.0, 0.3], [[0.2, 0.05, 0.0], [0.05, 0.1, 0.0], [0.0, 0.0, 0.05]])?;
//! let request = RendezvousRequest { seed: 7, ..RendezvousRequest::new(1, belief) };
//! let answer = client.rendezvous(&request, Duration::from_secs(5))?;
//! println!("fly the viewer to {} (E = {:.3})", answer.viewer_position, answer.cost);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! Waiting for a reply first busy-polls for [`ClientConfig::poll`] (a reply to a
//! cheap request arrives within microseconds), then sleeps on an iceoryx2 event the
//! daemon sends with the reply, so a long query costs the client no CPU.
#![warn(missing_docs)]

mod client;
mod error;

pub use client::{Client, ClientConfig, iceoryx_config};
pub use dyfos_shared::wire::map::MapInfo;
pub use dyfos_shared::wire::rendezvous::{RendezvousCheck, RendezvousRequest};
pub use dyfos_shared::wire::stats::DaemonStats;
pub use dyfos_shared::wire::{DEFAULT_PREFIX, Rejection, Status};
pub use error::{ClientOpenError, IpcFailure, MapRequestError, RendezvousError, StatsRequestError};

/// The iceoryx2 service variant of the client's ports: the thread-safe one, so a
/// [`Client`] can move between threads (defined once, with the services, in
/// `dyfos_shared::wire::services`).
pub use dyfos_shared::wire::services::Ipc;

/// Client, requests, answers, map deltas, errors and `nalgebra`, in one `use`.
pub mod prelude {
    pub use crate::{
        Client, ClientConfig, ClientOpenError, DaemonStats, MapInfo, MapRequestError, Rejection, RendezvousCheck,
        RendezvousError, RendezvousRequest, StatsRequestError, Status,
    };
    pub use dyfos_shared::prelude::*;
    pub use dyfos_shared::wire::map::MapId;
}
