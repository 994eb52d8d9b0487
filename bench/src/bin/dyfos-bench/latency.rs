//! `dyfos-bench latency`: query latency and throughput of `dyfosd`.
//!
//! Starts its own `dyfosd` (found next to this executable; own service prefix,
//! iceoryx2 domain and temporary state directory), uploads the SPEC §10 numerical
//! maps, and for each configuration starts N client processes — this executable in
//! its hidden `latency-worker` mode — which connect, warm up, wait for a common
//! start signal on stdin, run for T seconds and write their samples to a file. The
//! coordinator merges them, runs the in-process baseline and iceoryx2's raw
//! request-response floor (a busy-polling server thread here, client processes as
//! above), stops the daemon with SIGTERM, and prints and writes the report.

use anyhow::{Context, bail};
use dyfos_bench::latency::{
    Arrivals, CHURN_PER_SECOND, FloorClient, GreedyClient, Latencies, RequestSet, RunSamples, Workload, drive,
    in_process, map_id, serve_floor,
};
use dyfos_bench::svg::{Series, line_plot};
use dyfos_bench::table::{self, Align};
use dyfos_client::{Client, ClientConfig, RendezvousError};
use dyfos_process::child::KillOnDrop;
use dyfos_service::launch::DyfosdCommand;
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::io::{BufRead, BufReader, Write as _};
use std::path::{Path, PathBuf};
use std::process::{ChildStdout, Command, ExitStatus, Stdio};
use std::sync::Arc;
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

/// Flags of `dyfos-bench latency`.
#[derive(Debug, clap::Args)]
pub struct LatencyArgs {
    /// Seconds each configuration runs.
    #[arg(allow_hyphen_values = true, long, default_value_t = 2.0)]
    seconds: f64,
    /// Closed loop: numbers of client processes, each sending back to back.
    #[arg(long, value_delimiter = ',', default_value = "1,2,4,8,16")]
    clients: Vec<usize>,
    /// Open loop: null-query (and floor) rates, requests per second over all clients.
    #[arg(allow_hyphen_values = true, long, value_delimiter = ',', default_value = "1000,10000")]
    null_rates: Vec<f64>,
    /// Open loop: `dyfos` query rates, per second over all clients.
    #[arg(allow_hyphen_values = true, long, value_delimiter = ',', default_value = "250,500")]
    dyfos_rates: Vec<f64>,
    /// Open loop: client processes sharing the rate.
    #[arg(long, default_value_t = 4)]
    open_clients: usize,
    /// Workloads to run, comma-separated: `floor` (raw iceoryx2 round trip), `null`
    /// (check-mode queries), `dyfos` (searches).
    #[arg(long, value_delimiter = ',', default_value = "floor,null,dyfos", value_parser = parse_workload)]
    workloads: Vec<Workload>,
    /// Numerical maps (SPEC §10) the queries cycle over.
    #[arg(long, default_value_t = 20)]
    maps: usize,
    /// Seed of the maps, searches and arrival schedules.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// The daemon binary (default: `dyfosd` next to this executable).
    #[arg(long)]
    dyfosd: Option<PathBuf>,
    /// A flag for the daemon, e.g. `--daemon-arg=--set=scheduling.poll_us=1000`; repeatable.
    #[arg(long = "daemon-arg", value_name = "FLAG", allow_hyphen_values = true)]
    daemon_args: Vec<String>,
    /// Mixed run: null-query rate (one client, open loop) while `--mixed-dyfos-clients`
    /// send `dyfos` queries back to back; 0 skips it.
    #[arg(allow_hyphen_values = true, long, default_value_t = 1000.0)]
    mixed_null_rate: f64,
    /// Mixed run: `dyfos` clients keeping the workers busy.
    #[arg(long, default_value_t = 4)]
    mixed_dyfos_clients: usize,
    /// Mixed and contention runs: the `dyfos` clients send this many queries a second
    /// over all of them (open loop) instead of back to back, so that two daemons
    /// whose searches differ in speed are compared under the same load; 0: back to back.
    #[arg(allow_hyphen_values = true, long, default_value_t = 0.0)]
    mixed_dyfos_rate: f64,
    /// Before/after: also run the one-client closed loops, the first null rate in
    /// open loop, the mixed run and the contention runs against a second daemon
    /// started with these extra flags (e.g.
    /// `--compare-daemon-arg=--set=scheduling.worker_slice_us=0`), in the same run.
    #[arg(long = "compare-daemon-arg", value_name = "FLAG", allow_hyphen_values = true)]
    compare_daemon_args: Vec<String>,
    /// Before/after: the second daemon's binary, e.g. a build of an earlier commit
    /// in a `git worktree` (default: the first daemon's). Runs the comparison even
    /// without `--compare-daemon-arg`.
    #[arg(long, value_name = "FILE")]
    compare_dyfosd: Option<PathBuf>,
    /// Directory for the table (markdown), summary (JSON) and plots (SVG); the
    /// `--compare-daemon-arg` daemon's rows go to `latency-compare.json`.
    #[arg(long, default_value = "bench/out")]
    out: PathBuf,
    /// How long each client busy-polls for a reply before it sleeps on the reply
    /// event (`ClientConfig::poll`), µs; default: the client library's default.
    #[arg(long)]
    client_poll_us: Option<u64>,
    /// Skip the contention runs (cheap requests while searches run: `stats` and map
    /// requests beside `dyfos` clients, CPU hogs, a greedy client, clients that come
    /// and go, idle CPU); they also run against the second daemon.
    #[arg(long)]
    skip_contention: bool,
    /// Keep each client process's raw samples (JSON, one file per client and
    /// configuration, numbered in the order they ran) in this directory, for
    /// looking at a distribution beyond its percentiles.
    #[arg(long)]
    samples: Option<PathBuf>,
    /// Contention runs: seconds without traffic over which the daemon's idle CPU is measured.
    #[arg(allow_hyphen_values = true, long, default_value_t = 30.0)]
    idle_seconds: f64,
    /// Contention runs: CPU hog processes beside the daemon (default: one per core).
    #[arg(long)]
    hogs: Option<usize>,
}

