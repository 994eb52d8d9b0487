//! `dyfosd --record` and `dyfos replay`: a recording daemon serves a
//! soak-like mix from several clients (queries of every algorithm and mode, map
//! uploads, deltas and inline deltas between them); the file is read back with the
//! MCAP crate's reader (channels, schemas, message counts = what the clients got),
//! replayed (every answer identical, exit 0), replayed with a changed parameter
//! (differences, exit 1), cut at several offsets (read up to the cut), and a
//! recording daemon with a small size limit is killed with SIGKILL (its rotated
//! files replay on their own, the current one up to its last complete message).

use dyfos_client::prelude::*;
use dyfos_service::daemon::record::topics;
use dyfos_tests::soak::{WRITER_MAP, maps, plan, writer_batch};
use dyfos_tests::{PATIENCE, Sandbox, Scratch, bin, wait_for};
use std::collections::BTreeMap;
use std::path::Path;
use std::process::{Command, Output};
use std::sync::{Arc, Mutex};

const TIMEOUT: std::time::Duration = PATIENCE;

/// What the clients got back, by what the recording should hold.
#[derive(Debug, Default)]
struct Sent {
    /// Accepted queries (answers, checks, worker-side refusals).
    queries: u64,
    /// Accepted map requests (create, apply, upload chunks, snapshot pages, delete,
    /// list steps).
    map_requests: u64,
    /// Map changes (create, apply, upload, inline deltas, delete).
    map_changes: u64,
}

/// Every message of a complete recording, by topic, read with the MCAP reader;
/// checks the channels' schemas and encodings.
fn read_complete(path: &Path) -> BTreeMap<String, Vec<serde_json::Value>> {
    let bytes = std::fs::read(path).expect("the recording");
    let summary = mcap::Summary::read(&bytes).expect("a summary").expect("a finished file has a summary");
    let topics_seen: Vec<&str> = summary.channels.values().map(|c| c.topic.as_str()).collect();
    for topic in topics::ALL {
        assert!(topics_seen.contains(&topic), "channel {topic} missing: {topics_seen:?}");
    }
    let mut schemas: BTreeMap<String, serde_json::Value> = BTreeMap::new();
    for channel in summary.channels.values() {
        assert_eq!(channel.message_encoding, "json");
        let schema = channel.schema.as_ref().expect("every channel has a schema");
        assert_eq!(schema.name, topics::schema_name(&channel.topic));
        assert_eq!(schema.encoding, "jsonschema");
        let parsed: serde_json::Value = serde_json::from_slice(&schema.data).expect("the schema is JSON");
        assert_eq!(parsed["title"], schema.name.as_str());
        schemas.insert(channel.topic.clone(), parsed);
    }
    let mut out: BTreeMap<String, Vec<serde_json::Value>> = BTreeMap::new();
    for m in mcap::MessageStream::new(&bytes).expect("an MCAP file") {
        let m = m.expect("every message reads back");
        let json: serde_json::Value = serde_json::from_slice(&m.data).expect("every message is JSON");
        // Every field written is one its schema declares.
        let declared = &schemas[&m.channel.topic]["properties"];
        for field in json.as_object().expect("every message is an object").keys() {
            assert!(declared.get(field).is_some(), "{}: `{field}` is not in the schema {declared}", m.channel.topic);
        }
        out.entry(m.channel.topic.clone()).or_default().push(json);
    }
    let stats = summary.stats.expect("statistics");
    assert_eq!(stats.message_count, out.values().map(|v| v.len() as u64).sum::<u64>());
    out
}

/// Messages readable from a (maybe cut) recording, up to the first incomplete one.
fn readable(bytes: &[u8]) -> usize {
    let Ok(stream) = mcap::MessageStream::new_with_options(bytes, mcap::read::Options::IgnoreEndMagic.into()) else {
        return 0;
    };
    stream.take_while(Result::is_ok).count()
}

fn replay(args: &[&str]) -> Output {
    Command::new(bin("dyfos")).arg("replay").args(args).output().expect("run dyfos replay")
}

fn text(o: &Output) -> String {
    format!("{}{}", String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr))
}

