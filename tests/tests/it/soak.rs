//! Soak: client processes querying, a writer process streaming map deltas, and
//! chaos — client processes killed with SIGKILL mid-request and replaced, the daemon
//! killed with SIGKILL and restarted, stopped with SIGTERM and restarted. Then every
//! logged request is checked: an answer equal to the offline library's for the same
//! seed and map version (the writer's map rebuilt from its log), or a specific error,
//! never silence; the writer's map equals the replay of its acknowledged deltas
//! (none lost, none applied twice); the daemon's memory and shared-memory segments
//! stayed bounded; nothing of ours is left in `/dev/shm` or iceoryx2's state folder.
//!
//! The normal test run soaks for 20 s. Longer runs are opt-in:
//!
//! ```text
//! DYFOS_SOAK_SECS=1800 DYFOS_SOAK_REPORT=/tmp/soak.json \
//!     cargo test -p dyfos-tests --test it soak:: -- --nocapture
//! ```
//!
//! Environment: `DYFOS_SOAK_SECS` (duration, default 20), `DYFOS_SOAK_CLIENTS`
//! (query processes, default 8), `DYFOS_SOAK_DAEMON_EVERY` (seconds between daemon
//! faults, default a third of the run, at most 120), `DYFOS_SOAK_VERIFY` (answers
//! re-solved offline, default 300), `DYFOS_SOAK_REPORT` (write the figures there as
//! JSON), `DYFOS_SOAK_SEED` (the chaos schedule's seed).

use dyfos_client::prelude::*;
use dyfos_service::search::SearchControl;
use dyfos_tests::soak::{Outcome, Record, SoakMap, WRITER_MAP, WriterRecord, maps, read_log, request_of};
use dyfos_tests::{DaemonProcess, KillOnDrop, PATIENCE, Sandbox, bin, wait_for, without_micros};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

fn env_u64(name: &str, default: u64) -> u64 {
    std::env::var(name).ok().and_then(|v| v.parse().ok()).unwrap_or(default)
}

struct Config {
    secs: u64,
    clients: u32,
    daemon_every: u64,
    verify: usize,
    seed: u64,
    report: Option<PathBuf>,
}

impl Config {
    fn from_env() -> Config {
        let secs = env_u64("DYFOS_SOAK_SECS", 20).max(5);
        Config {
            secs,
            clients: env_u64("DYFOS_SOAK_CLIENTS", 8).clamp(1, 48) as u32,
            daemon_every: env_u64("DYFOS_SOAK_DAEMON_EVERY", (secs / 3).clamp(2, 120)).max(2),
            verify: env_u64("DYFOS_SOAK_VERIFY", 300) as usize,
            seed: env_u64("DYFOS_SOAK_SEED", 1),
            report: std::env::var_os("DYFOS_SOAK_REPORT").map(PathBuf::from),
        }
    }
}

/// A `soak-client` process.
struct Proc {
    id: u32,
    log: PathBuf,
    child: KillOnDrop,
}

fn spawn(mode: &str, id: u32, sandbox: &Sandbox, run: &Path) -> Proc {
    let log = run.join(format!("{mode}-{id}.jsonl"));
    let stderr = std::fs::File::create(run.join(format!("{mode}-{id}.stderr"))).expect("stderr file");
    let child = Command::new(bin("soak-client"))
        .arg(mode)
        .args(["--prefix", &sandbox.prefix, "--domain", &sandbox.domain, "--id", &id.to_string()])
        .arg("--log")
        .arg(&log)
        .arg("--stop")
        .arg(run.join("stop"))
        .stdout(Stdio::null())
        .stderr(stderr)
        .spawn()
        .expect("start soak-client");
    Proc { id, log, child: KillOnDrop::new(child) }
}

fn proc_status_kib(pid: u32, key: &str) -> Option<u64> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    let line = status.lines().find(|l| l.starts_with(key))?;
    line.split_whitespace().nth(1)?.parse().ok()
}

fn open_fds(pid: u32) -> usize {
    std::fs::read_dir(format!("/proc/{pid}/fd")).map_or(0, |d| d.count())
}

fn shm_segments(domain: &str) -> usize {
    std::fs::read_dir("/dev/shm")
        .map(|d| d.flatten().filter(|e| e.file_name().to_string_lossy().starts_with(domain)).count())
        .unwrap_or(0)
}

