//! Cheap requests do not wait for searches: with every worker busy
//! searching (and one more query queued), a check-mode query, a `stats` request
//! and a map snapshot are each answered while all the searches are still
//! unanswered; and a queued query of a second client is taken before the queued
//! one of a client that already has searches running (the fair queue), and does
//! not even wait for a running one to end (a search is held for it).
//!
//! The searches check 4097 sight lines a candidate (4096 perimeter points) on a map
//! whose voxel grid spans the whole search space at 5 cm (as in `daemon_abandon.rs`),
//! with a 10-minute deadline: far longer than
//! anything here waits. Nothing is timed: the assertions are on which replies
//! exist at a point of the exchange. The searches are given up at the end (their
//! pending replies dropped), which frees the workers.

use dyfos_client::prelude::*;
use dyfos_shared::wire::rendezvous::Mode;
use dyfos_tests::{PATIENCE, PendingRendezvous, RawClient, Sandbox, slow_search_scenario, wait_for_stats};
use std::time::Duration;

/// A long search of map 1.
fn search(algorithm: Algorithm, seed: u64) -> RendezvousRequest {
    let s = slow_search_scenario();
    RendezvousRequest {
        algorithm,
        seed,
        params: s.params,
        deadline: Some(Duration::from_secs(600)),
        ..RendezvousRequest::new(1, s.belief)
    }
}

fn send(raw: &RawClient, request: &RendezvousRequest, id: u64) -> PendingRendezvous {
    raw.send(request.header(Mode::Solve, id, [0, 0]), &request.records())
}

/// The searches that have been answered so far.
fn answered(pending: &[PendingRendezvous]) -> usize {
    pending.iter().filter(|p| p.receive().expect("receive").is_some()).count()
}

#[test]
fn cheap_requests_are_answered_while_every_worker_searches() {
    let (sandbox, _daemon, mut admin) = Sandbox::with_slow_daemon("cheap-first");

    // Two raw clients, each connected (one round trip) before anything is timed by
    // order. The first sends a brute search (it may hold all workers but one) and
    // two `dyfos` searches (one takes the other worker, one waits).
    let greedy = RawClient::open(&sandbox);
    let other = RawClient::open(&sandbox);
    for raw in [&greedy, &other] {
        let reply = raw.rendezvous(search(Algorithm::Dyfos, 0).header(Mode::Check, 9, [0, 0]), &[]);
        assert_eq!(reply.status, 0, "{reply:?}");
    }
    let pending = vec![
        send(&greedy, &search(Algorithm::Brute, 1), 1),
        send(&greedy, &search(Algorithm::Dyfos, 2), 2),
        send(&greedy, &search(Algorithm::Dyfos, 3), 3),
    ];
    wait_for_stats(&mut admin, "both workers to search with one query queued", |s| s.running == 2 && s.queued == 1);

    // Each cheap request is answered while no search is.
    let check = admin.check(&search(Algorithm::Dyfos, 4), PATIENCE).unwrap();
    assert_eq!(answered(&pending), 0, "a search finished before the check-mode query was answered");
    assert_eq!(check.map_version, admin.snapshot(1, PATIENCE).unwrap().version());
    assert_eq!(answered(&pending), 0, "a search finished before the map snapshot was answered");
    let stats = admin.stats(PATIENCE).unwrap();
    assert_eq!(answered(&pending), 0, "a search finished before the stats request was answered");
    assert_eq!((stats.running, stats.queued, stats.queries_served), (2, 1, 0), "{stats:?}");

    // A second client's query, queued after the first client's: a fair queue gives
    // it the next free worker. Free one by giving up the running `dyfos` search of
    // the first client (the daemon abandons it); its queued `dyfos` then stays
    // queued behind the second client's.
    let second = send(&other, &search(Algorithm::Dyfos, 5), 5);
    wait_for_stats(&mut admin, "the second client's query to queue", |s| s.queued == 2);
    let mut pending = pending;
    drop(pending.remove(1));
    wait_for_stats(&mut admin, "the given-up search to be abandoned and a worker to take the next query", |s| {
        s.queries_abandoned == 1 && s.running == 2 && s.queued == 1
    });
    // So the second client's search is the one running: giving it up abandons a
    // search. (First come, first served, it would still be queued, behind the
    // first client's, and nothing would be abandoned.) A worker that took it but was
    // slow to start it skips it instead, which counts the same.
    assert!(second.receive().unwrap().is_none(), "the second client's search runs (10-minute deadline)");
    drop(second);
    wait_for_stats(&mut admin, "the second client's running search to be abandoned", |s| s.queries_abandoned == 2);

    // Give the rest up: the workers go idle.
    drop(pending);
    wait_for_stats(&mut admin, "the searches to be abandoned", |s| s.running == 0 && s.queued == 0);
}

/// A client with no search running does not wait for another client's searches to
/// end: with both cores searching for a client that has three queries in flight,
/// a second client's short query (the example map) is answered while every one of
/// the first client's searches is still unanswered, because the daemon holds one
/// of them at its next checkpoint and runs the short query on its core. Without
/// holding, the short query waits for a greedy search to end and this test fails.
#[test]
fn a_second_clients_query_does_not_wait_for_a_greedy_clients_searches() {
    let (sandbox, _daemon, mut admin) = Sandbox::with_slow_daemon("hold");
    let example = dyfos_tests::scenario("example.json");
    admin.upload_map(2, &example.world, false, PATIENCE).unwrap();

    let greedy = RawClient::open(&sandbox);
    let reply = greedy.rendezvous(search(Algorithm::Dyfos, 0).header(Mode::Check, 9, [0, 0]), &[]);
    assert_eq!(reply.status, 0, "{reply:?}");
    let pending: Vec<_> = (1..=3).map(|i| send(&greedy, &search(Algorithm::Dyfos, i), i)).collect();
    wait_for_stats(&mut admin, "both workers to search with one query queued", |s| s.running == 2 && s.queued == 1);

    let mut other = sandbox.client();
    let short = RendezvousRequest { seed: 4, params: example.params, ..RendezvousRequest::new(2, example.belief) };
    let answer = other.rendezvous(&short, PATIENCE).expect("answered while the greedy client's searches run");
    assert_eq!(answer.map_version, admin.snapshot(2, PATIENCE).unwrap().version());
    assert_eq!(answered(&pending), 0, "a greedy search finished first");
    // The held search went on: two of the greedy client's run, one waits.
    wait_for_stats(&mut admin, "the held search to go on", |s| {
        s.running == 2 && s.queued == 1 && s.queries_served == 1
    });

    drop(pending);
    wait_for_stats(&mut admin, "the searches to be abandoned", |s| s.running == 0 && s.queued == 0);
}
