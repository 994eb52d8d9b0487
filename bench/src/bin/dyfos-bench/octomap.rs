//! `dyfos-bench octomap`: OctoMap maps. `dyfos` query cost per candidate
//! on the real Freiburg map and on a synthetic building against cylinder maps, in
//! process; then, through a real `dyfosd`, loading a building `.bt`, 10 000-cell
//! updates, a restart and queries, with bytes per cell and the daemon's memory.

use anyhow::Context;
use dyfos_bench::evaluation::{Contender, Timing, duration, evaluate};
use dyfos_bench::numerical::{NumericalConfig, numerical_map, voxelized};
use dyfos_bench::octomap::{Building, RESOLUTION, ROOM_CELLS};
use dyfos_bench::stats::Summary;
use dyfos_client::{Client, ClientConfig};
use dyfos_process::child::KillOnDrop;
use dyfos_service::launch::DyfosdCommand;
use dyfos_shared::answer::Algorithm;
use dyfos_shared::math::Point3;
use dyfos_shared::scenario::Scenario;
use dyfos_shared::wire::rendezvous::RendezvousRequest;
use dyfos_shared::world::octomap::{Octomap, write_bt};
use dyfos_shared::world::{Bounds, MapDelta, Sun, VoxelBlock, World};
use std::fmt::Write;
use std::path::{Path, PathBuf};

use std::time::{Duration, Instant};

/// Flags of `dyfos-bench octomap`.
#[derive(Debug, clap::Args)]
pub struct OctomapArgs {
    /// Real OctoMap scenarios (with an `octomap` entry) to time queries on.
    #[arg(long, default_value = "tests/data/octomap/geb079-scenario.json")]
    scenario: Vec<PathBuf>,
    /// Queries (seeds) per map for the in-process timing.
    #[arg(long, default_value_t = 10)]
    queries: usize,
    /// Occupied cells of the synthetic buildings loaded into the daemon, comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "10000000")]
    cells: Vec<u64>,
    /// Cells of each incremental update.
    #[arg(long, default_value_t = 10_000)]
    update_cells: usize,
    /// Incremental updates timed per building.
    #[arg(long, default_value_t = 20)]
    updates: usize,
    /// The daemon binary (default: `dyfosd` next to this executable).
    #[arg(long)]
    dyfosd: Option<PathBuf>,
    /// Directory for the report (markdown).
    #[arg(long, default_value = "bench/out")]
    out: PathBuf,
}

const TIMEOUT: Duration = Duration::from_secs(600);

pub fn run(args: &OctomapArgs) -> anyhow::Result<()> {
    let mut report = String::new();
    let _ = writeln!(report, "load average before: {}\n", load_average());
    report.push_str(&query_costs(args)?);
    for &cells in &args.cells {
        report.push_str(&daemon_run(args, cells)?);
    }
    let _ = writeln!(report, "\nload average after: {}", load_average());
    std::fs::create_dir_all(&args.out)?;
    let file = args.out.join("octomap.md");
    std::fs::write(&file, &report).with_context(|| format!("cannot write {}", file.display()))?;
    print!("{report}");
    Ok(())
}

