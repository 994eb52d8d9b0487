//! `dyfos-ffi-bench`: what the C ABI adds to a check-mode round trip.
//!
//! Starts a `dyfosd` (next to this executable, or `--dyfosd PATH`) on a private
//! prefix and domain, creates one map, then sends the same check-mode request
//! through the Rust client (`Client::check`) and through the C ABI
//! (`dyfos_client_check`, called as C calls it) in alternating rounds, and prints
//! the latency percentiles of both and their difference, measured in the same run.
//!
//! ```text
//! dyfos-ffi-bench [--dyfosd PATH] [--calls N] [--round N]
//! ```
#![allow(unsafe_code)] // Calls the C ABI, as a C program would.

use ::dyfos_client::prelude::*;
use dyfos::{
    DYFOS_STATUS_OK, dyfos_client, dyfos_client_check, dyfos_client_connect, dyfos_client_free,
    dyfos_rendezvous_request, dyfos_rendezvous_request_init,
};
use dyfos_process::child::KillOnDrop;
use std::ffi::CString;
use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

const TIMEOUT: Duration = Duration::from_secs(10);

struct Args {
    dyfosd: PathBuf,
    calls: usize,
    round: usize,
}

fn args() -> Result<Args, String> {
    let exe = std::env::current_exe().map_err(|e| e.to_string())?;
    let mut args = Args { dyfosd: exe.with_file_name("dyfosd"), calls: 20_000, round: 200 };
    let mut it = std::env::args().skip(1);
    while let Some(flag) = it.next() {
        let mut value = || it.next().ok_or_else(|| format!("{flag} needs a value"));
        match flag.as_str() {
            "--dyfosd" => args.dyfosd = PathBuf::from(value()?),
            "--calls" => args.calls = value()?.parse().map_err(|e| format!("--calls: {e}"))?,
            "--round" => args.round = value()?.parse().map_err(|e| format!("--round: {e}"))?,
            _ => {
                return Err(format!(
                    "unknown flag {flag}; usage: dyfos-ffi-bench [--dyfosd PATH] [--calls N] [--round N]"
                ));
            }
        }
    }
    if args.round == 0 || args.calls < args.round {
        return Err("need --calls >= --round > 0".into());
    }
    Ok(args)
}

/// The daemon, stopped with SIGTERM (and its state directory removed) on drop.
struct Daemon(KillOnDrop, PathBuf);

impl Drop for Daemon {
    fn drop(&mut self) {
        self.0.terminate(TIMEOUT);
        let _ = std::fs::remove_dir_all(&self.1);
    }
}

/// Percentile `q` (0..=1) of sorted nanoseconds, in µs.
fn percentile(sorted: &[u64], q: f64) -> f64 {
    let i = ((sorted.len() - 1) as f64 * q).round() as usize;
    sorted[i] as f64 / 1000.0
}

