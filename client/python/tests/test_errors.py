"""Every error family is raised, with the wire status and the daemon's sentence."""

from __future__ import annotations

import signal
import threading
import time
from pathlib import Path
from typing import Any, Dict, List, Type

import pytest

import dyfos
from conftest import DATA, PATIENCE, slow_scenario, wait_until, write_json

EXAMPLE = DATA / "example.json"
MEAN = [0.0, 0.0, 0.3]
COV = [[0.2, 0.05, 0.0], [0.05, 0.1, 0.0], [0.0, 0.0, 0.05]]


def raises(family: Type[dyfos.DyfosError], status: str, call: Any, *args: Any, **kwargs: Any) -> dyfos.DyfosError:
    """Calls ``call`` and checks it raised ``family`` with ``status`` and a detail."""
    with pytest.raises(family) as info:
        call(*args, **kwargs)
    e = info.value
    assert type(e) is family, f"{type(e).__name__}: {e}"
    assert e.status == status, str(e)
    assert isinstance(e.detail, str) and len(e.detail) > 10, e.detail
    assert str(e) == f"{status}: {e.detail}"
    return e


def infeasible_map(client: dyfos.Client, map_id: int) -> None:
    """A map filled by one tall box: the viewer collides wherever it goes."""
    client.create_map(map_id, [-10, -10, 10, 10], (0.7, 2.1))
    wall = {"upsert_obstacle": {"id": 1, "box": {"min": [-10.0, -10.0, 0.0], "max": [10.0, 10.0, 100.0]}}}
    client.apply(map_id, [wall])


def test_unknown_map(client: dyfos.Client) -> None:
    raises(dyfos.UnknownMapError, "unknown_map", client.rendezvous, 0xDEAD, MEAN, COV)
    raises(dyfos.UnknownMapError, "unknown_map", client.check, 0xDEAD, MEAN, COV)
    raises(dyfos.UnknownMapError, "unknown_map", client.snapshot, 0xDEAD)
    raises(dyfos.UnknownMapError, "unknown_map", client.apply, 0xDEAD, [{"clear": {}}])


def test_map_version_mismatch(client: dyfos.Client) -> None:
    map_id = client.upload_scenario(EXAMPLE)
    e = raises(dyfos.MapVersionMismatchError, "map_version_mismatch", client.rendezvous, map_id, MEAN, COV, expected_version=99)
    assert not e.retryable
    raises(dyfos.MapVersionMismatchError, "map_version_mismatch", client.apply, map_id, [], expected_version=99)


@pytest.mark.parametrize(
    "status, kwargs",
    [
        ("invalid_params", {"params": {"rho_mim": 2.0}}),
        ("invalid_params", {"params": {"rho_min": 7.0, "rho_max": 6.0}}),
        ("invalid_params", {"params": {"perimeter_points": 8.0}}),
        ("invalid_belief", {"cov": [[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0]]}),
        ("invalid_belief", {"mean": [float("nan"), 0.0, 0.0]}),
        ("invalid_algorithm", {"algorithm": "gradient-descent"}),
        ("malformed_request", {"mean": [0.0, 0.0]}),
        ("malformed_request", {"cov": [[1.0, 0.0], [0.0, 1.0]]}),
        ("malformed_request", {"budget": 0}),
        ("malformed_request", {"deadline": -1.0}),
        ("invalid_deadline", {"deadline": 7200.0}),
        ("unsupported_model", {"params": {"model": "learned"}}),
        ("malformed_delta", {"deltas": [{"NoSuchDelta": {}}]}),
        ("invalid_delta", {"deltas": [{"remove_obstacle": {"id": 99}}]}),
    ],
)
def test_invalid_requests(client: dyfos.Client, status: str, kwargs: Dict[str, Any]) -> None:
    map_id = client.upload_scenario(EXAMPLE)
    args = {"mean": MEAN, "cov": COV, **kwargs}
    e = raises(dyfos.InvalidRequestError, status, client.rendezvous, map_id, **args)
    assert isinstance(e, ValueError)
    assert not e.retryable
    # The same in check mode.
    raises(dyfos.InvalidRequestError, status, client.check, map_id, **args)


