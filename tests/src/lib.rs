//! Helpers for the multi-process integration tests: each test gets its own
//! [`Sandbox`] (service prefix, iceoryx2 domain and state directory), starts the
//! real `dyfosd` binary, and every process it starts is killed when dropped.
//!
//! ```no_run
//! use dyfos_tests::Sandbox;
//!
//! let sandbox = Sandbox::new("doc");
//! let daemon = sandbox.start_daemon(&[]);
//! let mut client = sandbox.client();
//! assert_eq!(client.stats(std::time::Duration::from_secs(5)).unwrap().maps, 0);
//! drop(daemon);
//! ```

pub mod hosts;
pub mod mission;
pub mod soak;

use dyfos_client::{Client, ClientConfig};
use dyfos_service::launch::DyfosdCommand;
use dyfos_shared::world::World;
use std::path::{Path, PathBuf};
use std::process::{Command, ExitStatus, Stdio};
use std::sync::OnceLock;
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::{Duration, Instant};

/// How long any wait in these tests may take before the test fails.
pub const PATIENCE: Duration = Duration::from_secs(30);

/// The directory holding the workspace's binaries (`target/debug`), found next to
/// the running test executable (`target/debug/deps/…`).
pub fn bin_dir() -> PathBuf {
    let exe = std::env::current_exe().expect("the test executable's path");
    let deps = exe.parent().expect("deps dir");
    deps.parent().expect("target profile dir").to_path_buf()
}

/// A workspace binary (`dyfosd`, `dyfos`, `dyfos-rover`, …) or, with `examples/` in
/// front, an example. The first call in a test process builds the workspace's
/// targets if they are missing (see [`build_binaries`]), so `cargo test` needs no
/// build before it.
pub fn bin(name: &str) -> PathBuf {
    static BUILT: OnceLock<Result<(), String>> = OnceLock::new();
    if let Err(e) = BUILT.get_or_init(build_binaries) {
        panic!("{e}");
    }
    let path = bin_dir().join(name);
    assert!(path.exists(), "{} is missing after building the workspace", path.display());
    path
}

/// Builds the workspace's targets with the cargo running the tests (`CARGO`), into
/// the target directory and profile of the running test executable: tests need
/// other packages' binaries, which cargo builds for a test only in its own package
/// (`CARGO_BIN_EXE_*`; depending on another package's binary is unstable). One
/// `--workspace --all-targets` build rather than one per binary (as escargot does):
/// it resolves features as `cargo test --workspace` does (`--bins` alone resolves
/// others and compiles the tree again), so after that or after
/// `cargo build --workspace --all-targets` it only checks that all is fresh.
fn build_binaries() -> Result<(), String> {
    let profile_dir = bin_dir();
    let profile = match profile_dir.file_name().and_then(|n| n.to_str()) {
        Some("debug") => "dev".to_string(),
        Some(name) => name.to_string(),
        None => return Err(format!("{} is not a cargo profile directory", profile_dir.display())),
    };
    let parent = profile_dir.parent().ok_or("the target directory")?;
    let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
    let mut cmd = Command::new(cargo);
    cmd.args(["build", "--quiet", "--workspace", "--all-targets", "--profile", &profile]);
    // `target/<triple>/<profile>` when the tests were built with `--target`.
    if parent.join("CACHEDIR.TAG").exists() {
        cmd.arg("--target-dir").arg(parent);
    } else {
        let triple = parent.file_name().and_then(|n| n.to_str()).ok_or("the target triple")?;
        cmd.args(["--target", triple]).arg("--target-dir").arg(parent.parent().ok_or("the target directory")?);
    }
    let workspace = Path::new(env!("CARGO_MANIFEST_DIR")).parent().ok_or("the workspace directory")?;
    let status = cmd.current_dir(workspace).status().map_err(|e| format!("cannot run {cmd:?}: {e}"))?;
    if status.success() { Ok(()) } else { Err(format!("{cmd:?} failed ({status}); its errors are above")) }
}

