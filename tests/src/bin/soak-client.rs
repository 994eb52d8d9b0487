//! `soak-client`: a process of the soak test (`tests/tests/it/soak.rs`).
//!
//! ```text
//! soak-client query --prefix P --domain D --id N --log FILE --stop FILE
//! soak-client write --prefix P --domain D --id N --log FILE --stop FILE
//! ```
//!
//! `query` sends the mix of [`dyfos_tests::soak::plan`] until the stop file exists,
//! logging each request before it is sent and its outcome after. `write` streams
//! the batches of [`dyfos_tests::soak::writer_batch`] into the writer map, each with
//! the version it expects, so that a batch whose acknowledgement was lost (the
//! daemon died in between) is never applied twice: its retry is refused with
//! `map_version_mismatch`, and a snapshot tells whether it was applied.
//! Both ride out daemon restarts. Exit code 0 when stopped, 2 on bad arguments.

use dyfos_client::prelude::*;
use dyfos_client::{MapRequestError, RendezvousError};
use dyfos_tests::soak::{
    Outcome, Record, SOAK_TIMEOUT, WRITER_MAP, WriterRecord, log_line, map_outcome, maps, plan, rendezvous_outcome,
    writer_batch,
};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::{Duration, Instant};

struct Args {
    mode: String,
    prefix: String,
    domain: String,
    id: u32,
    log: PathBuf,
    stop: PathBuf,
}

fn parse() -> Result<Args, String> {
    let mut it = std::env::args().skip(1);
    let mode = it.next().ok_or("missing mode: query or write")?;
    let (mut prefix, mut domain, mut id, mut log, mut stop) = (None, None, None, None, None);
    while let Some(flag) = it.next() {
        let value = it.next().ok_or_else(|| format!("{flag} needs a value"))?;
        match flag.as_str() {
            "--prefix" => prefix = Some(value),
            "--domain" => domain = Some(value),
            "--id" => id = Some(value.parse::<u32>().map_err(|e| format!("--id {value}: {e}"))?),
            "--log" => log = Some(PathBuf::from(value)),
            "--stop" => stop = Some(PathBuf::from(value)),
            other => return Err(format!("unknown flag {other}")),
        }
    }
    Ok(Args {
        mode,
        prefix: prefix.ok_or("--prefix is required")?,
        domain: domain.ok_or("--domain is required")?,
        id: id.ok_or("--id is required")?,
        log: log.ok_or("--log is required")?,
        stop: stop.ok_or("--stop is required")?,
    })
}

/// Connects, retrying while the daemon is away; `None` once the stop file exists.
fn connect(args: &Args) -> Option<Client> {
    let config = ClientConfig {
        prefix: args.prefix.clone(),
        domain: Some(args.domain.clone()),
        connect_timeout: Duration::from_secs(1),
        ..ClientConfig::default()
    };
    loop {
        if args.stop.exists() {
            return None;
        }
        match Client::connect(&config) {
            Ok(c) => return Some(c),
            Err(_) => std::thread::sleep(Duration::from_millis(20)),
        }
    }
}

fn open_log(path: &Path) -> std::fs::File {
    std::fs::OpenOptions::new().create(true).append(true).open(path).expect("open the soak log")
}

fn micros(since: Instant) -> u64 {
    u64::try_from(since.elapsed().as_micros()).unwrap_or(u64::MAX)
}

fn query(args: &Args) {
    let maps = maps();
    let mut log = open_log(&args.log);
    let Some(mut client) = connect(args) else { return };
    let mut writer_version = None;
    for n in 0.. {
        if args.stop.exists() {
            return;
        }
        let planned = plan(args.id, n, &maps, writer_version);
        log_line(&mut log, &Record::Sent(planned.sent.clone()));
        let timeout = SOAK_TIMEOUT + planned.request.deadline.unwrap_or_default();
        let start = Instant::now();
        let outcome = if planned.sent.check {
            match client.check(&planned.request, timeout) {
                Ok(c) => Outcome::Checked { map_version: c.map_version },
                Err(e) => rendezvous_outcome(&e),
            }
        } else {
            match client.rendezvous(&planned.request, timeout) {
                Ok(a) => Outcome::Answer { answer: a.to_json(), map_version: a.map_version, stop: a.stop },
                Err(e) => rendezvous_outcome(&e),
            }
        };
        let micros = micros(start);
        let map_version = match &outcome {
            Outcome::Answer { map_version, .. } | Outcome::Checked { map_version } => Some(*map_version),
            _ => None,
        };
        if planned.sent.map == WRITER_MAP && map_version.is_some() {
            writer_version = map_version;
        }
        let pause = matches!(outcome, Outcome::Failed { .. })
            || matches!(&outcome, Outcome::Rejected { status, .. } if status == "busy" || status == "shutting_down");
        log_line(&mut log, &Record::Done { n, micros, outcome });
        if pause {
            std::thread::sleep(Duration::from_millis(20));
        }
    }
}

/// Whether an error says nothing about the batch (no daemon, daemon gone, busy, …):
/// the same batch is sent again with the same expected version.
fn says_nothing(outcome: &Outcome) -> bool {
    match outcome {
        Outcome::Failed { .. } => true,
        Outcome::Rejected { status, .. } => matches!(status.as_str(), "busy" | "shutting_down" | "storage_failed"),
        _ => false,
    }
}

