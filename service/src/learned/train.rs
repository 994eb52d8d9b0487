//! Training the `learned` SDSMM with candle (CPU), in builds with the `train` feature.
//!
//! The network is the one `dyfos_shared::sdsmm::Learned` runs: inputs
//! `learned_input` standardised by the training set's mean and std, two `tanh`
//! layers of width `hidden`, three outputs (a, b, d) forming the Cholesky factor of R
//! in the line-of-sight frame. The loss is paper eq. 5's negative log-likelihood per
//! sample, `a + d + ½|L⁻¹e_los|² + ln 2π` (= `½(ln det R + eᵀR⁻¹e) + ln 2π`), with
//! `e_los = Rot(β)ᵀe`. Adam on shuffled mini-batches; the last `validation` fraction of
//! the data is held out; the learning rate halves after `plateau` epochs without a
//! better validation NLL and training stops after `patience`, keeping the best epoch.
//!
//! Seeded: the initial weights and the batch order come from one ChaCha8 stream
//! (candle cannot seed its CPU generator, so the weights are drawn here).
//!
//! ```no_run
//! use dyfos_service::learned::{generate, DataSpec, train::{train, TrainConfig}};
//!
//! let data = generate(&DataSpec { samples: 50_000, seed: 1, ..DataSpec::default() });
//! let trained = train(&data, &TrainConfig::default(), |e| println!("{e:?}")).unwrap();
//! std::fs::write("model.bin", trained.model.to_bytes()).unwrap();
//! ```

use super::data::{DataSet, Sample};
use candle_core::{DType, Device, Tensor, Var};
use candle_nn::{AdamW, Optimizer, ParamsAdamW};
use dyfos_shared::sdsmm::{
    LEARNED_INPUTS, LEARNED_OUTPUTS, LOG_STD_RANGE, Learned, LearnedModelError, LearnedWeights, MAX_HIDDEN,
    learned_input,
};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// How to train.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrainConfig {
    /// Width of both hidden layers (1..=64).
    pub hidden: usize,
    /// Most epochs.
    pub max_epochs: usize,
    /// Mini-batch size.
    pub batch: usize,
    /// Adam's initial learning rate.
    pub learning_rate: f64,
    /// Epochs without improvement before the learning rate halves.
    pub plateau: usize,
    /// Epochs without improvement before training stops.
    pub patience: usize,
    /// Fraction of the data held out for validation (the last samples).
    pub validation: f64,
    /// Seed of the initial weights and the batch order.
    pub seed: u64,
}

impl Default for TrainConfig {
    fn default() -> Self {
        TrainConfig {
            hidden: 48,
            max_epochs: 400,
            batch: 512,
            learning_rate: 3e-3,
            plateau: 6,
            patience: 25,
            validation: 0.2,
            seed: 0,
        }
    }
}

/// One epoch's figures.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EpochReport {
    /// 1-based epoch number.
    pub epoch: usize,
    /// Mean training NLL over the epoch's batches, nats per sample.
    pub train_nll: f64,
    /// Validation NLL after the epoch, nats per sample.
    pub validation_nll: f64,
    /// The learning rate used.
    pub learning_rate: f64,
    /// Whether this is the best validation NLL so far.
    pub improved: bool,
}

/// The outcome.
pub struct Trained {
    /// The best epoch's weights, ready for inference.
    pub model: Learned,
    /// The same weights inside candle (for checking the two against each other).
    pub network: Network,
    /// Every epoch.
    pub history: Vec<EpochReport>,
    /// The epoch whose weights were kept.
    pub best_epoch: usize,
    /// Training and validation sample counts.
    pub split: (usize, usize),
}