/// Polls `done` until it returns `Some`, panicking with `what` after [`PATIENCE`].
pub fn wait_for<T>(what: &str, done: impl FnMut() -> Option<T>) -> T {
    wait_for_showing(what, String::new, done)
}

/// What [`wait_for_showing`] shows of a process: its log file as it is then.
pub fn log_of(path: &Path) -> impl Fn() -> String + use<> {
    let path = path.to_path_buf();
    move || format!("its log:\n{}", std::fs::read_to_string(&path).unwrap_or_default())
}

/// [`wait_for`], with `context()` (say, the log of the process waited for) in the
/// panic message, read when the patience runs out.
pub fn wait_for_showing<T>(what: &str, context: impl Fn() -> String, mut done: impl FnMut() -> Option<T>) -> T {
    let start = Instant::now();
    loop {
        if let Some(v) = done() {
            return v;
        }
        assert!(start.elapsed() < PATIENCE, "timed out waiting for {what}\n{}", context());
        std::thread::sleep(Duration::from_millis(2));
    }
}

/// Polls the daemon's stats through `client` until `done` holds of them, panicking
/// with `what` after [`PATIENCE`]; returns the stats that did.
pub fn wait_for_stats(
    client: &mut Client,
    what: &str,
    done: impl Fn(&dyfos_shared::wire::stats::DaemonStats) -> bool,
) -> dyfos_shared::wire::stats::DaemonStats {
    wait_for(what, || Some(client.stats(PATIENCE).expect("stats")).filter(|s| done(s)))
}

static NEXT: AtomicU32 = AtomicU32::new(0);

/// One test's isolated world: a service prefix, an iceoryx2 domain (so its shared
/// memory files are recognisable) and a state directory, removed on drop.
#[derive(Debug)]
pub struct Sandbox {
    /// Service-name prefix, e.g. `t-restart-1234-0/`.
    pub prefix: String,
    /// iceoryx2 file prefix, e.g. `dyt1234_0_`; other hosts of the same test take
    /// theirs from [`Sandbox::host_domain`].
    pub domain: String,
    /// The daemon's state directory.
    pub state_dir: PathBuf,
}

impl Sandbox {
    /// A fresh sandbox named after the test.
    pub fn new(test: &str) -> Sandbox {
        let n = NEXT.fetch_add(1, Ordering::Relaxed);
        let pid = std::process::id();
        let state_dir = std::env::temp_dir().join(format!("dyfos-test-{test}-{pid}-{n}"));
        let _ = std::fs::remove_dir_all(&state_dir);
        Sandbox { prefix: format!("t-{test}-{pid}-{n}/"), domain: format!("dyt{pid}_{n}_"), state_dir }
    }

    /// The iceoryx2 domain of another host of this test, e.g. `dyr1234_0_` for
    /// `'r'`: removed on drop with the sandbox's own. Killed processes leave their
    /// files behind, and iceoryx2 stats every file of its folders each time a node
    /// starts, so leftovers of other domains slow down every later client.
    pub fn host_domain(&self, host: char) -> String {
        format!("dy{host}{}", self.domain_suffix())
    }

    /// What every domain of this sandbox ends with: `1234_0_`.
    fn domain_suffix(&self) -> &str {
        &self.domain[3..]
    }

    /// Whether a file name belongs to one of this sandbox's domains.
    fn owns_file(&self, name: &str) -> bool {
        name.starts_with("dy") && name.get(3..).is_some_and(|rest| rest.starts_with(self.domain_suffix()))
    }

    /// A client configuration for this sandbox.
    pub fn client_config(&self) -> ClientConfig {
        ClientConfig {
            prefix: self.prefix.clone(),
            domain: Some(self.domain.clone()),
            connect_timeout: PATIENCE,
            ..ClientConfig::default()
        }
    }

