//! The `learned` SDSMM's life outside the hot path: simulated training data
//! ([`generate`], [`DataSet`]), loading a model file ([`load_model`]) and, in builds
//! with the `train` feature, training with candle (`train`).
//!
//! The forward pass itself lives in `dyfos_shared::sdsmm::Learned`; this module only
//! moves bytes between files and it.
//!
//! ```no_run
//! use dyfos_service::learned::load_model;
//! use dyfos_shared::prelude::*;
//!
//! let weights = load_model("model.bin".as_ref()).unwrap();
//! let params = Params { model: ModelKind::Learned, ..Params::default() };
//! let model = NoiseModel::from_params_and_weights(&params, Some(&weights)).unwrap();
//! # let _ = model;
//! ```

mod data;
#[cfg(feature = "train")]
pub mod train;

pub use data::{COLUMNS, DataSet, DataSetError, DataSpec, Sample, generate, mean_nll, sample_nll};

use dyfos_shared::sdsmm::{Learned, LearnedModelError};
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Why a model file cannot be loaded.
#[derive(Debug, thiserror::Error)]
pub enum ModelLoadError {
    /// The file cannot be read (missing, no permission, …).
    #[error("cannot read model file {}: {source}; train one with `dyfos train --data DATA --out MODEL`", path.display())]
    Read {
        /// The path tried.
        path: PathBuf,
        /// The I/O error.
        #[source]
        source: std::io::Error,
    },
    /// The bytes are not a usable model.
    #[error("model file {} {source}", path.display())]
    Invalid {
        /// The path read.
        path: PathBuf,
        /// What is wrong.
        #[source]
        source: LearnedModelError,
    },
}

/// Reads and checks a model file (written by `dyfos train`): a missing, truncated,
/// corrupt or wrong-shaped file is an error here, never later.
pub fn load_model(path: &Path) -> Result<Arc<Learned>, ModelLoadError> {
    let bytes = std::fs::read(path).map_err(|source| ModelLoadError::Read { path: path.to_owned(), source })?;
    Learned::from_bytes(&bytes)
        .map(Arc::new)
        .map_err(|source| ModelLoadError::Invalid { path: path.to_owned(), source })
}

#[cfg(test)]
mod tests {
    use super::*;
    use dyfos_process::scratch::Scratch;

    #[test]
    fn missing_and_corrupt_files_are_clear_errors() {
        let dir = Scratch::new("load-model");
        let missing = dir.0.join("missing.bin");
        let e = load_model(&missing).unwrap_err().to_string();
        assert!(e.contains("cannot read model file") && e.contains("missing.bin") && e.contains("dyfos train"), "{e}");
        let json = dir.0.join("scenario.json");
        std::fs::write(&json, b"{\"bounds\": [0, 0, 1, 1]}").unwrap();
        let e = load_model(&json).unwrap_err().to_string();
        assert!(e.contains("is not a dyfos model file"), "{e}");
    }
}
