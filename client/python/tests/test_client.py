"""The binding against a real ``dyfosd``: answers, maps, parameters, numpy, threads."""

from __future__ import annotations

import copy
import json
import subprocess
import threading
from pathlib import Path
from typing import Any, Dict

import pytest

import dyfos
from conftest import DATA, DYFOS, Daemon, dyfos_cli, slow_scenario, write_json

EXAMPLE = DATA / "example.json"
BASIN = DATA / "anisotropic-mirror-basin.json"


def bits(value: Any) -> Any:
    """``value`` with every float as its exact bits (``float.hex``), so that equality
    means bit for bit, and ``0.0`` differs from ``-0.0`` and from the integer 0."""
    if isinstance(value, float):
        return ("float", value.hex())
    if isinstance(value, bool) or isinstance(value, (int, str)) or value is None:
        return (type(value).__name__, value)
    if isinstance(value, list):
        return [bits(v) for v in value]
    if isinstance(value, dict):
        return [(k, bits(v)) for k, v in value.items()]
    raise TypeError(f"unexpected {type(value)}")


def without_micros(answer: Dict[str, Any]) -> Dict[str, Any]:
    """An answer without ``micros`` (the search's run time differs between runs)."""
    out = dict(answer)
    del out["micros"]
    return out


def query(client: dyfos.Client, scenario: Path, **kwargs: Any) -> dyfos.Answer:
    s = dyfos.read_scenario(scenario)
    map_id = client.upload_scenario(scenario)
    return client.rendezvous(map_id, s["rover"]["mean"], s["rover"]["cov"], params=s.get("params"), **kwargs)


@pytest.mark.parametrize(
    "scenario, algorithm, seed",
    [
        (EXAMPLE, "dyfos", 1),
        (EXAMPLE, "dyfos", 7),
        (EXAMPLE, "dyfos-scipy", 3),
        (EXAMPLE, "random", 2),
        (EXAMPLE, "center", 5),
        (EXAMPLE, "brute", 0),
        (BASIN, "dyfos", 11),
        (BASIN, "dyfos-scipy", 4),
        (BASIN, "center", 9),
    ],
)
def test_answers_equal_dyfos_solve_bit_for_bit(
    client: dyfos.Client, scenario: Path, algorithm: str, seed: int
) -> None:
    expected = dyfos_cli("solve", str(scenario), "--algo", algorithm, "--seed", str(seed))
    answer = query(client, scenario, algorithm=algorithm, seed=seed)
    got = answer.to_dict()
    assert list(got) == list(expected), "the same keys in the same order"
    assert bits(without_micros(got)) == bits(without_micros(expected))
    assert json.loads(answer.to_json()) == got
    # The attributes are the dict's entries.
    for key, value in got.items():
        assert bits(getattr(answer, key)) == bits(value), key
    assert answer.algorithm == algorithm
    assert answer.stop in ("finished", "max_generations")


def test_answer_equals_dyfos_query_through_the_rust_client(daemon: Any, client: dyfos.Client) -> None:
    expected = dyfos_cli("query", str(BASIN), "--algo", "dyfos", "--seed", "3", *daemon.flags())
    got = query(client, BASIN, algorithm="dyfos", seed=3).to_dict()
    assert bits(without_micros(got)) == bits(without_micros(expected))


def test_parameters_left_out_are_the_spec_defaults(client: dyfos.Client, tmp_path: Path) -> None:
    scenario = dyfos.read_scenario(BASIN)
    scenario.pop("params", None)
    no_params = write_json(tmp_path, "no-params.json", scenario)
    expected = without_micros(dyfos_cli("solve", str(no_params), "--seed", "5"))
    map_id = client.upload_scenario(no_params)
    mean, cov = scenario["rover"]["mean"], scenario["rover"]["cov"]
    for params in (None, {}):
        got = client.rendezvous(map_id, mean, cov, seed=5, params=params).to_dict()
        assert bits(without_micros(got)) == bits(expected), params

    # One parameter given, the others at their defaults, as in a scenario's `params`.
    scenario["params"] = {"lambda": 2.0, "rho_max": 7.5}
    some = write_json(tmp_path, "some-params.json", scenario)
    expected_some = without_micros(dyfos_cli("solve", str(some), "--seed", "5"))
    got = client.rendezvous(map_id, mean, cov, seed=5, params={"lambda": 2.0, "rho_max": 7.5}).to_dict()
    assert bits(without_micros(got)) == bits(expected_some)
    assert bits(expected_some) != bits(expected), "the parameters change the answer"