    /// A connected client (the daemon must be starting or running).
    pub fn client(&self) -> Client {
        Client::connect(&self.client_config()).expect("connect to the test daemon")
    }

    /// An iceoryx2 node (plain `ipc::Service`, signals left to the test) in this
    /// sandbox's domain, and the names of its daemon's services: what a test needs to
    /// open those services itself.
    pub fn ipc_node(
        &self,
    ) -> (iceoryx2::prelude::Node<iceoryx2::prelude::ipc::Service>, dyfos_shared::wire::ServiceNames) {
        use iceoryx2::prelude::*;
        let config = dyfos_shared::wire::services::iceoryx_config(Some(&self.domain)).expect("domain");
        let node = NodeBuilder::new()
            .config(&config)
            .signal_handling_mode(SignalHandlingMode::Disabled)
            .create::<ipc::Service>()
            .expect("node");
        (node, dyfos_shared::wire::ServiceNames::new(&self.prefix).expect("prefix"))
    }

    /// Leaves in this sandbox's domain what a process killed while creating service
    /// `name` (`pattern`) leaves behind: its static file, still being written
    /// (owner read-write), and no node's tag. iceoryx2 reads the service as being
    /// created for good. Returns the file.
    pub fn leave_half_created(
        &self,
        name: &str,
        pattern: iceoryx2::service::messaging_pattern::MessagingPattern,
    ) -> PathBuf {
        use std::os::unix::fs::PermissionsExt;
        let config = dyfos_shared::wire::services::iceoryx_config(Some(&self.domain)).expect("domain");
        let name = iceoryx2::prelude::ServiceName::new(name).expect("service name");
        let file = dyfos_process::abandoned::static_file::<iceoryx2::prelude::ipc::Service>(&config, &name, pattern);
        std::fs::create_dir_all(file.parent().expect("service directory")).expect("service directory");
        std::fs::File::create(&file).expect("static file");
        std::fs::set_permissions(&file, std::fs::Permissions::from_mode(0o600)).expect("permissions");
        file
    }

    /// The flags that point a `dyfos` command at this sandbox's daemon.
    pub fn dyfos_flags(&self) -> Vec<String> {
        vec!["--prefix".into(), self.prefix.clone(), "--domain".into(), self.domain.clone()]
    }

    /// `dyfos SUBCOMMAND` pointed at this sandbox's daemon; add the command's own
    /// arguments to it.
    pub fn dyfos(&self, subcommand: &str) -> Command {
        let mut cmd = Command::new(bin("dyfos"));
        cmd.arg(subcommand).args(self.dyfos_flags());
        cmd
    }

    /// Starts `dyfos query FILE --algo brute ARGS` against this sandbox's daemon, its
    /// output piped.
    pub fn brute_query(&self, file: &Path, args: &[&str]) -> std::process::Child {
        let mut query = self.dyfos("query");
        query.arg(file).args(["--algo", "brute"]).args(args).stdout(Stdio::piped()).stderr(Stdio::piped());
        query.spawn().expect("start dyfos query")
    }

    /// A sandbox for test `test` with `dyfosd` (no flags) running in it. Bind it as
    /// `let (sandbox, _daemon) = …`, so that the daemon is killed before the sandbox
    /// removes its files.
    pub fn with_daemon(test: &str) -> (Sandbox, DaemonProcess) {
        let sandbox = Sandbox::new(test);
        let daemon = sandbox.start_daemon(&[]);
        (sandbox, daemon)
    }

    /// Starts `dyfosd` for this sandbox, logging at `debug`, and waits until it answers.
    pub fn start_daemon(&self, extra: &[&str]) -> DaemonProcess {
        self.start_daemon_logging("debug", extra)
    }

    /// Starts `dyfosd` for this sandbox (no flags), connects a client and uploads
    /// `world` as map `map` through it.
    pub fn start_serving(&self, map: dyfos_shared::wire::map::MapId, world: &World) -> (DaemonProcess, Client) {
        self.start_serving_with(&[], map, world)
    }

