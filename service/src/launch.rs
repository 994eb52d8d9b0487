//! `dyfosd` as the programs that run one of their own start it (the integration
//! tests, `dyfos-bench`, `dyfos demo`): isolated by its service prefix, iceoryx2
//! domain and state directory, its log in a file, held in a [`KillOnDrop`] so it
//! cannot outlive them.
//!
//! ```no_run
//! use dyfos_service::launch::DyfosdCommand;
//! use std::path::Path;
//!
//! let log = std::fs::File::create("/tmp/dyfosd.log").unwrap();
//! let mut daemon = DyfosdCommand::new(Path::new("target/debug/dyfosd"), "demo/", Path::new("/tmp/demo-state"))
//!     .domain("demo_")
//!     .log("info", log)
//!     .spawn()
//!     .unwrap();
//! // ... connect a client with the same prefix and domain ...
//! daemon.terminate(std::time::Duration::from_secs(5));
//! ```

use dyfos_process::child::KillOnDrop;
use std::ffi::OsStr;
use std::fs::File;
use std::path::Path;
use std::process::{Command, Stdio};

/// A `dyfosd` command line: `--prefix`, `--state-dir`, optionally `--domain`, a log
/// level and file, further flags; stdin and stdout discarded.
#[derive(Debug)]
pub struct DyfosdCommand(Command);

impl DyfosdCommand {
    /// The `dyfosd` at `path`, serving under `prefix`, its state in `state_dir`.
    pub fn new(path: &Path, prefix: &str, state_dir: &Path) -> Self {
        let mut cmd = Command::new(path);
        cmd.args(["--prefix", prefix]).arg("--state-dir").arg(state_dir);
        cmd.stdin(Stdio::null()).stdout(Stdio::null());
        DyfosdCommand(cmd)
    }

    /// Its own iceoryx2 domain (shared-memory file prefix).
    pub fn domain(mut self, domain: &str) -> Self {
        self.0.args(["--domain", domain]);
        self
    }

    /// Logs at `level` (`RUST_LOG` syntax) to `file`.
    pub fn log(mut self, level: &str, file: File) -> Self {
        self.0.env("RUST_LOG", level).stderr(file);
        self
    }

    /// Further flags, after those above.
    pub fn args<I: IntoIterator<Item = S>, S: AsRef<OsStr>>(mut self, args: I) -> Self {
        self.0.args(args);
        self
    }

    /// Starts it.
    pub fn spawn(mut self) -> std::io::Result<KillOnDrop> {
        KillOnDrop::spawn(&mut self.0)
    }
}