/// Flags of the hidden `latency-worker` mode: one client process.
#[derive(Debug, clap::Args)]
pub struct WorkerArgs {
    #[arg(long)]
    prefix: String,
    #[arg(long)]
    domain: String,
    #[arg(long, value_parser = parse_workload)]
    workload: Workload,
    /// Requests per second of this client; 0 for a closed loop.
    #[arg(allow_hyphen_values = true, long, default_value_t = 0.0)]
    rate: f64,
    #[arg(allow_hyphen_values = true, long)]
    seconds: f64,
    #[arg(long)]
    seed: u64,
    #[arg(long)]
    maps: usize,
    /// This client's index (its first map and its arrival stream).
    #[arg(long)]
    index: usize,
    /// The floor's service name.
    #[arg(long, default_value = "")]
    floor_service: String,
    /// Where to write the samples (JSON).
    #[arg(long)]
    out: PathBuf,
    /// `ClientConfig::poll`, µs.
    #[arg(long)]
    client_poll_us: Option<u64>,
}

fn parse_workload(s: &str) -> Result<Workload, String> {
    Workload::from_name(s)
        .ok_or_else(|| format!("unknown workload `{s}`: use floor, null, dyfos, stats, map, greedy, hog or churn"))
}

const TIMEOUT: Duration = Duration::from_secs(30);

fn error_name(e: &RendezvousError) -> String {
    match e {
        RendezvousError::Rejected(r) | RendezvousError::Invalid(r) => r.status.name().to_string(),
        RendezvousError::Timeout(_) => "timeout".into(),
        RendezvousError::DaemonGone => "daemon_gone".into(),
        RendezvousError::NoDaemon { .. } | RendezvousError::Connect(_) => "no_daemon".into(),
        RendezvousError::Ipc(_) => "ipc".into(),
        RendezvousError::Interrupted => "interrupted".into(),
    }
}

/// Tells the coordinator this client is connected and warm, then waits for `go`.
fn ready_then_go() -> anyhow::Result<()> {
    println!("ready");
    std::io::stdout().flush()?;
    let mut line = String::new();
    std::io::stdin().read_line(&mut line)?;
    if line.trim() != "go" {
        bail!("expected `go` on stdin, got `{}`", line.trim());
    }
    Ok(())
}

/// The client configuration of a worker process.
fn client_config(args: &WorkerArgs) -> ClientConfig {
    let defaults = ClientConfig::default();
    ClientConfig {
        prefix: args.prefix.clone(),
        domain: Some(args.domain.clone()),
        connect_timeout: TIMEOUT,
        poll: args.client_poll_us.map_or(defaults.poll, Duration::from_micros),
    }
}

/// The `latency-worker` mode: one client process.
pub fn worker(args: &WorkerArgs) -> anyhow::Result<()> {
    let set = RequestSet::new(args.seed, args.maps);
    let arrivals = if args.rate > 0.0 { Arrivals::Open { rate: args.rate } } else { Arrivals::Closed };
    let duration = Duration::from_secs_f64(args.seconds);
    let stream = args.index as u64;
    let samples = match args.workload {
        Workload::Floor => {
            let mut floor = FloorClient::open(&args.domain, &args.floor_service, &set.requests[0], TIMEOUT)
                .map_err(anyhow::Error::msg)?;
            for _ in 0..200 {
                floor.call(TIMEOUT).map_err(anyhow::Error::msg)?;
            }
            ready_then_go()?;
            drive(arrivals, duration, args.seed, stream, |_| floor.call(TIMEOUT))
        }
        Workload::Hog => {
            ready_then_go()?;
            let start = Instant::now();
            let cpu0 = cpu_seconds(std::process::id()).unwrap_or(0.0);
            let mut x = 0u64;
            while start.elapsed() < duration {
                for _ in 0..10_000 {
                    x = std::hint::black_box(x.wrapping_mul(6364136223846793005).wrapping_add(1));
                }
            }
            let elapsed_s = start.elapsed().as_secs_f64();
            let cpu_s = cpu_seconds(std::process::id()).unwrap_or(0.0) - cpu0;
            RunSamples { elapsed_s, cpu_s, ..RunSamples::default() }
        }
        Workload::Greedy => {
            let mut greedy = GreedyClient::open(&args.domain, &args.prefix).map_err(anyhow::Error::msg)?;
            ready_then_go()?;
            greedy.run(&set, args.index, duration).map_err(anyhow::Error::msg)?
        }
        Workload::Churn => {
            let config = client_config(args);
            Client::connect(&config)?.stats(TIMEOUT)?;
            ready_then_go()?;
            drive(Arrivals::Open { rate: CHURN_PER_SECOND }, duration, args.seed, stream, |_| {
                let mut client = Client::connect(&config).map_err(|_| "no_daemon".to_string())?;
                client.stats(TIMEOUT).map(|_| None).map_err(|_| "stats_error".to_string())
            })
        }
        workload @ (Workload::Null | Workload::Dyfos | Workload::Stats | Workload::Map) => {
            let config = client_config(args);
            let mut client = Client::connect(&config)?;
            let mut call = |k: usize| {
                let (i, request) = set.pick(args.index, k);
                match workload {
                    Workload::Null => client.check(request, TIMEOUT).map(|_| None).map_err(|e| error_name(&e)),
                    Workload::Stats => client.stats(TIMEOUT).map(|_| None).map_err(|_| "stats_error".to_string()),
                    Workload::Map => {
                        client.snapshot(map_id(i), TIMEOUT).map(|_| None).map_err(|_| "map_error".to_string())
                    }
                    _ => client.rendezvous(request, TIMEOUT).map(|a| Some(a.micros)).map_err(|e| error_name(&e)),
                }
            };
            let warm_up = if workload == Workload::Dyfos { 2 } else { 200 };
            for k in 0..warm_up {
                call(k).map_err(|e| anyhow::anyhow!("warm-up request failed: {e}"))?;
            }
            ready_then_go()?;
            drive(arrivals, duration, args.seed, stream, call)
        }
    };
    let json = serde_json::to_string(&samples)?;
    std::fs::write(&args.out, json).with_context(|| format!("cannot write {}", args.out.display()))?;
    Ok(())
}

/// Waits up to `limit` for `child` to exit.
fn wait_exit(child: &mut KillOnDrop, limit: Duration) -> anyhow::Result<ExitStatus> {
    let id = child.id();
    child.wait_timeout(limit).with_context(|| format!("process {id} did not exit within {limit:?}"))
}

/// Everything the run shares: paths, names, the requests.
struct Bench<'a> {
    args: &'a LatencyArgs,
    exe: PathBuf,
    prefix: String,
    domain: String,
    tmp: PathBuf,
    floor_service: String,
    /// The running daemon's process id (for its CPU time), 0 if none.
    daemon_pid: std::cell::Cell<u32>,
    /// Configurations run so far (names the files of `--samples`).
    configs_run: std::cell::Cell<usize>,
}

