//! `dyfos-bench`: benchmarks and reproductions of the paper's evaluations. A thin
//! layer over the `dyfos_bench` library: one subcommand per benchmark, each in its
//! own module here (parse flags, call the library, print tables, write files).
//!
//! Add a benchmark by adding a module with an `Args` struct and a `run` function,
//! and one variant to [`Command`].

mod compare;
mod latency;
mod learned;
mod numerical;
mod octomap;

use clap::{Parser, Subcommand};
use std::process::ExitCode;

/// Benchmarks and paper reproductions for dyfos.
#[derive(Debug, Parser)]
#[command(name = "dyfos-bench", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// The paper's numerical evaluation (SPEC §10): E and run time per algorithm on
    /// seeded random maps, and query time as the map grows.
    Numerical(numerical::NumericalArgs),
    /// Query latency and throughput of dyfosd (closed and open loop, N client
    /// processes), against the in-process call and iceoryx2's raw round trip.
    Latency(latency::LatencyArgs),
    /// OctoMap maps: query cost per candidate against cylinder maps, and,
    /// through dyfosd, loading a building `.bt`, 10 000-cell updates, a restart.
    Octomap(octomap::OctomapArgs),
    /// One client process of `latency` (started by it).
    #[command(hide = true)]
    LatencyWorker(latency::WorkerArgs),
    /// This build's `dyfos solve` against another build's, interleaved on the same
    /// scenarios: medians, ratios, whether every answer is identical.
    Compare(compare::CompareArgs),
    /// The learned SDSMM against the synthetic camera it was trained on: held-out
    /// NLL, std plots, planning judged by the true model, query time.
    Learned(learned::LearnedArgs),
}

fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Numerical(args) => numerical::run(&args),
        Command::Latency(args) => latency::run(&args),
        Command::LatencyWorker(args) => latency::worker(&args),
        Command::Learned(args) => learned::run(&args),
        Command::Octomap(args) => octomap::run(&args),
        Command::Compare(args) => compare::run(&args),
    }
}

fn main() -> ExitCode {
    match run(Cli::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("dyfos-bench: {e:#}");
            ExitCode::FAILURE
        }
    }
}

dyfos_process::numeric_flags_test!(super::Cli);