    /// A sandbox for test `test` with a daemon of two workers (so one `brute` search
    /// may take both) and the world of [`slow_search_scenario`] as map 1, and a
    /// client. Bound as `let (sandbox, daemon, client) = …`, they drop in the right
    /// order.
    pub fn with_slow_daemon(test: &str) -> (Sandbox, DaemonProcess, Client) {
        let sandbox = Sandbox::new(test);
        let (daemon, client) = sandbox.start_serving_with(&["--workers", "2"], 1, &slow_search_scenario().world);
        (sandbox, daemon, client)
    }

    fn start_serving_with(
        &self,
        flags: &[&str],
        map: dyfos_shared::wire::map::MapId,
        world: &World,
    ) -> (DaemonProcess, Client) {
        let daemon = self.start_daemon(flags);
        let mut client = self.client();
        client.upload_map(map, world, false, PATIENCE).expect("upload the test map");
        (daemon, client)
    }

    /// Starts `dyfosd` with `RUST_LOG=level` and waits until it answers.
    pub fn start_daemon_logging(&self, level: &str, extra: &[&str]) -> DaemonProcess {
        let log = self.state_dir.with_extension(format!("log-{}", NEXT.fetch_add(1, Ordering::Relaxed)));
        let log_file = std::fs::File::create(&log).expect("daemon log file");
        let child = DyfosdCommand::new(&bin("dyfosd"), &self.prefix, &self.state_dir)
            .domain(&self.domain)
            .log(level, log_file)
            .args(extra)
            .spawn()
            .expect("start dyfosd");
        let mut daemon = DaemonProcess { child, log };
        let mut client = wait_for("dyfosd to serve", || {
            if let Some(status) = daemon.child.try_wait() {
                panic!("dyfosd exited at start ({status}):\n{}", daemon.log());
            }
            Client::connect(&ClientConfig { connect_timeout: Duration::from_millis(50), ..self.client_config() }).ok()
        });
        client.stats(PATIENCE).expect("the new daemon answers stats");
        daemon
    }

    /// Shared-memory files of this sandbox's domain, except iceoryx2's persistent
    /// per-domain node counter (`*.global_mgmt`, 16 bytes, never removed by design).
    pub fn shm_leftovers(&self) -> Vec<String> {
        std::fs::read_dir("/dev/shm")
            .map(|entries| {
                entries
                    .flatten()
                    .map(|e| e.file_name().to_string_lossy().into_owned())
                    .filter(|n| n.starts_with(&self.domain) && !n.ends_with(".global_mgmt"))
                    .collect()
            })
            .unwrap_or_default()
    }

    /// Files of this sandbox's domain in iceoryx2's state folder ([`iceoryx_root`]:
    /// node and service details, event sockets), as paths relative to it.
    pub fn state_leftovers(&self) -> Vec<String> {
        let root = iceoryx_root();
        state_files(&root, &|name| name.starts_with(&self.domain))
            .into_iter()
            .map(|p| p.strip_prefix(&root).unwrap_or(&p).display().to_string())
            .collect()
    }
}

/// iceoryx2's state folder (`/tmp/iceoryx2/` unless configured otherwise), where
/// node and service details and event sockets live beside the shared memory.
pub fn iceoryx_root() -> PathBuf {
    PathBuf::from(iceoryx2::config::Config::default().global.root_path().to_string())
}

