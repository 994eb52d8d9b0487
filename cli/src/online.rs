//! `dyfos query`, `dyfos map …` and `dyfos stats`: the same work as the offline
//! commands, asked of a running `dyfosd` through the client library.

use crate::Failure;
use crate::offline::{SearchArgs, load_scenario};
use anyhow::anyhow;
use dyfos_client::prelude::*;
use dyfos_client::{MapRequestError, RendezvousError};
use dyfos_shared::map_json::{deltas_from_json, map_to_json, world_from_json_with_files};
use std::path::PathBuf;
use std::time::Duration;

/// How to reach the daemon (shared by every online command).
#[derive(Debug, Clone, clap::Args)]
pub struct DaemonArgs {
    /// Service-name prefix of the daemon (its `--prefix`).
    #[arg(long, default_value = dyfos_client::DEFAULT_PREFIX)]
    pub prefix: String,
    /// iceoryx2 domain of the daemon (its `--domain`).
    #[arg(long)]
    pub domain: Option<String>,
    /// Seconds to wait for the daemon's reply.
    #[arg(allow_hyphen_values = true, long, default_value_t = 60.0)]
    pub timeout: f64,
}

impl DaemonArgs {
    fn timeout(&self) -> Result<Duration, Failure> {
        Duration::try_from_secs_f64(self.timeout)
            .map_err(|_| Failure::invalid(anyhow!("--timeout {} is not a number of seconds", self.timeout)))
    }

    fn connect(&self) -> Result<Client, Failure> {
        let config =
            ClientConfig { prefix: self.prefix.clone(), domain: self.domain.clone(), ..ClientConfig::default() };
        Client::connect(&config).map_err(|e| Failure::from(anyhow!(e)))
    }
}

/// Flags of `dyfos query`.
#[derive(Debug, clap::Args)]
pub struct QueryArgs {
    /// Scenario file (SPEC §11 JSON): its map is uploaded, its rover queried.
    pub scenario: PathBuf,
    #[command(flatten)]
    pub search: SearchArgs,
    /// Milliseconds the daemon may search before answering with its best so far.
    #[arg(long)]
    pub deadline_ms: Option<u64>,
    /// Map id to upload to (default: derived from the map's content, so the same
    /// scenario reuses its map).
    #[arg(long)]
    pub map: Option<MapId>,
    /// Replace the map if it exists with other content.
    #[arg(long)]
    pub replace: bool,
    #[command(flatten)]
    pub daemon: DaemonArgs,
}

/// `dyfos map` subcommands.
#[derive(Debug, clap::Subcommand)]
pub enum MapCommand {
    /// Create an empty map.
    Create {
        /// Map id.
        id: MapId,
        /// Bounds: X_MIN Y_MIN X_MAX Y_MAX.
        #[arg(long, num_args = 4, allow_hyphen_values = true, required = true)]
        bounds: Vec<f64>,
        /// Sun: ELEVATION AZIMUTH (rad).
        #[arg(long, num_args = 2, allow_hyphen_values = true, required = true)]
        sun: Vec<f64>,
        #[command(flatten)]
        daemon: DaemonArgs,
    },
    /// Upload a scenario file's map (bounds, sun, obstacles, voxels or octomap), a map
    /// as `dyfos map snapshot` prints it, or an OctoMap `.bt` file as the map's
    /// occupied cells (`--octomap` with `--bounds` and `--sun`).
    Upload {
        /// Map id.
        id: MapId,
        /// Scenario file, or a map file (a snapshot: any JSON object without `rover`).
        #[arg(required_unless_present = "octomap")]
        scenario: Option<PathBuf>,
        /// An OctoMap `.bt` file (type `OcTree`) whose occupied cells are the map.
        #[arg(long, conflicts_with = "scenario", requires_all = ["bounds", "sun"])]
        octomap: Option<PathBuf>,
        /// With `--octomap`: where the minimum corner of OctoMap cell (0, 0, 0) lies in
        /// the map frame, X Y Z (default 0 0 0).
        #[arg(long, num_args = 3, allow_hyphen_values = true, requires = "octomap")]
        origin: Option<Vec<f64>>,
        /// With `--octomap`: map bounds X_MIN Y_MIN X_MAX Y_MAX.
        #[arg(long, num_args = 4, allow_hyphen_values = true, requires = "octomap")]
        bounds: Option<Vec<f64>>,
        /// With `--octomap`: sun ELEVATION AZIMUTH (rad).
        #[arg(long, num_args = 2, allow_hyphen_values = true, requires = "octomap")]
        sun: Option<Vec<f64>>,
        /// Replace an existing map.
        #[arg(long)]
        replace: bool,
        #[command(flatten)]
        daemon: DaemonArgs,
    },
    /// Apply a JSON array of map deltas atomically (docs/deltas.md), e.g.
    /// `[{"remove_obstacle": {"id": 3}}, {"set_sun": {"elevation": 0.5, "azimuth": 1.0}}]`.
    Apply {
        /// Map id.
        id: MapId,
        /// JSON file with the deltas.
        deltas: PathBuf,
        /// Fail unless the map is at this version.
        #[arg(long)]
        expected_version: Option<u64>,
        #[command(flatten)]
        daemon: DaemonArgs,
    },
    /// Print a map as JSON: `map`, `version` and a scenario's map fields
    /// (docs/deltas.md); `dyfos map upload` takes it back.
    Snapshot {
        /// Map id.
        id: MapId,
        /// Write the map's occupied voxels to this OctoMap `.bt` file instead of
        /// printing the map; prints the resolution and origin the file cannot hold.
        #[arg(long)]
        bt: Option<PathBuf>,
        #[command(flatten)]
        daemon: DaemonArgs,
    },
    /// Delete a map.
    Delete {
        /// Map id.
        id: MapId,
        /// Fail unless the map is at this version.
        #[arg(long)]
        expected_version: Option<u64>,
        #[command(flatten)]
        daemon: DaemonArgs,
    },
    /// List the daemon's maps in id order, one JSON object a line: `map`, `version`,
    /// `generation`, `bounds`, `sun`. Nothing if it holds none. Maps made or deleted
    /// while it lists may or may not be in the list.
    List {
        #[command(flatten)]
        daemon: DaemonArgs,
    },
}