/// CPU time (user + system) of process `pid` so far, s; `None` if unreadable.
/// `/proc/PID/stat` counts clock ticks of 1/100 s (Linux's `USER_HZ`).
fn cpu_seconds(pid: u32) -> Option<f64> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    let (_, rest) = stat.rsplit_once(')')?;
    let fields: Vec<&str> = rest.split_whitespace().collect();
    // Fields after the `(comm)` start at field 3 (state); utime and stime are 14 and 15.
    let ticks: u64 = fields.get(11)?.parse::<u64>().ok()? + fields.get(12)?.parse::<u64>().ok()?;
    Some(ticks as f64 / 100.0)
}

/// The machine's CPU time so far from `/proc/stat`'s `cpu` line, in ticks: the
/// time the hypervisor gave other guests while this one's cores had work
/// (`steal`), and all of it. `None` off Linux.
#[derive(Debug, Clone, Copy)]
struct MachineTicks {
    steal: u64,
    total: u64,
}

impl MachineTicks {
    fn now() -> Option<Self> {
        let stat = std::fs::read_to_string("/proc/stat").ok()?;
        let line = stat.lines().find(|l| l.starts_with("cpu "))?;
        // user nice system idle iowait irq softirq steal (guest time is inside user).
        let ticks: Vec<u64> = line.split_whitespace().skip(1).take(8).map(|t| t.parse().ok()).collect::<Option<_>>()?;
        (ticks.len() == 8).then(|| MachineTicks { steal: ticks[7], total: ticks.iter().sum() })
    }

    /// The share of the machine's time since `self` that the hypervisor took: a
    /// shared host's noise, which no design of ours changes (0 on bare metal).
    fn steal_since(self) -> Option<f64> {
        let now = MachineTicks::now()?;
        let total = now.total.checked_sub(self.total).filter(|t| *t > 0)?;
        Some(now.steal.saturating_sub(self.steal) as f64 / total as f64)
    }
}

/// Client processes of one workload in one configuration.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Group {
    workload: Workload,
    clients: usize,
    /// Open loop: requests per second over all of the group's clients.
    rate: Option<f64>,
}

impl Group {
    fn closed(workload: Workload, clients: usize) -> Self {
        Group { workload, clients, rate: None }
    }

    fn open(workload: Workload, clients: usize, rate: f64) -> Self {
        Group { workload, clients, rate: Some(rate) }
    }

    fn label(&self) -> String {
        match self.rate {
            None => format!("{} closed loop, {} client(s)", self.workload.name(), self.clients),
            Some(r) => format!("{} open loop, {r}/s over {} client(s)", self.workload.name(), self.clients),
        }
    }
}

/// One group's merged result.
#[derive(Debug, Clone)]
struct Row {
    workload: Workload,
    clients: usize,
    /// Offered rate for open loop.
    rate: Option<f64>,
    /// The other groups that ran at the same time, if any.
    alongside: Option<String>,
    throughput: f64,
    latency: Option<Latencies>,
    /// Open loop: how late the client processes sent (their own scheduling delay).
    late: Option<Latencies>,
    /// Open loop: latency from the actual send (without that delay).
    from_send: Option<Latencies>,
    /// Cores the daemon kept busy during the run (its CPU time / wall time).
    daemon_cpu: Option<f64>,
    /// The share of the machine's time the hypervisor took during the run.
    steal: Option<f64>,
    /// `dyfos`: search time in the daemon, and end-to-end minus search.
    search: Option<Latencies>,
    /// Hogs: the cores their processes used (CPU time / wall time, summed).
    own_cpu: Option<f64>,
    overhead: Option<Latencies>,
    errors: BTreeMap<String, u64>,
    unsent: u64,
}

impl Row {
    fn of(group: Group, runs: Vec<RunSamples>) -> Row {
        let throughput =
            runs.iter().filter(|r| r.elapsed_s > 0.0).map(|r| r.latency_ns.len() as f64 / r.elapsed_s).sum();
        let mut latency: Vec<u64> = Vec::new();
        let mut late: Vec<u64> = Vec::new();
        let mut from_send: Vec<u64> = Vec::new();
        let mut search: Vec<u64> = Vec::new();
        let mut overhead: Vec<u64> = Vec::new();
        let mut errors = BTreeMap::new();
        let mut unsent = 0;
        let own: f64 = runs.iter().filter(|r| r.elapsed_s > 0.0).map(|r| r.cpu_s / r.elapsed_s).sum();
        let own_cpu = (group.workload == Workload::Hog).then_some(own);
        for r in runs {
            if r.search_us.len() == r.latency_ns.len() {
                for (ns, us) in r.latency_ns.iter().zip(&r.search_us) {
                    search.push(us * 1000);
                    overhead.push(ns.saturating_sub(us * 1000));
                }
            }
            latency.extend(r.latency_ns);
            late.extend(r.late_ns);
            from_send.extend(r.from_send_ns);
            for (k, v) in r.errors {
                *errors.entry(k).or_default() += v;
            }
            unsent += r.unsent;
        }
        Row {
            workload: group.workload,
            clients: group.clients,
            rate: group.rate,
            alongside: None,
            daemon_cpu: None,
            steal: None,
            throughput,
            latency: Latencies::of_nanos(&mut latency),
            late: Latencies::of_nanos(&mut late),
            from_send: Latencies::of_nanos(&mut from_send),
            search: Latencies::of_nanos(&mut search),
            own_cpu,
            overhead: Latencies::of_nanos(&mut overhead),
            errors,
            unsent,
        }
    }
}