def test_invalid_map_requests(client: dyfos.Client, tmp_path: Path) -> None:
    map_id = 0x1BAD
    client.create_map(map_id, [-10, -10, 10, 10], (0.7, 2.1))
    raises(dyfos.InvalidRequestError, "map_exists", client.create_map, map_id, [-10, -10, 10, 10], (0.7, 2.1))
    e = raises(
        dyfos.InvalidRequestError,
        "invalid_delta",
        client.apply,
        map_id,
        [{"set_sun": {"elevation": 0.5, "azimuth": 1.0}}, {"remove_obstacle": {"id": 42}}],
    )
    assert e.index == 1
    assert client.snapshot(map_id)["version"] == 0, "a rejected batch changes nothing"
    e = raises(dyfos.InvalidRequestError, "malformed_delta", client.apply, map_id, "[{\"remove_obstacle\": 3}]")
    assert e.index == 0
    assert e.detail.startswith("deltas[0].remove_obstacle: invalid type: integer `3`, expected a JSON object"), e.detail
    assert 'a valid remove_obstacle: {"remove_obstacle": {"id": 2}}' in e.detail, e.detail
    # The spelling before docs/deltas.md: the kind's new name and an example of it.
    old = [{"set_sun": {"elevation": 0.5, "azimuth": 1.0}}, {"UpsertObstacle": {"id": 1, "obstacle": {}}}]
    e = raises(dyfos.InvalidRequestError, "malformed_delta", client.apply, map_id, old)
    assert e.index == 1
    assert e.detail.startswith("deltas[1]: unknown variant `UpsertObstacle`"), e.detail
    assert "(did you mean `upsert_obstacle`?)" in e.detail and 'a valid upsert_obstacle: {"upsert_obstacle": {"id": 1' in e.detail
    e = raises(dyfos.InvalidRequestError, "malformed_delta", client.apply, map_id, [{"set_sun": {"elevation": 0.5}}])
    assert e.detail.startswith("deltas[0].set_sun: missing field `azimuth`"), e.detail
    assert client.snapshot(map_id)["version"] == 0, "a malformed batch changes nothing"
    # Bounds and sun given as arguments get the daemon's code for them, as in C.
    raises(dyfos.InvalidRequestError, "invalid_delta", client.create_map, 0x2BAD, [10, 10, -10, -10], (0.7, 2.1))
    raises(dyfos.InvalidRequestError, "invalid_delta", client.create_map, 0x2BAD, [-10, -10, 10, 10], (5.0, 2.1))
    raises(dyfos.InvalidRequestError, "invalid_delta", client.apply, map_id, [{"set_sun": {"elevation": 5.0, "azimuth": 2.1}}])
    raises(dyfos.InvalidRequestError, "invalid_scenario", client.upload_scenario, {"bounds": [0, 0, 1, 1]})
    bad = dyfos.read_scenario(EXAMPLE)
    bad["params"] = {"rho_min": 9.0, "rho_max": 6.0}
    e = raises(dyfos.InvalidRequestError, "invalid_scenario", client.upload_scenario, write_json(tmp_path, "bad.json", bad))
    assert "params.rho_min" in e.detail
    raises(dyfos.InvalidRequestError, "invalid_scenario", client.upload_scenario, tmp_path / "missing.json")
    other = dyfos.read_scenario(EXAMPLE)
    other["sun"]["azimuth"] = 1.0
    raises(dyfos.InvalidRequestError, "map_exists", client.upload_scenario, other, map_id=map_id)


def test_no_feasible_pose(client: dyfos.Client) -> None:
    infeasible_map(client, 0xF00)
    e = raises(dyfos.NoFeasiblePoseError, "no_feasible_pose", client.rendezvous, 0xF00, MEAN, COV, algorithm="dyfos")
    assert e.map_version == 1  # the map as it is: create (0), one wall (1)


def test_a_failed_query_tells_the_version_its_inline_deltas_made(client: dyfos.Client) -> None:
    infeasible_map(client, 0xF02)
    sun = {"set_sun": {"elevation": 0.5, "azimuth": 1.0}}
    e = raises(
        dyfos.NoFeasiblePoseError, "no_feasible_pose", client.rendezvous, 0xF02, MEAN, COV, deltas=[sun, sun]
    )
    assert e.map_version == 3, "the two inline deltas stay applied"
    stale = raises(
        dyfos.MapVersionMismatchError, "map_version_mismatch", client.rendezvous, 0xF02, MEAN, COV, expected_version=1
    )
    assert stale.map_version == 3
    unknown = raises(dyfos.UnknownMapError, "unknown_map", client.rendezvous, 0xF03, MEAN, COV)
    assert unknown.map_version is None


def test_deadline_exceeded(client: dyfos.Client) -> None:
    infeasible_map(client, 0xF01)
    raises(
        dyfos.DeadlineExceededError,
        "deadline_exceeded",
        client.rendezvous,
        0xF01,
        MEAN,
        COV,
        algorithm="brute",
        deadline=0.001,
    )


def test_over_capacity(client: dyfos.Client) -> None:
    map_id = client.upload_scenario(EXAMPLE)
    too_many = [{"set_sun": {"elevation": 0.5, "azimuth": 1.0}}] * 1025
    raises(dyfos.BusyError, "over_capacity", client.rendezvous, map_id, MEAN, COV, deltas=too_many)