/// Why training failed.
#[derive(Debug, thiserror::Error)]
pub enum TrainError {
    /// Too little data to split.
    #[error(
        "the data set has {0} samples; training needs at least 10 (write more with `dyfos train-data --samples N`)"
    )]
    TooFewSamples(usize),
    /// A setting out of range.
    #[error("{0}")]
    Config(String),
    /// candle failed.
    #[error("candle: {0}")]
    Candle(#[from] candle_core::Error),
    /// The weights cannot be exported (e.g. training diverged to NaN).
    #[error("the trained weights are unusable: {0}")]
    Export(#[from] LearnedModelError),
}

/// The network's parameters as candle variables.
pub struct Network {
    hidden: usize,
    mean: Tensor,
    std: Tensor,
    w1: Var,
    b1: Var,
    w2: Var,
    b2: Var,
    w3: Var,
    b3: Var,
}

fn uniform(rng: &mut ChaCha8Rng, n: usize, bound: f32) -> Vec<f32> {
    (0..n).map(|_| (rng.random::<f32>() * 2.0 - 1.0) * bound).collect()
}

impl Network {
    fn init(
        hidden: usize,
        mean: [f32; LEARNED_INPUTS],
        std: [f32; LEARNED_INPUTS],
        out_bias: [f32; LEARNED_OUTPUTS],
        rng: &mut ChaCha8Rng,
        dev: &Device,
    ) -> candle_core::Result<Self> {
        // PyTorch's default bound 1/√fan_in; the output layer starts small so the first
        // predictions are the data's overall spread (`out_bias`).
        let k1 = 1.0 / (LEARNED_INPUTS as f32).sqrt();
        let k2 = 1.0 / (hidden as f32).sqrt();
        Ok(Network {
            hidden,
            mean: Tensor::from_slice(&mean, (1, LEARNED_INPUTS), dev)?,
            std: Tensor::from_slice(&std, (1, LEARNED_INPUTS), dev)?,
            w1: Var::from_vec(uniform(rng, hidden * LEARNED_INPUTS, k1), (hidden, LEARNED_INPUTS), dev)?,
            b1: Var::from_vec(uniform(rng, hidden, k1), hidden, dev)?,
            w2: Var::from_vec(uniform(rng, hidden * hidden, k2), (hidden, hidden), dev)?,
            b2: Var::from_vec(uniform(rng, hidden, k2), hidden, dev)?,
            w3: Var::from_vec(uniform(rng, LEARNED_OUTPUTS * hidden, 0.1 * k2), (LEARNED_OUTPUTS, hidden), dev)?,
            b3: Var::from_slice(&out_bias, LEARNED_OUTPUTS, dev)?,
        })
    }

    fn vars(&self) -> Vec<Var> {
        vec![self.w1.clone(), self.b1.clone(), self.w2.clone(), self.b2.clone(), self.w3.clone(), self.b3.clone()]
    }

    /// Raw (unstandardised) inputs `(N, 7)` → outputs `(N, 3)`.
    pub fn forward(&self, x: &Tensor) -> candle_core::Result<Tensor> {
        let x = x.broadcast_sub(&self.mean)?.broadcast_div(&self.std)?;
        let h1 = x.matmul(&self.w1.as_tensor().t()?)?.broadcast_add(self.b1.as_tensor())?.tanh()?;
        let h2 = h1.matmul(&self.w2.as_tensor().t()?)?.broadcast_add(self.b2.as_tensor())?.tanh()?;
        h2.matmul(&self.w3.as_tensor().t()?)?.broadcast_add(self.b3.as_tensor())
    }

    /// The outputs (a, b, d) candle computes for `inputs` (from `learned_input`).
    pub fn outputs(&self, inputs: &[[f64; LEARNED_INPUTS]]) -> candle_core::Result<Vec<[f64; LEARNED_OUTPUTS]>> {
        let flat: Vec<f32> = inputs.iter().flat_map(|r| r.iter().map(|v| *v as f32)).collect();
        let x = Tensor::from_vec(flat, (inputs.len(), LEARNED_INPUTS), self.mean.device())?;
        let out = self.forward(&x)?.to_vec2::<f32>()?;
        Ok(out.iter().map(|r| std::array::from_fn(|k| f64::from(r[k]))).collect())
    }

    fn snapshot(&self) -> candle_core::Result<Vec<Tensor>> {
        self.vars().iter().map(|v| v.as_tensor().copy()).collect()
    }

    fn restore(&self, saved: &[Tensor]) -> candle_core::Result<()> {
        for (v, t) in self.vars().iter().zip(saved) {
            v.set(t)?;
        }
        Ok(())
    }

    /// The weights as a `Learned` model, with a provenance note.
    pub fn to_learned(&self, note: String) -> Result<Learned, TrainError> {
        let flat2 = |v: &Var| -> candle_core::Result<Vec<f32>> { v.as_tensor().flatten_all()?.to_vec1::<f32>() };
        let mean = self.mean.flatten_all()?.to_vec1::<f32>()?;
        let std = self.std.flatten_all()?.to_vec1::<f32>()?;
        Ok(Learned::new(LearnedWeights {
            hidden: self.hidden,
            input_mean: std::array::from_fn(|i| mean[i]),
            input_std: std::array::from_fn(|i| std[i]),
            w1: flat2(&self.w1)?,
            b1: flat2(&self.b1)?,
            w2: flat2(&self.w2)?,
            b2: flat2(&self.b2)?,
            w3: flat2(&self.w3)?,
            b3: flat2(&self.b3)?,
            note,
        })?)
    }
}

/// Mean NLL of outputs `(N, 3)` against line-of-sight errors `(N, 2)`.
fn nll(out: &Tensor, e_los: &Tensor) -> candle_core::Result<Tensor> {
    let (lo, hi) = (LOG_STD_RANGE.0 as f32, LOG_STD_RANGE.1 as f32);
    let a = out.narrow(1, 0, 1)?.clamp(lo, hi)?;
    let b = out.narrow(1, 1, 1)?;
    let d = out.narrow(1, 2, 1)?.clamp(lo, hi)?;
    let e1 = e_los.narrow(1, 0, 1)?;
    let e2 = e_los.narrow(1, 1, 1)?;
    // L = [[exp a, 0], [b, exp d]]; y = L⁻¹e by forward substitution.
    let y1 = (e1 * a.neg()?.exp()?)?;
    let y2 = ((e2 - (&b * &y1)?)? * d.neg()?.exp()?)?;
    let quad = ((y1.sqr()? + y2.sqr()?)? * 0.5)?;
    let per_sample = ((a + d)? + quad)?;
    per_sample.mean_all()?.affine(1.0, std::f64::consts::TAU.ln())
}

/// Inputs `(N, 7)` and line-of-sight errors `(N, 2)` as f32 tensors.
fn tensors(samples: &[Sample], dev: &Device) -> candle_core::Result<(Tensor, Tensor)> {
    let mut x = Vec::with_capacity(samples.len() * LEARNED_INPUTS);
    let mut e = Vec::with_capacity(samples.len() * 2);
    for s in samples {
        x.extend(learned_input(&s.features).iter().map(|v| *v as f32));
        let (sb, cb) = s.features.bearing.sin_cos();
        let [ex, ey] = s.error;
        e.push((cb * ex + sb * ey) as f32);
        e.push((-sb * ex + cb * ey) as f32);
    }
    Ok((Tensor::from_vec(x, (samples.len(), LEARNED_INPUTS), dev)?, Tensor::from_vec(e, (samples.len(), 2), dev)?))
}

/// Per-column mean and std (std floored at 1e-6) of the network inputs.
fn standardisation(samples: &[Sample]) -> ([f32; LEARNED_INPUTS], [f32; LEARNED_INPUTS]) {
    let n = samples.len() as f64;
    let mut sum = [0f64; LEARNED_INPUTS];
    let mut sq = [0f64; LEARNED_INPUTS];
    for s in samples {
        for (i, v) in learned_input(&s.features).iter().enumerate() {
            sum[i] += v;
            sq[i] += v * v;
        }
    }
    let mean: [f64; LEARNED_INPUTS] = std::array::from_fn(|i| sum[i] / n);
    let std: [f64; LEARNED_INPUTS] = std::array::from_fn(|i| (sq[i] / n - mean[i] * mean[i]).max(0.0).sqrt().max(1e-6));
    (mean.map(|v| v as f32), std.map(|v| v as f32))
}

/// Trains on `data` (see the module doc); `on_epoch` sees every epoch's figures.
pub fn train(
    data: &DataSet,
    config: &TrainConfig,
    mut on_epoch: impl FnMut(&EpochReport),
) -> Result<Trained, TrainError> {
    if data.samples.len() < 10 {
        return Err(TrainError::TooFewSamples(data.samples.len()));
    }
    if !(1..=MAX_HIDDEN).contains(&config.hidden) {
        return Err(TrainError::Config(format!("--hidden {} must be in 1..={MAX_HIDDEN}", config.hidden)));
    }
    if !(config.validation > 0.0 && config.validation < 1.0) {
        return Err(TrainError::Config(format!("--validation {} must be in (0, 1)", config.validation)));
    }
    if config.batch == 0 || config.max_epochs == 0 {
        return Err(TrainError::Config("--batch and --epochs must be at least 1".into()));
    }
    if !(config.learning_rate.is_finite() && config.learning_rate > 0.0) {
        return Err(TrainError::Config(format!("--lr {} must be > 0", config.learning_rate)));
    }
    let dev = Device::Cpu;
    let mut rng = ChaCha8Rng::seed_from_u64(config.seed);
    let (train_set, val_set) = data.split(config.validation);
    let (mean, std) = standardisation(train_set);
    let (xs, es) = tensors(train_set, &dev)?;
    let (xv, ev) = tensors(val_set, &dev)?;
    // Start from the data's overall spread along and across the line of sight.
    let spread = es.sqr()?.mean(0)?.to_vec1::<f32>()?;
    let out_bias = [0.5 * spread[0].max(1e-12).ln(), 0.0, 0.5 * spread[1].max(1e-12).ln()];
    let network = Network::init(config.hidden, mean, std, out_bias, &mut rng, &dev)?;
    let params = ParamsAdamW { lr: config.learning_rate, weight_decay: 0.0, ..ParamsAdamW::default() };
    let mut opt = AdamW::new(network.vars(), params)?;

    let mut order: Vec<u32> = (0..train_set.len() as u32).collect();
    let mut history = Vec::new();
    let mut best = (f64::INFINITY, 0usize, network.snapshot()?);
    let mut since_best = 0;
    let mut lr = config.learning_rate;
    for epoch in 1..=config.max_epochs {
        for i in (1..order.len()).rev() {
            order.swap(i, rng.random_range(0..=i));
        }
        let (mut total, mut count) = (0.0, 0usize);
        for chunk in order.chunks(config.batch) {
            let idx = Tensor::from_slice(chunk, chunk.len(), &dev)?;
            let loss = nll(&network.forward(&xs.index_select(&idx, 0)?)?, &es.index_select(&idx, 0)?)?;
            opt.backward_step(&loss)?;
            total += f64::from(loss.to_scalar::<f32>()?) * chunk.len() as f64;
            count += chunk.len();
        }
        let validation_nll = f64::from(nll(&network.forward(&xv)?, &ev)?.to_dtype(DType::F32)?.to_scalar::<f32>()?);
        let improved = validation_nll < best.0 - 1e-5;
        if improved {
            best = (validation_nll, epoch, network.snapshot()?);
            since_best = 0;
        } else {
            since_best += 1;
        }
        let report =
            EpochReport { epoch, train_nll: total / count as f64, validation_nll, learning_rate: lr, improved };
        on_epoch(&report);
        history.push(report);
        if !validation_nll.is_finite() || since_best >= config.patience {
            break;
        }
        if since_best > 0 && since_best % config.plateau == 0 {
            lr *= 0.5;
            opt.set_learning_rate(lr);
        }
    }
    network.restore(&best.2)?;
    let note = format!(
        "dyfos train: {} training + {} validation samples, hidden {}, batch {}, lr {}, seed {}, best epoch {} of {}, validation NLL {:.5}",
        train_set.len(),
        val_set.len(),
        config.hidden,
        config.batch,
        config.learning_rate,
        config.seed,
        best.1,
        history.len(),
        best.0
    );
    let model = network.to_learned(note)?;
    Ok(Trained { model, network, history, best_epoch: best.1, split: (train_set.len(), val_set.len()) })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::learned::{DataSpec, generate, mean_nll};
    use dyfos_shared::sdsmm::{Paper, Synthetic};

    #[test]
    fn inference_matches_candle_and_training_learns() {
        let data = generate(&DataSpec { samples: 20_000, seed: 11, ..DataSpec::default() });
        let config = TrainConfig { hidden: 16, max_epochs: 10, batch: 256, ..TrainConfig::default() };
        let mut epochs = 0;
        let trained = train(&data, &config, |_| epochs += 1).unwrap();
        assert_eq!(epochs, trained.history.len());
        // The exported f32 forward pass agrees with candle's on held-out inputs.
        let (_, val) = data.split(config.validation);
        let inputs: Vec<_> = val.iter().map(|s| learned_input(&s.features)).collect();
        let candle = trained.network.outputs(&inputs).unwrap();
        for (input, want) in inputs.iter().zip(&candle) {
            let got = trained.model.forward(input);
            for k in 0..LEARNED_OUTPUTS {
                assert!((got[k] - want[k]).abs() < 1e-4, "{got:?} vs candle {want:?}");
            }
        }
        // candle's validation NLL is what the shared model scores in f64.
        let best = trained.history[trained.best_epoch - 1].validation_nll;
        assert!((mean_nll(&trained.model, val) - best).abs() < 1e-3, "{} vs {best}", mean_nll(&trained.model, val));
        // A few epochs already beat the linear model and approach the truth.
        let (learned, paper, truth) =
            (mean_nll(&trained.model, val), mean_nll(&Paper, val), mean_nll(&Synthetic::default(), val));
        assert!(learned < paper - 0.1 && learned < truth + 0.15, "learned {learned}, paper {paper}, truth {truth}");
    }

    #[test]
    fn same_seed_same_weights() {
        let data = generate(&DataSpec { samples: 600, seed: 12, ..DataSpec::default() });
        let config = TrainConfig { hidden: 8, max_epochs: 2, batch: 128, seed: 5, ..TrainConfig::default() };
        let a = train(&data, &config, |_| {}).unwrap().model;
        let b = train(&data, &config, |_| {}).unwrap().model;
        assert_eq!(a.to_bytes(), b.to_bytes());
        let c = train(&data, &TrainConfig { seed: 6, ..config }, |_| {}).unwrap().model;
        assert_ne!(a.weights().w1, c.weights().w1);
    }

    #[test]
    fn bad_settings_are_refused() {
        let data = generate(&DataSpec { samples: 5, seed: 1, ..DataSpec::default() });
        assert!(matches!(train(&data, &TrainConfig::default(), |_| {}), Err(TrainError::TooFewSamples(5))));
        let data = generate(&DataSpec { samples: 50, seed: 1, ..DataSpec::default() });
        let e = train(&data, &TrainConfig { hidden: 65, ..TrainConfig::default() }, |_| {}).err().unwrap();
        assert!(e.to_string().contains("--hidden 65"), "{e}");
    }
}