/// [`drive`] against a daemon with two workers recording to `file`, stopped cleanly
/// after it.
fn record(sandbox: &Sandbox, file: &Path, per_client: u64) -> Sent {
    let mut daemon = sandbox.start_daemon_logging("info", &["--workers", "2", "--record", file.to_str().unwrap()]);
    let sent = drive(sandbox, per_client);
    assert!(daemon.terminate().success(), "{}", daemon.log());
    sent
}

/// The mix: three query clients on three maps (two uploaded, one created and
/// changed by a writer between the queries, also inline).
fn drive(sandbox: &Sandbox, per_client: u64) -> Sent {
    let maps = maps();
    let sent = Arc::new(Mutex::new(Sent::default()));
    let mut admin = sandbox.client();
    let writer = &maps[0];
    admin.create_map(WRITER_MAP, *writer.world.bounds(), *writer.world.sun(), TIMEOUT).expect("create");
    let mut chunks = 0;
    for m in &maps[1..] {
        admin.upload_map(m.id, &m.world, false, TIMEOUT).expect("upload");
        chunks += dyfos_shared::wire::map::world_chunks(&m.world).len() as u64;
    }
    {
        let mut s = sent.lock().unwrap();
        s.map_requests += 1 + chunks;
        s.map_changes += 3;
    }
    let version = Arc::new(Mutex::new(0u64));
    std::thread::scope(|scope| {
        for client in 0..3u32 {
            let (sent, maps, version) = (Arc::clone(&sent), &maps, Arc::clone(&version));
            scope.spawn(move || {
                let mut c = sandbox.client();
                for n in 0..per_client {
                    let seen = Some(*version.lock().unwrap());
                    let planned = plan(client, n, maps, seen);
                    let accepted = if planned.sent.check {
                        c.check(&planned.request, TIMEOUT).is_ok()
                    } else {
                        match c.rendezvous(&planned.request, TIMEOUT) {
                            Ok(_) => true,
                            Err(RendezvousError::Rejected(r)) => {
                                matches!(r.status, Status::NoFeasiblePose | Status::DeadlineExceeded)
                            }
                            Err(e) => panic!("query failed: {e}"),
                        }
                    };
                    sent.lock().unwrap().queries += u64::from(accepted);
                }
            });
        }
        // The writer: deltas by map request, and every third batch inline with a
        // query of the writer's map.
        scope.spawn(|| {
            let mut c = sandbox.client();
            let mut world = writer.world.clone();
            for k in 0..per_client {
                let (batch, valid, _) = writer_batch(7, k, &world);
                let mut s = sent.lock().unwrap();
                if k % 3 == 2 {
                    let request = RendezvousRequest {
                        deltas: batch.clone(),
                        algorithm: Algorithm::Center,
                        seed: k,
                        ..RendezvousRequest::new(WRITER_MAP, writer.belief)
                    };
                    drop(s);
                    let result = c.rendezvous(&request, TIMEOUT);
                    s = sent.lock().unwrap();
                    match result {
                        Ok(_) => {}
                        Err(RendezvousError::Rejected(r)) if r.status == Status::NoFeasiblePose => {}
                        Err(RendezvousError::Rejected(r)) => {
                            assert!(!valid, "a valid inline batch was refused: {r:?}");
                            continue;
                        }
                        Err(e) => panic!("inline query failed: {e}"),
                    }
                    s.queries += 1;
                } else {
                    match c.apply(WRITER_MAP, None, &batch, TIMEOUT) {
                        Ok(_) => s.map_requests += 1,
                        Err(e) => {
                            assert!(!valid, "a valid batch was refused: {e}");
                            continue;
                        }
                    }
                }
                assert!(valid, "an invalid batch was accepted");
                s.map_changes += 1;
                world = world.apply(&batch).expect("the batch applies offline too");
                *version.lock().unwrap() = world.version();
            }
        });
    });
    // A snapshot (one page), a deletion and a listing (one step per map, and the last).
    admin.snapshot(3, TIMEOUT).expect("snapshot");
    admin.delete_map(2, None, TIMEOUT).expect("delete");
    let listed = admin.list_maps(TIMEOUT).expect("list").len() as u64;
    assert_eq!(listed, maps.len() as u64 - 1);
    let mut s = sent.lock().unwrap();
    s.map_requests += 2 + listed + 1;
    s.map_changes += 1;
    std::mem::take(&mut *s)
}

