//! `dyfos demo --hosts 2`: two hosts on one machine. The rover runs in a network
//! namespace of its own with its own iceoryx2 domain; the viewer, in a second
//! namespace, shares the demo's domain with `dyfosd` and the evaluation. A veth
//! pair joins the two namespaces, and a `dyfos-link` on each side carries the
//! mission between them over Zenoh, with credentials made for the demo.

use anyhow::{Context, bail};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

/// The rover host's address on the veth pair, where its link listens.
pub const ROVER_ENDPOINT: &str = "tcp/10.78.0.1:7447";

/// Two network namespaces joined by a veth pair, removed on drop.
pub struct TwoHosts {
    /// The rover's namespace.
    pub rover: String,
    /// The viewer's namespace.
    pub viewer: String,
    /// The rover host's iceoryx2 domain.
    pub rover_domain: String,
    /// The mission's credentials file (`user:password`).
    pub credentials: PathBuf,
}

fn ip_path() -> &'static str {
    if Path::new("/usr/sbin/ip").exists() { "/usr/sbin/ip" } else { "ip" }
}

fn ip(args: &[&str]) -> anyhow::Result<()> {
    let out = Command::new(ip_path())
        .args(args)
        .stdin(Stdio::null())
        .output()
        .context("cannot run `ip` (iproute2); install it (apt-get install iproute2)")?;
    if !out.status.success() {
        bail!(
            "`ip {}` failed: {}; `--hosts 2` needs root (network namespaces)",
            args.join(" "),
            String::from_utf8_lossy(&out.stderr).trim()
        );
    }
    Ok(())
}

impl TwoHosts {
    /// Makes the namespaces and the credentials (in `dir`).
    pub fn create(dir: &Path) -> anyhow::Result<TwoHosts> {
        let pid = std::process::id();
        let mut hosts = TwoHosts {
            rover: String::new(),
            viewer: String::new(),
            rover_domain: format!("dyr{pid}_"),
            credentials: dir.join("mission.credentials"),
        };
        for (name, field) in [(format!("dyfos-demo-{pid}-rover"), 0), (format!("dyfos-demo-{pid}-viewer"), 1)] {
            ip(&["netns", "add", &name])?;
            if field == 0 {
                hosts.rover = name.clone()
            } else {
                hosts.viewer = name.clone()
            }
            ip(&["-n", &name, "link", "set", "lo", "up"])?;
        }
        ip(&[
            "link",
            "add",
            "dl0",
            "netns",
            &hosts.rover,
            "type",
            "veth",
            "peer",
            "name",
            "dl0",
            "netns",
            &hosts.viewer,
        ])?;
        for (ns, addr) in [(&hosts.rover, "10.78.0.1/24"), (&hosts.viewer, "10.78.0.2/24")] {
            ip(&["-n", ns, "addr", "add", addr, "dev", "dl0"])?;
            ip(&["-n", ns, "link", "set", "dl0", "up"])?;
        }
        let nanos = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_nanos());
        std::fs::write(&hosts.credentials, format!("demo:{:032x}\n", nanos ^ (u128::from(pid) << 64)))
            .with_context(|| format!("cannot write {}", hosts.credentials.display()))?;
        Ok(hosts)
    }

    /// `program` run in namespace `ns`.
    pub fn command(&self, ns: &str, program: &Path) -> Command {
        let mut cmd = Command::new(ip_path());
        cmd.args(["netns", "exec", ns]).arg(program);
        cmd
    }
}

impl Drop for TwoHosts {
    fn drop(&mut self) {
        for ns in [&self.rover, &self.viewer] {
            if !ns.is_empty()
                && let Err(e) = ip(&["netns", "del", ns])
            {
                tracing::warn!("{e}");
            }
        }
        let _ = std::fs::remove_file(&self.credentials);
    }
}