fn run() -> Result<(), String> {
    let a = args()?;
    let pid = std::process::id();
    let prefix = format!("dyfos-ffi-bench-{pid}/");
    let domain = format!("dfb{pid}_");
    let state = std::env::temp_dir().join(format!("dyfos-ffi-bench-{pid}"));
    let child = Command::new(&a.dyfosd)
        .args(["--prefix", &prefix, "--domain", &domain, "--state-dir"])
        .arg(&state)
        .env("RUST_LOG", "warn")
        .stdout(Stdio::null())
        .spawn()
        .map_err(|e| format!("cannot start {}: {e}", a.dyfosd.display()))?;
    let _daemon = Daemon(KillOnDrop::new(child), state);

    let config = ClientConfig {
        prefix: prefix.clone(),
        domain: Some(domain.clone()),
        connect_timeout: TIMEOUT,
        ..ClientConfig::default()
    };
    let mut rust = Client::connect(&config).map_err(|e| e.to_string())?;
    let bounds = Bounds::new([-10.0, -10.0, 10.0, 10.0]).map_err(|e| e.to_string())?;
    let sun = Sun::new(0.7, 2.1).map_err(|e| e.to_string())?;
    rust.create_map(1, bounds, sun, TIMEOUT).map_err(|e| e.to_string())?;
    let mean = [0.0, 0.0, 0.3];
    let cov = [[0.2, 0.05, 0.0], [0.05, 0.1, 0.0], [0.0, 0.0, 0.05]];
    let request = RendezvousRequest::new(1, Belief::new(mean, cov).map_err(|e| e.to_string())?);

    // What the C path validates per request before it reaches the Rust client
    // (the Rust client is handed a request already validated).
    {
        use dyfos_shared::wire::rendezvous::WireParams;
        let n = 200_000;
        let t = Instant::now();
        for _ in 0..n {
            std::hint::black_box(Belief::new(std::hint::black_box(mean), std::hint::black_box(cov)).is_ok());
        }
        println!("C-side validation per request: Belief::new {:.0} ns", t.elapsed().as_nanos() as f64 / n as f64);
        let w0 = WireParams::default();
        let t = Instant::now();
        for _ in 0..n {
            std::hint::black_box(Params::try_from(std::hint::black_box(&w0)).is_ok());
        }
        println!("  Params::try_from, no field set: {:.0} ns", t.elapsed().as_nanos() as f64 / n as f64);
        let w1 = WireParams::from(&Params::default());
        let t = Instant::now();
        for _ in 0..n {
            std::hint::black_box(Params::try_from(std::hint::black_box(&w1)).is_ok());
        }
        println!("  Params::try_from, every field set: {:.0} ns", t.elapsed().as_nanos() as f64 / n as f64);
    }
    let (c_prefix, c_domain) = (CString::new(prefix).unwrap_or_default(), CString::new(domain).unwrap_or_default());
    let mut handle: *mut dyfos_client = std::ptr::null_mut();
    // SAFETY: valid C strings and a local output.
    let status = unsafe { dyfos_client_connect(c_prefix.as_ptr(), c_domain.as_ptr(), 10_000, &mut handle) };
    if status != DYFOS_STATUS_OK {
        return Err(format!("dyfos_client_connect: status {status}"));
    }
    let mut c_request = std::mem::MaybeUninit::<dyfos_rendezvous_request>::uninit();
    // SAFETY: writes the whole struct.
    if unsafe { dyfos_rendezvous_request_init(c_request.as_mut_ptr()) } != DYFOS_STATUS_OK {
        return Err("dyfos_rendezvous_request_init failed".into());
    }
    // SAFETY: initialised just above.
    let mut c_request = unsafe { c_request.assume_init() };
    c_request.map = 1;
    c_request.mean = mean;
    c_request.cov = cov;

    let mut rust_call = || -> Result<u64, String> {
        let start = Instant::now();
        rust.check(&request, TIMEOUT).map_err(|e| e.to_string())?;
        Ok(start.elapsed().as_nanos() as u64)
    };
    let c_call = || -> Result<u64, String> {
        let mut version = 0u64;
        let start = Instant::now();
        // SAFETY: a live handle, an initialised request without deltas, a local output.
        let status = unsafe { dyfos_client_check(handle, 0, &c_request, &mut version) };
        let nanos = start.elapsed().as_nanos() as u64;
        if status != DYFOS_STATUS_OK {
            return Err(format!("dyfos_client_check: status {status}"));
        }
        Ok(nanos)
    };
    for _ in 0..a.round.max(1000) {
        rust_call()?;
        c_call()?;
    }
    let (mut through_rust, mut through_c) = (Vec::with_capacity(a.calls), Vec::with_capacity(a.calls));
    let start = Instant::now();
    for r in 0..a.calls / a.round {
        // Alternate which goes first, so neither always follows the other.
        for first in [r % 2 == 0, r % 2 != 0] {
            for _ in 0..a.round {
                if first {
                    through_rust.push(rust_call()?);
                } else {
                    through_c.push(c_call()?);
                }
            }
        }
    }
    let wall = start.elapsed();
    // SAFETY: the handle from dyfos_client_connect, freed once.
    unsafe { dyfos_client_free(handle) };
    through_rust.sort_unstable();
    through_c.sort_unstable();
    println!(
        "check-mode round trips, {} each, alternating rounds of {} ({:.1} s)",
        through_rust.len(),
        a.round,
        wall.as_secs_f64()
    );
    println!("| path | p10 µs | p50 µs | p90 µs | p99 µs |");
    println!("|---|---|---|---|---|");
    for (name, s) in [("Rust client (`Client::check`)", &through_rust), ("C ABI (`dyfos_client_check`)", &through_c)] {
        println!(
            "| {name} | {:.2} | {:.2} | {:.2} | {:.2} |",
            percentile(s, 0.1),
            percentile(s, 0.5),
            percentile(s, 0.9),
            percentile(s, 0.99)
        );
    }
    println!(
        "C ABI − Rust client: p50 {:+.2} µs, p10 {:+.2} µs",
        percentile(&through_c, 0.5) - percentile(&through_rust, 0.5),
        percentile(&through_c, 0.1) - percentile(&through_rust, 0.1)
    );
    Ok(())
}

fn main() -> std::process::ExitCode {
    match run() {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("dyfos-ffi-bench: {e}");
            std::process::ExitCode::FAILURE
        }
    }
}
