//! The soak test's shared pieces: its maps, the request and map-delta generators,
//! and the log records that `soak-client` processes write and the test reads back.
//!
//! Every request and every map change is logged *before* it is sent and its outcome
//! after, one JSON line each, so that the test can check every answer against the
//! offline library (same seed, same map version) and replay the acknowledged deltas.
//!
//! ```
//! use dyfos_tests::soak::{Record, maps, plan};
//!
//! let maps = maps();
//! let planned = plan(3, 17, &maps, None);
//! // Seeds are unique per (client, request): an answer meant for another client
//! // cannot pass the offline comparison.
//! assert_eq!(planned.sent.seed, (3 << 40) | 17);
//! let line = serde_json::to_string(&Record::Sent(planned.sent.clone())).unwrap();
//! assert!(matches!(serde_json::from_str(&line).unwrap(), Record::Sent(s) if s == planned.sent));
//! ```

use crate::scenario;
use dyfos_client::prelude::*;
use dyfos_client::{MapRequestError, RendezvousError};
use dyfos_shared::world::{AxisBox, VerticalCylinder};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use std::io::Write;
use std::path::Path;
use std::time::Duration;

/// The map the writer process streams deltas into.
pub const WRITER_MAP: MapId = 1;

/// How long a soak process waits for any one reply before calling it silence.
pub const SOAK_TIMEOUT: Duration = Duration::from_secs(30);

/// Obstacle ids the writer uses (so the map stays small however long it runs).
const WRITER_IDS: u32 = 48;

/// An obstacle id that never exists: removing it is a deliberately invalid delta.
pub const MISSING_ID: u32 = 9_999;

/// A map of the soak and the belief and parameters its queries use.
#[derive(Debug, Clone)]
pub struct SoakMap {
    /// Its id in the daemon.
    pub id: MapId,
    /// Its content at version 0.
    pub world: World,
    /// The rover belief queried.
    pub belief: Belief,
    /// Parameters (the model is chosen per request).
    pub params: Params,
}

/// The writer's map (empty at first) and two fixed maps from the test data.
pub fn maps() -> Vec<SoakMap> {
    let belief =
        Belief::new([0.5, -0.5, 0.3], [[0.2, 0.05, 0.0], [0.05, 0.1, 0.0], [0.0, 0.0, 0.05]]).expect("a valid belief");
    let writer =
        World::empty(Bounds::new([-12.0, -12.0, 12.0, 12.0]).expect("bounds"), Sun::new(0.6, 1.0).expect("sun"));
    let example = scenario("example.json");
    let numerical = scenario("golden/scenarios/numerical/map_00.json");
    vec![
        SoakMap { id: WRITER_MAP, world: writer, belief, params: Params::default() },
        SoakMap { id: 2, world: example.world, belief: example.belief, params: example.params },
        SoakMap { id: 3, world: numerical.world, belief: numerical.belief, params: numerical.params },
    ]
}

/// One request as logged before it is sent: everything needed to redo it offline.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Sent {
    /// The request's number within its client process.
    pub n: u64,
    /// The map.
    pub map: MapId,
    /// The algorithm.
    pub algorithm: Algorithm,
    /// The seed, `client << 40 | n`.
    pub seed: u64,
    /// Evaluation budget.
    pub budget: Option<u64>,
    /// Deadline, µs.
    pub deadline_us: Option<u64>,
    /// SDSMM.
    pub model: ModelKind,
    /// Expected map version.
    pub expected_version: Option<u64>,
    /// Check mode (validate only) rather than solve.
    pub check: bool,
}

/// How a request ended, as the client saw it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Outcome {
    /// A pose: the answer as `dyfos solve` prints it.
    Answer {
        /// `Answer::to_json`.
        answer: serde_json::Value,
        /// The map version searched.
        map_version: u64,
        /// Why the search stopped.
        stop: StopReason,
    },
    /// A check-mode reply.
    Checked {
        /// The version that would have been searched.
        map_version: u64,
    },
    /// The daemon refused the request with a code.
    Rejected {
        /// The status name.
        status: String,
        /// Its message.
        message: String,
    },
    /// No reply from the daemon: `no_daemon`, `daemon_gone`, `timeout`, `connect`,
    /// `invalid` or `ipc`.
    Failed {
        /// The kind.
        kind: String,
        /// The error text.
        message: String,
    },
}

/// One line of a query client's log.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "ev", rename_all = "snake_case")]
pub enum Record {
    /// About to send.
    Sent(Sent),
    /// The outcome of request `n`, after `micros`.
    Done {
        /// The request's number.
        n: u64,
        /// Client-side round trip, µs.
        micros: u64,
        /// What came back.
        outcome: Outcome,
    },
}