fn load_average() -> String {
    std::fs::read_to_string("/proc/loadavg")
        .unwrap_or_default()
        .split_whitespace()
        .take(3)
        .collect::<Vec<_>>()
        .join(" ")
}

/// One daemon process's life.
#[derive(Debug, Default)]
struct Incarnation {
    pid: u32,
    rss_kib: Vec<u64>,
    fds_max: usize,
    stats: Option<DaemonStats>,
    ended_by: &'static str,
}

impl Incarnation {
    fn new(pid: u32) -> Self {
        Incarnation { pid, ..Default::default() }
    }

    /// RSS once warmed up (a fifth into its life) and at its end.
    fn rss_start_end(&self) -> (u64, u64) {
        let v = &self.rss_kib;
        if v.is_empty() {
            return (0, 0);
        }
        (v[v.len() / 5], v[v.len() - 1])
    }
}

#[derive(Debug, Default)]
struct Faults {
    client_kill9: u64,
    client_kill9_mid_request: u64,
    daemon_kill9: u64,
    daemon_sigterm: u64,
}

fn percentile(sorted: &[u64], q: f64) -> u64 {
    if sorted.is_empty() {
        return 0;
    }
    sorted[((sorted.len() - 1) as f64 * q).round() as usize]
}

/// The writer map at every version an answer needs, rebuilt from the writer's log.
fn writer_worlds(
    initial: &World,
    applied: &[(u64, u64, Vec<MapDelta>)],
    wanted: &BTreeSet<u64>,
) -> BTreeMap<u64, World> {
    let mut out = BTreeMap::new();
    let mut world = initial.clone();
    if wanted.contains(&world.version()) {
        out.insert(world.version(), world.clone());
    }
    for (_, to, deltas) in applied {
        world = world.apply(deltas).expect("an acknowledged batch applies to the replayed map");
        assert_eq!(world.version(), *to);
        if wanted.contains(to) {
            out.insert(*to, world.clone());
        }
    }
    out
}

fn offline(world: &World, map: &SoakMap, sent: &dyfos_tests::soak::Sent) -> Result<Answer, dyfos_service::SearchError> {
    let request = request_of(sent, map);
    let model = NoiseModel::from_params(&request.params).expect("model");
    let control = SearchControl { budget: request.budget, ..SearchControl::seeded(request.seed) };
    dyfos_service::solve(world, &map.belief, &request.params, &model, request.algorithm, &control)
}

/// Everything a soak run leaves to check: the processes' logs, what the daemon's
/// incarnations looked like, and the maps before and after a clean restart.
struct Soak {
    cfg: Config,
    run: PathBuf,
    maps: Vec<SoakMap>,
    writer_log: Vec<WriterRecord>,
    /// Each query process's id, log, and whether it was killed.
    client_logs: Vec<(u32, PathBuf, bool)>,
    /// Each query process that was stopped, and how it exited.
    exits: Vec<(u32, std::process::ExitStatus)>,
    incarnations: Vec<Incarnation>,
    faults: Faults,
    shm_samples: Vec<(f64, usize)>,
    /// Every map at the end of the run, and again after a SIGTERM and a restart.
    snapshots: Vec<World>,
    after_restart: Vec<World>,
    shm_left: Vec<String>,
    state_left: Vec<String>,
    load_at_start: String,
    load_at_end: String,
}

