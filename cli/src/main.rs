//! `dyfos`: the DyFOS command line. A thin layer over `dyfos-service` (and
//! `dyfos-client`, `dyfos-mission` for the online commands, the demo and `ape`):
//! parse the flags, run one library call, print JSON, map errors to exit codes.
//!
//! Exit codes: 0 success, 2 invalid input (the message names the field), 3 no
//! feasible pose, 1 anything else; `dyfos replay` has its own (see its `--help`).

mod ape;
mod demo;
mod hosts;
mod offline;
mod online;
mod replay;
mod train;

use clap::{Parser, Subcommand};
use std::process::ExitCode;

/// Where to put a viewer's camera to localize a perception-denied rover.
#[derive(Debug, Parser)]
#[command(name = "dyfos", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Run the paper's simulated evaluation end to end: dyfosd, a rover and a viewer
    /// per algorithm; print the APE table and write an SVG per algorithm.
    Demo(demo::DemoArgs),
    /// Print the APE table of missions from their MCAP files (`dyfos-rover --mcap`, the demo's `mission-*.mcap`).
    Ape(ape::ApeArgs),
    /// Search a scenario file offline and print the answer as JSON.
    Solve(offline::SolveArgs),
    /// Evaluate one candidate x = (ρ, ψ, φ, ψ_v) of a scenario and print the verdict as JSON.
    Eval(offline::EvalArgs),
    /// Ask a running dyfosd: upload the scenario's map, query its rover, print the answer as `solve` does.
    Query(online::QueryArgs),
    /// Create, upload, change, print or delete a map held by dyfosd.
    #[command(subcommand)]
    Map(online::MapCommand),
    /// Print dyfosd's health and counters as JSON.
    Stats(online::StatsArgs),
    /// Re-run every query of a recording (`dyfosd --record`) against this build and
    /// report, per query, whether the answer is bit-identical.
    Replay(replay::ReplayArgs),
    /// Simulate camera measurements for training the learned SDSMM.
    TrainData(train::TrainDataArgs),
    /// Train the learned SDSMM on a data set (needs a build with `--features train`).
    Train(train::TrainArgs),
}

/// An error with the exit code it deserves.
#[derive(Debug)]
pub struct Failure {
    code: u8,
    error: anyhow::Error,
}

impl Failure {
    /// Bad input: exit 2.
    pub fn invalid(error: impl Into<anyhow::Error>) -> Self {
        Failure { code: 2, error: error.into() }
    }

    /// No feasible pose: exit 3.
    pub fn infeasible(error: impl Into<anyhow::Error>) -> Self {
        Failure { code: 3, error: error.into() }
    }
}

impl<E: Into<anyhow::Error>> From<E> for Failure {
    fn from(error: E) -> Self {
        Failure { code: 1, error: error.into() }
    }
}

/// Prints a JSON object with one top-level field per line and each value compact,
/// which reads well in a terminal and still parses as JSON.
pub fn print_json(value: &serde_json::Value) {
    let Some(object) = value.as_object() else {
        println!("{value}");
        return;
    };
    let fields: Vec<String> =
        object.iter().map(|(k, v)| format!("  {}: {v}", serde_json::Value::from(k.as_str()))).collect();
    println!("{{\n{}\n}}", fields.join(",\n"));
}

fn run(cli: Cli) -> Result<(), Failure> {
    match cli.command {
        Command::Demo(args) => demo::demo(&args),
        Command::Ape(args) => ape::ape(&args),
        Command::Solve(args) => offline::solve(&args),
        Command::Eval(args) => offline::eval(&args),
        Command::Query(args) => online::query(&args),
        Command::Map(command) => online::map(&command),
        Command::Stats(args) => online::stats(&args),
        Command::Replay(args) => replay::replay(&args),
        Command::TrainData(args) => train::train_data(&args),
        Command::Train(args) => train::train(&args),
    }
}

fn main() -> ExitCode {
    match run(Cli::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(f) => {
            eprintln!("dyfos: {:#}", f.error);
            ExitCode::from(f.code)
        }
    }
}

dyfos_process::numeric_flags_test!(super::Cli);
