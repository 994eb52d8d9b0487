//! Helpers for the mission tests: a small world, and `dyfos-rover` /
//! `dyfos-viewer` processes in a [`Sandbox`], killed when dropped.
//!
//! ```no_run
//! use dyfos_tests::Sandbox;
//! use dyfos_tests::mission::{MissionFiles, small_mission};
//!
//! let sandbox = Sandbox::new("doc-mission");
//! let _daemon = sandbox.start_daemon(&[]);
//! let files = MissionFiles::new(&sandbox, &small_mission());
//! let mut viewer = files.viewer("m", "dyfos", 1, &[]);
//! let mut rover = files.rover("m", 1, "0", &[]);
//! assert!(rover.wait_exit().success());
//! assert!(viewer.wait_exit().success());
//! ```

use crate::hosts::{Hosts, ROVER, VIEWER};
use crate::{KillOnDrop, Sandbox, bin, log_of, wait_for_showing};
use dyfos_mission::eval::{MissionTrace, Recorder};
use dyfos_mission::mission::Mission;
use dyfos_mission::mission::log::read_events;
use dyfos_mission::mission::topics::TopicsConfig;
use dyfos_mission::sim::OdometryNoise;
use dyfos_shared::math::Point2;
use dyfos_shared::params::Params;
use dyfos_shared::posterior::Belief;
use dyfos_shared::world::{Bounds, Obstacle, Sun, VerticalCylinder, World};
use std::path::{Path, PathBuf};
use std::process::{Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

/// A 16 m × 16 m world with 6 trees and 4 waypoints over 10 m. The odometry is
/// noisier than the built-in mission's, so that a rover left to dead reckoning
/// drifts by decimetres to metres within these few legs.
pub fn small_mission() -> Mission {
    let trees = [[-0.5, 1.0], [-3.0, 0.5], [1.5, -3.5], [3.5, 3.0], [-1.0, -4.0], [5.0, -1.5]];
    let world = World::new(
        0,
        Bounds::new([-8.0, -8.0, 8.0, 8.0]).expect("bounds"),
        Sun::new(0.6, 2.4).expect("sun"),
        trees.iter().enumerate().map(|(i, c)| {
            let tree = VerticalCylinder { center: Point2::new(c[0], c[1]), radius: 0.5, height: 10.0 };
            (i as u32 + 1, Obstacle::Cylinder(tree))
        }),
        None,
    )
    .expect("world");
    let heading = 1.5f64.atan2(2.0);
    Mission {
        world,
        params: Params::default(),
        initial_belief: Belief::new(
            [-4.0, -3.0, heading],
            [[0.0025, 0.0, 0.0], [0.0, 0.0025, 0.0], [0.0, 0.0, 0.0025]],
        )
        .expect("belief"),
        waypoints: vec![[-2.0, -1.5], [0.5, -1.5], [2.0, 0.5], [4.5, 1.0]],
        true_start: None,
        viewer_start: ([-4.0, -3.0, 3.0], heading),
        odometry: OdometryNoise { trans_per_m: 0.005, trans_per_rad: 0.0005, rot_per_m: 0.005, rot_per_rad: 0.01 },
        sun_azimuth_rate: 0.0,
    }
}

/// A mission file for one test, beside the sandbox's state directory, removed on drop.
#[derive(Debug)]
pub struct MissionFiles<'a> {
    sandbox: &'a Sandbox,
    /// The mission file.
    pub mission: PathBuf,
    dir: PathBuf,
    logs: std::sync::atomic::AtomicU32,
}

impl<'a> MissionFiles<'a> {
    /// Writes `mission` for the processes of `sandbox`.
    pub fn new(sandbox: &'a Sandbox, mission: &Mission) -> Self {
        let dir = sandbox.state_dir.with_extension("mission");
        std::fs::create_dir_all(&dir).expect("mission dir");
        let path = dir.join("mission.json");
        std::fs::write(&path, mission.to_json()).expect("write mission");
        MissionFiles { sandbox, mission: path, dir, logs: Default::default() }
    }

    fn command(&self, binary: &str, name: &str, seed: u64, time_scale: &str) -> Command {
        self.command_on(Command::new(bin(binary)), &self.sandbox.domain, name, seed, time_scale)
    }

    fn command_on(&self, mut cmd: Command, domain: &str, name: &str, seed: u64, time_scale: &str) -> Command {
        cmd.args(["--prefix", &self.sandbox.prefix, "--domain", domain, "--mission-name", name])
            .arg("--mission")
            .arg(&self.mission)
            .args(["--seed", &seed.to_string(), "--time-scale", time_scale])
            .env("RUST_LOG", "debug")
            .stdin(Stdio::null())
            .stdout(Stdio::null());
        cmd
    }

    fn spawn(&self, mut cmd: Command, what: &str) -> Robot {
        let log = self.dir.join(format!("{what}.log"));
        let events = self.dir.join(format!("{what}.jsonl"));
        cmd.arg("--events").arg(&events);
        cmd.stderr(std::fs::File::create(&log).expect("log file"));
        let child = cmd.spawn().unwrap_or_else(|e| panic!("start {what}: {e}"));
        Robot { child: KillOnDrop::new(child), log, events }
    }