/// Runs the soak: the processes, the chaos, a clean stop, one more restart.
fn soak(cfg: Config) -> Soak {
    let sandbox = Sandbox::new("soak");
    let run = std::env::temp_dir().join(format!("dyfos-soak-{}-{}", std::process::id(), sandbox.domain));
    let _ = std::fs::remove_dir_all(&run);
    std::fs::create_dir_all(&run).expect("run dir");
    let load_at_start = load_average();
    let mut rng = ChaCha8Rng::seed_from_u64(cfg.seed);

    let mut daemon: DaemonProcess = sandbox.start_daemon(&[]);
    let mut incarnations = vec![Incarnation::new(daemon.pid())];
    let maps = maps();
    {
        let mut admin = sandbox.client();
        let w = &maps[0].world;
        assert_eq!(admin.create_map(WRITER_MAP, *w.bounds(), *w.sun(), PATIENCE).unwrap(), 0);
        for m in &maps[1..] {
            assert_eq!(admin.upload_map(m.id, &m.world, false, PATIENCE).unwrap(), 0);
        }
    }
    let mut admin = sandbox.client();

    let writer = spawn("write", 1000, &sandbox, &run);
    let mut live: Vec<Proc> = (1..=cfg.clients).map(|id| spawn("query", id, &sandbox, &run)).collect();
    let mut killed: Vec<(u32, PathBuf)> = Vec::new();
    let mut next_id = cfg.clients + 1;
    let mut faults = Faults::default();
    let mut shm_samples: Vec<(f64, usize)> = Vec::new();

    let start = Instant::now();
    let end = start + Duration::from_secs(cfg.secs);
    let mut next_client_kill = start + Duration::from_millis(rng.random_range(800..2200));
    let mut next_daemon_fault = start + Duration::from_secs(cfg.daemon_every);
    let mut next_stats = start;
    let mut kill9_next = true;
    while Instant::now() < end {
        std::thread::sleep(Duration::from_millis(200));
        let now = Instant::now();
        let inc = incarnations.last_mut().expect("one incarnation");
        if let Some(rss) = proc_status_kib(inc.pid, "VmRSS:") {
            inc.rss_kib.push(rss);
        }
        inc.fds_max = inc.fds_max.max(open_fds(inc.pid));
        shm_samples.push((start.elapsed().as_secs_f64(), shm_segments(&sandbox.domain)));
        if now >= next_stats {
            if let Ok(s) = admin.stats(Duration::from_secs(2)) {
                inc.stats = Some(s);
            }
            next_stats = now + Duration::from_secs(1);
        }
        // Victims are clients past their start (they have sent a request): a process
        // killed while iceoryx2 creates its node, or cleans up a dead one, can leave
        // files iceoryx2 cannot clean (bench/RESULTS.md, "Soak with chaos").
        let started: Vec<usize> = (0..live.len()).filter(|i| !read_log::<Record>(&live[*i].log).is_empty()).collect();
        if now >= next_client_kill && !started.is_empty() {
            let victim = live.swap_remove(started[rng.random_range(0..started.len())]);
            let mut guard = victim.child;
            guard.kill(); // SIGKILL
            faults.client_kill9 += 1;
            if matches!(read_log::<Record>(&victim.log).last(), Some(Record::Sent(_))) {
                faults.client_kill9_mid_request += 1;
            }
            killed.push((victim.id, victim.log));
            live.push(spawn("query", next_id, &sandbox, &run));
            next_id += 1;
            next_client_kill = now + Duration::from_millis(rng.random_range(800..2200));
        }
        if now >= next_daemon_fault && now + Duration::from_secs(2) < end {
            if let Ok(s) = admin.stats(Duration::from_secs(2)) {
                inc.stats = Some(s);
            }
            if kill9_next {
                daemon.kill9();
                faults.daemon_kill9 += 1;
                inc.ended_by = "kill -9";
            } else {
                let status = daemon.terminate();
                assert!(status.success(), "dyfosd after SIGTERM: {status}\n{}", daemon.log());
                faults.daemon_sigterm += 1;
                inc.ended_by = "SIGTERM";
            }
            kill9_next = !kill9_next;
            daemon = sandbox.start_daemon(&[]);
            incarnations.push(Incarnation::new(daemon.pid()));
            next_daemon_fault = Instant::now() + Duration::from_secs(cfg.daemon_every);
        }
    }

    // Stop every process; each finishes its request in flight and exits.
    std::fs::write(run.join("stop"), b"").unwrap();
    let mut procs: Vec<Proc> = live;
    procs.push(writer);
    let exits: Vec<(u32, std::process::ExitStatus)> =
        procs.iter_mut().map(|p| (p.id, wait_for("a soak process to stop", || p.child.try_wait()))).collect();
    let inc = incarnations.last_mut().expect("one incarnation");
    inc.stats = admin.stats(PATIENCE).ok();
    inc.ended_by = "end";
    let snapshots: Vec<World> = maps.iter().map(|m| admin.snapshot(m.id, PATIENCE).unwrap()).collect();
    let load_at_end = load_average();
    let writer_log: Vec<WriterRecord> = read_log(&procs.last().expect("writer").log);
    let mut client_logs: Vec<(u32, PathBuf, bool)> = killed.iter().map(|(id, log)| (*id, log.clone(), true)).collect();
    client_logs.extend(procs[..procs.len() - 1].iter().map(|p| (p.id, p.log.clone(), false)));

    // A clean stop, and the maps again from disk.
    drop(admin);
    let status = daemon.terminate();
    assert!(status.success(), "final SIGTERM: {status}\n{}", daemon.log());
    let mut daemon = sandbox.start_daemon(&[]);
    let after_restart = {
        let mut admin = sandbox.client();
        maps.iter().map(|m| admin.snapshot(m.id, PATIENCE).unwrap()).collect()
    };
    assert!(daemon.terminate().success());
    Soak {
        shm_left: sandbox.shm_leftovers(),
        state_left: sandbox.state_leftovers(),
        cfg,
        run,
        maps,
        writer_log,
        client_logs,
        exits,
        incarnations,
        faults,
        shm_samples,
        snapshots,
        after_restart,
        load_at_start,
        load_at_end,
    }
}