#[test]
fn a_recorded_run_replays_identically_and_a_changed_parameter_shows() {
    let sandbox = Sandbox::new("record");
    let dir = Scratch::new("record-replay");
    let file = dir.0.join("traffic.mcap");
    let sent = record(&sandbox, &file, 10);

    let messages = read_complete(&file);
    let count = |t: &str| messages.get(t).map_or(0, Vec::len) as u64;
    assert_eq!(count(topics::CONFIG), 1);
    assert_eq!(count(topics::MAP_STATE), 0, "the daemon started without maps");
    assert_eq!(count(topics::RENDEZVOUS), sent.queries, "every accepted query is recorded");
    assert_eq!(count(topics::MAP), sent.map_requests, "every accepted map request is recorded");
    assert_eq!(count(topics::MAP_CHANGE), sent.map_changes, "every map change is recorded");
    assert_eq!(count(topics::RECORDER), 0, "nothing was dropped");
    let config = &messages[topics::CONFIG][0];
    assert_eq!(config["config"]["prefix"], sandbox.prefix.as_str());
    // Every key of the daemon's configuration, and no other: it reads back as one and
    // writes out the same; `workers` as started.
    let head: dyfos_service::daemon::DaemonConfig =
        serde_json::from_value(config["config"].clone()).expect("the head is a configuration");
    assert_eq!(head.to_json(head.workers), config["config"]);
    assert_eq!((head.workers, head.recording.path.as_deref()), (2, Some(file.as_path())));
    assert_eq!(config["build"]["version"], env!("CARGO_PKG_VERSION"));
    let causes: Vec<&str> = messages[topics::MAP_CHANGE].iter().map(|m| m["cause"].as_str().unwrap_or("?")).collect();
    for cause in ["create", "upload", "apply", "inline", "delete"] {
        assert!(causes.contains(&cause), "no `{cause}` change in {causes:?}");
    }
    // The listing's steps: from 0, then past each map described, the last describing none.
    let steps: Vec<(u64, u64, u64)> = messages[topics::MAP]
        .iter()
        .filter(|m| m["kind"] == "list")
        .map(|m| {
            (
                m["map"].as_u64().unwrap(),
                m["reply"]["map"].as_u64().unwrap(),
                m["reply"]["chunk_count"].as_u64().unwrap(),
            )
        })
        .collect();
    assert_eq!(steps.len(), 3, "{steps:?}");
    assert_eq!((steps[0].0, steps[0].2, steps[2].2), (0, 2, 0), "{steps:?}");
    assert_eq!((steps[1].0, steps[1].2), (steps[0].1 + 1, 1), "{steps:?}");
    let modes: Vec<&str> = messages[topics::RENDEZVOUS].iter().map(|m| m["mode"].as_str().unwrap_or("?")).collect();
    assert!(modes.contains(&"check") && modes.contains(&"solve"), "{modes:?}");

    let path = file.to_str().unwrap();
    let same = replay(&[path]);
    let out = text(&same);
    assert_eq!(same.status.code(), Some(0), "{out}");
    assert!(out.contains(" 0 different") && out.contains("recording complete"), "{out}");
    assert!(!out.contains("DIFFERENT"), "{out}");

    // A parameter changed for every query: the answers move, and replay says so.
    let changed = replay(&[path, "--set", "rho_max=4.5", "--quiet"]);
    let out = text(&changed);
    assert_eq!(changed.status.code(), Some(1), "{out}");
    assert!(out.contains("DIFFERENT") && out.contains("ΔE = "), "{out}");
    assert!(replay(&[path, "--set", "rho_mxa=4"]).status.code() == Some(2), "a bad name is invalid input");

    // Cut copies read up to the cut; replay replays what is there and says it is cut.
    let bytes = std::fs::read(&file).unwrap();
    let total = readable(&bytes);
    assert_eq!(total as u64, messages.values().map(|v| v.len() as u64).sum::<u64>());
    let mut last = 0;
    for fraction in [0.3, 0.6, 0.85] {
        let cut = (bytes.len() as f64 * fraction) as usize;
        let got = readable(&bytes[..cut]);
        assert!(got > last && got < total, "cut at {cut} of {}: {got} of {total} messages", bytes.len());
        last = got;
        let copy = dir.0.join(format!("cut-{cut}.mcap"));
        std::fs::write(&copy, &bytes[..cut]).unwrap();
        let o = replay(&[copy.to_str().unwrap(), "--quiet"]);
        let out = text(&o);
        assert_eq!(o.status.code(), Some(4), "{out}");
        assert!(out.contains(&format!("truncated after {got} messages")) && out.contains(" 0 different"), "{out}");
    }
}