/// A planned request.
#[derive(Debug, Clone)]
pub struct Planned {
    /// What is logged.
    pub sent: Sent,
    /// What is sent.
    pub request: RendezvousRequest,
}

/// The request a client process sends as its `n`-th: a mix of maps, algorithms,
/// models, budgets, deadlines, expected versions and check mode, drawn from
/// `(client, n)`. `writer_version` is the writer map's last version this client saw.
pub fn plan(client: u32, n: u64, maps: &[SoakMap], writer_version: Option<u64>) -> Planned {
    let seed = (u64::from(client) << 40) | n;
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x50a4_50a4);
    let map = match rng.random_range(0..100) {
        0..45 => &maps[0],
        45..75 => &maps[1],
        _ => &maps[2],
    };
    let check = rng.random_range(0..100) < 12;
    let (algorithm, mut budget) = match rng.random_range(0..100) {
        0..40 => (Algorithm::Dyfos, None),
        40..48 => (Algorithm::Dyfos, Some(rng.random_range(200..2000))),
        48..58 => (Algorithm::DyfosScipy, None),
        58..73 => (Algorithm::Random, None),
        73..88 => (Algorithm::Center, None),
        _ => (Algorithm::Brute, Some(rng.random_range(1000..6000))),
    };
    let deadline_us = (rng.random_range(0..100) < 8).then(|| rng.random_range(1_000..30_000));
    if deadline_us.is_some() && algorithm == Algorithm::Brute {
        // A full grid: only the deadline stops it.
        budget = None;
    }
    let model = if rng.random_range(0..100) < 70 { ModelKind::Paper } else { ModelKind::Anisotropic };
    let expected_version = if map.id == WRITER_MAP {
        writer_version.filter(|_| rng.random_range(0..100) < 15)
    } else {
        // Fixed maps stay at version 0: 1 must be refused.
        (rng.random_range(0..100) < 6).then(|| rng.random_range(0..2))
    };
    let sent = Sent { n, map: map.id, algorithm, seed, budget, deadline_us, model, expected_version, check };
    let request = request_of(&sent, map);
    Planned { sent, request }
}

/// The request a logged [`Sent`] describes.
pub fn request_of(sent: &Sent, map: &SoakMap) -> RendezvousRequest {
    RendezvousRequest {
        expected_version: sent.expected_version,
        algorithm: sent.algorithm,
        seed: sent.seed,
        budget: sent.budget,
        deadline: sent.deadline_us.map(Duration::from_micros),
        params: Params { model: sent.model, ..map.params },
        ..RendezvousRequest::new(map.id, map.belief)
    }
}

/// The client-side failure kind of an error without a daemon status.
fn failure(text: &str, debug: &str) -> Outcome {
    let kind = if debug.starts_with("Timeout") {
        "timeout"
    } else if debug.starts_with("DaemonGone") {
        "daemon_gone"
    } else if debug.starts_with("NoDaemon") {
        "no_daemon"
    } else if debug.starts_with("Connect") {
        "connect"
    } else if debug.starts_with("Invalid") {
        "invalid"
    } else {
        "ipc"
    };
    Outcome::Failed { kind: kind.to_string(), message: text.to_string() }
}

/// A rendezvous error as an [`Outcome`].
pub fn rendezvous_outcome(e: &RendezvousError) -> Outcome {
    match e {
        RendezvousError::Rejected(r) => {
            Outcome::Rejected { status: r.status.name().to_string(), message: r.message.clone() }
        }
        other => failure(&other.to_string(), &format!("{other:?}")),
    }
}

/// A map error as an [`Outcome`].
pub fn map_outcome(e: &MapRequestError) -> Outcome {
    match e {
        MapRequestError::Rejected(r) => {
            Outcome::Rejected { status: r.status.name().to_string(), message: r.message.clone() }
        }
        other => failure(&other.to_string(), &format!("{other:?}")),
    }
}

/// One line of the writer's log.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "ev", rename_all = "snake_case")]
pub enum WriterRecord {
    /// Batch `k` took the map from version `from` to `to`. `ack_lost`: the daemon
    /// died after applying it and before answering; the retry (same expected
    /// version) was refused with `map_version_mismatch` and a snapshot showed the
    /// batch applied exactly once.
    Applied {
        /// Batch number.
        k: u64,
        /// Version before.
        from: u64,
        /// Version after.
        to: u64,
        /// The batch.
        deltas: Vec<MapDelta>,
        /// Sent inline with a rendezvous query rather than to the map service.
        inline: bool,
        /// The acknowledgement was lost and the outcome read back.
        ack_lost: bool,
        /// Sends it took.
        attempts: u32,
    },
    /// Batch `k` (deliberately invalid) was refused as a whole.
    Rejected {
        /// Batch number.
        k: u64,
        /// Version it was sent against.
        from: u64,
        /// The status name.
        status: String,
        /// Whether the writer meant it to be valid (then the test fails).
        valid: bool,
    },
    /// An attempt failed without an answer about the batch; it is sent again.
    Retry {
        /// Batch number.
        k: u64,
        /// What happened.
        outcome: Outcome,
    },
    /// Something that must not happen; the test fails.
    Fatal {
        /// Batch number.
        k: u64,
        /// What.
        message: String,
    },
}