/// The writer's log read back: the batches the daemon acknowledged, and what went
/// wrong on the way.
#[derive(Default)]
struct WriterLog {
    applied: Vec<(u64, u64, Vec<MapDelta>)>,
    version: u64,
    ack_lost: u64,
    inline: u64,
    rejected_invalid: u64,
    retries: u64,
    failures: Vec<String>,
}

fn writer_log(log: &[WriterRecord]) -> WriterLog {
    let mut w = WriterLog::default();
    for r in log {
        match r {
            WriterRecord::Applied { k, from, to, deltas, inline, ack_lost, .. } => {
                if *from != w.version || *to != from + deltas.len() as u64 || deltas.is_empty() {
                    w.failures.push(format!("writer batch {k}: {from} -> {to} after version {}", w.version));
                }
                w.version = *to;
                w.ack_lost += u64::from(*ack_lost);
                w.inline += u64::from(*inline);
                w.applied.push((*from, *to, deltas.clone()));
            }
            WriterRecord::Rejected { k, from, status, valid } => {
                if *valid || status != "invalid_delta" || *from != w.version {
                    w.failures.push(format!("writer batch {k} (valid: {valid}) at {from} rejected: {status}"));
                }
                w.rejected_invalid += 1;
            }
            WriterRecord::Retry { k, outcome } => {
                w.retries += 1;
                if matches!(outcome, Outcome::Failed { kind, .. } if kind == "timeout" || kind == "ipc") {
                    w.failures.push(format!("writer batch {k}: {outcome:?}"));
                }
            }
            WriterRecord::Fatal { k, message } => w.failures.push(format!("writer batch {k}: {message}")),
        }
    }
    w
}

/// The query processes' logs read back: every outcome counted and checked against
/// its request, and the answers to re-solve offline.
#[derive(Default)]
struct ClientLogs {
    sent: u64,
    counts: BTreeMap<String, u64>,
    latencies: Vec<u64>,
    to_verify: Vec<(dyfos_tests::soak::Sent, Option<(serde_json::Value, u64)>)>,
    failures: Vec<String>,
}