    /// Starts `dyfos-viewer` for mission `name` with `algo`, unpaced, map id 1.
    pub fn viewer(&self, name: &str, algo: &str, seed: u64, extra: &[&str]) -> Robot {
        let mut cmd = self.command("dyfos-viewer", name, seed, "0");
        cmd.args(["--algo", algo, "--connect-timeout", "30", "--observe-timeout", "30"]).args(extra);
        self.spawn(cmd, &format!("{name}-viewer"))
    }

    /// Starts `dyfos-rover` for mission `name`, at `time_scale` (0: unpaced).
    pub fn rover(&self, name: &str, seed: u64, time_scale: &str, extra: &[&str]) -> Robot {
        let mut cmd = self.command("dyfos-rover", name, seed, time_scale);
        cmd.args(["--viewer-timeout", "30"]).args(extra);
        self.spawn(cmd, &format!("{name}-rover"))
    }

    /// The iceoryx2 domain of the rover's host in a two-host test (the viewer's
    /// host, with the daemon and the recorder, is the sandbox's own domain).
    pub fn rover_domain(&self) -> String {
        self.sandbox.host_domain('r')
    }

    /// The mission's credentials file for `dyfos-link` (written on first use).
    pub fn credentials(&self) -> PathBuf {
        let path = self.dir.join("crew.credentials");
        if !path.exists() {
            std::fs::write(&path, format!("crew:secret-{}-{}\n", std::process::id(), self.sandbox.prefix.len()))
                .expect("write credentials");
        }
        path
    }

    /// Starts `dyfos-rover` on the rover's host of `hosts`, in its own domain.
    pub fn rover_on(&self, hosts: &Hosts, name: &str, seed: u64, time_scale: &str, extra: &[&str]) -> Robot {
        let domain = self.rover_domain();
        let mut cmd = self.command_on(hosts.command(ROVER, &bin("dyfos-rover")), &domain, name, seed, time_scale);
        cmd.args(["--viewer-timeout", "30"]).args(extra);
        self.spawn(cmd, &format!("{name}-rover"))
    }

    /// Starts `dyfos-viewer` on the viewer's host of `hosts` (the sandbox's domain and daemon).
    pub fn viewer_on(&self, hosts: &Hosts, name: &str, algo: &str, seed: u64, extra: &[&str]) -> Robot {
        let mut cmd =
            self.command_on(hosts.command(VIEWER, &bin("dyfos-viewer")), &self.sandbox.domain, name, seed, "0");
        cmd.args(["--algo", algo, "--connect-timeout", "30", "--observe-timeout", "30"]).args(extra);
        self.spawn(cmd, &format!("{name}-viewer-{}", self.next_log()))
    }

    /// Starts `dyfos-link` on `host` of `hosts` (`ROVER` listens, `VIEWER` connects),
    /// with the mission's credentials; `what` names its log.
    pub fn link_on(&self, hosts: &Hosts, host: usize, name: &str, extra: &[&str]) -> Robot {
        let mut cmd = hosts.command(host, &bin("dyfos-link"));
        let (side, domain) =
            if host == ROVER { ("rover", self.rover_domain()) } else { ("viewer", self.sandbox.domain.clone()) };
        cmd.args(["--side", side, "--prefix", &self.sandbox.prefix, "--domain", &domain, "--mission-name", name]);
        if host == ROVER {
            cmd.args(["--listen", "tcp/0.0.0.0:7447"]);
        } else {
            cmd.args(["--connect", &hosts.rover_endpoint(host, 7447)]);
        }
        cmd.arg("--credentials").arg(self.credentials()).args(extra);
        cmd.env("RUST_LOG", "info").stdin(Stdio::null()).stdout(Stdio::null());
        let log = self.dir.join(format!("{name}-link-{side}-{}.log", self.next_log()));
        cmd.stderr(std::fs::File::create(&log).expect("log file"));
        let child = cmd.spawn().unwrap_or_else(|e| panic!("start dyfos-link: {e}"));
        Robot { child: KillOnDrop::new(child), log, events: self.dir.join("none.jsonl") }
    }

    fn next_log(&self) -> u32 {
        self.logs.fetch_add(1, std::sync::atomic::Ordering::Relaxed)
    }

    /// Runs `dyfos demo` on this mission file, unpaced, with the arms `dyfos` and
    /// `center`, writing to `out`, with `extra` flags. Fails the test,
    /// with what it printed, unless it succeeds; returns its standard output.
    pub fn demo(&self, out: &Path, extra: &[&str]) -> String {
        let output = Command::new(bin("dyfos"))
            .args(["demo", "--time-scale", "0", "--algos", "dyfos,center"])
            .args(extra)
            .arg("--mission")
            .arg(&self.mission)
            .arg("--out")
            .arg(out)
            .output()
            .expect("run dyfos demo");
        let stdout = String::from_utf8_lossy(&output.stdout).to_string();
        assert!(output.status.success(), "dyfos demo {extra:?}: {stdout}\n{}", String::from_utf8_lossy(&output.stderr));
        stdout
    }