/// In-process `dyfos` queries: CPU-µs per candidate on cylinder maps, the same maps
/// as 0.1 and 0.05 m grids, the real OctoMap scenarios and a building.
fn query_costs(args: &OctomapArgs) -> anyhow::Result<String> {
    let n = args.queries.max(1);
    let contender = [Contender::algorithm(Algorithm::Dyfos, 1)];
    let cylinders: Vec<Scenario> = (0..n as u64).map(|i| numerical_map(1, i, &NumericalConfig::paper())).collect();
    let mut rows: Vec<(String, u64, Vec<Scenario>)> =
        vec![("25 cylinders (SPEC §10 maps)".into(), 0, cylinders.clone())];
    for r in [0.1, 0.05] {
        let grids: Vec<Scenario> = cylinders.iter().map(|s| voxelized(s, r)).collect::<Result<_, _>>()?;
        let cells = grids.iter().map(|g| g.world.voxels().map_or(0, |v| v.len())).max().unwrap_or(0);
        rows.push((format!("the same as {r} m voxels"), cells, grids));
    }
    for path in &args.scenario {
        let text = std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
        let base = path.parent().unwrap_or(Path::new("."));
        let scenario =
            Scenario::from_json_with_files(&text, |f| std::fs::read(base.join(f)).map_err(|e| e.to_string()))?;
        let cells = scenario.world.voxels().map_or(0, |v| v.len());
        rows.push((format!("OctoMap {}", path.display()), cells, vec![scenario; n]));
    }
    let building = Building::with_cells(2_000_000);
    let world = building.world()?;
    let cells = world.voxels().map_or(0, |v| v.len());
    let side = building.side as f64 * RESOLUTION;
    rows.push((format!("building {side:.0} × {side:.0} m, 0.05 m"), cells, vec![building.scenario(world)?; n]));

    let mut out = format!(
        "### `dyfos` query cost per candidate, in process, one thread ({n} queries a map, seeds 1..={n})\n\n\
         | map | occupied cells | wall median | wall max | CPU median | evaluations median | CPU-µs per evaluation | × cylinders | feasible |\n\
         |---|---:|---:|---:|---:|---:|---:|---:|---:|\n"
    );
    let mut reference = None;
    for (name, cells, scenarios) in rows {
        let run = evaluate(&scenarios, &contender, 1, 3);
        let q = &run.queries[0];
        let t = Timing::of(q);
        let per = t.micros_per_evaluation.as_ref().map_or(f64::NAN, |s| s.median);
        let reference = *reference.get_or_insert(per);
        let s = t.seconds.context("no queries")?;
        let _ = writeln!(
            out,
            "| {name} | {} | {} | {} | {} | {:.0} | {per:.3} | {:.2} | {}/{} |",
            if cells == 0 { "–".to_string() } else { cells.to_string() },
            duration(s.median),
            duration(s.max),
            t.cpu_seconds.map_or("–".into(), |c| duration(c.median)),
            t.evaluations.map_or(f64::NAN, |e| e.median),
            per / reference,
            q.iter().filter(|q| q.feasible()).count(),
            q.len()
        );
    }
    Ok(out)
}

/// `dyfosd`, killed on drop unless it was stopped.
struct Daemon(KillOnDrop);

impl Daemon {
    fn start(dyfosd: &Path, prefix: &str, domain: &str, state: &Path, log: &Path) -> anyhow::Result<Daemon> {
        let log = std::fs::OpenOptions::new().create(true).append(true).open(log)?;
        let child = DyfosdCommand::new(dyfosd, prefix, state)
            .domain(domain)
            .log("info", log)
            .spawn()
            .with_context(|| format!("cannot start {}", dyfosd.display()))?;
        Ok(Daemon(child))
    }

    fn pid(&self) -> u32 {
        self.0.id()
    }

    /// SIGTERM and a clean exit.
    fn stop(&mut self) -> anyhow::Result<()> {
        anyhow::ensure!(self.0.is_running(), "not running");
        self.0.terminate(Duration::from_secs(60)).map(drop).context("dyfosd did not stop within 60 s")
    }

    /// Resident memory, MiB.
    fn rss_mib(&self) -> f64 {
        let status = std::fs::read_to_string(format!("/proc/{}/status", self.pid())).unwrap_or_default();
        status
            .lines()
            .find_map(|l| l.strip_prefix("VmRSS:"))
            .and_then(|v| v.split_whitespace().next()?.parse::<f64>().ok())
            .map_or(f64::NAN, |kb| kb / 1024.0)
    }
}

fn connect(prefix: &str, domain: &str) -> anyhow::Result<Client> {
    let config = ClientConfig {
        prefix: prefix.into(),
        domain: Some(domain.into()),
        connect_timeout: Duration::from_secs(120),
        ..ClientConfig::default()
    };
    Ok(Client::connect(&config)?)
}