/// Reads every query log; `boundaries` are the writer map's versions between
/// acknowledged batches (the only ones a query may see).
fn client_logs(logs: &[(u32, PathBuf, bool)], boundaries: &BTreeSet<u64>) -> ClientLogs {
    let mut c = ClientLogs::default();
    let failures = &mut c.failures;
    for (id, log, was_killed) in logs {
        let mut pending: Option<dyfos_tests::soak::Sent> = None;
        let mut last_writer_version = 0;
        for record in read_log::<Record>(log) {
            match record {
                Record::Sent(s) => {
                    if let Some(p) = &pending {
                        failures.push(format!("client {id}: request {} got no outcome", p.n));
                    }
                    c.sent += 1;
                    pending = Some(s);
                }
                Record::Done { n, micros, outcome } => {
                    let Some(s) = pending.take().filter(|s| s.n == n) else {
                        failures.push(format!("client {id}: outcome of {n} without its request"));
                        continue;
                    };
                    let mut version_seen = None;
                    let key = match &outcome {
                        Outcome::Answer { answer, map_version, stop } => {
                            c.latencies.push(micros);
                            version_seen = Some(*map_version);
                            if s.check || answer["algorithm"] != s.algorithm.name() {
                                failures.push(format!("client {id} #{n}: answer {answer} to {s:?}"));
                            }
                            if *stop == StopReason::Deadline && s.deadline_us.is_none() {
                                failures.push(format!("client {id} #{n}: stopped by a deadline it did not set"));
                            }
                            if *stop != StopReason::Deadline {
                                c.to_verify.push((s.clone(), Some((answer.clone(), *map_version))));
                            }
                            "ok".to_string()
                        }
                        Outcome::Checked { map_version } => {
                            version_seen = Some(*map_version);
                            if !s.check {
                                failures.push(format!("client {id} #{n}: check reply to a solve request"));
                            }
                            "ok_check".to_string()
                        }
                        Outcome::Rejected { status, message } => {
                            let allowed = match status.as_str() {
                                "busy" | "shutting_down" => true,
                                "no_feasible_pose" => !s.check,
                                "deadline_exceeded" => s.deadline_us.is_some(),
                                "map_version_mismatch" => match s.expected_version {
                                    Some(v) if s.map != WRITER_MAP => v != 0,
                                    Some(_) => true,
                                    None => false,
                                },
                                _ => false,
                            };
                            if !allowed {
                                failures.push(format!("client {id} #{n}: {status}: {message} for {s:?}"));
                            }
                            if status == "no_feasible_pose" && s.map != WRITER_MAP {
                                c.to_verify.push((s.clone(), None));
                            }
                            status.clone()
                        }
                        Outcome::Failed { kind, message } => {
                            if !matches!(kind.as_str(), "no_daemon" | "daemon_gone" | "connect") {
                                failures.push(format!("client {id} #{n}: {kind}: {message} for {s:?}"));
                            }
                            format!("client:{kind}")
                        }
                    };
                    *c.counts.entry(key).or_default() += 1;
                    if let Some(v) = version_seen {
                        if s.expected_version.is_some_and(|e| e != v) {
                            failures.push(format!("client {id} #{n}: answered at version {v} for {s:?}"));
                        }
                        if s.map == WRITER_MAP {
                            if !boundaries.contains(&v) {
                                failures.push(format!("client {id} #{n}: writer map version {v} never existed"));
                            }
                            if v < last_writer_version {
                                failures.push(format!("client {id} #{n}: writer map went back to {v}"));
                            }
                            last_writer_version = v;
                        } else if v != 0 {
                            failures.push(format!("client {id} #{n}: fixed map {} at version {v}", s.map));
                        }
                    }
                }
            }
        }
        if pending.is_some() && !was_killed {
            failures.push(format!("client {id}: its last request got no outcome"));
        }
    }
    c
}

/// What the cases read: the run, and its logs read back once.
struct Checked {
    soak: Soak,
    writer: WriterLog,
    clients: ClientLogs,
    /// Answers re-solved offline, and the mismatches.
    verified: usize,
    offline_failures: Vec<String>,
    rss_max: u64,
    shm_settled: usize,
    shm_max: usize,
}

