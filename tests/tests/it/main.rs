//! The multi-process integration tests, one module per topic, linked into one test
//! binary (a binary per file linked the whole tree once each). Run one topic with
//! `cargo test -p dyfos-tests --test it map_service::`.
//!
//! The daemon, the `dyfos` command and the robots they start are the workspace's
//! own binaries; `dyfos_tests::bin` builds them once per run if they are missing.

mod compare;
mod daemon_abandon;
mod daemon_answers;
mod daemon_cheap_first;
mod daemon_config;
mod daemon_learned;
mod daemon_lifecycle;
mod daemon_priority;
mod daemon_validation;
mod floors;
mod hostile;
mod hosts;
mod map_json;
mod map_service;
mod mission;
mod mission_mcap;
mod octomap;
mod properties;
mod record_replay;
mod soak;
mod wire_doc;
mod wire_doc_python;