/// Files under `root` (at most three levels: `root/nodes/<node>/<file>`) whose name
/// starts with `domain`.
fn state_files(root: &Path, owns: &dyn Fn(&str) -> bool) -> Vec<PathBuf> {
    fn walk(dir: &Path, owns: &dyn Fn(&str) -> bool, depth: u32, out: &mut Vec<PathBuf>) {
        let Ok(entries) = std::fs::read_dir(dir) else { return };
        for e in entries.flatten() {
            let is_dir = e.file_type().is_ok_and(|t| t.is_dir());
            if is_dir && depth > 0 {
                walk(&e.path(), owns, depth - 1, out);
            } else if !is_dir && owns(&e.file_name().to_string_lossy()) {
                out.push(e.path());
            }
        }
    }
    let mut out = Vec::new();
    walk(root, owns, 2, &mut out);
    out.sort();
    out
}

impl Drop for Sandbox {
    /// Removes the state directory and everything of the sandbox's domains (its
    /// own and its other hosts') that a killed process left behind, in `/dev/shm`
    /// and in iceoryx2's state folder alike (removing one without the other would
    /// leave iceoryx2 confused).
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.state_dir);
        if let Ok(entries) = std::fs::read_dir("/dev/shm") {
            for e in entries.flatten() {
                if self.owns_file(&e.file_name().to_string_lossy()) {
                    let _ = std::fs::remove_file(e.path());
                }
            }
        }
        for file in state_files(&iceoryx_root(), &|name| self.owns_file(name)) {
            let _ = std::fs::remove_file(&file);
            // A node's folder held only that node's files: remove it once empty.
            if let Some(dir) = file.parent().filter(|d| d.parent().is_some_and(|p| p.ends_with("nodes"))) {
                let _ = std::fs::remove_dir(dir);
            }
        }
    }
}

/// A running `dyfosd`, killed (SIGKILL) when dropped.
#[derive(Debug)]
pub struct DaemonProcess {
    child: KillOnDrop,
    log: PathBuf,
}

impl DaemonProcess {
    /// The process id.
    pub fn pid(&self) -> u32 {
        self.child.id()
    }

    /// Its log so far.
    pub fn log(&self) -> String {
        std::fs::read_to_string(&self.log).unwrap_or_default()
    }

    /// SIGKILL, and reap.
    pub fn kill9(&mut self) {
        self.child.kill();
    }

    /// SIGTERM, then waits for the exit.
    pub fn terminate(&mut self) -> ExitStatus {
        self.stop_with("TERM")
    }

    /// Sends `signal_name` (`TERM`, `INT`), then waits for the exit.
    pub fn stop_with(&mut self, signal_name: &str) -> ExitStatus {
        signal(self.pid(), signal_name);
        wait_for_showing(&format!("dyfosd to exit after SIG{signal_name}"), log_of(&self.log), || self.child.try_wait())
    }

    /// Whether the process has not exited.
    pub fn is_running(&mut self) -> bool {
        self.child.is_running()
    }
}

impl Drop for DaemonProcess {
    fn drop(&mut self) {
        self.kill9();
        // A failing test shows what the daemon said: the log goes with the sandbox.
        if std::thread::panicking() {
            let log = self.log();
            let lines: Vec<&str> = log.lines().collect();
            eprintln!("--- the last lines of dyfosd's log ---\n{}", lines[lines.len().saturating_sub(80)..].join("\n"));
        }
        let _ = std::fs::remove_file(&self.log);
    }
}

/// Sends a signal (`TERM`, `KILL`, …) to a process by id.
pub fn signal(pid: u32, name: &str) {
    let ok = Command::new("kill").arg(format!("-{name}")).arg(pid.to_string()).status().is_ok_and(|s| s.success());
    assert!(ok, "kill -{name} {pid} failed");
}

pub use dyfos_process::child::KillOnDrop;

/// The workspace's test data directory.
pub fn data(path: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("data").join(path)
}

pub use dyfos_process::scratch::Scratch;

/// The scenario file `path` of the test data.
pub fn scenario(path: &str) -> dyfos_shared::scenario::Scenario {
    let text = std::fs::read_to_string(data(path)).unwrap_or_else(|e| panic!("scenario file {path}: {e}"));
    dyfos_shared::scenario::Scenario::from_json(&text).unwrap_or_else(|e| panic!("scenario {path}: {e}"))
}