fn check(soak: Soak) -> Checked {
    let writer = writer_log(&soak.writer_log);
    let boundaries: BTreeSet<u64> = std::iter::once(0).chain(writer.applied.iter().map(|a| a.1)).collect();
    let clients = client_logs(&soak.client_logs, &boundaries);

    // Spot checks against the offline library.
    let (maps, verify) = (&soak.maps, soak.cfg.verify.max(1));
    let step = (clients.to_verify.len() / verify).max(1);
    let sample: Vec<_> = clients.to_verify.iter().step_by(step).take(verify).collect();
    let wanted: BTreeSet<u64> =
        sample.iter().filter(|(s, _)| s.map == WRITER_MAP).filter_map(|(_, a)| a.as_ref().map(|a| a.1)).collect();
    let worlds = writer_worlds(&maps[0].world, &writer.applied, &wanted);
    let (mut verified, mut offline_failures) = (0, Vec::new());
    for (s, got) in &sample {
        let map = maps.iter().find(|m| m.id == s.map).expect("a soak map");
        let world = match got {
            Some((_, v)) if s.map == WRITER_MAP => match worlds.get(v) {
                Some(w) => w,
                None => continue, // a version that never existed: the clients' case says so
            },
            _ => &map.world,
        };
        match (got, offline(world, map, s)) {
            (Some((answer, _)), Ok(expected)) => {
                let expected = without_micros(expected.to_json());
                if without_micros(answer.clone()) != expected {
                    offline_failures.push(format!("{s:?}: daemon {answer} != offline {expected}"));
                }
            }
            (None, Err(_)) => {}
            (got, expected) => offline_failures.push(format!("{s:?}: daemon {got:?} vs offline {expected:?}")),
        }
        verified += 1;
    }

    let rss_max = soak.incarnations.iter().flat_map(|i| i.rss_kib.iter().copied()).max().unwrap_or(0);
    // Segments once every process is up: the most seen in the run's first third
    // (before the second daemon fault). Growth past that means leaked segments.
    let third = soak.cfg.secs as f64 / 3.0;
    let shm_settled = soak.shm_samples.iter().filter(|(t, _)| *t < third).map(|(_, n)| *n).max().unwrap_or(0);
    let shm_max = soak.shm_samples.iter().map(|(_, n)| *n).max().unwrap_or(0);
    Checked { soak, writer, clients, verified, offline_failures, rss_max, shm_settled, shm_max }
}

/// One property of a soak run: what is wrong, empty if it holds.
type Case = fn(&Checked) -> Vec<String>;

/// What a soak run must show, each named in its failure.
const CASES: [(&str, Case); 9] = [
    ("every process stopped cleanly", |c| {
        c.soak
            .exits
            .iter()
            .filter(|(_, s)| !s.success())
            .map(|(id, s)| format!("soak-client {id} exited with {s}"))
            .collect()
    }),
    ("the writer's batches were acknowledged in order", |c| c.writer.failures.clone()),
    ("the writer's map is the replay of its acknowledged deltas (none lost, none twice)", |c| {
        let replayed = c
            .writer
            .applied
            .iter()
            .try_fold(c.soak.maps[0].world.clone(), |w, (_, _, d)| w.apply(d))
            .expect("the acknowledged batches replay");
        let map = &c.soak.snapshots[0];
        let mut failures = Vec::new();
        if replayed != *map {
            failures.push(format!(
                "version {} differs from the replay (version {})",
                map.version(),
                replayed.version()
            ));
        }
        for (m, s) in c.soak.maps[1..].iter().zip(&c.soak.snapshots[1..]) {
            if *s != m.world {
                failures.push(format!("fixed map {} changed", m.id));
            }
        }
        failures
    }),
    ("every request got an answer or a specific error", |c| c.clients.failures.clone()),
    ("answers equal the offline library's", |c| c.offline_failures.clone()),
    ("the daemon's memory and shared memory stayed bounded", |c| {
        let mut failures = Vec::new();
        if c.rss_max > 512 * 1024 {
            failures.push(format!("dyfosd RSS reached {} KiB", c.rss_max));
        }
        for inc in &c.soak.incarnations {
            let (s, e) = inc.rss_start_end();
            if inc.rss_kib.len() >= 25 && e > 2 * s + 32 * 1024 {
                failures.push(format!("dyfosd {} grew from {s} KiB to {e} KiB", inc.pid));
            }
        }
        if c.shm_max > 3 * c.shm_settled + 32 {
            failures.push(format!("shared-memory segments grew from {} to {}", c.shm_settled, c.shm_max));
        }
        failures
    }),
    ("the maps survive a clean restart", |c| {
        let maps = c.soak.maps.iter().zip(c.soak.snapshots.iter().zip(&c.soak.after_restart));
        maps.filter(|(_, (before, after))| before != after).map(|(m, _)| format!("map {} differs", m.id)).collect()
    }),
    ("a clean stop leaves nothing behind", |c| {
        let (shm, state) = (&c.soak.shm_left, &c.soak.state_left);
        if shm.is_empty() && state.is_empty() { vec![] } else { vec![format!("left behind: {shm:?} {state:?}")] }
    }),
    ("the soak did what it claims", |c| {
        let (f, answers) = (&c.soak.faults, c.clients.counts.get("ok").copied().unwrap_or(0));
        let mut failures = Vec::new();
        if !(f.client_kill9 >= 1 && f.daemon_kill9 >= 1 && f.daemon_sigterm >= 1) {
            failures.push(format!("too few faults: {f:?}"));
        }
        if answers < 20 {
            failures.push(format!("too few answers: {:?}", c.clients.counts));
        }
        if c.writer.applied.is_empty() || c.verified < 10 {
            failures.push(format!("{} batches, {} answers verified", c.writer.applied.len(), c.verified));
        }
        failures
    }),
];

