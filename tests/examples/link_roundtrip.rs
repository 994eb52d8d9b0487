//! Benchmark of the cross-host link: the rendezvous → measurement round
//! trip across two network namespaces joined by a veth pair, each with its own
//! iceoryx2 domain and a `dyfos-link`, against the same round trip inside one
//! domain (no link), in the same run; the links' memory; how long a killed and
//! restarted link takes to carry a round trip again. Needs root.
//!
//! ```text
//! cargo build --workspace --bins --examples
//! target/debug/examples/link_roundtrip [ROUND_TRIPS]
//! ```
//!
//! A responder thread on the "viewer's host" answers each rendezvous state at once
//! with a measurement of the same step; the "rover" thread times send → receipt.

use dyfos_mission::mission::topics::{Inbox, Outbox, Topics, TopicsConfig};
use dyfos_shared::posterior::Belief;
use dyfos_shared::wire::mission::{
    MEASUREMENT_TOPIC, Measurement, MeasurementMsg, NoMeasurement, Observation, RENDEZVOUS_TOPIC, RendezvousState,
    RendezvousStateMsg,
};
use dyfos_tests::hosts::{Hosts, ROVER, VIEWER};
use std::process::{Child, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

fn topics(prefix: &str, domain: &str) -> Topics {
    Topics::open(&TopicsConfig { prefix: prefix.into(), domain: Some(domain.into()), mission: "bench".into() })
        .expect("topics")
}

/// Answers every rendezvous on `domain` with a measurement of its step, until `stop`.
fn responder(prefix: String, domain: String, stop: Arc<AtomicBool>) -> std::thread::JoinHandle<()> {
    std::thread::spawn(move || {
        let t = topics(&prefix, &domain);
        let inbox: Inbox<RendezvousStateMsg> = t.inbox("mission", RENDEZVOUS_TOPIC, 64).unwrap();
        let outbox: Outbox<MeasurementMsg> = t.outbox("mission", MEASUREMENT_TOPIC).unwrap();
        while !stop.load(Ordering::Relaxed) {
            if let Some(r) = inbox.recv_timeout(Duration::from_millis(50), &|| stop.load(Ordering::Relaxed)) {
                let m = Measurement {
                    step: r.step,
                    sim_time: 0.0,
                    observation: Observation::NotObserved(NoMeasurement::OutOfView),
                    viewer: None,
                    predicted_cost: None,
                };
                let _ = outbox.send(MeasurementMsg::from(&m));
            }
        }
    })
}

struct Pinger {
    _t: Topics,
    out: Outbox<RendezvousStateMsg>,
    inbox: Inbox<MeasurementMsg>,
    step: u32,
}

impl Pinger {
    fn new(prefix: &str, domain: &str) -> Pinger {
        let t = topics(prefix, domain);
        Pinger {
            out: t.outbox("mission", RENDEZVOUS_TOPIC).unwrap(),
            inbox: t.inbox("mission", MEASUREMENT_TOPIC, 64).unwrap(),
            _t: t,
            step: 0,
        }
    }

    /// One round trip; `None` when no answer came within `timeout`.
    fn ping(&mut self, timeout: Duration) -> Option<Duration> {
        self.step += 1;
        let belief = Belief::new([0.0, 0.0, 0.0], [[0.01, 0.0, 0.0], [0.0, 0.01, 0.0], [0.0, 0.0, 0.01]]).unwrap();
        let msg = RendezvousState::Rendezvous { step: self.step, sim_time: 0.0, belief };
        let start = Instant::now();
        self.out.send(RendezvousStateMsg::from(&msg)).unwrap();
        loop {
            let left = timeout.checked_sub(start.elapsed())?;
            match self.inbox.recv_timeout(left, &|| false) {
                Some(m) if m.step == self.step => return Some(start.elapsed()),
                Some(_) => {}
                None => return None,
            }
        }
    }
}

fn percentile(sorted: &[f64], p: f64) -> f64 {
    sorted[((sorted.len() - 1) as f64 * p).round() as usize]
}

fn report(name: &str, samples: &mut [f64]) -> (f64, f64) {
    samples.sort_by(f64::total_cmp);
    let (p50, p99) = (percentile(samples, 0.5), percentile(samples, 0.99));
    println!(
        "{name:<28} n={:<5} p50 {p50:8.1} µs  p99 {p99:8.1} µs  max {:8.1} µs",
        samples.len(),
        samples[samples.len() - 1]
    );
    (p50, p99)
}

fn rss_kib(pid: u32) -> u64 {
    std::fs::read_to_string(format!("/proc/{pid}/status"))
        .ok()
        .and_then(|s| s.lines().find(|l| l.starts_with("VmRSS:")).map(str::to_string))
        .and_then(|l| l.split_whitespace().nth(1).and_then(|v| v.parse().ok()))
        .unwrap_or(0)
}

fn main() {
    let n: usize = std::env::args().nth(1).and_then(|a| a.parse().ok()).unwrap_or(2000);
    let Some(hosts) = Hosts::create("link_roundtrip", false) else { std::process::exit(1) };
    let pid = std::process::id();
    let prefix = format!("bench-link-{pid}/");
    let (rover_domain, viewer_domain, local) = (format!("dbr{pid}_"), format!("dbv{pid}_"), format!("dbl{pid}_"));
    let credentials = std::env::temp_dir().join(format!("dyfos-bench-link-{pid}.credentials"));
    std::fs::write(&credentials, format!("bench:secret-{pid}-0123\n")).unwrap();
    let link_bin = dyfos_tests::bin("dyfos-link");
    let start_link = |host: usize| -> Child {
        let mut cmd = hosts.command(host, &link_bin);
        let (side, domain) = if host == ROVER { ("rover", &rover_domain) } else { ("viewer", &viewer_domain) };
        cmd.args(["--side", side, "--prefix", &prefix, "--domain", domain, "--mission-name", "bench"]);
        if host == ROVER {
            cmd.args(["--listen", "tcp/0.0.0.0:7447"]);
        } else {
            cmd.args(["--connect", &hosts.rover_endpoint(VIEWER, 7447)]);
        }
        cmd.arg("--credentials").arg(&credentials).stdout(Stdio::null()).stderr(Stdio::null());
        cmd.spawn().expect("start dyfos-link")
    };
    let links_started = Instant::now();
    let mut links = [start_link(ROVER), start_link(VIEWER)];

    let stop = Arc::new(AtomicBool::new(false));
    let responders = [
        responder(prefix.clone(), viewer_domain.clone(), stop.clone()),
        responder(prefix.clone(), local.clone(), stop.clone()),
    ];
    std::thread::sleep(Duration::from_millis(300));

    // One domain, no link: the baseline.
    let mut here = Pinger::new(&prefix, &local);
    while here.ping(Duration::from_secs(1)).is_none() {}
    let mut local_us: Vec<f64> =
        (0..n).filter_map(|_| here.ping(Duration::from_secs(5))).map(|d| d.as_secs_f64() * 1e6).collect();

    // Across the link: warm up until the first answer.
    let mut rover = Pinger::new(&prefix, &rover_domain);
    let connecting = Instant::now();
    while rover.ping(Duration::from_millis(500)).is_none() {
        assert!(connecting.elapsed() < Duration::from_secs(30), "the link never answered");
    }
    println!("first round trip over the link {:.2} s after the links started", links_started.elapsed().as_secs_f64());
    for _ in 0..100 {
        rover.ping(Duration::from_secs(5));
    }
    let mut lost = 0;
    let mut link_us = Vec::with_capacity(n);
    for _ in 0..n {
        match rover.ping(Duration::from_secs(5)) {
            Some(d) => link_us.push(d.as_secs_f64() * 1e6),
            None => lost += 1,
        }
    }
    println!("round trip rendezvous → measurement ({n} sequential, after 100 warm-up):");
    let (lp50, lp99) = report("one host (iceoryx2 only)", &mut local_us);
    let (zp50, zp99) = report("two hosts (dyfos-link, zenoh)", &mut link_us);
    println!("ratio two hosts / one host: p50 {:.1}×, p99 {:.1}×; lost {lost}", zp50 / lp50, zp99 / lp99);
    println!(
        "RSS: rover-side link {} MiB, viewer-side link {} MiB",
        rss_kib(links[0].id()) / 1024,
        rss_kib(links[1].id()) / 1024
    );

    // Restart: kill the rover's link, start it again, time until a round trip passes.
    let _ = links[0].kill();
    let _ = links[0].wait();
    let killed = Instant::now();
    links[0] = start_link(ROVER);
    while rover.ping(Duration::from_millis(200)).is_none() {
        assert!(killed.elapsed() < Duration::from_secs(60), "no round trip after the restart");
    }
    println!("rover-side link killed and restarted: round trips again after {:.2} s", killed.elapsed().as_secs_f64());

    stop.store(true, Ordering::Relaxed);
    for r in responders {
        let _ = r.join();
    }
    for mut l in links {
        dyfos_process::shutdown::terminate(l.id());
        let _ = l.wait();
    }
    let _ = std::fs::remove_file(&credentials);
}
