//! `dyfos replay FILE.mcap`: re-runs every query a recording daemon answered
//! (`dyfosd --record`) against this build and says, per query, whether the answer
//! is bit-identical. See `docs/record.md`.

use crate::Failure;
use anyhow::{Context, anyhow};
use dyfos_service::daemon::answer_query;
use dyfos_service::daemon::record::{MapChange, MapState, RecordedReply, RecordedRequest, topics};
use dyfos_service::search::SearchControl;
use dyfos_shared::wire::map::MapId;
use dyfos_shared::world::World;
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Flags of `dyfos replay`.
///
/// Exit codes: 0 every query identical and every file complete; 1 an answer
/// differs (or another failure); 2 a file is not a readable recording or a flag is
/// invalid; 4 no answer differs but a recording is incomplete: truncated (a killed
/// daemon), records dropped by the recorder, or queries whose map could not be
/// rebuilt. Queries that stopped at their deadline cannot be reproduced; they are
/// reported and do not change the exit code.
#[derive(Debug, clap::Args)]
#[command(after_help = "Exit codes: 0 all answers identical and every recording complete; 1 some answer differs; \
2 unreadable file or bad flag; 4 nothing differs but a recording is incomplete (truncated, records dropped, \
or maps that could not be rebuilt). A truncated file is replayed up to its last complete message.")]
pub struct ReplayArgs {
    /// Recordings written by `dyfosd --record`; each replays on its own.
    #[arg(required = true, value_name = "FILE.mcap")]
    pub files: Vec<PathBuf>,
    /// Overrides a SPEC §11 parameter for every query, NAME=VALUE (repeatable), e.g.
    /// `--set rho_max=5`: what the answers would have been with it.
    #[arg(long = "set", value_name = "NAME=VALUE")]
    pub set: Vec<String>,
    /// Model file of the learned SDSMM, for queries with model `learned` (default:
    /// the file the recording daemon loaded, if it is still there).
    #[arg(long, value_name = "FILE")]
    pub model: Option<PathBuf>,
    /// Worker threads for `brute` (default: all cores; the answer does not change).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Print only the queries that differ and the summary.
    #[arg(long, short)]
    pub quiet: bool,
}

/// The `--set` overrides as a JSON object (values parsed as JSON, else strings).
fn overrides(set: &[String]) -> Result<serde_json::Map<String, serde_json::Value>, Failure> {
    let mut out = serde_json::Map::new();
    for item in set {
        let (name, value) = item
            .split_once('=')
            .ok_or_else(|| Failure::invalid(anyhow!("--set {item}: write NAME=VALUE, e.g. --set rho_max=5")))?;
        let value = serde_json::from_str(value).unwrap_or_else(|_| serde_json::Value::String(value.to_string()));
        out.insert(name.trim().to_string(), value);
    }
    // Check the names and values once, against the SPEC defaults.
    let probe = serde_json::Value::Object(out.clone());
    dyfos_shared::scenario::params_from_json(&probe.to_string())
        .map_err(|e| Failure::invalid(anyhow!("--set: {e}")))?;
    Ok(out)
}

/// Counts of one file's replay.
#[derive(Debug, Default)]
struct Tally {
    messages: u64,
    identical: u64,
    different: u64,
    /// Stopped at their deadline: not reproducible.
    deadline: u64,
    /// Their map (version) could not be rebuilt, or their request not.
    unreplayable: u64,
    checks: u64,
    map_changes: u64,
    map_requests: u64,
    dropped: u64,
    truncated: bool,
    broken_changes: u64,
}

/// Replays every file; the exit code as documented on [`ReplayArgs`].
pub fn replay(args: &ReplayArgs) -> Result<(), Failure> {
    let set = overrides(&args.set)?;
    let threads = args.threads.unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
    let mut different = 0;
    let mut incomplete = false;
    for file in &args.files {
        let t = replay_file(file, &set, args, threads)?;
        different += t.different;
        incomplete |= t.truncated || t.dropped > 0 || t.unreplayable > 0 || t.broken_changes > 0;
    }
    if different > 0 {
        return Err(Failure { code: 1, error: anyhow!("{different} answer(s) differ from the recording") });
    }
    if incomplete {
        return Err(Failure {
            code: 4,
            error: anyhow!("no answer differs, but the recording is incomplete (see above)"),
        });
    }
    Ok(())
}