#[test]
fn a_killed_recording_daemon_leaves_readable_rotated_files() {
    let sandbox = Sandbox::new("record-kill");
    let dir = Scratch::new("record-kill");
    let file = dir.0.join("field.mcap");
    // Two workers: the recording's order is still the order the client saw its
    // answers in (a query is recorded before its reply is sent), so the last one on
    // disk means every earlier one is too.
    let args = [
        "--workers",
        "2",
        "--record",
        file.to_str().unwrap(),
        "--set",
        "recording.max_bytes=6000",
        "--set",
        "recording.keep=2",
    ];
    let mut daemon = sandbox.start_daemon_logging("info", &args);
    let maps = maps();
    let mut c = sandbox.client();
    c.upload_map(2, &maps[1].world, false, TIMEOUT).expect("upload");
    let mut answered = 0;
    for seed in 0..12 {
        let request = RendezvousRequest {
            algorithm: if seed % 2 == 0 { Algorithm::Center } else { Algorithm::Random },
            seed,
            ..RendezvousRequest::new(2, maps[1].belief)
        };
        answered += u64::from(c.rendezvous(&request, TIMEOUT).is_ok());
    }
    assert!(answered > 0);
    let rotated = |i: usize| dir.0.join(format!("field.{i}.mcap"));
    // The writer flushes after each batch: wait until the last query is on disk.
    wait_for("the recording to hold the last query", || {
        let last_written =
            [file.clone(), rotated(1)].iter().any(|f| std::fs::read(f).is_ok_and(|b| seeds_in(&b).contains(&11)));
        (last_written && rotated(2).exists()).then_some(())
    });
    daemon.kill9();
    assert!(!rotated(3).exists(), "recording.keep = 2 keeps two rotated files");
    // Killed between the two renames of a rotation, the next file has not taken its
    // name yet; a current file always has its head (it takes its name with it).
    let current_bytes = std::fs::read(&file).ok();
    let current = match &current_bytes {
        Some(bytes) => file_index(bytes),
        None => file_index(&std::fs::read(rotated(1)).unwrap()) + 1,
    };
    for i in [1, 2] {
        let path = rotated(i);
        let messages = read_complete(&path);
        assert_eq!(messages[topics::MAP_STATE].len(), 1, "every file starts with the maps' state");
        assert_eq!(messages[topics::CONFIG][0]["file_index"].as_u64(), Some((current - i) as u64));
        // Which messages a file holds depends on how the writer's batches fell (the
        // upload's, queries'); that it holds one does not.
        let body: usize = messages
            .iter()
            .filter(|(t, _)| ![topics::CONFIG, topics::MAP_STATE].contains(&t.as_str()))
            .map(|(_, m)| m.len())
            .sum();
        assert!(body > 0, "a file is rotated only once it holds a message");
        let o = replay(&[path.to_str().unwrap()]);
        let out = text(&o);
        assert_eq!(o.status.code(), Some(0), "{out}");
        assert!(out.contains(" 0 different"), "{out}");
    }
    // The current file lost only what was not written; it replays up to there.
    let Some(bytes) = current_bytes else { return };
    assert!(!bytes.ends_with(mcap::MAGIC), "a killed daemon cannot have finished its file");
    assert!(readable(&bytes) >= 2, "config and map state at least");
    let o = replay(&[file.to_str().unwrap()]);
    let out = text(&o);
    assert_eq!(o.status.code(), Some(4), "{out}");
    assert!(out.contains("truncated after") && out.contains(" 0 different"), "{out}");
}