/// Flags of `dyfos stats`.
#[derive(Debug, clap::Args)]
pub struct StatsArgs {
    #[command(flatten)]
    pub daemon: DaemonArgs,
}

/// A daemon error with its exit code: bad input 2, no feasible pose 3, else 1.
fn failure(status: Option<Status>, error: impl Into<anyhow::Error>) -> Failure {
    match status {
        Some(Status::NoFeasiblePose | Status::DeadlineExceeded) => Failure::infeasible(error),
        Some(
            Status::MalformedRequest
            | Status::InvalidAlgorithm
            | Status::InvalidBelief
            | Status::InvalidParams
            | Status::UnsupportedModel
            | Status::InvalidDeadline
            | Status::MalformedDelta
            | Status::InvalidDelta
            | Status::UnknownMap
            | Status::MapVersionMismatch
            | Status::MapExists
            | Status::OverCapacity,
        ) => Failure::invalid(error),
        _ => Failure::from(error.into()),
    }
}

fn map_failure(e: MapRequestError) -> Failure {
    failure(e.status(), e)
}

fn rendezvous_failure(e: RendezvousError) -> Failure {
    failure(e.status(), e)
}

/// `dyfos query`.
pub fn query(args: &QueryArgs) -> Result<(), Failure> {
    let scenario = load_scenario(&args.scenario)?;
    let timeout = args.daemon.timeout()?;
    let mut client = args.daemon.connect()?;
    let (map, version) =
        client.upload_scenario_map(&scenario.world, args.map, args.replace, timeout).map_err(map_failure)?;
    let request = RendezvousRequest {
        expected_version: Some(version),
        algorithm: args.search.algo,
        seed: args.search.seed,
        budget: args.search.budget,
        deadline: args.deadline_ms.map(Duration::from_millis),
        params: scenario.params,
        ..RendezvousRequest::new(map, scenario.belief)
    };
    let answer = client.rendezvous(&request, timeout).map_err(rendezvous_failure)?;
    crate::print_json(&answer.to_json());
    Ok(())
}