def test_numpy_arrays_are_accepted(client: dyfos.Client) -> None:
    np = pytest.importorskip("numpy")
    s = dyfos.read_scenario(EXAMPLE)
    map_id = client.upload_scenario(EXAMPLE)
    from_lists = client.rendezvous(map_id, s["rover"]["mean"], s["rover"]["cov"], seed=2).to_dict()
    for dtype in (np.float64, np.float32):
        mean = np.array(s["rover"]["mean"], dtype=np.float64).astype(dtype)
        cov = np.array(s["rover"]["cov"], dtype=np.float64).astype(dtype)
        got = client.rendezvous(map_id, mean, cov, seed=np.uint64(2)).to_dict()
        if dtype is np.float64:
            assert bits(without_micros(got)) == bits(without_micros(from_lists))
        else:
            assert got["algorithm"] == "dyfos"  # float32 rounds the belief: a valid, other answer
    # Tuples and numpy scalars in lists too; bounds and sun as arrays.
    mean = tuple(np.float64(v) for v in s["rover"]["mean"])
    assert client.check(map_id, mean, np.array(s["rover"]["cov"])) == 0
    assert client.create_map(0xA11CE, np.array([-5.0, -5.0, 5.0, 5.0]), np.array([0.5, 1.0])) == 0


def test_scenario_as_path_text_or_dict_gives_the_same_map(client: dyfos.Client) -> None:
    text = EXAMPLE.read_text()
    ids = {
        client.upload_scenario(EXAMPLE),
        client.upload_scenario(str(EXAMPLE)),
        client.upload_scenario(text),
        client.upload_scenario(json.loads(text)),
    }
    assert len(ids) == 1
    map_id = ids.pop()
    snap = client.snapshot(map_id)
    assert snap["map"] == map_id
    assert snap["bounds"] == json.loads(text)["bounds"]
    assert [o["id"] for o in snap["obstacles"]] == [1, 2]


def test_the_delta_file_of_every_kind_applies_as_with_dyfos_map_apply(
    client: dyfos.Client, daemon: Daemon, tmp_path: Path
) -> None:
    """The same file (docs/deltas.md's) through ``dyfos map apply`` and through
    ``Client.apply`` as a path, as JSON text and as a list: the same map each time,
    and the snapshots read back as scenario-like maps."""
    deltas = DATA / "deltas-every-kind.json"

    def cli(*args: str) -> Dict[str, Any]:
        out = subprocess.run([DYFOS, "map", *args, *daemon.flags()], capture_output=True, text=True, timeout=300)
        assert out.returncode == 0, out.stderr
        return json.loads(out.stdout)

    cli("create", "7007", "--bounds", "-10", "-10", "10", "10", "--sun", "0.7", "2.1")
    cli("apply", "7007", str(deltas), "--expected-version", "0")
    expected = cli("snapshot", "7007")
    assert expected["obstacles"] == [{"id": 1, "cylinder": {"x": 2.0, "y": 1.0, "radius": 0.5, "height": 10.0}}]
    assert expected["voxels"]["occupied"] == [[0, 0, 4], [0, 0, 5], [0, 0, 6], [1, 2, 4]]
    for n, given in enumerate([deltas, deltas.read_text(), json.loads(deltas.read_text())]):
        map_id = 7100 + n
        client.create_map(map_id, [-10, -10, 10, 10], (0.7, 2.1))
        assert client.apply(map_id, given, expected_version=0) == expected["version"]
        snap = client.snapshot(map_id)
        assert {**snap, "map": 7007} == expected, type(given)
    # A snapshot is a map description: it uploads as it is, to the same content.
    copy_id = client.upload_scenario(expected, map_id=7200)
    assert {**client.snapshot(copy_id), "map": 7007, "version": expected["version"]} == expected
    # Its obstacles and voxels are valid deltas as they stand.
    client.create_map(7201, [-20, -20, 20, 20], (0.5, 1.0))
    rebuilt = [{"upsert_obstacle": o} for o in expected["obstacles"]] + [{"set_voxels": expected["voxels"]}]
    client.apply(7201, rebuilt)
    assert {k: v for k, v in client.snapshot(7201).items() if k not in ("map", "version")} == {
        k: v for k, v in expected.items() if k not in ("map", "version")
    }