impl Bench<'_> {
    /// Runs one configuration: the client processes of every group at once.
    fn run_groups(&self, groups: &[Group]) -> anyhow::Result<Vec<Row>> {
        let a = self.args;
        let label: Vec<String> = groups.iter().map(Group::label).collect();
        let label = label.join(" + ");
        eprintln!("latency: {label}");
        let mut children = Vec::new();
        let mut outputs = Vec::new();
        for (g, group) in groups.iter().enumerate() {
            for i in 0..group.clients {
                let out = self.tmp.join(format!("{}-{g}-{i}.json", group.workload.name()));
                let _ = std::fs::remove_file(&out);
                let per_client = group.rate.map_or(0.0, |r| r / group.clients as f64);
                let child = Command::new(&self.exe)
                    .arg("latency-worker")
                    .args(["--prefix", &self.prefix, "--domain", &self.domain, "--workload", group.workload.name()])
                    .args(["--rate", &per_client.to_string(), "--seconds", &a.seconds.to_string()])
                    .args(["--seed", &a.seed.to_string(), "--maps", &a.maps.to_string(), "--index", &i.to_string()])
                    .args(["--floor-service", &self.floor_service])
                    .args(a.client_poll_us.iter().flat_map(|us| ["--client-poll-us".to_string(), us.to_string()]))
                    .arg("--out")
                    .arg(&out)
                    .stdin(Stdio::piped())
                    .stdout(Stdio::piped())
                    .stderr(Stdio::inherit())
                    .spawn()
                    .with_context(|| format!("cannot start {}", self.exe.display()))?;
                children.push(KillOnDrop::new(child));
                outputs.push((g, out));
            }
        }
        // Everyone connected and warm: start together.
        for c in &mut children {
            let stdout: ChildStdout = c.child_mut().and_then(|c| c.stdout.take()).context("worker stdout")?;
            let mut line = String::new();
            BufReader::new(stdout).read_line(&mut line)?;
            if line.trim() != "ready" {
                bail!("client process {} failed before the start (see its error above)", c.id());
            }
        }
        for c in &mut children {
            let stdin = c.child_mut().and_then(|c| c.stdin.as_mut()).context("worker stdin")?;
            stdin.write_all(b"go\n")?;
            stdin.flush()?;
        }
        let daemon = self.daemon_pid.get();
        let (cpu_start, wall_start, machine_start) = (cpu_seconds(daemon), Instant::now(), MachineTicks::now());
        let limit = Duration::from_secs_f64(a.seconds * 3.0) + TIMEOUT;
        let mut runs: Vec<Vec<RunSamples>> = vec![Vec::new(); groups.len()];
        for (c, (g, out)) in children.iter_mut().zip(&outputs) {
            let status = wait_exit(c, limit)?;
            if !status.success() {
                bail!("client process of `{label}` failed ({status})");
            }
            let text = std::fs::read_to_string(out).with_context(|| format!("cannot read {}", out.display()))?;
            runs[*g].push(serde_json::from_str::<RunSamples>(&text).with_context(|| format!("{}", out.display()))?);
            match (&a.samples, out.file_name()) {
                (Some(dir), Some(name)) => {
                    let kept = dir.join(format!("{:03}-{}", self.configs_run.get(), name.to_string_lossy()));
                    std::fs::rename(out, &kept)
                        .or_else(|_| std::fs::copy(out, &kept).map(|_| ()))
                        .with_context(|| format!("cannot keep the samples in {}", kept.display()))?;
                }
                _ => {
                    let _ = std::fs::remove_file(out);
                }
            }
        }
        self.configs_run.set(self.configs_run.get() + 1);
        let daemon_cpu = match (cpu_start, cpu_seconds(daemon)) {
            (Some(a), Some(b)) => Some((b - a) / wall_start.elapsed().as_secs_f64()),
            _ => None,
        };
        let steal = machine_start.and_then(MachineTicks::steal_since);
        let rows = groups.iter().zip(runs).enumerate().map(|(g, (group, runs))| {
            let others: Vec<String> =
                groups.iter().enumerate().filter(|(o, _)| *o != g).map(|(_, o)| o.label()).collect();
            Row {
                alongside: (!others.is_empty()).then(|| others.join(" + ")),
                daemon_cpu,
                steal,
                ..Row::of(*group, runs)
            }
        });
        Ok(rows.collect())
    }

    fn run_config(&self, group: Group) -> anyhow::Result<Row> {
        Ok(self.run_groups(&[group])?.remove(0))
    }
}

/// Starts `dyfosd` for the bench and waits until it serves.
fn start_daemon(b: &Bench, dyfosd: &Path, extra: &[String], state: &Path, log: &Path) -> anyhow::Result<KillOnDrop> {
    let log_file = std::fs::File::create(log).with_context(|| format!("cannot create {}", log.display()))?;
    DyfosdCommand::new(dyfosd, &b.prefix, state)
        .domain(&b.domain)
        .log(&std::env::var("RUST_LOG").unwrap_or_else(|_| "warn".into()), log_file)
        .args(&b.args.daemon_args)
        .args(extra)
        .spawn()
        .with_context(|| format!("cannot start {}", dyfosd.display()))
}

/// SIGTERM, then wait for a clean exit.
fn stop_daemon(daemon: &mut KillOnDrop) -> anyhow::Result<ExitStatus> {
    let ok = Command::new("kill").arg("-TERM").arg(daemon.id().to_string()).status().is_ok_and(|s| s.success());
    if !ok {
        bail!("could not send SIGTERM to dyfosd ({})", daemon.id());
    }
    wait_exit(daemon, TIMEOUT)
}

/// Shared-memory files of `domain` left in /dev/shm (iceoryx2's per-domain node
/// counter `*.global_mgmt` is kept by design), removed after listing.
fn shm_leftovers(domain: &str) -> Vec<String> {
    let mut left = Vec::new();
    if let Ok(entries) = std::fs::read_dir("/dev/shm") {
        for e in entries.flatten() {
            let name = e.file_name().to_string_lossy().into_owned();
            if name.starts_with(domain) {
                if !name.ends_with(".global_mgmt") {
                    left.push(name);
                }
                let _ = std::fs::remove_file(e.path());
            }
        }
    }
    left
}

fn us(v: f64) -> String {
    if v >= 100.0 { format!("{v:.0}") } else { format!("{v:.1}") }
}

fn errors_cell(row: &Row) -> String {
    let mut parts: Vec<String> = row.errors.iter().map(|(k, v)| format!("{k} {v}")).collect();
    if row.unsent > 0 {
        parts.push(format!("unsent {}", row.unsent));
    }
    if parts.is_empty() { "0".into() } else { parts.join(", ") }
}

/// The daemon's CPU use during the run, in % of one core.
fn cpu_cell(r: &Row) -> String {
    match (r.workload, r.daemon_cpu) {
        (Workload::Floor, _) | (_, None) => "–".into(),
        (_, Some(c)) => format!("{:.0} %", c * 100.0),
    }
}

fn latency_cells(l: Option<Latencies>) -> String {
    match l {
        Some(l) => {
            format!("{} | {} | {} | {} | {}", us(l.p50_us), us(l.p90_us), us(l.p99_us), us(l.p999_us), us(l.max_us))
        }
        None => "– | – | – | – | –".into(),
    }
}

