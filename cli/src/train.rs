//! `dyfos train-data` (simulated measurements for the learned SDSMM) and `dyfos train`
//! (fits it; needs the `train` feature, i.e. candle).

use crate::Failure;
use anyhow::Context;
use dyfos_service::learned::{DataSpec, generate};
use std::path::PathBuf;

/// Flags of `dyfos train-data`.
#[derive(Debug, clap::Args)]
pub struct TrainDataArgs {
    /// Where to write the data set.
    #[arg(long)]
    pub out: PathBuf,
    /// Number of simulated measurements.
    #[arg(long, default_value_t = 400_000)]
    pub samples: usize,
    /// Seed of the simulation: the same seed writes the same file.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
}

/// Flags of `dyfos train`.
#[derive(Debug, clap::Args)]
pub struct TrainArgs {
    /// Data set written by `dyfos train-data`.
    #[arg(long)]
    pub data: PathBuf,
    /// Where to write the model file (load it with `dyfos solve --model`).
    #[arg(long)]
    pub out: PathBuf,
    /// Width of the two hidden layers (1..=64).
    #[arg(long, default_value_t = 48)]
    pub hidden: usize,
    /// Most epochs.
    #[arg(long, default_value_t = 400)]
    pub epochs: usize,
    /// Mini-batch size.
    #[arg(long, default_value_t = 512)]
    pub batch: usize,
    /// Adam's initial learning rate.
    #[arg(allow_hyphen_values = true, long, default_value_t = 3e-3)]
    pub lr: f64,
    /// Stop after this many epochs without a better validation NLL.
    #[arg(long, default_value_t = 25)]
    pub patience: usize,
    /// Fraction of the data held out for validation (the last samples).
    #[arg(allow_hyphen_values = true, long, default_value_t = 0.2)]
    pub validation: f64,
    /// Seed of the initial weights and the batch order.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
}

/// `dyfos train-data`.
pub fn train_data(args: &TrainDataArgs) -> Result<(), Failure> {
    if args.samples == 0 {
        return Err(Failure::invalid(anyhow::anyhow!("--samples must be at least 1")));
    }
    let data = generate(&DataSpec { samples: args.samples, seed: args.seed, ..DataSpec::default() });
    std::fs::write(&args.out, data.to_bytes())
        .with_context(|| format!("cannot write data set {}", args.out.display()))?;
    eprintln!("dyfos: wrote {} samples to {}", data.samples.len(), args.out.display());
    Ok(())
}

/// Reads a data set; every problem is exit code 2.
#[cfg(feature = "train")]
fn load_data(path: &std::path::Path) -> Result<dyfos_service::learned::DataSet, Failure> {
    use dyfos_service::learned::DataSet;

    let bytes = std::fs::read(path)
        .with_context(|| {
            format!("cannot read data set {}; write one with `dyfos train-data --out FILE`", path.display())
        })
        .map_err(Failure::invalid)?;
    DataSet::from_bytes(&bytes).map_err(|e| Failure::invalid(anyhow::anyhow!("data set {} {e}", path.display())))
}

/// `dyfos train`, in a build without candle.
#[cfg(not(feature = "train"))]
pub fn train(_args: &TrainArgs) -> Result<(), Failure> {
    Err(Failure::from(anyhow::anyhow!(
        "`dyfos train` is not enabled in this build (it needs the candle training framework); \
         rebuild with `cargo build --release -p dyfos-cli --features train` and run `target/release/dyfos train`"
    )))
}

/// `dyfos train`: fits the learned SDSMM with a progress bar and the validation NLL
/// of every epoch.
#[cfg(feature = "train")]
pub fn train(args: &TrainArgs) -> Result<(), Failure> {
    use dyfos_service::learned::mean_nll;
    use dyfos_service::learned::train::{TrainConfig, TrainError, train};
    use dyfos_shared::sdsmm::Paper;
    use indicatif::{ProgressBar, ProgressStyle};

    let data = load_data(&args.data)?;
    let config = TrainConfig {
        hidden: args.hidden,
        max_epochs: args.epochs,
        batch: args.batch,
        learning_rate: args.lr,
        patience: args.patience,
        validation: args.validation,
        seed: args.seed,
        ..TrainConfig::default()
    };
    let bar = ProgressBar::new(args.epochs as u64);
    bar.set_style(
        ProgressStyle::with_template("{elapsed_precise} [{bar:30}] epoch {pos}/{len} {msg}")
            .map_err(anyhow::Error::from)?
            .progress_chars("=> "),
    );
    let trained = train(&data, &config, |e| {
        bar.set_position(e.epoch as u64);
        bar.set_message(format!("validation NLL {:.5}", e.validation_nll));
        let line = format!(
            "epoch {:4}  train NLL {:9.5}  validation NLL {:9.5}  lr {:.1e}{}",
            e.epoch,
            e.train_nll,
            e.validation_nll,
            e.learning_rate,
            if e.improved { "  *" } else { "" }
        );
        // A hidden bar (stderr not a terminal) swallows `println`: print plainly then.
        if bar.is_hidden() { eprintln!("{line}") } else { bar.println(line) }
    })
    .map_err(|e| match e {
        TrainError::TooFewSamples(_) | TrainError::Config(_) => Failure::invalid(e),
        other => Failure::from(other),
    })?;
    bar.finish_and_clear();
    std::fs::write(&args.out, trained.model.to_bytes())
        .with_context(|| format!("cannot write model file {}", args.out.display()))?;
    let (_, validation) = data.split(args.validation);
    eprintln!(
        "dyfos: best epoch {} of {}; validation NLL {:.5} (the linear `paper` model: {:.5}); wrote {} ({} training, {} validation samples)",
        trained.best_epoch,
        trained.history.len(),
        mean_nll(&trained.model, validation),
        mean_nll(&Paper, validation),
        args.out.display(),
        trained.split.0,
        trained.split.1,
    );
    Ok(())
}