def test_map_life_cycle_create_apply_snapshot_check_delete(client: dyfos.Client, tmp_path: Path) -> None:
    map_id = 0xC0FFEE
    assert client.create_map(map_id, [-10, -10, 10, 10], (0.7, 2.1)) == 0
    cylinder = {"upsert_obstacle": {"id": 4, "cylinder": {"x": 2.0, "y": 1.0, "radius": 0.5, "height": 10.0}}}
    try:
        version = client.apply(map_id, [cylinder], expected_version=0)
    except dyfos.InvalidRequestError as e:
        pytest.fail(f"the delta format of `dyfos map apply` files: {e}")
    assert version == 1
    snap = client.snapshot(map_id)
    assert snap["version"] == 1 and [o["id"] for o in snap["obstacles"]] == [4]
    # Deltas as JSON text and as a file, like `dyfos map apply`.
    assert client.apply(map_id, json.dumps([{"set_sun": {"elevation": 0.5, "azimuth": 1.0}}])) == 2
    path = write_json(tmp_path, "deltas.json", [{"remove_obstacle": {"id": 4}}])
    assert client.apply(map_id, path, expected_version=2) == 3
    assert client.snapshot(map_id)["obstacles"] == []
    assert client.snapshot(map_id)["sun"] == {"elevation": 0.5, "azimuth": 1.0}

    mean, cov = [0.0, 0.0, 0.3], [[0.2, 0.05, 0.0], [0.05, 0.1, 0.0], [0.0, 0.0, 0.05]]
    # Check mode validates inline deltas on a copy: the stored map does not change.
    assert client.check(map_id, mean, cov, deltas=[cylinder], expected_version=3) == 4
    assert client.snapshot(map_id)["version"] == 3
    # A query's inline deltas change the stored map before the search.
    answer = client.rendezvous(map_id, mean, cov, seed=1, deltas=[cylinder], expected_version=3)
    assert answer.map_version == 4
    assert client.snapshot(map_id)["version"] == 4
    client.delete_map(map_id, expected_version=4)
    with pytest.raises(dyfos.UnknownMapError):
        client.snapshot(map_id)


def test_stats_count_what_was_served(client: dyfos.Client) -> None:
    before = client.stats()
    query(client, EXAMPLE, seed=1)
    after = client.stats()
    assert after["pid"] == before["pid"]
    assert after["queries_served"] == before["queries_served"] + 1
    assert set(after["latency_us"]) == {"p50", "p90", "p99", "max", "samples"}


def test_budget_and_deadline_reach_the_daemon(client: dyfos.Client) -> None:
    expected = dyfos_cli("solve", str(EXAMPLE), "--algo", "brute", "--budget", "300")
    answer = query(client, EXAMPLE, algorithm="brute", budget=300)
    assert bits(without_micros(answer.to_dict())) == bits(without_micros(expected))
    assert answer.stop == "budget"
    answer = query(client, EXAMPLE, algorithm="dyfos", seed=1, deadline=10.0)
    assert answer.stop == "finished"


def test_one_client_shared_by_threads(daemon: Any) -> None:
    s = dyfos.read_scenario(EXAMPLE)
    mean, cov, params = s["rover"]["mean"], s["rover"]["cov"], s["params"]
    seeds = list(range(6))
    with daemon.client() as c:
        map_id = c.upload_scenario(EXAMPLE)
        expected = {seed: without_micros(c.rendezvous(map_id, mean, cov, seed=seed, params=params).to_dict()) for seed in seeds}
        got: Dict[int, Any] = {}
        errors = []

        def work(seed: int) -> None:
            try:
                for _ in range(3):
                    assert c.check(map_id, mean, cov) == 0
                    got[seed] = without_micros(c.rendezvous(map_id, mean, cov, seed=seed, params=params).to_dict())
            except BaseException as e:  # noqa: BLE001 - reported below
                errors.append(e)

        threads = [threading.Thread(target=work, args=(seed,)) for seed in seeds]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        assert errors == []
        assert {k: bits(v) for k, v in got.items()} == {k: bits(v) for k, v in expected.items()}


def test_the_gil_is_released_while_a_query_waits(daemon: Any, tmp_path: Path) -> None:
    """While one thread waits in a long query, another runs Python and sees the daemon
    searching it: impossible if the waiting thread held the GIL."""
    scenario = slow_scenario()
    slow = write_json(tmp_path, "slow.json", scenario)
    mean, cov = scenario["rover"]["mean"], scenario["rover"]["cov"]
    with daemon.client() as waiting, daemon.client() as watcher:
        map_id = waiting.upload_scenario(slow)
        result: Dict[str, Any] = {}

        def long_query() -> None:
            try:
                result["answer"] = waiting.rendezvous(
                    map_id, mean, cov, algorithm="brute", params=scenario["params"], deadline=3.0
                )
            except BaseException as e:  # noqa: BLE001 - checked below
                result["error"] = e

        t = threading.Thread(target=long_query)
        t.start()
        seen_running_while_waiting = False
        while t.is_alive() and not seen_running_while_waiting:
            running = watcher.stats()["running"]
            seen_running_while_waiting = running >= 1 and t.is_alive()
        t.join()
        assert "error" not in result, result.get("error")
        assert seen_running_while_waiting
        assert result["answer"].stop == "deadline"