/// `dyfos map …`.
pub fn map(command: &MapCommand) -> Result<(), Failure> {
    match command {
        MapCommand::Create { id, bounds, sun, daemon } => {
            let b = Bounds::new([bounds[0], bounds[1], bounds[2], bounds[3]]).map_err(Failure::invalid)?;
            let s = Sun::new(sun[0], sun[1]).map_err(Failure::invalid)?;
            let version = daemon.connect()?.create_map(*id, b, s, daemon.timeout()?).map_err(map_failure)?;
            crate::print_json(&serde_json::json!({"map": id, "version": version}));
        }
        MapCommand::Upload { id, scenario, octomap, origin, bounds, sun, replace, daemon } => {
            let world = match (scenario, octomap) {
                (Some(file), _) => map_file_world(file)?,
                (None, Some(file)) => octomap_world(file, origin.as_deref(), bounds.as_deref(), sun.as_deref())?,
                (None, None) => return Err(Failure::invalid(anyhow!("give a scenario file or --octomap FILE.bt"))),
            };
            let version =
                daemon.connect()?.upload_map(*id, &world, *replace, daemon.timeout()?).map_err(map_failure)?;
            crate::print_json(&serde_json::json!({"map": id, "version": version}));
        }
        MapCommand::Apply { id, deltas, expected_version, daemon } => {
            let text = std::fs::read_to_string(deltas)
                .map_err(|e| Failure::invalid(anyhow!("cannot read {}: {e}", deltas.display())))?;
            let batch = deltas_from_json(&text).map_err(|e| Failure::invalid(anyhow!("{}: {e}", deltas.display())))?;
            let version =
                daemon.connect()?.apply(*id, *expected_version, &batch, daemon.timeout()?).map_err(map_failure)?;
            crate::print_json(&serde_json::json!({"map": id, "version": version}));
        }
        MapCommand::Snapshot { id, bt: Some(file), daemon } => {
            let world = daemon.connect()?.snapshot(*id, daemon.timeout()?).map_err(map_failure)?;
            let Some(voxels) = world.voxels() else {
                return Err(Failure::invalid(anyhow!("map {id} has no voxels to write as an OctoMap")));
            };
            let bytes = dyfos_shared::world::octomap::write_bt(voxels.resolution(), voxels.cells())
                .map_err(Failure::invalid)?;
            std::fs::write(file, bytes).map_err(|e| anyhow!("cannot write {}: {e}", file.display()))?;
            // A .bt holds cells by key only: the origin, and any cylinders and boxes,
            // are not in it.
            crate::print_json(&serde_json::json!({
                "map": id,
                "version": world.version(),
                "bt": file,
                "cells": voxels.len(),
                "resolution": voxels.resolution(),
                "origin": <[f64; 3]>::from(voxels.origin().coords),
                "obstacles_not_written": world.obstacles().len(),
            }));
        }
        MapCommand::Snapshot { id, bt: None, daemon } => {
            let world = daemon.connect()?.snapshot(*id, daemon.timeout()?).map_err(map_failure)?;
            crate::print_json(&map_to_json(Some(*id), &world));
        }
        MapCommand::Delete { id, expected_version, daemon } => {
            daemon.connect()?.delete_map(*id, *expected_version, daemon.timeout()?).map_err(map_failure)?;
            crate::print_json(&serde_json::json!({"map": id, "deleted": true}));
        }
        MapCommand::List { daemon } => {
            let maps = daemon.connect()?.list_maps(daemon.timeout()?).map_err(map_failure)?;
            for map in maps {
                println!("{}", map.to_json());
            }
        }
    }
    Ok(())
}

/// The world of `dyfos map upload ID FILE`: a scenario's map if the file has a
/// `rover`, else a map as `dyfos map snapshot` prints it (its `map` and `version`
/// are not used: the daemon numbers its own versions). Every problem is exit code 2.
fn map_file_world(file: &std::path::Path) -> Result<World, Failure> {
    let text =
        std::fs::read_to_string(file).map_err(|e| Failure::invalid(anyhow!("cannot read {}: {e}", file.display())))?;
    // An `octomap.file` is relative to the scenario's folder (SPEC §11).
    let folder = file.parent().unwrap_or(std::path::Path::new("."));
    let read = |name: &str| std::fs::read(folder.join(name)).map_err(|e| format!("cannot read `{name}`: {e}"));
    world_from_json_with_files(&text, read).map_err(|e| Failure::invalid(anyhow!("{}: {e}", file.display())))
}

/// The world of `dyfos map upload --octomap`: the file's occupied cells as voxels
/// (SPEC §1), no obstacles. Every problem is exit code 2.
fn octomap_world(
    file: &std::path::Path,
    origin: Option<&[f64]>,
    bounds: Option<&[f64]>,
    sun: Option<&[f64]>,
) -> Result<World, Failure> {
    let (Some(&[x0, y0, x1, y1]), Some(&[elevation, azimuth])) = (bounds, sun) else {
        return Err(Failure::invalid(anyhow!("--octomap needs --bounds X_MIN Y_MIN X_MAX Y_MAX and --sun EL AZ")));
    };
    let origin = match origin {
        Some(&[x, y, z]) => Point3::new(x, y, z),
        _ => Point3::origin(),
    };
    let bytes = std::fs::read(file).map_err(|e| Failure::invalid(anyhow!("cannot read {}: {e}", file.display())))?;
    let bounds = Bounds::new([x0, y0, x1, y1]).map_err(|e| Failure::invalid(anyhow!("--bounds: {e}")))?;
    let sun = Sun::new(elevation, azimuth).map_err(|e| Failure::invalid(anyhow!("--sun: {e}")))?;
    dyfos_shared::world::octomap::world_from_bt(&bytes, origin, bounds, sun)
        .map_err(|e| Failure::invalid(anyhow!("{}: {e}", file.display())))
}

/// `dyfos stats`.
pub fn stats(args: &StatsArgs) -> Result<(), Failure> {
    let stats = args.daemon.connect()?.stats(args.daemon.timeout()?).map_err(|e| Failure::from(anyhow!(e)))?;
    crate::print_json(&stats.to_json());
    Ok(())
}