fn table(rows: &[&Row], open: bool) -> String {
    let (l, r) = (Align::Left, Align::Right);
    let mut columns = vec![("workload", l), ("clients", r)];
    columns.extend(open.then_some(("offered /s", r)));
    columns.extend([("answered /s", r), ("p50 µs", r), ("p90 µs", r), ("p99 µs", r), ("p99.9 µs", r), ("max µs", r)]);
    columns.extend(open.then_some(("sent late p99 µs", r)));
    columns.extend([("dyfosd CPU", r), ("errors", l)]);
    let mut out = String::new();
    table::header(&mut out, &columns);
    for row in rows {
        let mut cells = vec![row.workload.name().to_string(), row.clients.to_string()];
        cells.extend(row.rate.map(|x| format!("{x:.0}")));
        cells.extend([format!("{:.0}", row.throughput), latency_cells(row.latency)]);
        cells.extend(open.then(|| row.late.map_or("–".into(), |l| us(l.p99_us))));
        cells.extend([cpu_cell(row), errors_cell(row)]);
        table::row(&mut out, &cells);
    }
    out
}

/// The 1-minute load average (other processes compete for the 2 cores).
fn load_average() -> String {
    std::fs::read_to_string("/proc/loadavg")
        .ok()
        .and_then(|s| s.split_whitespace().next().map(str::to_string))
        .unwrap_or_else(|| "?".into())
}

/// Runs the benchmark, prints the report, writes the files.
pub fn run(args: &LatencyArgs) -> anyhow::Result<()> {
    if !(args.seconds > 0.0 && args.seconds.is_finite()) {
        bail!("--seconds must be positive");
    }
    if args.clients.contains(&0) || args.open_clients == 0 {
        bail!("client counts must be at least 1");
    }
    std::fs::create_dir_all(&args.out).with_context(|| format!("cannot create {}", args.out.display()))?;
    if let Some(dir) = &args.samples {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    }
    let exe = std::env::current_exe().context("cannot find this executable")?;
    let dyfosd = match &args.dyfosd {
        Some(p) => p.clone(),
        None => exe.with_file_name("dyfosd"),
    };
    if !dyfosd.exists() {
        bail!(
            "{} not found; build it next to dyfos-bench (`cargo build --release --workspace --bins`) or pass --dyfosd",
            dyfosd.display()
        );
    }
    let pid = std::process::id();
    let tmp = std::env::temp_dir().join(format!("dyfos-bench-latency-{pid}"));
    std::fs::create_dir_all(&tmp).with_context(|| format!("cannot create {}", tmp.display()))?;
    let b = Bench {
        args,
        exe,
        prefix: format!("bench-latency-{pid}/"),
        domain: format!("dyb{pid}_"),
        floor_service: format!("bench-latency-{pid}/floor"),
        tmp: tmp.clone(),
        daemon_pid: std::cell::Cell::new(0),
        configs_run: std::cell::Cell::new(0),
    };
    let (load_before, machine_before) = (load_average(), MachineTicks::now());
    let result = run_with_daemon(&b, &dyfosd).and_then(|(mut report, rows, shutdown, idle)| {
        let mut compared = None;
        if !args.compare_daemon_args.is_empty() || args.compare_dyfosd.is_some() {
            let other = args.compare_dyfosd.as_deref().unwrap_or(&dyfosd);
            let (baseline, idle) = run_baseline(&b, other)?;
            report.push_str(&before_after(&rows, &baseline, &second_daemon(args)));
            compared = Some((baseline, idle));
        }
        if let Some(idle) = idle {
            let seconds = args.idle_seconds;
            let _ =
                write!(report, "\nIdle: dyfosd used {:.2} % of a core over {seconds} s without traffic", idle * 100.0);
            if let Some(other) = compared.as_ref().and_then(|(_, i)| *i) {
                let _ = write!(report, "; {} {:.2} %", second_daemon(args), other * 100.0);
            }
            report.push_str(".\n");
        }
        let baseline = compared.map(|(r, _)| r).unwrap_or_default();
        report.push_str(&steal_note(machine_before, &rows, &baseline));
        Ok((report, rows, baseline, shutdown))
    });
    let left = shm_leftovers(&b.domain);
    let _ = std::fs::remove_dir_all(&tmp);
    let (mut report, rows, baseline, shutdown) = result?;
    let _ = writeln!(
        report,
        "\nLoad average (1 min) before and after the run: {load_before}, {}. Daemon shutdown: {shutdown}; shared-memory files left in /dev/shm: {}.",
        load_average(),
        if left.is_empty() { "none".to_string() } else { left.join(", ") }
    );
    write_files(args, &report, &rows, &baseline)?;
    println!("{report}");
    Ok(())
}

/// How much of the machine the hypervisor took over the run and in its worst
/// configuration: on a shared host, a run whose tails moved together with the
/// steal says more about the neighbours than about the daemon.
fn steal_note(run_start: Option<MachineTicks>, rows: &[Row], baseline: &[Row]) -> String {
    let Some(run) = run_start.and_then(MachineTicks::steal_since) else {
        return String::new();
    };
    let worst = rows
        .iter()
        .map(|r| (r, ""))
        .chain(baseline.iter().map(|r| (r, " (the other daemon)")))
        .filter_map(|(r, which)| Some((r.steal?, r, which)))
        .max_by(|a, b| a.0.total_cmp(&b.0));
    let mut out = format!(
        "\nHost steal time (the hypervisor ran other guests while this one's cores had work): {:.2} % over the run",
        100.0 * run
    );
    if let Some((steal, r, which)) = worst {
        let beside = r.alongside.as_ref().map_or(String::new(), |a| format!(", beside {a}"));
        let load = r.rate.map_or("closed loop".to_string(), |x| format!("open loop {x:.0}/s"));
        let _ = write!(
            out,
            "; at most {:.2} % in one configuration: {} {load}, {} client(s){beside}{which}",
            100.0 * steal,
            r.workload.name(),
            r.clients
        );
    }
    out.push_str(".\n");
    out
}

type Outcome = (String, Vec<Row>, String, Option<f64>);

/// What the daemon itself measured (receipt to reply) over exactly one configuration.
#[derive(Debug, Clone, Copy)]
struct InDaemon {
    queries: u64,
    p50_us: u64,
    p99_us: u64,
}