#[test]
fn a_failing_recording_stops_with_one_log_line_and_the_daemon_serves_on() {
    // /dev/full takes the file's creation and fails every write (ENOSPC): a full disk.
    if !Path::new("/dev/full").exists() {
        eprintln!("no /dev/full on this system; skipped");
        return;
    }
    let sandbox = Sandbox::new("record-full");
    let mut daemon = sandbox.start_daemon_logging("info", &["--workers", "2", "--record", "/dev/full"]);
    let maps = maps();
    let mut c = sandbox.client();
    c.upload_map(2, &maps[1].world, false, TIMEOUT).expect("upload");
    for seed in 0..3 {
        let request =
            RendezvousRequest { algorithm: Algorithm::Center, seed, ..RendezvousRequest::new(2, maps[1].belief) };
        c.rendezvous(&request, TIMEOUT).expect("the daemon answers while its recording fails");
    }
    let log = wait_for("the recording to stop", || {
        let log = daemon.log();
        log.contains("recording stopped").then_some(log)
    });
    assert_eq!(log.matches("recording stopped").count(), 1, "{log}");
    assert!(log.contains("No space left on device"), "{log}");
    assert!(daemon.terminate().success(), "{}", daemon.log());
    assert!(Path::new("/dev/full").exists(), "the device is never rotated away");
}

/// The seeds of the queries readable in a (maybe unfinished) recording.
fn seeds_in(bytes: &[u8]) -> Vec<u64> {
    let Ok(stream) = mcap::MessageStream::new_with_options(bytes, mcap::read::Options::IgnoreEndMagic.into()) else {
        return Vec::new();
    };
    stream
        .map_while(Result::ok)
        .filter(|m| m.channel.topic == topics::RENDEZVOUS)
        .filter_map(|m| serde_json::from_slice::<serde_json::Value>(&m.data).ok()?["request"]["seed"].as_u64())
        .collect()
}

/// The `file_index` of a recording's head.
fn file_index(bytes: &[u8]) -> usize {
    let stream = mcap::MessageStream::new_with_options(bytes, mcap::read::Options::IgnoreEndMagic.into()).unwrap();
    let head = stream.map_while(Result::ok).find(|m| m.channel.topic == topics::CONFIG).expect("a head");
    let json: serde_json::Value = serde_json::from_slice(&head.data).unwrap();
    json["file_index"].as_u64().unwrap() as usize
}

/// A delta in the spelling recordings held before `docs/deltas.md` (serde's derived
/// form of the Rust type), written from the current one: what an old file holds.
fn old_spelling(delta: &serde_json::Value) -> serde_json::Value {
    use serde_json::json;
    let (kind, v) = delta.as_object().and_then(|o| o.iter().next()).expect("a delta is a one-key object");
    let run = |items: &str| {
        let occupied = v.get("occupied").is_some();
        let list = if occupied { &v["occupied"] } else { &v["free"] };
        json!({"resolution": v["resolution"], "origin": v["origin"], items: list, "occupied": occupied})
    };
    match kind.as_str() {
        "upsert_obstacle" => {
            let obstacle = match (v.get("cylinder"), v.get("box")) {
                (Some(c), _) => {
                    json!({"Cylinder": {"center": [c["x"], c["y"]], "radius": c["radius"], "height": c["height"]}})
                }
                (_, Some(b)) => json!({"Box": {"min": b["min"], "max": b["max"]}}),
                _ => panic!("{delta}"),
            };
            json!({"UpsertObstacle": {"id": v["id"], "obstacle": obstacle}})
        }
        "remove_obstacle" => json!({"RemoveObstacle": {"id": v["id"]}}),
        "set_voxels" => json!({"SetVoxels": run("cells")}),
        "set_voxel_blocks" => json!({"SetVoxelBlocks": run("blocks")}),
        "set_sun" => json!({"SetSun": v}),
        "set_bounds" => json!({"SetBounds": {"min": [v[0], v[1]], "max": [v[2], v[3]]}}),
        "clear" => json!("Clear"),
        other => panic!("unknown kind {other}"),
    }
}

