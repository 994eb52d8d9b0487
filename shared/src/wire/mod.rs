//! Wire types of the daemon's iceoryx2 services (see `dyfosd`).