    /// Where the rover and the viewer write their MCAP files (`--mcap`): beside the
    /// mission file, removed with it.
    pub fn mcap_files(&self) -> (PathBuf, PathBuf) {
        (self.dir.join("rover.mcap"), self.dir.join("viewer.mcap"))
    }

    /// A recorder for mission `name`: open it before starting the rover.
    pub fn recorder(&self, name: &str) -> Recorder {
        Recorder::open(&TopicsConfig {
            prefix: self.sandbox.prefix.clone(),
            domain: Some(self.sandbox.domain.clone()),
            mission: name.to_string(),
        })
        .expect("open the recorder")
    }

    /// Runs mission `name` to its end, unpaced, with `seed`: the recorder, a viewer
    /// searching with dyfos (`viewer_extra`), the rover (`rover_extra`); both must
    /// exit 0. Returns the rover, the viewer and the recorded trace.
    pub fn run(
        &self,
        name: &str,
        seed: u64,
        viewer_extra: &[&str],
        rover_extra: &[&str],
    ) -> (Robot, Robot, MissionTrace) {
        let (recorder, mut viewer, mut rover) = self.start(name, seed, "0", viewer_extra, rover_extra);
        let trace = finish(recorder, &mut rover, &mut viewer);
        (rover, viewer, trace)
    }

    /// Starts mission `name` with `seed`: the recorder, a viewer searching with
    /// dyfos (`viewer_extra`), the rover at `time_scale` (`rover_extra`). Returns
    /// them in that order.
    pub fn start(
        &self,
        name: &str,
        seed: u64,
        time_scale: &str,
        viewer_extra: &[&str],
        rover_extra: &[&str],
    ) -> (Recorder, Robot, Robot) {
        let recorder = self.recorder(name);
        let viewer = self.viewer(name, "dyfos", seed, viewer_extra);
        let rover = self.rover(name, seed, time_scale, rover_extra);
        (recorder, viewer, rover)
    }
}

impl Drop for MissionFiles<'_> {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

/// A rover or viewer process, killed when dropped.
#[derive(Debug)]
pub struct Robot {
    child: KillOnDrop,
    log: PathBuf,
    events: PathBuf,
}

impl Robot {
    /// The process id.
    pub fn pid(&self) -> u32 {
        self.child.id()
    }

    /// Waits (at most [`crate::PATIENCE`]) for the exit.
    pub fn wait_exit(&mut self) -> ExitStatus {
        assert!(self.child.child_mut().is_some(), "still running");
        wait_for_showing("a mission process to exit", log_of(&self.log), || self.child.try_wait())
    }

    /// `Some(status)` if it has exited.
    pub fn try_exit(&mut self) -> Option<ExitStatus> {
        self.child.try_wait()
    }

    /// SIGTERM, and wait (at most [`crate::PATIENCE`]) for the exit.
    pub fn terminate(&mut self) -> ExitStatus {
        if self.child.child_mut().is_some() {
            dyfos_process::shutdown::terminate(self.child.id());
        }
        self.wait_exit()
    }

    /// SIGKILL, and reap.
    pub fn kill9(&mut self) {
        self.child.kill();
    }

    /// Its log (stderr) so far.
    pub fn log(&self) -> String {
        std::fs::read_to_string(&self.log).unwrap_or_default()
    }

    /// Its JSON-lines events so far.
    pub fn events(&self) -> Vec<serde_json::Value> {
        read_events(&self.events).unwrap_or_default()
    }

    /// The event log's path.
    pub fn events_path(&self) -> &Path {
        &self.events
    }
}

/// Records the mission until the rover exits (at most [`crate::PATIENCE`]);
/// returns its status and the trace.
pub fn record_until_exit(mut recorder: Recorder, rover: &mut Robot) -> (ExitStatus, MissionTrace) {
    let start = Instant::now();
    loop {
        recorder.poll();
        if let Some(status) = rover.try_exit() {
            return (status, recorder.finish());
        }
        assert!(start.elapsed() < crate::PATIENCE, "the rover did not finish:\n{}", rover.log());
        recorder.wait(Duration::from_millis(20));
    }
}

/// Records the mission until the rover exits; the rover, then the viewer must exit
/// 0. Returns the trace.
pub fn finish(recorder: Recorder, rover: &mut Robot, viewer: &mut Robot) -> MissionTrace {
    let (status, trace) = record_until_exit(recorder, rover);
    assert!(status.success(), "rover failed:\n{}", rover.log());
    assert!(viewer.wait_exit().success(), "viewer failed:\n{}", viewer.log());
    trace
}

/// The events named `event`, as (step, event) pairs in log order.
pub fn steps_of<'e>(events: &'e [serde_json::Value], event: &str) -> Vec<(u64, &'e serde_json::Value)> {
    events
        .iter()
        .filter(|e| e["event"] == event)
        .map(|e| (e["step"].as_u64().unwrap_or_else(|| panic!("{event} without a step: {e}")), e))
        .collect()
}
