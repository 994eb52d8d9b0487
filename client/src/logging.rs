//! Logging setup shared by the dyfos binaries (`dyfosd`, `dyfos-rover`,
//! `dyfos-viewer`).
//!
//! ```no_run
//! dyfos_client::logging::init();
//! tracing::info!("the log goes to stderr; RUST_LOG=debug shows more");
//! ```

use tracing_subscriber::EnvFilter;

/// Logs to stderr through `tracing`, filtered by `RUST_LOG` (default `info`), in
/// colour only on a terminal. iceoryx2 logs through `tracing` too (its `tracing`
/// feature); its own level comes from `IOX2_LOG_LEVEL` (default `Warn`), since at
/// `info` it reports every port it opens. A second call does nothing.
pub fn init() {
    let filter = EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new("info"));
    let ansi = std::io::IsTerminal::is_terminal(&std::io::stderr());
    let _ = tracing_subscriber::fmt().with_env_filter(filter).with_writer(std::io::stderr).with_ansi(ansi).try_init();
    iceoryx2::prelude::set_log_level_from_env_or(iceoryx2::prelude::LogLevel::Warn);
}
