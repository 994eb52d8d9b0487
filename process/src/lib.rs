//! # dyfos-process
//!
//! The bottom floor of the dyfos processes: what every binary (`dyfosd`, `dyfos`,
//! `dyfos-rover`, `dyfos-viewer`, `dyfos-link`, `dyfos-bench`) and the client
//! library need of the operating system, and nothing of DyFOS itself. It depends on
//! no other dyfos crate.
//!
//! - [`idle`]: whether the machine has a core to spare, for the wait strategies of
//!   the daemon and the client;
//! - [`shutdown`]: Ctrl-C and SIGTERM noticed and latched, never fatal;
//! - [`abandoned`]: iceoryx2 services whose creator died creating them, removed;
//! - [`child`]: a child process killed when its owner lets go of it;
//! - [`netns`]: network namespaces standing for hosts on one machine (Linux);
//! - [`panic`]: what a caught panic said (the C boundary, the link's stop);
//! - [`scratch`]: a test's scratch directory, removed when dropped;
//! - [`logging`] (feature `logging`): the log on stderr, with its flood limit;
//! - [`cli`] (feature `cli`): the conventions every dyfos command line keeps.
//!
//! Both features are on by default; `dyfos-client` turns them off, so a robot that
//! links it compiles neither a log subscriber nor clap.
#![warn(missing_docs)]

// iceoryx2-bb-posix (signals, in `shutdown`) logs through iceoryx2-log, which
// needs a logger linked in; a process that links this crate but not iceoryx2 gets
// the one iceoryx2 would give it.
extern crate iceoryx2_bb_loggers as _;

pub mod abandoned;
pub mod child;
#[cfg(feature = "cli")]
pub mod cli;
pub mod idle;
#[cfg(feature = "logging")]
pub mod logging;
#[cfg(target_os = "linux")]
pub mod netns;
pub mod panic;
pub mod scratch;
pub mod shutdown;