fn replay_file(
    path: &Path,
    set: &serde_json::Map<String, serde_json::Value>,
    args: &ReplayArgs,
    threads: usize,
) -> Result<Tally, Failure> {
    let bytes = std::fs::read(path)
        .with_context(|| format!("cannot read recording {}", path.display()))
        .map_err(Failure::invalid)?;
    let stream = mcap::MessageStream::new_with_options(&bytes, mcap::read::Options::IgnoreEndMagic.into())
        .map_err(|e| Failure::invalid(anyhow!("{} is not an MCAP file: {e}", path.display())))?;
    let name = path.display().to_string();
    let mut t = Tally::default();
    // Every map at every version seen: queries answered by workers are recorded
    // after later changes may have been.
    let mut worlds: HashMap<(MapId, u64), Arc<World>> = HashMap::new();
    let mut learned = match &args.model {
        Some(m) => Some(dyfos_service::learned::load_model(m).map_err(Failure::invalid)?),
        None => None,
    };
    let mut ended_cleanly = true;
    for message in stream {
        let message = match message {
            Ok(m) => m,
            Err(e) => {
                println!("{name}: truncated after {} messages ({e}); replaying what was read", t.messages);
                ended_cleanly = false;
                break;
            }
        };
        t.messages += 1;
        let json: serde_json::Value = match serde_json::from_slice(&message.data) {
            Ok(j) => j,
            Err(e) => {
                println!("{name}: message {} on {} is not JSON ({e}); skipped", t.messages, message.channel.topic);
                t.unreplayable += 1;
                continue;
            }
        };
        match message.channel.topic.as_str() {
            topics::CONFIG => {
                let model = json["config"]["model"].as_str().map(PathBuf::from);
                if learned.is_none()
                    && let Some(m) = model.filter(|m| m.exists())
                {
                    learned = dyfos_service::learned::load_model(&m).ok();
                }
                if !args.quiet {
                    println!(
                        "{name}: recorded by dyfosd {} (pid {}, file {} of its run); replayed by dyfos {}",
                        json["build"]["version"].as_str().unwrap_or("?"),
                        json["pid"],
                        json["file_index"],
                        env!("CARGO_PKG_VERSION")
                    );
                }
                t.dropped = t.dropped.max(json["dropped_before"].as_u64().unwrap_or(0));
            }
            topics::MAP_STATE => match serde_json::from_value::<MapState>(json).map_err(|e| e.to_string()) {
                Ok(state) => match state.rebuild() {
                    Ok(w) => {
                        worlds.insert((state.map, state.version), Arc::new(w));
                    }
                    Err(e) => {
                        println!("{name}: map {} at version {} cannot be rebuilt: {e}", state.map, state.version);
                        t.broken_changes += 1;
                    }
                },
                Err(e) => {
                    println!("{name}: unreadable map state: {e}");
                    t.broken_changes += 1;
                }
            },
            topics::MAP_CHANGE => {
                t.map_changes += 1;
                if let Err(e) = apply_change(json, &mut worlds) {
                    println!("{name}: {e}");
                    t.broken_changes += 1;
                }
            }
            topics::MAP => t.map_requests += 1,
            topics::RECORDER => {
                t.dropped = t.dropped.max(json["dropped_total"].as_u64().unwrap_or(0));
            }
            topics::RENDEZVOUS => {
                replay_query(&name, &json, &worlds, set, learned.as_ref(), threads, args.quiet, &mut t)
            }
            other => {
                if !args.quiet {
                    println!("{name}: channel {other} is not dyfosd's; skipped");
                }
            }
        }
    }
    let complete = ended_cleanly && bytes.ends_with(mcap::MAGIC);
    if ended_cleanly && !complete {
        println!(
            "{name}: truncated after {} messages (no end of file: the daemon was killed); replayed them",
            t.messages
        );
    }
    t.truncated = !complete;
    let queries = t.identical + t.different + t.deadline + t.unreplayable;
    println!(
        "{name}: {queries} queries replayed: {} identical, {} different, {} stopped at their deadline (not reproducible), {} not replayable; {} checks, {} map changes, {} map requests; {}{}",
        t.identical,
        t.different,
        t.deadline,
        t.unreplayable,
        t.checks,
        t.map_changes,
        t.map_requests,
        if complete {
            "recording complete".to_string()
        } else {
            format!("recording truncated after {} messages", t.messages)
        },
        if t.dropped > 0 || t.broken_changes > 0 {
            format!(
                "; INCOMPLETE: {} records dropped by the recorder, {} map changes not rebuilt",
                t.dropped, t.broken_changes
            )
        } else {
            String::new()
        }
    );
    Ok(t)
}

/// Rebuilds the map version a change produced.
fn apply_change(json: serde_json::Value, worlds: &mut HashMap<(MapId, u64), Arc<World>>) -> Result<(), String> {
    let change: MapChange = serde_json::from_value(json).map_err(|e| format!("unreadable map change: {e}"))?;
    let map = change.map;
    if let Some(state) = &change.state {
        let w = state.rebuild().map_err(|e| format!("map {map} version {}: {e}", change.version))?;
        worlds.insert((map, change.version), Arc::new(w));
        return Ok(());
    }
    let Some(from) = change.from_version else {
        // A deletion: the versions stay, queries in flight may need them.
        return Ok(());
    };
    let base = worlds.get(&(map, from)).ok_or_else(|| {
        format!(
            "map {map} version {} cannot be rebuilt: version {from} is not in the recording (records dropped?)",
            change.version
        )
    })?;
    let next = base.apply(&change.deltas).map_err(|e| format!("map {map}: the recorded deltas fail now: {e}"))?;
    if next.version() != change.version {
        return Err(format!("map {map}: the deltas made version {}, the daemon's {}", next.version(), change.version));
    }
    worlds.insert((map, change.version), Arc::new(next));
    Ok(())
}

