//! What the examples share: the daemon they reach, and their map.

use dyfos_client::prelude::*;
use std::time::Duration;

/// The client configuration of a daemon serving `prefix` (default `dyfos/`) in the
/// iceoryx2 domain `domain` (default iceoryx2's): the examples' `[PREFIX [DOMAIN]]`.
pub fn config(prefix: Option<String>, domain: Option<String>) -> ClientConfig {
    ClientConfig {
        prefix: prefix.unwrap_or_else(|| dyfos_client::DEFAULT_PREFIX.to_string()),
        domain,
        ..ClientConfig::default()
    }
}

/// Creates `map`, an empty 20 m square, unless it exists: `true` if this call
/// created it.
pub fn create_map(client: &mut Client, map: MapId, timeout: Duration) -> Result<bool, Box<dyn std::error::Error>> {
    let bounds = Bounds::new([-10.0, -10.0, 10.0, 10.0])?;
    match client.create_map(map, bounds, Sun::new(0.7, 2.1)?, timeout) {
        Ok(_) => Ok(true),
        Err(e) if e.status() == Some(Status::MapExists) => Ok(false),
        Err(e) => Err(e.into()),
    }
}