def test_close_and_context_manager(daemon: Any) -> None:
    with daemon.client() as c:
        assert not c.closed
        c.stats()
    assert c.closed
    c.close()  # idempotent
    with pytest.raises(dyfos.DyfosError) as e:
        c.stats()
    assert e.value.status == "client_closed"
    assert "closed" in repr(c)


def test_answer_to_dict_is_a_fresh_copy(client: dyfos.Client) -> None:
    answer = query(client, EXAMPLE, seed=1)
    d = answer.to_dict()
    saved = copy.deepcopy(d)
    d["x"][0] = 123.0
    assert answer.to_dict() == saved


def test_an_octomap_uploads_updates_and_answers_as_its_scenario(client: dyfos.Client) -> None:
    """``upload_octomap`` (path or bytes) makes the map the scenario naming the same
    ``.bt`` describes: ``dyfos solve`` of that scenario answers the same, bit for bit;
    voxel deltas update it; a file that is not a ``.bt`` is refused, naming why."""
    scenario = DATA / "octomap" / "geb079-scenario.json"
    s = dyfos.read_scenario(scenario)
    bt = DATA / "octomap" / "geb079.bt"
    kwargs: Dict[str, Any] = dict(bounds=s["bounds"], sun=(0.6, 2.4), origin=s["octomap"]["origin"])
    assert client.upload_octomap(0x0C70, bt, **kwargs) == 0
    assert client.upload_octomap(0x0C71, bt.read_bytes(), **kwargs) == 0
    got = client.rendezvous(0x0C70, s["rover"]["mean"], s["rover"]["cov"], params=s["params"], seed=4).to_dict()
    expected = dyfos_cli("solve", str(scenario), "--seed", "4")
    assert bits(without_micros(got)) == bits(without_micros(expected))
    snapshot = client.snapshot(0x0C71)
    assert len(snapshot["voxels"]["occupied"]) == 185_673
    voxels = {"resolution": snapshot["voxels"]["resolution"], "origin": snapshot["voxels"]["origin"]}
    freed = snapshot["voxels"]["occupied"][:10]
    version = client.apply(0x0C71, [{"set_voxels": {**voxels, "free": freed}}])
    assert version == 1
    assert len(client.snapshot(0x0C71)["voxels"]["occupied"]) == 185_673 - 10
    with pytest.raises(dyfos.InvalidRequestError) as refused:
        client.upload_octomap(0x0C72, scenario, **kwargs)
    assert "not an OctoMap .bt file" in str(refused.value)


def test_list_maps_walks_every_map_in_id_order(own_daemon: Any) -> None:
    """``list_maps`` describes each map as ``snapshot`` and ``dyfos map list`` do, both
    ends of the id range included; a deleted map is gone, one made again under its id
    has another generation."""
    d = own_daemon()
    top = 2**64 - 1
    with d.client() as client:
        assert client.list_maps() == []
        for n, map_id in enumerate([top, 0, 4242]):
            client.create_map(map_id, [-10 - n, -10, 10, 10], (0.7, 2.1))
        client.apply(4242, [{"clear": {}}, {"set_sun": {"elevation": 0.5, "azimuth": 1.0}}])
        listed = client.list_maps(timeout=30)
        assert [m["map"] for m in listed] == [0, 4242, top]
        assert [m["version"] for m in listed] == [0, 2, 0]
        for m in listed:
            snap = client.snapshot(m["map"])
            assert (m["version"], m["bounds"], m["sun"]) == (snap["version"], snap["bounds"], snap["sun"])
            assert isinstance(m["generation"], int) and m["generation"] != 0
        out = subprocess.run([DYFOS, "map", "list", *d.flags()], capture_output=True, text=True, timeout=300)
        assert out.returncode == 0, out.stderr
        assert [json.loads(line) for line in out.stdout.splitlines()] == listed
        client.delete_map(4242)
        assert [m["map"] for m in client.list_maps()] == [0, top]
        client.create_map(4242, [-10, -10, 10, 10], (0.7, 2.1))
        again = client.list_maps()[1]
        assert (again["map"], again["version"]) == (4242, 0) and again["generation"] != listed[1]["generation"]