/// Copies a finished recording with every delta in the old spelling; returns how
/// many deltas it rewrote.
fn rewrite_in_old_spelling(from: &Path, to: &Path) -> usize {
    let bytes = std::fs::read(from).unwrap();
    let file = std::io::BufWriter::new(std::fs::File::create(to).unwrap());
    let mut out = mcap::WriteOptions::new().compression(None).create(file).unwrap();
    let mut channels: BTreeMap<String, u16> = BTreeMap::new();
    let mut rewritten = 0;
    // The delta arrays of a message, where it has them.
    let mut rewrite = |json: &mut serde_json::Value, path: &[&str]| {
        let list = path.iter().try_fold(json, |v, key| v.get_mut(*key));
        for d in list.and_then(serde_json::Value::as_array_mut).into_iter().flatten() {
            *d = old_spelling(d);
            rewritten += 1;
        }
    };
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        let channel = match channels.get(&m.channel.topic) {
            Some(id) => *id,
            None => {
                let schema = m.channel.schema.as_ref().unwrap();
                let schema_id = out.add_schema(&schema.name, &schema.encoding, schema.data.as_ref()).unwrap();
                let id = out.add_channel(schema_id, &m.channel.topic, "json", &BTreeMap::new()).unwrap();
                channels.insert(m.channel.topic.clone(), id);
                id
            }
        };
        let mut json: serde_json::Value = serde_json::from_slice(&m.data).unwrap();
        match m.channel.topic.as_str() {
            topics::MAP_STATE => rewrite(&mut json, &["content"]),
            topics::MAP_CHANGE => {
                rewrite(&mut json, &["deltas"]);
                rewrite(&mut json, &["state", "content"]);
            }
            topics::RENDEZVOUS => rewrite(&mut json, &["request", "deltas"]),
            _ => {}
        }
        let header = mcap::records::MessageHeader {
            channel_id: channel,
            sequence: m.sequence,
            log_time: m.log_time,
            publish_time: m.publish_time,
        };
        out.write_to_known_channel(&header, &serde_json::to_vec(&json).unwrap()).unwrap();
    }
    out.finish().unwrap();
    rewritten
}

/// Recordings made before deltas had the spelling of `docs/deltas.md` hold serde's
/// derived form (`{"UpsertObstacle": {"id": 1, "obstacle": {"Cylinder": …}}}`):
/// they still replay, every answer identical. Two files: one whose maps came by
/// `create`, `upload`, `apply` and inline deltas, one that starts with map states.
#[test]
fn a_recording_in_the_old_delta_spelling_still_replays() {
    let sandbox = Sandbox::new("record-old");
    let dir = Scratch::new("record-old");
    let first = dir.0.join("first.mcap");
    record(&sandbox, &first, 6);
    // The maps are kept in the state directory: the next file starts with them.
    let second = dir.0.join("second.mcap");
    let mut daemon = sandbox.start_daemon_logging("info", &["--record", second.to_str().unwrap()]);
    let maps = maps();
    let mut c = sandbox.client();
    for seed in 0..3 {
        let request =
            RendezvousRequest { algorithm: Algorithm::Center, seed, ..RendezvousRequest::new(3, maps[2].belief) };
        c.rendezvous(&request, TIMEOUT).expect("a query of a kept map");
    }
    let inline = RendezvousRequest {
        deltas: vec![MapDelta::SetSun(Sun::new(0.4, 2.0).unwrap()), MapDelta::Clear],
        ..RendezvousRequest::new(WRITER_MAP, maps[0].belief)
    };
    c.check(&inline, TIMEOUT).expect("a check with inline deltas");
    assert!(daemon.terminate().success(), "{}", daemon.log());

    for (file, expect_states) in [(&first, false), (&second, true)] {
        let messages = read_complete(file);
        assert_eq!(messages.contains_key(topics::MAP_STATE), expect_states, "{}", file.display());
        let old = file.with_extension("old.mcap");
        let rewritten = rewrite_in_old_spelling(file, &old);
        assert!(rewritten > 0, "{}: no delta to rewrite", file.display());
        let old_text = String::from_utf8_lossy(&std::fs::read(&old).unwrap()).into_owned();
        assert!(old_text.contains("\"UpsertObstacle\"") && !old_text.contains("upsert_obstacle\":"), "{old_text}");
        let (new_run, old_run) = (replay(&[file.to_str().unwrap()]), replay(&[old.to_str().unwrap()]));
        let summary = |o: &Output| text(o).lines().last().unwrap_or("").split_once(": ").map(|(_, s)| s.to_string());
        assert_eq!(old_run.status.code(), Some(0), "{}", text(&old_run));
        assert!(
            text(&old_run).contains(" 0 different") && text(&old_run).contains("recording complete"),
            "{}",
            text(&old_run)
        );
        assert_eq!(summary(&old_run), summary(&new_run), "the old file replays as the new one");
    }
}
