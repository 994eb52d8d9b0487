//! `dyfos ape FILE.mcap…`: the absolute position error of missions run by hand,
//! from the `/dyfos/ape` channel of their MCAP files (`dyfos-rover --mcap`, or the
//! demo's `mission-*.mcap`, in either profile), as the demo's table: one column per
//! file.

use crate::Failure;
use crate::demo::ape_table;
use anyhow::anyhow;
use dyfos_mission::eval::{ApeStats, ros2};
use std::path::{Path, PathBuf};

/// The channel holding the error of each sample (`dyfos.Ape`, field `ape_m`).
const APE_TOPIC: &str = "/dyfos/ape";

/// Arguments of `dyfos ape`.
#[derive(Debug, clap::Args)]
#[command(after_help = "Exit codes: 0 success; 2 a file that cannot be read, is not MCAP or has no /dyfos/ape.")]
pub struct ApeArgs {
    /// MCAP files of missions (`dyfos-rover --mcap FILE`, or the demo's `mission-*.mcap`).
    #[arg(required = true, value_name = "FILE.mcap")]
    pub files: Vec<PathBuf>,
}

/// `dyfos ape`.
pub fn ape(args: &ApeArgs) -> Result<(), Failure> {
    let mut columns = Vec::with_capacity(args.files.len());
    let mut samples = Vec::with_capacity(args.files.len());
    for path in &args.files {
        let stats = file_ape(path).map_err(Failure::invalid)?;
        let name = path.file_stem().map_or_else(|| path.display().to_string(), |s| s.to_string_lossy().into_owned());
        samples.push(format!("{name}: {}", stats.count));
        columns.push((name, vec![stats.centimetres()]));
    }
    let columns: Vec<(&str, Vec<[f64; 5]>)> = columns.iter().map(|(n, c)| (n.as_str(), c.clone())).collect();
    println!("Absolute position error of the rover, from {APE_TOPIC}:\n");
    print!("{}", ape_table(&columns));
    println!("\nSamples: {}", samples.join(", "));
    Ok(())
}

/// The APE statistics of one file's `/dyfos/ape` samples, in sample order (as the
/// demo takes them from its recorder).
fn file_ape(path: &Path) -> anyhow::Result<ApeStats> {
    let name = path.display();
    let bytes = std::fs::read(path).map_err(|e| anyhow!("cannot read {name}: {e}"))?;
    if !bytes.starts_with(mcap::MAGIC) {
        return Err(anyhow!("{name} is not an MCAP file (it does not start with MCAP's magic bytes)"));
    }
    let stream = mcap::MessageStream::new(&bytes).map_err(|e| anyhow!("{name} is not an MCAP file: {e}"))?;
    let mut errors: Vec<(u64, f64)> = Vec::new();
    for (index, message) in stream.enumerate() {
        let message = message.map_err(|e| anyhow!("{name}: unreadable after {index} messages: {e}"))?;
        if message.channel.topic != APE_TOPIC {
            continue;
        }
        let (sample, ape) = if message.channel.message_encoding == "cdr" {
            // The ROS 2 profile (`--mcap-profile ros2`).
            let (sample, ape) =
                ros2::decode_ape(&message.data).map_err(|e| anyhow!("{name}: message {index} on {APE_TOPIC}: {e}"))?;
            (Some(sample), Some(ape))
        } else {
            let value: serde_json::Value = serde_json::from_slice(&message.data)
                .map_err(|e| anyhow!("{name}: message {index} on {APE_TOPIC} is not JSON: {e}"))?;
            (value["sample"].as_u64(), value["ape_m"].as_f64())
        };
        let (Some(sample), Some(ape)) = (sample, ape.filter(|v| v.is_finite() && *v >= 0.0)) else {
            return Err(anyhow!(
                "{name}: message {index} on {APE_TOPIC} needs `sample` (an integer) and `ape_m` (metres, ≥ 0)"
            ));
        };
        errors.push((sample, ape));
    }
    errors.sort_by_key(|(sample, _)| *sample);
    errors.dedup_by_key(|(sample, _)| *sample);
    let errors: Vec<f64> = errors.into_iter().map(|(_, e)| e).collect();
    ApeStats::from_errors(&errors).ok_or_else(|| {
        anyhow!(
            "{name} has no {APE_TOPIC} messages: write the file with `dyfos-rover --mcap` (the rover knows the error) or `dyfos demo`"
        )
    })
}
