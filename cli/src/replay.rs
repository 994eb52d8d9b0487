//! `dyfos replay FILE.mcap`: re-runs every query a recording daemon answered
//! (`dyfosd --record`) against this build and says, per query, whether the answer
//! is bit-identical. See `docs/record.md`. The flags and the exit code; the replay
//! itself is `dyfos_service::daemon::record::replay`.

use crate::Failure;
use anyhow::anyhow;
use dyfos_service::daemon::record::replay::{ReplayOptions, replay_file};
use std::path::PathBuf;

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

/// Replays every file; the exit code as documented on [`ReplayArgs`].
pub fn replay(args: &ReplayArgs) -> Result<(), Failure> {
    let options = ReplayOptions {
        set: overrides(&args.set)?,
        model: args.model.clone(),
        threads: args.threads.unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get())),
        quiet: args.quiet,
    };
    let mut different = 0;
    let mut incomplete = false;
    for file in &args.files {
        let t = replay_file(file, &options, &mut |line| println!("{line}")).map_err(Failure::invalid)?;
        different += t.different;
        incomplete |= t.incomplete();
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
