//! Linux network namespaces standing for hosts on one machine (the two-host demo
//! and the cross-host tests): made with iproute2's `ip`, joined by veth pairs,
//! removed on drop. Needs root.
//!
//! ```no_run
//! use dyfos_process::netns::{Netns, join};
//!
//! let a = Netns::create("demo-a").unwrap();
//! let b = Netns::create("demo-b").unwrap();
//! join((&a, "dl0", "10.78.0.1"), (&b, "dl0", "10.78.0.2")).unwrap();
//! let status = a.command(std::path::Path::new("/bin/true")).status().unwrap();
//! assert!(status.success());
//! ```

use std::path::Path;
use std::process::{Command, Stdio};

/// A network namespace, deleted on drop.
#[derive(Debug)]
pub struct Netns {
    name: String,
}

/// `ip`: iproute2 from `/usr/sbin` (not always on a user's `PATH`), else from `PATH`.
pub fn ip_path() -> &'static str {
    if Path::new("/usr/sbin/ip").exists() { "/usr/sbin/ip" } else { "ip" }
}

/// Runs `ip ARGS`; the error says what failed and `ip`'s own message.
pub fn ip(args: &[&str]) -> Result<(), String> {
    let out = Command::new(ip_path())
        .args(args)
        .stdin(Stdio::null())
        .output()
        .map_err(|e| format!("cannot run `ip` (iproute2; apt-get install iproute2): {e}"))?;
    if out.status.success() {
        Ok(())
    } else {
        Err(format!("`ip {}` failed: {}", args.join(" "), String::from_utf8_lossy(&out.stderr).trim()))
    }
}

impl Netns {
    /// Makes namespace `name` with its loopback up.
    pub fn create(name: &str) -> Result<Netns, String> {
        ip(&["netns", "add", name])?;
        let ns = Netns { name: name.to_string() };
        ip(&["-n", name, "link", "set", "lo", "up"])?;
        Ok(ns)
    }

    /// Its name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// `program` to be run inside it.
    pub fn command(&self, program: &Path) -> Command {
        let mut cmd = Command::new(ip_path());
        cmd.args(["netns", "exec", &self.name]).arg(program);
        cmd
    }

    /// Brings its interface `dev` up or down (a radio fade).
    pub fn set_link(&self, dev: &str, up: bool) -> Result<(), String> {
        ip(&["-n", &self.name, "link", "set", dev, if up { "up" } else { "down" }])
    }
}

impl Drop for Netns {
    fn drop(&mut self) {
        if let Err(e) = ip(&["netns", "del", &self.name]) {
            eprintln!("cannot remove network namespace {}: {e}", self.name);
        }
    }
}

/// Joins two namespaces with a veth pair: in each, interface `dev` with address
/// `addr`/24, up.
pub fn join(a: (&Netns, &str, &str), b: (&Netns, &str, &str)) -> Result<(), String> {
    let ((na, deva, _), (nb, devb, _)) = (a, b);
    ip(&["link", "add", deva, "netns", &na.name, "type", "veth", "peer", "name", devb, "netns", &nb.name])?;
    for (ns, dev, addr) in [a, b] {
        ip(&["-n", &ns.name, "addr", "add", &format!("{addr}/24"), "dev", dev])?;
        ns.set_link(dev, true)?;
    }
    Ok(())
}