fn write(args: &Args) {
    let mut log = open_log(&args.log);
    let Some(mut client) = connect(args) else { return };
    let seed = u64::from(args.id);
    let mut world = loop {
        match client.snapshot(WRITER_MAP, SOAK_TIMEOUT) {
            Ok(w) => break w,
            Err(e) if e.is_retryable() => std::thread::sleep(Duration::from_millis(20)),
            Err(e) => {
                log_line(&mut log, &WriterRecord::Fatal { k: 0, message: format!("first snapshot: {e}") });
                return;
            }
        }
    };
    let belief = maps()[0].belief;
    for k in 0.. {
        if args.stop.exists() {
            return;
        }
        let (deltas, valid, inline) = writer_batch(seed, k, &world);
        let from = world.version();
        let mut attempts = 0;
        loop {
            attempts += 1;
            // Both paths carry the version the batch was made for.
            let sent: Result<u64, Outcome> = if inline {
                // One inline batch in three rides a query that finds nothing: the
                // deltas stay applied, and the reply must say which version they made
                // (checked against the replay like any acknowledged version).
                let request = RendezvousRequest {
                    expected_version: Some(from),
                    deltas: deltas.clone(),
                    algorithm: Algorithm::Center,
                    seed: k,
                    params: if k % 3 == 1 { unreachable_params() } else { Params::default() },
                    ..RendezvousRequest::new(WRITER_MAP, belief)
                };
                match client.rendezvous(&request, SOAK_TIMEOUT) {
                    Ok(a) => Ok(a.map_version),
                    Err(RendezvousError::Rejected(r))
                        if matches!(r.status, Status::NoFeasiblePose | Status::DeadlineExceeded) =>
                    {
                        // No version (u64::MAX) fails the check below as Fatal.
                        Ok(r.map_version.unwrap_or(u64::MAX))
                    }
                    Err(e) => Err(rendezvous_outcome(&e)),
                }
            } else {
                client.apply(WRITER_MAP, Some(from), &deltas, SOAK_TIMEOUT).map_err(|e| map_outcome(&e))
            };
            match sent {
                Ok(to) => {
                    if !valid || to != from + deltas.len() as u64 {
                        let message = format!("batch (valid: {valid}) took version {from} to {to}");
                        log_line(&mut log, &WriterRecord::Fatal { k, message });
                        return;
                    }
                    world = world.apply(&deltas).expect("valid batch");
                    let record = WriterRecord::Applied { k, from, to, deltas, inline, ack_lost: false, attempts };
                    log_line(&mut log, &record);
                    break;
                }
                Err(outcome) if says_nothing(&outcome) => {
                    log_line(&mut log, &WriterRecord::Retry { k, outcome });
                    std::thread::sleep(Duration::from_millis(20));
                    if args.stop.exists() {
                        return;
                    }
                }
                Err(Outcome::Rejected { status, .. }) if status == "map_version_mismatch" && attempts > 1 => {
                    // An earlier attempt was applied but its answer was lost: read back.
                    let now = loop {
                        match client.snapshot(WRITER_MAP, SOAK_TIMEOUT) {
                            Ok(w) => break w,
                            Err(e @ MapRequestError::Rejected(_)) => {
                                let message = format!("snapshot after a lost ack: {e}");
                                log_line(&mut log, &WriterRecord::Fatal { k, message });
                                return;
                            }
                            Err(_) => std::thread::sleep(Duration::from_millis(20)),
                        }
                    };
                    let applied = world.apply(&deltas).ok();
                    if !valid || applied.as_ref() != Some(&now) {
                        let message = format!(
                            "version mismatch at {from}: the map is at {}, not this batch applied once",
                            now.version()
                        );
                        log_line(&mut log, &WriterRecord::Fatal { k, message });
                        return;
                    }
                    world = now;
                    let to = world.version();
                    let record = WriterRecord::Applied { k, from, to, deltas, inline, ack_lost: true, attempts };
                    log_line(&mut log, &record);
                    break;
                }
                Err(Outcome::Rejected { status, .. }) => {
                    log_line(&mut log, &WriterRecord::Rejected { k, from, status, valid });
                    break;
                }
                Err(other) => {
                    log_line(&mut log, &WriterRecord::Fatal { k, message: format!("{other:?}") });
                    return;
                }
            }
        }
        std::thread::sleep(Duration::from_millis(5));
    }
}

/// Parameters no viewer pose satisfies: it must fly at 7–8 m but see the rover
/// within 2 m.
fn unreachable_params() -> Params {
    Params { z_min: 7.0, z_max: 8.0, rho_min: 1.0, rho_max: 2.0, ..Params::default() }
}

fn main() -> ExitCode {
    let args = match parse() {
        Ok(a) => a,
        Err(e) => {
            eprintln!("soak-client: {e}");
            return ExitCode::from(2);
        }
    };
    match args.mode.as_str() {
        "query" => query(&args),
        "write" => write(&args),
        other => {
            eprintln!("soak-client: unknown mode {other}; use query or write");
            return ExitCode::from(2);
        }
    }
    ExitCode::SUCCESS
}