/// The request and reply of a `/dyfosd/rendezvous` message.
fn parse_exchange(json: &serde_json::Value) -> Result<(RecordedRequest, RecordedReply), String> {
    let request = serde_json::from_value(json["request"].clone()).map_err(|e| e.to_string())?;
    let reply = serde_json::from_value(json["reply"].clone()).map_err(|e| e.to_string())?;
    Ok((request, reply))
}

fn short(r: &RecordedReply) -> String {
    if r.status == "ok" {
        format!("ok x = {:?}, E = {:?}, evaluations {:?}, stop {}", r.x, r.cost, r.evaluations, r.stop)
    } else {
        format!("{}: {}", r.status, r.message)
    }
}

#[allow(clippy::too_many_arguments)]
fn replay_query(
    name: &str,
    json: &serde_json::Value,
    worlds: &HashMap<(MapId, u64), Arc<World>>,
    set: &serde_json::Map<String, serde_json::Value>,
    learned: Option<&Arc<dyfos_shared::sdsmm::Learned>>,
    threads: usize,
    quiet: bool,
    t: &mut Tally,
) {
    let parsed = parse_exchange(json);
    let request_id = json["request_id"].as_u64().unwrap_or(0);
    let (recorded_request, recorded) = match parsed {
        Ok(p) => p,
        Err(e) => {
            println!("{name}: request {request_id}: unreadable ({e}); not replayed");
            t.unreplayable += 1;
            return;
        }
    };
    let label = format!(
        "request {request_id} (map {} v{}, {}, seed {})",
        recorded_request.map, recorded.map_version, recorded_request.algorithm, recorded_request.seed
    );
    let mut params = recorded_request.params.clone();
    if let Some(p) = params.as_object_mut() {
        p.extend(set.iter().map(|(k, v)| (k.clone(), v.clone())));
    }
    let request = match recorded_request.rebuild_with(&params) {
        Ok(r) => r,
        Err(e) => {
            println!("{name}: {label}: {e}; not replayed");
            t.unreplayable += 1;
            return;
        }
    };
    if json["mode"] == "check" {
        t.checks += 1;
        let base = recorded.map_version.checked_sub(request.deltas.len() as u64);
        let checked = base
            .and_then(|b| worlds.get(&(request.map, b)))
            .map(|w| w.apply(&request.deltas).map(|n| n.version()).map_err(|e| e.to_string()));
        match checked {
            Some(Ok(v)) if v == recorded.map_version => {}
            Some(Ok(v)) => {
                println!("{name}: {label} (check): DIFFERENT: version {v} now, {} recorded", recorded.map_version);
                t.different += 1;
            }
            Some(Err(e)) => {
                println!("{name}: {label} (check): DIFFERENT: the deltas fail now ({e})");
                t.different += 1;
            }
            None => {
                println!("{name}: {label} (check): its map version is not in the recording; not replayed");
                t.unreplayable += 1;
            }
        }
        return;
    }
    if recorded.stop == "deadline" || recorded.status == "deadline_exceeded" {
        if !quiet {
            println!("{name}: {label}: stopped at its deadline when recorded; not reproducible, not compared");
        }
        t.deadline += 1;
        return;
    }
    if request.params.model == dyfos_shared::params::ModelKind::Learned && learned.is_none() {
        println!("{name}: {label}: uses the learned model; give its file with --model to replay it");
        t.unreplayable += 1;
        return;
    }
    let Some(world) = worlds.get(&(request.map, recorded.map_version)) else {
        println!(
            "{name}: {label}: map {} at version {} is not in the recording; not replayed",
            request.map, recorded.map_version
        );
        t.unreplayable += 1;
        return;
    };
    // The recorded deadline only ever stopped the search early, and this one did
    // not stop at it: replay without one.
    let control = SearchControl { budget: request.budget, threads, ..SearchControl::seeded(request.seed) };
    let Some(reply) = answer_query(world, &request, request_id, learned, &control) else {
        println!("{name}: {label}: the search was abandoned; not replayed");
        t.unreplayable += 1;
        return;
    };
    let replayed = RecordedReply::of(&reply);
    if recorded.identical(&replayed) {
        t.identical += 1;
        if !quiet {
            println!("{name}: {label}: identical");
        }
        return;
    }
    t.different += 1;
    println!("{name}: {label}: DIFFERENT");
    println!("  recorded: {}", short(&recorded));
    println!("  replayed: {}", short(&replayed));
    if recorded.status == "ok" && replayed.status == "ok" {
        println!("  ΔE = replayed − recorded = {:?}", replayed.cost - recorded.cost);
    }
}