/// A scenario whose searches take long (for tests about what happens while searches
/// run; a `dyfos` query most of a second, a `brute` one minutes): `hard_01` with 4096
/// perimeter points (SPEC's most, 4097 sight lines a candidate) and a 5 cm voxel layer
/// under the whole search space whose top every sight line ends just above.
pub fn slow_search_scenario() -> dyfos_shared::scenario::Scenario {
    use dyfos_shared::world::MapDelta;
    let text = std::fs::read_to_string(data("golden/scenarios/hard/hard_01.json")).expect("hard_01");
    let mut s = dyfos_shared::scenario::Scenario::from_json(&text).expect("hard_01 parses");
    s.params.perimeter_points = dyfos_shared::limits::MAX_PERIMETER_POINTS;
    // A layer of cells 15–20 cm above the ground under the whole search space, and
    // the marker 1 µm above its top: no sight line is blocked, but each ends closer to
    // the layer than any box test can settle (a thousandth of a cell), so each walks
    // the layer's cells near its end; two cells at opposite corners make the grid's
    // box span the whole search space, so no sight line is clipped away before its walk.
    s.params.marker_height = 0.2 + 1e-6;
    let resolution = 0.05;
    let (side, top) = ((24.0 / resolution) as i64, (12.0 / resolution) as i64);
    let voxels = MapDelta::SetVoxels {
        resolution,
        origin: dyfos_shared::math::Point3::new(-12.0, -12.0, 0.0),
        cells: (0..side)
            .flat_map(|x| (0..side).map(move |y| [x, y, 3]))
            .chain([[0, 0, 0], [side - 1, side - 1, top - 1]])
            .collect(),
        occupied: true,
    };
    s.world = s.world.apply(&[voxels]).expect("voxels fit the map");
    s
}

/// An answer's JSON without its compute time, for bit-for-bit comparisons
/// (`serde_json` prints every `f64` so that it reads back exactly).
pub fn without_micros(mut json: serde_json::Value) -> serde_json::Value {
    json.as_object_mut().expect("an answer object").remove("micros");
    json
}

/// Creates map `id` empty (version 0) in the shape the service tests use: a 20 m
/// square about the origin, the sun at elevation 0.7 and azimuth 2.1 rad. Returns
/// its bounds.
pub fn create_test_map(client: &mut Client, id: u64) -> dyfos_shared::world::Bounds {
    let bounds = dyfos_shared::world::Bounds::new([-10.0, -10.0, 10.0, 10.0]).expect("bounds");
    let sun = dyfos_shared::world::Sun::new(0.7, 2.1).expect("sun");
    client.create_map(id, bounds, sun, PATIENCE).expect("create the test map");
    bounds
}

/// A daemon in a sandbox of its own, a client and a raw client of it: where the
/// tests of bad and hostile requests start. Fields drop in order: the clients, then
/// the daemon, then the sandbox's files.
pub struct RawFixture {
    /// Sends any header and records.
    pub raw: RawClient,
    /// The client library, to set up and check maps.
    pub client: Client,
    /// The daemon, started with no flags.
    pub daemon: DaemonProcess,
    /// Its prefix, domain and state directory.
    pub sandbox: Sandbox,
}

impl RawFixture {
    /// Starts the daemon of test `name` and connects both clients.
    pub fn new(name: &str) -> RawFixture {
        let sandbox = Sandbox::new(name);
        let daemon = sandbox.start_daemon(&[]);
        let client = sandbox.client();
        let raw = RawClient::open(&sandbox);
        RawFixture { raw, client, daemon, sandbox }
    }