def test_local_timeout(client: dyfos.Client, tmp_path: Path) -> None:
    s = slow_scenario()
    map_id = client.upload_scenario(s)
    e = raises(
        dyfos.DyfosTimeoutError,
        "timeout",
        client.rendezvous,
        map_id,
        s["rover"]["mean"],
        s["rover"]["cov"],
        algorithm="brute",
        params=s["params"],
        timeout=0.2,
    )
    assert isinstance(e, TimeoutError)
    # The client is still usable, and the daemon abandons the search nobody waits for.
    assert client.check(map_id, MEAN, COV) == 0
    deadline = time.monotonic() + PATIENCE
    while client.stats()["running"] > 0:
        assert time.monotonic() < deadline, "the abandoned search still runs"
        time.sleep(0.01)


def test_no_daemon() -> None:
    e = raises(
        dyfos.DaemonGoneError,
        "no_daemon",
        dyfos.Client,
        prefix="py-nobody-serves-this/",
        domain="dypnobody_",
        timeout=0.05,
    )
    assert isinstance(e, ConnectionError)
    assert e.retryable
    assert "dyfosd --prefix py-nobody-serves-this/" in e.detail
    raises(dyfos.InvalidRequestError, "invalid_prefix", dyfos.Client, prefix="no spaces/", timeout=0.05)
    raises(dyfos.InvalidRequestError, "invalid_domain", dyfos.Client, domain="a/b", timeout=0.05)


def test_client_closed(daemon: Any) -> None:
    c = daemon.client()
    c.close()
    e = raises(dyfos.DyfosError, "client_closed", c.check, 1, MEAN, COV)
    assert type(e) is dyfos.DyfosError


def test_busy_shutting_down_and_daemon_gone(own_daemon: Any, tmp_path: Path) -> None:
    """One worker, one queue slot: a third slow query is refused `busy`. A daemon
    told to stop refuses new work `shutting_down`; one killed mid-query leaves its
    client `daemon_gone`."""
    d = own_daemon("--workers", "1", "--set", "limits.max_queued=1")
    s = slow_scenario()
    mean, cov, params = s["rover"]["mean"], s["rover"]["cov"], s["params"]
    with d.client() as c:
        map_id = c.upload_scenario(s)
    results: List[Any] = [None] * 3

    def slow_query(i: int, deadline: float) -> None:
        with d.client() as c:
            try:
                results[i] = c.rendezvous(map_id, mean, cov, algorithm="brute", params=params, deadline=deadline)
            except dyfos.DyfosError as e:
                results[i] = e

    with d.client() as watcher:
        first = threading.Thread(target=slow_query, args=(0, 4.0))
        first.start()
        wait_until(lambda: watcher.stats()["running"] == 1)
        second = threading.Thread(target=slow_query, args=(1, 4.0))
        second.start()
        wait_until(lambda: watcher.stats()["queued"] == 1)
        slow_query(2, 4.0)
        e = results[2]
        assert isinstance(e, dyfos.BusyError) and e.status == "busy", e
        assert e.retryable

        d.process.send_signal(signal.SIGTERM)
        # Once it sees the signal, the daemon finishes what it has (the deadlines bound
        # it) and refuses new work.
        deadline = time.monotonic() + PATIENCE
        while True:
            try:
                watcher.check(map_id, MEAN, COV)
            except dyfos.DyfosError as refused:
                e = refused
                break
            assert time.monotonic() < deadline, "the daemon kept taking work after SIGTERM"
            time.sleep(0.001)
        assert type(e) is dyfos.BusyError and e.status == "shutting_down", e
        assert e.retryable
        first.join()
        second.join()
    assert all(isinstance(r, (dyfos.Answer, dyfos.DyfosError)) for r in results[:2]), results

    # Killed mid-query: the waiting client sees the daemon go.
    d2 = own_daemon()
    with d2.client() as c:
        map_id = c.upload_scenario(s)
        result: Dict[str, Any] = {}

        def query() -> None:
            try:
                result["answer"] = c.rendezvous(map_id, mean, cov, algorithm="brute", params=params)
            except dyfos.DyfosError as e:
                result["error"] = e

        t = threading.Thread(target=query)
        t.start()
        with d2.client() as watcher:
            wait_until(lambda: watcher.stats()["running"] >= 1)
        d2.kill(signal.SIGKILL)
        t.join(PATIENCE)
        assert not t.is_alive()
        e = result.get("error")
        assert isinstance(e, dyfos.DaemonGoneError) and e.status == "daemon_gone", result
        assert e.retryable