/// Connects to the bench's daemon (`which`, whose log is in the error if it never
/// came up) and uploads `set`'s maps.
fn connect_and_upload(b: &Bench, set: &RequestSet, log: &Path, which: &str) -> anyhow::Result<Client> {
    let config = ClientConfig {
        prefix: b.prefix.clone(),
        domain: Some(b.domain.clone()),
        connect_timeout: TIMEOUT,
        ..ClientConfig::default()
    };
    let mut client = Client::connect(&config).with_context(|| {
        format!("{which} did not start; its log:\n{}", std::fs::read_to_string(log).unwrap_or_default())
    })?;
    for (i, s) in set.scenarios.iter().enumerate() {
        client.upload_map(map_id(i), &s.world, false, TIMEOUT).with_context(|| format!("uploading map {i}"))?;
    }
    Ok(client)
}

fn run_with_daemon(b: &Bench, dyfosd: &Path) -> anyhow::Result<Outcome> {
    let a = b.args;
    let set = RequestSet::new(a.seed, a.maps);
    let duration = Duration::from_secs_f64(a.seconds);
    let state = b.tmp.join("state");
    let log = b.tmp.join("dyfosd.log");
    let mut daemon = start_daemon(b, dyfosd, &[], &state, &log)?;
    b.daemon_pid.set(daemon.id());
    let mut client = connect_and_upload(b, &set, &log, "dyfosd")?;
    let workers = client.stats(TIMEOUT)?.workers;

    let mut rows = Vec::new();
    let mut in_daemon = None;
    for w in &a.workloads {
        match w {
            Workload::Floor => {
                let stop = Arc::new(AtomicBool::new(false));
                let server = {
                    let (domain, service, stop) = (b.domain.clone(), b.floor_service.clone(), Arc::clone(&stop));
                    let max = a.open_clients.max(1);
                    std::thread::spawn(move || serve_floor(&domain, &service, max, &stop))
                };
                let mut run = || -> anyhow::Result<()> {
                    rows.push(b.run_config(Group::closed(Workload::Floor, 1))?);
                    for r in &a.null_rates {
                        rows.push(b.run_config(Group::open(Workload::Floor, a.open_clients, *r))?);
                    }
                    Ok(())
                };
                let result = run();
                stop.store(true, std::sync::atomic::Ordering::Relaxed);
                let served = server.join().map_err(|_| anyhow::anyhow!("floor server panicked"))?;
                result?;
                served.map_err(anyhow::Error::msg)?;
            }
            Workload::Greedy | Workload::Hog | Workload::Churn => {
                bail!("`{}` runs only in the contention runs (leave it out of --workloads)", w.name())
            }
            Workload::Null | Workload::Dyfos | Workload::Stats | Workload::Map => {
                for n in &a.clients {
                    let before = client.stats(TIMEOUT)?.queries_served;
                    rows.push(b.run_config(Group::closed(*w, *n))?);
                    // The daemon's latency window covers only this run's queries when
                    // they are all it served since `before` and no more than the window.
                    let s = client.stats(TIMEOUT)?;
                    if *w == Workload::Dyfos && *n == 1 && s.queries_served - before >= s.latency_samples {
                        in_daemon = Some(InDaemon {
                            queries: s.latency_samples,
                            p50_us: s.latency_micros[0],
                            p99_us: s.latency_micros[2],
                        });
                    }
                }
                let rates = if *w == Workload::Null { &a.null_rates } else { &a.dyfos_rates };
                for r in rates {
                    rows.push(b.run_config(Group::open(*w, a.open_clients, *r))?);
                }
            }
        }
    }
    let mixed = a.workloads.contains(&Workload::Null) && a.workloads.contains(&Workload::Dyfos);
    if mixed && a.mixed_null_rate > 0.0 && a.mixed_dyfos_clients > 0 {
        rows.extend(
            b.run_groups(&[Group::open(Workload::Null, 1, a.mixed_null_rate), searches(a, a.mixed_dyfos_clients)])?,
        );
    }
    let mut idle = None;
    if !a.skip_contention {
        let mut groups = contention_groups(a);
        if let Some(h) = contention_hogs(a) {
            groups.insert(0, vec![Group::closed(Workload::Hog, h)]);
        }
        for g in groups {
            rows.extend(b.run_groups(&g)?);
        }
        idle = measure_idle(b, daemon.id());
    }
    let stats = client.stats(TIMEOUT)?;
    drop(client);
    let shutdown = match stop_daemon(&mut daemon)? {
        s if s.success() => "clean (SIGTERM, exit 0)".to_string(),
        s => format!("NOT clean: {s}; log:\n{}", std::fs::read_to_string(&log).unwrap_or_default()),
    };

    // In-process baselines, with the daemon gone.
    eprintln!("latency: in-process baselines");
    let mut baselines = Vec::new();
    for w in [Workload::Null, Workload::Dyfos] {
        if a.workloads.contains(&w) {
            baselines.push((w, Row::of(Group::closed(w, 1), vec![in_process(w, &set, duration)])));
        }
    }

    let mut report = String::new();
    let _ = writeln!(
        report,
        "## Query latency and throughput\n\n{} s per configuration, {} numerical maps (SPEC §10, seed {}), dyfosd with {} workers{}.\n",
        a.seconds,
        a.maps,
        a.seed,
        workers,
        if a.daemon_args.is_empty() { String::new() } else { format!(" and `{}`", a.daemon_args.join(" ")) }
    );
    let alone = |r: &&Row| r.alongside.is_none();
    let closed: Vec<&Row> = rows.iter().filter(alone).filter(|r| r.rate.is_none()).collect();
    let open: Vec<&Row> = rows.iter().filter(alone).filter(|r| r.rate.is_some()).collect();
    let together: Vec<&Row> = rows.iter().filter(|r| r.alongside.is_some()).collect();
    report.push_str("### Closed loop (each client sends its next request when the last is answered)\n\n");
    report.push_str(&table(&closed, false));
    if !open.is_empty() {
        report.push_str("\n### Open loop (Poisson arrivals; latency from the scheduled send time)\n\n");
        report.push_str(&table(&open, true));
    }
    if !together.is_empty() {
        report.push_str("\n### Mixed: null queries while `dyfos` queries keep the workers busy (one run)\n\n");
        let open_rows: Vec<&Row> = together.iter().copied().filter(|r| r.rate.is_some()).collect();
        let closed_rows: Vec<&Row> = together.iter().copied().filter(|r| r.rate.is_none()).collect();
        report.push_str(&table(&open_rows, true));
        report.push('\n');
        report.push_str(&table(&closed_rows, false));
    }
    report.push_str(&comparison(&rows, &baselines, in_daemon));
    let _ = writeln!(
        report,
        "\nDaemon counters at the end: {} queries served, {} requests failed.",
        stats.queries_served, stats.requests_failed,
    );
    rows.extend(baselines.into_iter().map(|(_, r)| Row { clients: 0, ..r }));
    Ok((report, rows, shutdown, idle))
}

