//! The priorities of `dyfosd`'s threads: the IPC thread sleeps at `SCHED_FIFO`
//! (`scheduling.ipc_priority`, default 10) where the system allows it, so cheap
//! queries preempt running searches (`bench/RESULTS.md`, "Why the scheduling
//! defaults"); the search workers stay at its nice level unless neither real-time
//! nor a short time slice is allowed, when they run 5 nice levels lower. Linux
//! only: read from `/proc`.

#![cfg(target_os = "linux")]

use dyfos_tests::{Sandbox, wait_for};

/// Nice value of every thread of `pid`, by thread name.
fn thread_nices(pid: u32) -> Vec<(String, i32)> {
    let mut out = Vec::new();
    for task in std::fs::read_dir(format!("/proc/{pid}/task")).expect("the daemon's threads").flatten() {
        let comm = std::fs::read_to_string(task.path().join("comm")).unwrap_or_default().trim().to_string();
        let stat = std::fs::read_to_string(task.path().join("stat")).unwrap_or_default();
        // Fields after the `(comm)`: state is field 3, nice field 19.
        let Some((_, rest)) = stat.rsplit_once(')') else { continue };
        if let Some(nice) = rest.split_whitespace().nth(16).and_then(|n| n.parse().ok()) {
            out.push((comm, nice));
        }
    }
    out
}

/// Scheduling policy and real-time priority of the thread called `name` of `pid`.
fn policy_of(pid: u32, name: &str) -> (u32, u32) {
    for task in std::fs::read_dir(format!("/proc/{pid}/task")).expect("the daemon's threads").flatten() {
        let comm = std::fs::read_to_string(task.path().join("comm")).unwrap_or_default().trim().to_string();
        let stat = std::fs::read_to_string(task.path().join("stat")).unwrap_or_default();
        let Some((_, rest)) = stat.rsplit_once(')') else { continue };
        let fields: Vec<&str> = rest.split_whitespace().collect();
        // rt_priority is field 40, policy 41.
        if comm == name {
            return (fields[38].parse().unwrap(), fields[37].parse().unwrap());
        }
    }
    panic!("no thread {name} in {pid}")
}

fn workers_and_main(pid: u32) -> (Vec<i32>, i32) {
    let threads = thread_nices(pid);
    let workers: Vec<i32> = threads.iter().filter(|(c, _)| c.starts_with("dyfos-worker")).map(|(_, n)| *n).collect();
    let main = threads.iter().find(|(c, _)| c == "dyfosd").map(|(_, n)| *n).expect("the IPC thread");
    (workers, main)
}

#[test]
fn the_ipc_thread_sleeps_real_time_and_the_workers_are_niced_only_as_a_fallback() {
    let sandbox = Sandbox::new("priority-default");
    let daemon = sandbox.start_daemon(&["--workers", "3"]);
    // Three workers and a spare for each: they run queries on the cores of held
    // searches.
    assert_eq!(workers_and_main(daemon.pid()).0.len(), 6, "{:?}", thread_nices(daemon.pid()));
    let mut client = sandbox.client();
    assert_eq!(client.stats(dyfos_tests::PATIENCE).unwrap().workers, 3);
    drop(client);
    let (workers, main) = workers_and_main(daemon.pid());
    if daemon.log().contains("the search workers are niced instead") {
        // Neither real-time (no CAP_SYS_NICE / RLIMIT_RTPRIO) nor a short slice.
        assert!(workers.iter().all(|n| *n == (main + 5).min(19)), "fallback: {workers:?} vs {main}");
    } else if daemon.log().contains("real-time priority 10 refused") {
        // A short time slice instead: the workers need no lowering.
        assert!(workers.iter().all(|n| *n == main), "short slice: {workers:?} vs {main}");
    } else {
        assert!(
            !workers.is_empty() && workers.iter().all(|n| *n == main),
            "default keeps them equal: {workers:?} vs {main}"
        );
        // Idle, the IPC thread sleeps real-time (SCHED_FIFO = 1, with
        // SCHED_RESET_ON_FORK not shown in /proc); the workers stay SCHED_OTHER = 0.
        wait_for("the IPC thread to sleep real-time", || (policy_of(daemon.pid(), "dyfosd") == (1, 10)).then_some(()));
        assert_eq!(policy_of(daemon.pid(), "dyfos-worker-0"), (0, 0));
        assert!(daemon.log().contains("SCHED_FIFO priority 10"), "{}", daemon.log());
    }
    drop(daemon);

    // Off: the IPC thread stays normal.
    let sandbox = Sandbox::new("ipc-priority-off");
    let daemon = sandbox.start_daemon(&["--set", "scheduling.ipc_priority=0"]);
    let mut client = sandbox.client();
    client.stats(dyfos_tests::PATIENCE).unwrap();
    std::thread::sleep(std::time::Duration::from_millis(50));
    assert_eq!(policy_of(daemon.pid(), "dyfosd"), (0, 0));
    let (workers, main) = workers_and_main(daemon.pid());
    assert!(workers.iter().all(|n| *n == main), "{workers:?} vs {main}");
}
