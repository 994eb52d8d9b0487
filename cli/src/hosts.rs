//! `dyfos demo --hosts 2`: two hosts on one machine. The rover runs in a network
//! namespace of its own with its own iceoryx2 domain; the viewer, in a second
//! namespace, shares the demo's domain with `dyfosd` and the evaluation. A veth
//! pair joins the two namespaces, and a `dyfos-link` on each side carries the
//! mission between them over Zenoh, with credentials made for the demo.

use anyhow::{Context, anyhow};
use dyfos_process::netns::{Netns, join};
use std::path::{Path, PathBuf};

/// The rover host's address on the veth pair, where its link listens.
pub const ROVER_ENDPOINT: &str = "tcp/10.78.0.1:7447";

/// Two network namespaces joined by a veth pair, removed on drop.
pub struct TwoHosts {
    /// The rover's namespace.
    pub rover: Netns,
    /// The viewer's namespace.
    pub viewer: Netns,
    /// The rover host's iceoryx2 domain.
    pub rover_domain: String,
    /// The mission's credentials file (`user:password`).
    pub credentials: PathBuf,
}

/// What `ip` said, with why it may have failed.
fn needs_root(e: String) -> anyhow::Error {
    anyhow!("{e}; `--hosts 2` needs root (network namespaces)")
}

impl TwoHosts {
    /// Makes the namespaces and the credentials (in `dir`).
    pub fn create(dir: &Path) -> anyhow::Result<TwoHosts> {
        let pid = std::process::id();
        let rover = Netns::create(&format!("dyfos-demo-{pid}-rover")).map_err(needs_root)?;
        let viewer = Netns::create(&format!("dyfos-demo-{pid}-viewer")).map_err(needs_root)?;
        join((&rover, "dl0", "10.78.0.1"), (&viewer, "dl0", "10.78.0.2")).map_err(needs_root)?;
        let hosts = TwoHosts {
            rover,
            viewer,
            rover_domain: format!("dyr{pid}_"),
            credentials: dir.join("mission.credentials"),
        };
        let nanos = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_nanos());
        std::fs::write(&hosts.credentials, format!("demo:{:032x}\n", nanos ^ (u128::from(pid) << 64)))
            .with_context(|| format!("cannot write {}", hosts.credentials.display()))?;
        Ok(hosts)
    }
}

impl Drop for TwoHosts {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.credentials);
    }
}
