//! The keys and flags of earlier versions, and what an error about one says to
//! write instead.

/// Keys of earlier versions, which had no tables and a flag per key, and where
/// each went: a dotted key, or why it is gone. An unknown key or flag that is here
/// gets this in its error.
pub(super) const FORMER_KEYS: [(&str, Former); 17] = [
    ("spin_us", Former::Moved("scheduling.poll_us")),
    ("spin_max_us", Former::Moved("scheduling.poll_max_us")),
    ("ipc_priority", Former::Moved("scheduling.ipc_priority")),
    ("worker_yield_us", Former::Moved("scheduling.worker_yield_us")),
    ("worker_slice_us", Former::Moved("scheduling.worker_slice_us")),
    ("cpu_latency_us", Former::Moved("scheduling.cpu_latency_us")),
    ("max_clients", Former::Moved("limits.max_clients")),
    ("max_requests_per_client", Former::Moved("limits.max_requests_per_client")),
    ("max_queued", Former::Moved("limits.max_queued")),
    ("upload_idle_timeout_s", Former::Moved("limits.upload_idle_timeout_s")),
    ("record", Former::Moved("recording.path")),
    ("record_max_bytes", Former::Moved("recording.max_bytes")),
    ("record_keep", Former::Moved("recording.keep")),
    (
        "worker_nice",
        Former::Removed(
            "the search workers run below the IPC thread by themselves where it may neither run real-time nor take a short time slice",
        ),
    ),
    ("queue", Former::Removed("the search queue is always fair across clients")),
    ("worker_batch", Former::Removed("search workers are SCHED_OTHER with a long time slice")),
    (
        "legacy_scheduling",
        Former::Removed(
            "to compare with an earlier daemon, build it in a git worktree (`dyfos-bench latency --compare-dyfosd`)",
        ),
    ),
];

#[derive(Debug, Clone, Copy)]
pub(super) enum Former {
    Moved(&'static str),
    Removed(&'static str),
}

/// What became of `dyfosd`'s former flag `flag` (`--spin-us`, `--queue=fifo`): a
/// sentence saying what to write instead, or `None` if it never was a flag.
pub fn former_flag(flag: &str) -> Option<String> {
    let name = flag.strip_prefix("--")?.split('=').next()?.replace('-', "_");
    match former(&name)? {
        Former::Moved(key) => Some(format!(
            "{flag} was replaced by the key `{key}`: write `--set {key}=VALUE`, or `{}` under `[{}]` in the --config file",
            key.rsplit_once('.').map_or(key, |(_, k)| k),
            key.split_once('.').map_or("", |(t, _)| t),
        )),
        Former::Removed(why) => Some(format!("{flag} was removed: {why}")),
    }
}

pub(super) fn former(key: &str) -> Option<Former> {
    FORMER_KEYS.iter().find(|(k, _)| *k == key).map(|(_, f)| *f)
}