    /// Creates map `id` ([`create_test_map`]) with `deltas` applied (at version 0, as
    /// one batch of one delta each); returns its bounds and the map as the daemon
    /// holds it, what bad requests must leave unchanged.
    pub fn test_map_with(
        &mut self,
        id: u64,
        deltas: &[dyfos_shared::world::MapDelta],
    ) -> (dyfos_shared::world::Bounds, dyfos_shared::world::World) {
        let bounds = create_test_map(&mut self.client, id);
        let version = self.client.apply(id, Some(0), deltas, PATIENCE).expect("apply the deltas");
        assert_eq!(version, deltas.len() as u64);
        (bounds, self.client.snapshot(id, PATIENCE).expect("snapshot"))
    }
}

/// Every float of a wire parameter block, in field order (`t_vs` as its three):
/// what hostile and random requests set one at a time.
pub fn param_floats_mut(p: &mut dyfos_shared::wire::rendezvous::WireParams) -> [&mut f64; 17] {
    let [tx, ty, tz] = &mut p.t_vs;
    [
        &mut p.rover_radius,
        &mut p.marker_size,
        &mut p.marker_height,
        &mut p.viewer_radius,
        &mut p.safety_margin,
        &mut p.z_min,
        &mut p.z_max,
        &mut p.camera_pitch,
        tx,
        ty,
        tz,
        &mut p.f_h,
        &mut p.f_v,
        &mut p.rho_min,
        &mut p.rho_max,
        &mut p.kappa,
        &mut p.lambda,
    ]
}

/// A client that sends raw wire messages, as a buggy or hostile peer could: any
/// header, any records. Uses iceoryx2's plain `ipc::Service` (the daemon uses the
/// thread-safe variant; both share memory). Replies are polled.
pub struct RawClient {
    _node: iceoryx2::prelude::Node<iceoryx2::prelude::ipc::Service>,
    rendezvous: iceoryx2::port::client::Client<
        iceoryx2::prelude::ipc::Service,
        [WireDelta],
        RendezvousRequestHeader,
        RendezvousReply,
        (),
    >,
    map: iceoryx2::port::client::Client<
        iceoryx2::prelude::ipc::Service,
        [WireDelta],
        MapRequestHeader,
        [WireDelta],
        MapReplyHeader,
    >,
    wake: iceoryx2::port::notifier::Notifier<iceoryx2::prelude::ipc::Service>,
}

use dyfos_shared::wire::map::{MapReplyHeader, MapRequestHeader, WireDelta};
use dyfos_shared::wire::rendezvous::{RendezvousReply, RendezvousRequestHeader};

/// A rendezvous request of a [`RawClient`] in flight.
pub type PendingRendezvous = iceoryx2::pending_response::PendingResponse<
    iceoryx2::prelude::ipc::Service,
    [WireDelta],
    RendezvousRequestHeader,
    RendezvousReply,
    (),
>;

impl RawClient {
    /// Opens the sandbox daemon's services.
    pub fn open(sandbox: &Sandbox) -> RawClient {
        use dyfos_shared::wire::services;
        use iceoryx2::prelude::*;
        let (node, names) = sandbox.ipc_node();
        let services = services::Services::new(&node, &names);
        // Both request services carry a slice of records: one way to open a client.
        macro_rules! slice_client {
            ($service:ident) => {
                services
                    .$service()
                    .expect("service name")
                    .open()
                    .expect(concat!("open ", stringify!($service)))
                    .client_builder()
                    .initial_max_slice_len(8)
                    .allocation_strategy(AllocationStrategy::PowerOfTwo)
                    .create()
                    .expect(concat!(stringify!($service), " client"))
            };
        }
        let rendezvous = slice_client!(rendezvous);
        let map = slice_client!(map);
        let wake = services
            .wake()
            .expect("service name")
            .open()
            .expect("open wake")
            .notifier_builder()
            .create()
            .expect("wake notifier");
        RawClient { _node: node, rendezvous, map, wake }
    }