fn percentiles(sorted: &[u64]) -> serde_json::Value {
    serde_json::json!({
        "answers": sorted.len(),
        "p50": percentile(sorted, 0.5),
        "p90": percentile(sorted, 0.9),
        "p99": percentile(sorted, 0.99),
        "max": sorted.last().copied().unwrap_or(0),
    })
}

/// The figures of a run, printed and (with `DYFOS_SOAK_REPORT`) written.
fn report(c: &Checked, failures: usize) -> serde_json::Value {
    let (soak, w) = (&c.soak, &c.writer);
    let mut latencies = c.clients.latencies.clone();
    latencies.sort_unstable();
    let stats = || soak.incarnations.iter().filter_map(|i| i.stats.as_ref());
    let sum_stats = |f: fn(&DaemonStats) -> u64| stats().map(f).sum::<u64>();
    let mut daemon_errors: BTreeMap<String, u64> = BTreeMap::new();
    for s in stats() {
        for (status, n) in &s.errors {
            *daemon_errors.entry(Status::name(*status).to_string()).or_default() += n;
        }
    }
    let f = &soak.faults;
    serde_json::json!({
        "duration_s": soak.cfg.secs,
        "clients": soak.cfg.clients,
        "load_average_start": soak.load_at_start,
        "load_average_end": soak.load_at_end,
        "requests_sent": c.clients.sent,
        "outcomes": c.clients.counts,
        "client_latency_us": percentiles(&latencies),
        "faults": {
            "client_kill9": f.client_kill9,
            "client_kill9_mid_request": f.client_kill9_mid_request,
            "daemon_kill9": f.daemon_kill9,
            "daemon_sigterm": f.daemon_sigterm,
        },
        "writer": {
            "batches_applied": w.applied.len(),
            "final_version": w.version,
            "inline": w.inline,
            "ack_lost": w.ack_lost,
            "rejected_invalid": w.rejected_invalid,
            "retries": w.retries,
        },
        "verified_offline": c.verified,
        "daemon": {
            "queries_served": sum_stats(|s| s.queries_served),
            "map_requests": sum_stats(|s| s.map_requests),
            // Searches of clients killed mid-request that the daemon stopped.
            "queries_abandoned": sum_stats(|s| s.queries_abandoned),
            "errors_by_code": daemon_errors,
            "rss_max_kib": c.rss_max,
            "shm_segments": {"settled": c.shm_settled, "max": c.shm_max},
            "incarnations": soak.incarnations.iter().map(|i| {
                let (s, e) = i.rss_start_end();
                serde_json::json!({
                    "pid": i.pid,
                    "ended_by": i.ended_by,
                    "rss_start_kib": s,
                    "rss_end_kib": e,
                    "fds_max": i.fds_max,
                    "latency_p99_us": i.stats.as_ref().map_or(0, |s| s.latency_micros[2]),
                    "queries_served": i.stats.as_ref().map_or(0, |s| s.queries_served),
                })
            }).collect::<Vec<_>>(),
        },
        "leftovers": {"shm": soak.shm_left, "state": soak.state_left},
        "failures": failures,
    })
}

#[test]
fn soak_with_chaos_loses_nothing_and_answers_every_request() {
    let checked = check(soak(Config::from_env()));
    let failures: Vec<String> = CASES
        .iter()
        .flat_map(|(case, holds)| holds(&checked).into_iter().map(move |f| format!("{case}: {f}")))
        .collect();
    let report = report(&checked, failures.len());
    println!("{report:#}");
    if let Some(path) = &checked.soak.cfg.report {
        std::fs::write(path, format!("{report:#}\n")).expect("write the soak report");
    }
    let run = &checked.soak.run;
    assert!(failures.is_empty(), "{} failures (logs in {}):\n{}", failures.len(), run.display(), failures.join("\n"));
    let _ = std::fs::remove_dir_all(run);
}