/// Hog processes of the contention runs: `--hogs`, default one per core; `None` for 0.
fn contention_hogs(a: &LatencyArgs) -> Option<usize> {
    let h = a.hogs.unwrap_or_else(|| std::thread::available_parallelism().map_or(2, |n| n.get()));
    (h > 0).then_some(h)
}

/// The contention runs, which both daemons run (the null mix is
/// the mixed run): `stats` and map requests beside the `dyfos` clients, those
/// clients alone and beside CPU hogs, and a greedy client beside one `dyfos` client.
fn contention_groups(a: &LatencyArgs) -> Vec<Vec<Group>> {
    let n = a.mixed_dyfos_clients.max(1);
    let rate = if a.mixed_null_rate > 0.0 { a.mixed_null_rate } else { 1000.0 };
    let mut g = vec![
        vec![Group::open(Workload::Stats, 1, rate), searches(a, n)],
        vec![Group::open(Workload::Map, 1, rate), searches(a, n)],
        vec![searches(a, n)],
    ];
    if let Some(h) = contention_hogs(a) {
        g.push(vec![Group::closed(Workload::Hog, h), searches(a, n)]);
    }
    g.push(vec![Group::closed(Workload::Greedy, 1), Group::closed(Workload::Dyfos, 1)]);
    g.push(vec![Group::open(Workload::Null, 1, rate), Group::closed(Workload::Churn, 1)]);
    g
}

/// The `dyfos` clients the cheap requests of the mixed and contention runs run
/// beside: back to back, or at `--mixed-dyfos-rate` over all of them.
fn searches(a: &LatencyArgs, clients: usize) -> Group {
    if a.mixed_dyfos_rate > 0.0 {
        Group::open(Workload::Dyfos, clients, a.mixed_dyfos_rate)
    } else {
        Group::closed(Workload::Dyfos, clients)
    }
}

/// The daemon's CPU use over `--idle-seconds` without traffic, in cores.
fn measure_idle(b: &Bench, pid: u32) -> Option<f64> {
    let secs = b.args.idle_seconds;
    if !(secs > 0.0 && secs.is_finite()) {
        return None;
    }
    eprintln!("latency: {secs} s idle");
    let start = Instant::now();
    let before = cpu_seconds(pid)?;
    std::thread::sleep(Duration::from_secs_f64(secs));
    Some((cpu_seconds(pid)? - before) / start.elapsed().as_secs_f64())
}

/// The configurations of the before/after comparison.
fn baseline_groups(a: &LatencyArgs) -> Vec<Vec<Group>> {
    let mut configs = vec![vec![Group::closed(Workload::Dyfos, 1)], vec![Group::closed(Workload::Null, 1)]];
    if let Some(r) = a.null_rates.first() {
        configs.push(vec![Group::open(Workload::Null, a.open_clients, *r)]);
    }
    if a.mixed_null_rate > 0.0 && a.mixed_dyfos_clients > 0 {
        configs.push(vec![Group::open(Workload::Null, 1, a.mixed_null_rate), searches(a, a.mixed_dyfos_clients)]);
    }
    configs
}

/// Runs [`baseline_groups`] (and the contention runs and idle time) against the
/// second daemon: `dyfosd`, started with the `--compare-daemon-arg`s.
fn run_baseline(b: &Bench, dyfosd: &Path) -> anyhow::Result<(Vec<Row>, Option<f64>)> {
    let a = b.args;
    let set = RequestSet::new(a.seed, a.maps);
    let state = b.tmp.join("state-baseline");
    let log = b.tmp.join("dyfosd-baseline.log");
    eprintln!("latency: second daemon, {}", second_daemon(a));
    let mut daemon = start_daemon(b, dyfosd, &a.compare_daemon_args, &state, &log)?;
    b.daemon_pid.set(daemon.id());
    drop(connect_and_upload(b, &set, &log, "second dyfosd")?);
    let mut rows = Vec::new();
    for groups in baseline_groups(a) {
        rows.extend(b.run_groups(&groups)?);
    }
    let mut idle = None;
    if !a.skip_contention {
        for groups in contention_groups(a) {
            rows.extend(b.run_groups(&groups)?);
        }
        idle = measure_idle(b, daemon.id());
    }
    let status = stop_daemon(&mut daemon)?;
    if !status.success() {
        bail!("the second dyfosd did not stop cleanly ({status})");
    }
    Ok((rows, idle))
}

/// The second daemon of a before/after run, as its table heading names it.
fn second_daemon(a: &LatencyArgs) -> String {
    let mut what = match &a.compare_dyfosd {
        Some(bin) => format!("`{}`", bin.display()),
        None => "dyfosd".to_string(),
    };
    if !a.compare_daemon_args.is_empty() {
        let _ = write!(what, " with `{}`", a.compare_daemon_args.join(" "));
    }
    what
}

/// The same configurations with the first daemon (before) and the second (after).
fn before_after(before: &[Row], after: &[Row], second: &str) -> String {
    let mut out = format!("\n### The same configurations, same run: dyfosd as above (left) and {second} (right)\n\n");
    out.push_str("| configuration | answered /s | p50 µs | p99 µs | dyfosd CPU | the second: answered /s | p50 µs | p99 µs | dyfosd CPU |\n|---|---:|---:|---:|---:|---:|---:|---:|---:|\n");
    let same = |x: &Row, y: &Row| {
        x.workload == y.workload && x.clients == y.clients && x.rate == y.rate && x.alongside == y.alongside
    };
    let cells = |r: &Row| match r.latency {
        Some(l) => format!("{:.0} | {} | {} | {}", r.throughput, us(l.p50_us), us(l.p99_us), cpu_cell(r)),
        None => format!("{:.0} | – | – | {}", r.throughput, cpu_cell(r)),
    };
    for a in after {
        let Some(b) = before.iter().find(|b| same(a, b)) else { continue };
        let mut what = Group { workload: b.workload, clients: b.clients, rate: b.rate }.label();
        if let Some(o) = &b.alongside {
            let _ = write!(what, ", beside {o}");
        }
        let _ = writeln!(out, "| {what} | {} | {} |", cells(b), cells(a));
    }
    out
}

fn find(rows: &[Row], w: Workload, clients: usize) -> Option<&Row> {
    rows.iter().find(|r| r.workload == w && r.clients == clients && r.rate.is_none() && r.alongside.is_none())
}

