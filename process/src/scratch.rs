//! A scratch directory for a test: fresh, named after the test and the process so
//! that parallel runs do not collide, and removed when dropped (a failing test's
//! too).

use std::path::PathBuf;

/// A fresh directory `dyfos-NAME-PID` under the system's temporary directory,
/// removed on drop.
pub struct Scratch(pub PathBuf);

impl Scratch {
    /// Makes the directory, empty (what an earlier run of the same name left is removed).
    pub fn new(name: &str) -> Scratch {
        let dir = std::env::temp_dir().join(format!("dyfos-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("scratch dir");
        Scratch(dir)
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}