fn secs(d: Duration) -> String {
    duration(d.as_secs_f64())
}

/// Loads a building of `cells` cells into a fresh `dyfosd` from a `.bt` file, times
/// updates, queries and a restart.
fn daemon_run(args: &OctomapArgs, cells: u64) -> anyhow::Result<String> {
    let exe = std::env::current_exe()?;
    let dyfosd = args.dyfosd.clone().unwrap_or_else(|| exe.with_file_name("dyfosd"));
    let tag = format!("octobench{}", std::process::id());
    let (prefix, domain) = (format!("{tag}/"), format!("{tag}_"));
    let tmp = std::env::temp_dir().join(&tag);
    std::fs::create_dir_all(&tmp)?;
    let state = tmp.join("state");
    let log = tmp.join("dyfosd.log");
    let building = Building::with_cells(cells);
    let bt = tmp.join("building.bt");
    let written = Instant::now();
    std::fs::write(&bt, write_bt(RESOLUTION, building.cells())?)?;
    let write_time = written.elapsed();
    let file_bytes = std::fs::metadata(&bt)?.len();

    let mut daemon = Daemon::start(&dyfosd, &prefix, &domain, &state, &log)?;
    let mut client = connect(&prefix, &domain)?;
    let rss_empty = daemon.rss_mib();

    // The load, as `dyfos map upload ID --octomap FILE.bt` does it.
    let started = Instant::now();
    let bytes = std::fs::read(&bt)?;
    let map = Octomap::from_bt(&bytes)?;
    let parsed = started.elapsed();
    let grid = map.to_voxels(Point3::origin())?;
    drop(map);
    let side = building.side as f64 * RESOLUTION;
    let world = World::new(0, Bounds::new([0.0, 0.0, side, side])?, Sun::new(0.6, 2.4)?, [], Some(grid))?;
    let built = started.elapsed();
    let version = client.upload_map(1, &world, false, TIMEOUT)?;
    let loaded = started.elapsed();
    let grid = world.voxels().context("a grid")?;
    let (occupied, grid_bytes) = (grid.len(), grid.memory_bytes());
    let rss_loaded = daemon.rss_mib();
    let base_bytes = std::fs::metadata(state.join("map-1.bin")).map_or(0, |m| m.len());

    // Updates: a 10 000-cell slab set occupied, then free, in one delta each.
    let slab: Vec<_> = (0..args.update_cells as i64)
        .map(|n| [ROOM_CELLS * 2 + 10 + n % 80, ROOM_CELLS * 2 + 10 + (n / 80) % 80, 30 + n / 6400])
        .collect();
    let blocks = VoxelBlock::from_cells(slab.iter().copied());
    let mut update_times = Vec::new();
    let mut version = version;
    for i in 0..args.updates {
        let delta = MapDelta::SetVoxelBlocks {
            resolution: RESOLUTION,
            origin: Point3::origin(),
            blocks: blocks.clone(),
            occupied: i % 2 == 0,
        };
        let t = Instant::now();
        version = client.apply(1, Some(version), &[delta], TIMEOUT)?;
        update_times.push(t.elapsed().as_secs_f64());
    }
    let journal_bytes = std::fs::metadata(state.join("map-1.log")).map_or(0, |m| m.len());
    let updates = Summary::of(&update_times).context("updates")?;
    let mut final_world = world.apply(&[MapDelta::SetVoxelBlocks {
        resolution: RESOLUTION,
        origin: Point3::origin(),
        blocks: blocks.clone(),
        occupied: args.updates % 2 == 1,
    }])?;
    if args.updates == 0 {
        final_world = world.clone();
    }

    // Queries through the daemon.
    let scenario = building.scenario(final_world.clone())?;
    let mut query_times = Vec::new();
    for seed in 1..=5u64 {
        let request = RendezvousRequest { seed, params: scenario.params, ..RendezvousRequest::new(1, scenario.belief) };
        let t = Instant::now();
        let answer = client.rendezvous(&request, TIMEOUT)?;
        query_times.push(t.elapsed().as_secs_f64());
        anyhow::ensure!(answer.map_version == version, "answered on version {}", answer.map_version);
    }
    let queries = Summary::of(&query_times).context("queries")?;

    // Restart: stop, start, until the map is served again; then its content.
    drop(client);
    daemon.stop()?;
    let restarted = Instant::now();
    let mut daemon = Daemon::start(&dyfosd, &prefix, &domain, &state, &log)?;
    let mut client = connect(&prefix, &domain)?;
    let reload = restarted.elapsed();
    let rss_reloaded = daemon.rss_mib();
    let back = client.snapshot(1, TIMEOUT)?;
    let same = back.same_content(&final_world) && back.version() == version;
    anyhow::ensure!(same, "the map after the restart differs from the one before it");
    let t = Instant::now();
    let request = RendezvousRequest { seed: 1, params: scenario.params, ..RendezvousRequest::new(1, scenario.belief) };
    client.rendezvous(&request, TIMEOUT)?;
    let first_query = t.elapsed();
    drop(client);
    daemon.stop()?;
    let _ = std::fs::remove_dir_all(&tmp);

    let mib = |b: u64| b as f64 / (1 << 20) as f64;
    let mut out = String::new();
    let _ = writeln!(
        out,
        "\n### Building of {occupied} occupied cells ({side:.0} × {side:.0} m, 0.05 m) in dyfosd\n\n\
         | step | figure |\n|---|---:|\n\
         | `.bt` written by `write_bt` (not part of the load) | {} , {:.1} MiB |\n\
         | load: read + parse the `.bt` | {} |\n\
         | load: + cells into the grid and the world | {} |\n\
         | **load: + upload to dyfosd (chunks, build, base file written and synced)** | **{}** |\n\
         | grid storage, bytes per occupied cell | {:.2} ({:.1} MiB) |\n\
         | dyfosd RSS empty → loaded (MiB) | {rss_empty:.0} → {rss_loaded:.0} ({:.2} bytes per cell) |\n\
         | base file | {:.1} MiB ({:.2} bytes per cell) |\n\
         | **{}-cell update (`SetVoxelBlocks`, journal record synced), median / p90 / max of {}** | **{} / {} / {}** |\n\
         | journal after the updates | {:.2} MiB |\n\
         | `dyfos` query through dyfosd, median / max of 5 | {} / {} |\n\
         | **restart: start → map served again (base + journal replayed)** | **{}** |\n\
         | dyfosd RSS after the restart | {rss_reloaded:.0} MiB |\n\
         | snapshot after the restart = the map before it (cells, version {version}) | {} |\n\
         | first query after the restart | {} |",
        secs(write_time),
        mib(file_bytes),
        secs(parsed),
        secs(built),
        secs(loaded),
        grid_bytes as f64 / occupied as f64,
        mib(grid_bytes as u64),
        (rss_loaded - rss_empty) * (1 << 20) as f64 / occupied as f64,
        mib(base_bytes),
        base_bytes as f64 / occupied as f64,
        args.update_cells,
        update_times.len(),
        duration(updates.median),
        duration(quantile(&update_times, 0.9)),
        duration(updates.max),
        mib(journal_bytes),
        duration(queries.median),
        duration(queries.max),
        secs(reload),
        if same { "yes" } else { "no" },
        secs(first_query),
    );
    Ok(out)
}

fn quantile(values: &[f64], p: f64) -> f64 {
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    dyfos_bench::stats::quantile_sorted(&v, p)
}

fn load_average() -> String {
    std::fs::read_to_string("/proc/loadavg")
        .map_or("?".into(), |s| s.split_whitespace().take(3).collect::<Vec<_>>().join(" "))
}