    /// Sends a rendezvous request as is and returns the reply.
    pub fn rendezvous(&self, header: RendezvousRequestHeader, records: &[WireDelta]) -> RendezvousReply {
        let mut loan = self.rendezvous.loan_slice_uninit(records.len()).expect("loan");
        *loan.user_header_mut() = header;
        let pending = loan.write_from_slice(records).send().expect("send");
        self.wake.notify().expect("notify");
        wait_for("a rendezvous reply", || pending.receive().expect("receive").map(|r| *r.payload()))
    }

    /// Sends a rendezvous request and returns it in flight: its reply, once there,
    /// is `pending.receive()`; dropping it gives the query up.
    pub fn send(&self, header: RendezvousRequestHeader, records: &[WireDelta]) -> PendingRendezvous {
        let mut loan = self.rendezvous.loan_slice_uninit(records.len()).expect("loan");
        *loan.user_header_mut() = header;
        let pending = loan.write_from_slice(records).send().expect("send");
        self.wake.notify().expect("notify");
        pending
    }

    /// Sends a rendezvous request and drops its pending reply at once, as a client
    /// that gives up would.
    /// Whether it was sent (not when the client already has as many in flight as
    /// it may).
    pub fn send_and_drop(&self, header: RendezvousRequestHeader, records: &[WireDelta]) -> bool {
        let Ok(mut loan) = self.rendezvous.loan_slice_uninit(records.len()) else { return false };
        *loan.user_header_mut() = header;
        let sent = loan.write_from_slice(records).send();
        let _ = self.wake.notify();
        sent.is_ok()
    }

    /// Sends every request before reading any reply (at most the daemon's limit of
    /// requests in flight per client), then returns the replies in order.
    pub fn rendezvous_all(&self, requests: &[(RendezvousRequestHeader, Vec<WireDelta>)]) -> Vec<RendezvousReply> {
        let pending: Vec<_> = requests
            .iter()
            .map(|(header, records)| {
                let mut loan = self.rendezvous.loan_slice_uninit(records.len()).expect("loan");
                *loan.user_header_mut() = *header;
                loan.write_from_slice(records).send().expect("send")
            })
            .collect();
        self.wake.notify().expect("notify");
        pending
            .iter()
            .map(|p| wait_for("a rendezvous reply", || p.receive().expect("receive").map(|r| *r.payload())))
            .collect()
    }

    /// Sends a map request as is and returns the reply header and records.
    pub fn map(&self, header: MapRequestHeader, records: &[WireDelta]) -> (MapReplyHeader, Vec<WireDelta>) {
        let mut loan = self.map.loan_slice_uninit(records.len()).expect("loan");
        *loan.user_header_mut() = header;
        let pending = loan.write_from_slice(records).send().expect("send");
        self.wake.notify().expect("notify");
        wait_for("a map reply", || {
            pending.receive().expect("receive").map(|r| (*r.user_header(), r.payload().to_vec()))
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_sandbox_removes_its_hosts_files_and_no_other_sandboxs() {
        let sandbox = Sandbox::new("owns");
        let other = Sandbox::new("owns");
        let dir = iceoryx_root().join("services");
        std::fs::create_dir_all(&dir).unwrap();
        let mine = [
            PathBuf::from("/dev/shm").join(format!("{}leftover", sandbox.domain)),
            PathBuf::from("/dev/shm").join(format!("{}leftover", sandbox.host_domain('r'))),
            dir.join(format!("{}leftover.service", sandbox.host_domain('i'))),
        ];
        let theirs = PathBuf::from("/dev/shm").join(format!("{}leftover", other.host_domain('r')));
        for path in mine.iter().chain([&theirs]) {
            std::fs::write(path, b"left by a killed process").unwrap();
        }
        drop(sandbox);
        for path in &mine {
            assert!(!path.exists(), "{} outlived its sandbox", path.display());
        }
        assert!(theirs.exists(), "another sandbox's file was removed");
        drop(other);
        assert!(!theirs.exists());
    }
}