/// The floor, the in-process call and the daemon side by side.
fn comparison(rows: &[Row], baselines: &[(Workload, Row)], in_daemon: Option<InDaemon>) -> String {
    let mut out = String::from("\n### Daemon against the in-process call and the iceoryx2 floor (one client)\n\n");
    out.push_str("| path | p50 µs | p99 µs | p50 ratio to the daemon |\n|---|---:|---:|---:|\n");
    let base = |w| baselines.iter().find(|(b, _)| *b == w).map(|(_, r)| r);
    let null = find(rows, Workload::Null, 1).and_then(|r| r.latency);
    let mut line = |name: &str, l: Option<Latencies>, reference: Option<Latencies>| {
        if let Some(l) = l {
            let ratio = reference.map_or("–".into(), |r| format!("{:.3}", l.p50_us / r.p50_us));
            let _ = writeln!(out, "| {name} | {} | {} | {ratio} |", us(l.p50_us), us(l.p99_us));
        }
    };
    line(
        "iceoryx2 raw request-response, busy-polled (floor)",
        find(rows, Workload::Floor, 1).and_then(|r| r.latency),
        null,
    );
    line("daemon null query (check mode)", null, null);
    line("in-process validation of the same request", base(Workload::Null).and_then(|r| r.latency), null);
    let dyfos = find(rows, Workload::Dyfos, 1);
    let dyfos_l = dyfos.and_then(|r| r.latency);
    line("daemon `dyfos` query", dyfos_l, dyfos_l);
    line("in-process `dyfos` query (`solve`, one thread)", base(Workload::Dyfos).and_then(|r| r.latency), dyfos_l);
    if let Some(d) = dyfos {
        line("– of which the search, as timed in the daemon", d.search, dyfos_l);
        line("– of which the rest (end-to-end − search)", d.overhead, dyfos_l);
    }
    if let Some(d) = in_daemon {
        let _ = writeln!(
            out,
            "| daemon `dyfos` query, receipt to reply inside dyfosd ({} queries) | {} | {} | {} |",
            d.queries,
            d.p50_us,
            d.p99_us,
            dyfos_l.map_or("–".into(), |l| format!("{:.3}", d.p50_us as f64 / l.p50_us))
        );
    }

    out
}

/// The rows as `latency.json` lists them.
fn rows_json(rows: &[Row]) -> Vec<serde_json::Value> {
    rows.iter()
        .map(|r| {
            let l = |l: Option<Latencies>| {
                l.map(|l| {
                    serde_json::json!({"count": l.count, "p50_us": l.p50_us, "p90_us": l.p90_us, "p99_us": l.p99_us,
                        "p999_us": l.p999_us, "max_us": l.max_us, "mean_us": l.mean_us})
                })
            };
            serde_json::json!({
                "workload": r.workload.name(),
                "path": if r.clients == 0 { "in-process" } else { "daemon" },
                "clients": r.clients,
                "offered_per_s": r.rate,
                "answered_per_s": r.throughput,
                "latency": l(r.latency),
                "search": l(r.search),
                "overhead": l(r.overhead),
                "errors": r.errors,
                "unsent": r.unsent,
                "sent_late": l(r.late),
                "from_send": l(r.from_send),
                "alongside": r.alongside,
                "daemon_cpu_cores": r.daemon_cpu,
                "hog_cpu_cores": r.own_cpu,
                "host_steal": r.steal,
            })
        })
        .collect()
}

/// Reads one percentile of a [`Latencies`].
type Percentile = fn(&Latencies) -> f64;

fn write_files(args: &LatencyArgs, report: &str, rows: &[Row], baseline: &[Row]) -> anyhow::Result<()> {
    let write = |name: &str, text: &str| -> anyhow::Result<()> {
        let path = args.out.join(name);
        std::fs::write(&path, text).with_context(|| format!("cannot write {}", path.display()))?;
        eprintln!("wrote {}", path.display());
        Ok(())
    };
    write("latency.md", report)?;
    write("latency.json", &serde_json::to_string_pretty(&rows_json(rows))?)?;
    if !baseline.is_empty() {
        write("latency-compare.json", &serde_json::to_string_pretty(&rows_json(baseline))?)?;
    }
    for w in [Workload::Null, Workload::Dyfos] {
        let closed: Vec<&Row> = rows
            .iter()
            .filter(|r| r.workload == w && r.rate.is_none() && r.clients > 0 && r.alongside.is_none())
            .collect();
        if closed.is_empty() {
            continue;
        }
        let pick: [(&str, Percentile); 5] = [
            ("p50", |l| l.p50_us),
            ("p90", |l| l.p90_us),
            ("p99", |l| l.p99_us),
            ("p99.9", |l| l.p999_us),
            ("max", |l| l.max_us),
        ];
        let mut series: Vec<Series> = pick
            .iter()
            .map(|(name, f)| Series {
                name: (*name).into(),
                points: closed.iter().filter_map(|r| Some((r.clients as f64, f(&r.latency?)))).collect(),
            })
            .collect();
        let reference = match w {
            Workload::Null => rows.iter().find(|r| r.workload == Workload::Floor && r.rate.is_none()),
            _ => rows.iter().find(|r| r.workload == w && r.clients == 0),
        };
        if let Some(l) = reference.and_then(|r| r.latency) {
            let name = if w == Workload::Null { "iceoryx2 floor p50" } else { "in-process p50" };
            let xs = closed.iter().map(|r| r.clients as f64);
            series.push(Series { name: name.into(), points: xs.map(|x| (x, l.p50_us)).collect() });
        }
        let svg = line_plot(
            &format!("{} query latency, closed loop", w.name()),
            "client processes",
            "latency, µs",
            &series,
            true,
        );
        write(&format!("latency-{}.svg", w.name()), &svg)?;
    }
    let throughput: Vec<Series> = [Workload::Null, Workload::Dyfos]
        .iter()
        .map(|w| Series {
            name: format!("{} queries/s", w.name()),
            points: rows
                .iter()
                .filter(|r| r.workload == *w && r.rate.is_none() && r.clients > 0 && r.alongside.is_none())
                .map(|r| (r.clients as f64, r.throughput))
                .collect(),
        })
        .filter(|s| !s.points.is_empty())
        .collect();
    if !throughput.is_empty() {
        let svg =
            line_plot("Throughput, closed loop", "client processes", "answered queries per second", &throughput, true);
        write("latency-throughput.svg", &svg)?;
    }
    Ok(())
}
