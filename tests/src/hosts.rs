//! Two (or three) "hosts" on one machine for the cross-host tests: Linux network
//! namespaces joined by veth pairs, made with iproute2 and removed on drop (also
//! when a test fails). Each host's processes also get their own iceoryx2 domain,
//! so that the only way between them is the network.
//!
//! ```text
//!   viewer 10.77.0.2 ── 10.77.0.1 rover 10.77.1.1 ── 10.77.1.2 intruder (optional)
//! ```
//!
//! Needs root (CI runs as root); [`Hosts::create`] returns `None` after printing a
//! loud `SKIPPED` line otherwise.

use std::process::{Command, Stdio};
use std::sync::atomic::{AtomicU32, Ordering};

/// The rover's host.
pub const ROVER: usize = 0;
/// The viewer's host.
pub const VIEWER: usize = 1;
/// The third host, without the mission's credentials.
pub const INTRUDER: usize = 2;

/// Addresses: the rover's towards the viewer, the viewer's, the rover's towards the intruder, the intruder's.
const ROVER_IP: &str = "10.77.0.1";
const VIEWER_IP: &str = "10.77.0.2";
const ROVER_IP_2: &str = "10.77.1.1";
const INTRUDER_IP: &str = "10.77.1.2";

static NEXT: AtomicU32 = AtomicU32::new(0);

/// Network namespaces standing for hosts.
#[derive(Debug)]
pub struct Hosts {
    names: Vec<String>,
}

fn ip(args: &[&str]) -> Result<(), String> {
    let out = Command::new(ip_path()).args(args).stdin(Stdio::null()).output().map_err(|e| format!("ip: {e}"))?;
    if out.status.success() {
        Ok(())
    } else {
        Err(format!("ip {}: {}", args.join(" "), String::from_utf8_lossy(&out.stderr).trim()))
    }
}

fn ip_path() -> &'static str {
    if std::path::Path::new("/usr/sbin/ip").exists() { "/usr/sbin/ip" } else { "ip" }
}

impl Hosts {
    /// Makes the rover's and viewer's hosts (and the intruder's with `intruder`),
    /// or prints `SKIPPED` and returns `None` when not root or without iproute2.
    pub fn create(test: &str, intruder: bool) -> Option<Hosts> {
        let root = std::fs::read_to_string("/proc/self/status")
            .map(|s| s.lines().any(|l| l.starts_with("Uid:") && l.split_whitespace().nth(1) == Some("0")))
            .unwrap_or(false);
        if !root || Command::new(ip_path()).arg("-V").output().is_err() {
            eprintln!(
                "\n**********\nSKIPPED {test}: needs root and iproute2 (`ip`) to make network namespaces; CI runs as root\n**********\n"
            );
            return None;
        }
        let n = NEXT.fetch_add(1, Ordering::Relaxed);
        let tag = format!("dyfos-{}-{n}", std::process::id());
        let mut names = vec![format!("{tag}-rover"), format!("{tag}-viewer")];
        if intruder {
            names.push(format!("{tag}-intruder"));
        }
        let mut hosts = Hosts { names: Vec::new() };
        for name in &names {
            ip(&["netns", "add", name]).expect("ip netns add");
            hosts.names.push(name.clone());
            ip(&["-n", name, "link", "set", "lo", "up"]).expect("lo up");
        }
        let join = |a: usize, b: usize, ifa: &str, ifb: &str, ipa: &str, ipb: &str| {
            let (na, nb) = (&names[a], &names[b]);
            ip(&["link", "add", ifa, "netns", na, "type", "veth", "peer", "name", ifb, "netns", nb]).expect("veth");
            ip(&["-n", na, "addr", "add", &format!("{ipa}/24"), "dev", ifa]).expect("addr");
            ip(&["-n", nb, "addr", "add", &format!("{ipb}/24"), "dev", ifb]).expect("addr");
            ip(&["-n", na, "link", "set", ifa, "up"]).expect("up");
            ip(&["-n", nb, "link", "set", ifb, "up"]).expect("up");
        };
        join(ROVER, VIEWER, "dl0", "dl0", ROVER_IP, VIEWER_IP);
        if intruder {
            join(ROVER, INTRUDER, "dl1", "dl0", ROVER_IP_2, INTRUDER_IP);
        }
        Some(hosts)
    }

    /// `program` run inside host `host`'s network namespace.
    pub fn command(&self, host: usize, program: &std::path::Path) -> Command {
        let mut cmd = Command::new(ip_path());
        cmd.args(["netns", "exec", &self.names[host]]).arg(program);
        cmd
    }

    /// The rover host's Zenoh endpoint as seen from `host`.
    pub fn rover_endpoint(&self, host: usize, port: u16) -> String {
        let ip = if host == INTRUDER { ROVER_IP_2 } else { ROVER_IP };
        format!("tcp/{ip}:{port}")
    }

    /// Cuts (`false`) or restores (`true`) the rover–viewer link, as a radio fade does.
    pub fn set_link(&self, up: bool) {
        ip(&["-n", &self.names[ROVER], "link", "set", "dl0", if up { "up" } else { "down" }]).expect("ip link set");
        ip(&["-n", &self.names[VIEWER], "link", "set", "dl0", if up { "up" } else { "down" }]).expect("ip link set");
    }
}

impl Drop for Hosts {
    fn drop(&mut self) {
        for name in &self.names {
            if let Err(e) = ip(&["netns", "del", name]) {
                eprintln!("cannot remove network namespace {name}: {e}");
            }
        }
    }
}

/// A `stranger` process (`tests/src/bin/stranger.rs`) on host `host`, towards the
/// rover's link at `port`: `silent N` connections held open, or `garbage SECONDS`
/// of random frames. Killed when dropped.
#[derive(Debug)]
pub struct Stranger {
    child: std::process::Child,
    stdout: std::io::BufReader<std::process::ChildStdout>,
}

impl Stranger {
    /// Starts `stranger MODE ADDR AMOUNT` on `host`.
    pub fn start(hosts: &Hosts, host: usize, port: u16, mode: &str, amount: &str) -> Stranger {
        let addr = format!("{}:{port}", if host == INTRUDER { ROVER_IP_2 } else { ROVER_IP });
        let mut child = hosts
            .command(host, &crate::bin("stranger"))
            .args([mode, &addr, amount])
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .expect("start stranger");
        let stdout = std::io::BufReader::new(child.stdout.take().expect("stdout"));
        Stranger { child, stdout }
    }

    /// The next line it prints (`holding N`, `sent …`); empty once it has exited.
    pub fn line(&mut self) -> String {
        let mut line = String::new();
        let _ = std::io::BufRead::read_line(&mut self.stdout, &mut line);
        line.trim().to_string()
    }
}

impl Drop for Stranger {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}