/// The writer's `k`-th batch against `world`: 1–4 deltas (upserts, removals of
/// existing obstacles, voxel runs, sun moves, bounds, rarely a clear), and in 1 of
/// 12 batches a deliberately invalid last delta. Returns the batch, whether it is
/// valid, and whether to send it inline with a query.
pub fn writer_batch(seed: u64, k: u64, world: &World) -> (Vec<MapDelta>, bool, bool) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed.wrapping_mul(0x9e37_79b9_7f4a_7c15) ^ k);
    let mut sim = world.clone();
    let mut batch = Vec::new();
    for _ in 0..rng.random_range(1..=4) {
        let delta = match rng.random_range(0..100) {
            0..35 => MapDelta::UpsertObstacle {
                id: rng.random_range(1..=WRITER_IDS),
                obstacle: Obstacle::Cylinder(VerticalCylinder {
                    center: na::Point2::new(rng.random_range(-11.0..11.0), rng.random_range(-11.0..11.0)),
                    radius: rng.random_range(0.2..1.0),
                    height: rng.random_range(0.5..6.0),
                }),
            },
            35..50 => {
                let (x, y) = (rng.random_range(-11.0..10.0), rng.random_range(-11.0..10.0));
                MapDelta::UpsertObstacle {
                    id: rng.random_range(1..=WRITER_IDS),
                    obstacle: Obstacle::Box(AxisBox {
                        min: na::Point3::new(x, y, 0.0),
                        max: na::Point3::new(
                            x + rng.random_range(0.2..1.5),
                            y + rng.random_range(0.2..1.5),
                            rng.random_range(0.3..4.0),
                        ),
                    }),
                }
            }
            50..70 if !sim.obstacles().is_empty() => {
                let ids: Vec<u32> = sim.obstacles().keys().copied().collect();
                MapDelta::RemoveObstacle { id: ids[rng.random_range(0..ids.len())] }
            }
            50..85 => MapDelta::SetVoxels {
                resolution: 0.5,
                origin: na::Point3::new(-12.0, -12.0, 0.0),
                cells: (0..rng.random_range(1..8))
                    .map(|_| [rng.random_range(0..48), rng.random_range(0..48), rng.random_range(0..12)])
                    .collect(),
                occupied: rng.random_range(0..4) != 0,
            },
            85..95 => MapDelta::SetSun(
                Sun::new(rng.random_range(-0.5..1.4), rng.random_range(-3.0..3.0)).expect("sun in range"),
            ),
            95..98 => MapDelta::SetBounds(*sim.bounds()),
            _ => MapDelta::Clear,
        };
        sim = sim.apply(std::slice::from_ref(&delta)).expect("the generator makes valid deltas");
        batch.push(delta);
    }
    let valid = rng.random_range(0..12) != 0;
    if !valid {
        batch.push(MapDelta::RemoveObstacle { id: MISSING_ID });
    }
    let inline = rng.random_range(0..8) == 0;
    (batch, valid, inline)
}

/// Appends one JSON line to `file` with a single write (a process killed mid-way
/// leaves whole lines only, or a last partial line the reader skips).
pub fn log_line(file: &mut std::fs::File, record: &impl Serialize) {
    let mut line = serde_json::to_string(record).expect("log records serialize");
    line.push('\n');
    file.write_all(line.as_bytes()).expect("write the soak log");
}

/// Reads a JSON-lines log; a torn last line (the writer was killed) is skipped.
pub fn read_log<T: for<'de> Deserialize<'de>>(path: &Path) -> Vec<T> {
    let text = std::fs::read_to_string(path).unwrap_or_default();
    let lines: Vec<&str> = text.lines().collect();
    let mut out = Vec::with_capacity(lines.len());
    for (i, line) in lines.iter().enumerate() {
        match serde_json::from_str(line) {
            Ok(r) => out.push(r),
            Err(e) if i + 1 == lines.len() && !text.ends_with('\n') => {
                let _ = e;
            }
            Err(e) => panic!("{}:{}: unreadable log line ({e}): {line}", path.display(), i + 1),
        }
    }
    out
}
