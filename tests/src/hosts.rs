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

use dyfos_process::netns::{Netns, ip_path, join};
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
    hosts: Vec<Netns>,
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
        let roles: &[&str] = if intruder { &["rover", "viewer", "intruder"] } else { &["rover", "viewer"] };
        let hosts: Vec<Netns> =
            roles.iter().map(|role| Netns::create(&format!("{tag}-{role}")).expect("a network namespace")).collect();
        join((&hosts[ROVER], "dl0", ROVER_IP), (&hosts[VIEWER], "dl0", VIEWER_IP)).expect("the rover-viewer link");
        if intruder {
            join((&hosts[ROVER], "dl1", ROVER_IP_2), (&hosts[INTRUDER], "dl0", INTRUDER_IP))
                .expect("the intruder link");
        }
        Some(Hosts { hosts })
    }

    /// `program` run inside host `host`'s network namespace.
    pub fn command(&self, host: usize, program: &std::path::Path) -> Command {
        self.hosts[host].command(program)
    }

    /// The rover host's Zenoh endpoint as seen from `host`.
    pub fn rover_endpoint(&self, host: usize, port: u16) -> String {
        let ip = if host == INTRUDER { ROVER_IP_2 } else { ROVER_IP };
        format!("tcp/{ip}:{port}")
    }

    /// Cuts (`false`) or restores (`true`) the rover–viewer link, as a radio fade does.
    pub fn set_link(&self, up: bool) {
        self.hosts[ROVER].set_link("dl0", up).expect("ip link set");
        self.hosts[VIEWER].set_link("dl0", up).expect("ip link set");
    }
}

/// A `stranger` process (`tests/src/bin/stranger.rs`) on host `host`, towards the
/// rover's link at `port`: `silent N` connections held open, or `garbage SECONDS`
/// of random frames. Killed when dropped.
#[derive(Debug)]
pub struct Stranger {
    _child: crate::KillOnDrop,
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
        Stranger { _child: crate::KillOnDrop::new(child), stdout }
    }

    /// The next line it prints (`holding N`, `sent …`); empty once it has exited.
    pub fn line(&mut self) -> String {
        let mut line = String::new();
        let _ = std::io::BufRead::read_line(&mut self.stdout, &mut line);
        line.trim().to_string()
    }
}
