//! A client that goes away mid-query frees its worker: `dyfosd` abandons the
//! search (no reply, nobody to read it) and counts it in `queries_abandoned`.
//!
//! The doomed query is a `brute` search of [`dyfos_tests::slow_search_scenario`]
//! (4097 sight lines a candidate, each walking a voxel layer near its end): minutes
//! of search on two threads (brute evaluates far more candidates than `dyfos`), where the
//! daemon notices a gone client within milliseconds. Nothing here times anything:
//! the assertions are on the daemon's counters, polled with [`wait_for`].
//!
//! A query whose client leaves while it still waits for a worker is skipped when a
//! worker takes it, and counted the same way: every accepted query ends served,
//! failed or abandoned.

use dyfos_client::prelude::*;
use dyfos_shared::wire::rendezvous::Mode;
use dyfos_tests::{KillOnDrop, PATIENCE, RawClient, Sandbox, slow_search_scenario, wait_for, wait_for_stats};
use std::time::Duration;

fn brute(budget: Option<u64>) -> RendezvousRequest {
    let s = slow_search_scenario();
    RendezvousRequest { algorithm: Algorithm::Brute, budget, params: s.params, ..RendezvousRequest::new(1, s.belief) }
}

/// A file removed when dropped.
struct TempFile(std::path::PathBuf);

impl Drop for TempFile {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.0);
    }
}

fn abandoned(admin: &mut Client) -> u64 {
    admin.stats(PATIENCE).unwrap().queries_abandoned
}

/// Starts `dyfos query` on the slow scenario (a `brute` search) and waits until the
/// daemon searches for it. `dyfos query` uploads the scenario's world itself, under
/// an id of its own. The file is removed when the returned `TempFile` is dropped.
fn start_doomed_query(sandbox: &Sandbox, admin: &mut Client) -> (KillOnDrop, TempFile) {
    let file = TempFile(sandbox.state_dir.with_extension("slow.json"));
    std::fs::write(&file.0, slow_search_scenario().to_json()).unwrap();
    let child = KillOnDrop::new(sandbox.brute_query(&file.0, &[]));
    wait_for_stats(admin, "the doomed brute query to run", |s| s.running == 1);
    (child, file)
}

#[test]
fn a_killed_clients_search_is_abandoned_and_its_worker_serves_the_next() {
    let (sandbox, daemon, mut admin) = Sandbox::with_slow_daemon("abandon-kill");
    let (mut child, _file) = start_doomed_query(&sandbox, &mut admin);
    assert_eq!(abandoned(&mut admin), 0, "a search whose client is there goes on");
    child.kill(); // SIGKILL, and reap

    // iceoryx2 sees the killed client gone once its node is cleaned up: by the
    // daemon's housekeeping, or at once when a process of the domain creates a
    // node, as this new client does.
    let mut next = sandbox.client();
    wait_for_stats(&mut admin, "the orphaned search to be abandoned", |s| s.queries_abandoned == 1);
    wait_for_stats(&mut admin, "its worker to be free", |s| s.running == 0);

    // Two workers take one brute query at a time: this one runs on the freed slot.
    let answer = next.rendezvous(&brute(Some(2_000)), PATIENCE).expect("the next client is answered");
    assert_eq!(answer.evaluations.total, 2_000);
    let stats = admin.stats(PATIENCE).unwrap();
    assert_eq!((stats.queries_abandoned, stats.queries_served, stats.requests_failed), (1, 1, 0), "{stats:?}");
    let log = daemon.log();
    assert!(log.contains("query abandoned: its client has gone"), "{log}");

    // `dyfos stats` shows the counter.
    let out = sandbox.dyfos("stats").output().unwrap();
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).expect("stats JSON");
    assert_eq!(json["queries_abandoned"], 1, "{json}");
}

#[test]
fn a_client_that_stops_waiting_abandons_its_query() {
    let (sandbox, _daemon, mut admin) = Sandbox::with_slow_daemon("abandon-timeout");
    let mut impatient = sandbox.client();
    // The client gives up long before the search could end and drops its pending
    // response; no dead-node cleanup is needed to see that.
    let err = impatient.rendezvous(&brute(None), Duration::from_millis(200)).unwrap_err();
    assert!(matches!(err, RendezvousError::Timeout(_)), "{err}");
    wait_for_stats(&mut admin, "the search to be abandoned", |s| s.queries_abandoned == 1);
    wait_for_stats(&mut admin, "its worker to be free", |s| s.running == 0);
    // The same client is answered next, on the freed worker.
    let answer = impatient.rendezvous(&brute(Some(500)), PATIENCE).expect("answered after giving up once");
    assert_eq!(answer.evaluations.total, 500);
    assert_eq!(admin.stats(PATIENCE).unwrap().queries_served, 1);
}

/// Both workers search for one client and its third query waits. The client drops
/// that queued query, then a running one: the freed worker takes the queued query,
/// finds its client gone and skips it. Both count as abandoned. Before the skip was
/// counted, the count stayed at 1 and the wait below ran out.
#[test]
fn a_query_dropped_while_it_waits_for_a_worker_is_skipped_and_counted() {
    let (sandbox, _daemon, mut admin) = Sandbox::with_slow_daemon("abandon-queued");
    let raw = RawClient::open(&sandbox);
    let dyfos =
        RendezvousRequest { algorithm: Algorithm::Dyfos, deadline: Some(Duration::from_secs(600)), ..brute(None) };
    let send =
        |request: &RendezvousRequest, id: u64| raw.send(request.header(Mode::Solve, id, [0, 0]), &request.records());
    let running_brute = send(&brute(None), 1);
    let running_dyfos = send(&dyfos, 2);
    let queued = send(&dyfos, 3);
    wait_for_stats(&mut admin, "both workers to search with one query queued", |s| s.running == 2 && s.queued == 1);

    drop(queued);
    drop(running_dyfos);
    wait_for_stats(&mut admin, "the running search to be abandoned and the dropped queued query skipped", |s| {
        s.queries_abandoned == 2 && s.running == 1 && s.queued == 0
    });
    let stats = admin.stats(PATIENCE).unwrap();
    assert_eq!((stats.queries_served, stats.requests_failed), (0, 0), "{stats:?}");

    drop(running_brute);
    wait_for_stats(&mut admin, "the last search to be abandoned", |s| s.queries_abandoned == 3 && s.running == 0);
}

/// The daemon cleans up after a killed client by itself (its janitor thread, every
/// `HOUSEKEEPING`): with no other process of the domain starting meanwhile, the
/// killed client's search is still abandoned. The admin client's requests here are
/// answered at once, so its waits never run a cleanup either.
#[test]
fn the_daemon_cleans_up_after_a_killed_client_by_itself() {
    let (sandbox, daemon, mut admin) = Sandbox::with_slow_daemon("abandon-janitor");
    let (mut child, _file) = start_doomed_query(&sandbox, &mut admin);
    child.kill(); // SIGKILL, and reap
    wait_for_stats(&mut admin, "the orphaned search to be abandoned", |s| s.queries_abandoned == 1);
    // The janitor logs after its cleanup, which is what lets the IPC thread see the
    // client gone: the line may follow the abandonment by a moment.
    wait_for("the janitor to say it cleaned up", || {
        daemon.log().contains("removed resources of dead clients").then_some(())
    });
}
