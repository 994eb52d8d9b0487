//! Why a configuration was not taken.

use std::path::PathBuf;

/// Why a configuration was not taken. Each names the key and what to write
/// instead.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// The file cannot be read.
    #[error("cannot read {}: {source}", path.display())]
    Read {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The file is not TOML.
    #[error("{}: not a TOML file: {message}", path.display())]
    Syntax {
        /// The file.
        path: PathBuf,
        /// The parser's message, with the line.
        message: String,
    },
    /// A `--set` that is not `KEY=VALUE`.
    #[error(
        "--set `{0}`: write KEY=VALUE, e.g. `--set scheduling.cpu_latency_us=200` (`dyfosd --print-config` shows every key)"
    )]
    Set(String),
    /// A key that does not exist, or a value of the wrong type, in the file or a
    /// `--set`.
    #[error("{origin}: `{key}`: {message}")]
    Key {
        /// The file, or the `--set`.
        origin: String,
        /// The dotted key.
        key: String,
        /// What is wrong and what to write.
        message: String,
    },
    /// A value out of its range.
    #[error("{key} = {value} {rule}")]
    Invalid {
        /// The dotted key.
        key: &'static str,
        /// The value given.
        value: String,
        /// What it must be.
        rule: String,
    },
}
