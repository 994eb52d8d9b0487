"""``dyfos.Voxels``, ``Client.upload_voxels`` / ``update_voxels`` and ``default_params``:
what a ROS node needs to keep a map in step with octomap_server."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any, Dict, List

import pytest

import dyfos
from conftest import DATA, dyfos_cli, write_json

GEB079 = DATA / "octomap" / "geb079.bt"
SCENARIO = DATA / "octomap" / "geb079-scenario.json"
ORIGIN = [0.0, 0.0, 0.32]
#: geb079.bt's cell side, m.
RES = 0.08


def tree_of(bt: bytes) -> Dict[str, Any]:
    """An ``octomap_msgs/Octomap``-shaped dict of a ``.bt`` file: what octomap_server
    publishes (the tree stream without the file's header)."""
    at = bt.index(b"\ndata\n") + len(b"\ndata\n")
    res = next(line.split()[1] for line in bt[:at].decode().splitlines() if line.startswith("res "))
    return {"binary": True, "id": "OcTree", "resolution": float(res), "data": bt[at:]}


def snapshot_cells(client: dyfos.Client, map_id: int) -> List[List[int]]:
    return sorted(client.snapshot(map_id)["voxels"]["occupied"])


def test_voxels_from_a_bt_its_message_form_and_its_cell_centres_are_one_map(client: dyfos.Client) -> None:
    bt = GEB079.read_bytes()
    from_file = dyfos.Voxels.from_octomap(GEB079, ORIGIN)
    from_message = dyfos.Voxels.from_octomap_message(tree_of(bt), ORIGIN)
    assert len(from_file) == len(from_message) == 185_673
    assert (from_file.resolution, from_file.origin) == (RES, ORIGIN)
    assert from_message.change_records(from_file) == 0
    client.upload_octomap(0x7001, bt, [-12, -8, 31, 10], (0.6, 2.4), ORIGIN)
    cells = snapshot_cells(client, 0x7001)
    centres = [[(c + 0.5) * RES for c in cell] for cell in cells]
    from_points = dyfos.Voxels.from_points(centres, RES, ORIGIN)
    assert from_points.change_records(from_file) == 0
    numpy = pytest.importorskip("numpy")
    assert dyfos.Voxels.from_points(numpy.array(centres), RES, ORIGIN).change_records(from_file) == 0


def test_upload_voxels_answers_as_the_scenario_and_update_voxels_sends_only_changes(
    client: dyfos.Client, tmp_path: Path
) -> None:
    """An uploaded ``Voxels`` is the map ``dyfos solve`` reads from the scenario; the next
    map goes as one atomic batch of the changed cells, and the result is the map of those
    cells, bit for bit in its answers."""
    s = dyfos.read_scenario(SCENARIO)
    first = dyfos.Voxels.from_octomap(GEB079, ORIGIN)
    assert client.upload_voxels(0x7002, first, s["bounds"], (0.6, 2.4)) == 0
    got = client.rendezvous(0x7002, s["rover"]["mean"], s["rover"]["cov"], params=s["params"], seed=4).to_dict()
    expected = dyfos_cli("solve", str(SCENARIO), "--seed", "4")
    del got["micros"], expected["micros"]
    assert got == expected
    cells = snapshot_cells(client, 0x7002)
    kept, added = cells[500:], [[400, 400, 3], [401, 400, 3]]
    second = dyfos.Voxels.from_points([[(c + 0.5) * RES for c in cell] for cell in kept + added], RES, ORIGIN)
    records = second.change_records(first)
    assert records is not None and 2 < records <= dyfos.MAX_DELTAS_PER_BATCH
    # Two deltas, freed cells then occupied ones: two versions.
    assert client.update_voxels(0x7002, first, second, expected_version=0) == 2
    assert snapshot_cells(client, 0x7002) == sorted(kept + added)
    assert client.update_voxels(0x7002, second, second, expected_version=2) is None, "nothing to send"
    with pytest.raises(dyfos.MapVersionMismatchError):
        client.update_voxels(0x7002, second, first, expected_version=0)
    assert snapshot_cells(client, 0x7002) == sorted(kept + added), "a refused batch changes nothing"
    scenario = {k: v for k, v in s.items() if k != "octomap"}
    scenario["voxels"] = {"resolution": RES, "origin": ORIGIN, "occupied": kept + added}
    expected = dyfos_cli("solve", str(write_json(tmp_path, "s.json", scenario)), "--seed", "4")
    got = client.rendezvous(0x7002, s["rover"]["mean"], s["rover"]["cov"], params=s["params"], seed=4).to_dict()
    del got["micros"], expected["micros"]
    assert {**got, "map_version": 0} == expected


def test_changes_that_do_not_fit_a_batch_or_another_grid_are_refused(client: dyfos.Client) -> None:
    first = dyfos.Voxels.from_octomap(GEB079, ORIGIN)
    client.upload_voxels(0x7003, first, [-12, -8, 31, 10], (0.6, 2.4))
    empty = dyfos.Voxels.from_points([], RES, ORIGIN)
    assert first.change_records(empty) is not None and first.change_records(empty) > dyfos.MAX_DELTAS_PER_BATCH
    with pytest.raises(dyfos.BusyError) as e:
        client.update_voxels(0x7003, first, empty, expected_version=0)
    assert e.value.status == "over_capacity" and "upload" in e.value.detail
    moved = dyfos.Voxels.from_octomap(GEB079, [0.0, 0.0, 0.0])
    assert moved.change_records(first) is None
    with pytest.raises(dyfos.InvalidRequestError) as e:
        client.update_voxels(0x7003, first, moved)
    assert e.value.status == "invalid_delta"
    assert client.upload_voxels(0x7003, empty, [-12, -8, 31, 10], (0.6, 2.4), replace=True) == 1
    assert client.snapshot(0x7003)["voxels"]["occupied"] == []


@pytest.mark.parametrize(
    "make, needle",
    [
        (lambda: dyfos.Voxels.from_octomap(b"not a tree"), "not an OctoMap .bt file"),
        (lambda: dyfos.Voxels.from_octomap_message({**tree_of(GEB079.read_bytes()), "binary": False}), "octomap_full"),
        (
            lambda: dyfos.Voxels.from_octomap_message({**tree_of(GEB079.read_bytes()), "id": "ColorOcTree"}),
            "ColorOcTree",
        ),
        (
            lambda: dyfos.Voxels.from_octomap_message({**tree_of(GEB079.read_bytes()), "id": "OcTree\nres 5"}),
            "not supported",
        ),
        (lambda: dyfos.Voxels.from_octomap_message({**tree_of(GEB079.read_bytes()[:-3])}), "truncated"),
        (lambda: dyfos.Voxels.from_octomap_message({**tree_of(GEB079.read_bytes() + b"\0\0")}), "corrupt"),
        (lambda: dyfos.Voxels.from_points([[0.0, float("nan"), 0.0]], 0.1), "finite"),
        (lambda: dyfos.Voxels.from_points([[1e9, 0.0, 0.0]], 0.1), "beyond"),
        (lambda: dyfos.Voxels.from_points([[0.0, 0.0, 0.0]], 0.0), "resolution"),
    ],
)
def test_maps_that_cannot_be_read_are_refused_naming_why(make: Any, needle: str) -> None:
    with pytest.raises(dyfos.InvalidRequestError) as e:
        make()
    assert e.value.status == "invalid_delta"
    assert needle in str(e.value), str(e.value)


def test_an_empty_message_is_an_empty_map() -> None:
    assert (
        len(dyfos.Voxels.from_octomap_message({"binary": True, "id": "OcTree", "resolution": 0.05, "data": b""})) == 0
    )


def test_default_params_are_the_spec_defaults(client: dyfos.Client, tmp_path: Path) -> None:
    """``default_params()`` names every SPEC §11 parameter, and a request with them
    explicitly is the same as one without."""
    d = dyfos.default_params()
    assert list(d) == [
        "rover_radius",
        "perimeter_points",
        "marker_size",
        "marker_height",
        "viewer_radius",
        "safety_margin",
        "z_min",
        "z_max",
        "camera_pitch",
        "t_vs",
        "f_h",
        "f_v",
        "rho_min",
        "rho_max",
        "kappa",
        "lambda",
        "model",
    ]
    assert (d["rho_max"], d["perimeter_points"], d["model"], d["t_vs"]) == (6.0, 8, "paper", [0.1, 0.0, -0.05])
    s = dyfos.read_scenario(DATA / "example.json")
    map_id = client.upload_scenario(DATA / "example.json")
    with_defaults = client.rendezvous(map_id, s["rover"]["mean"], s["rover"]["cov"], params=d, seed=3).to_dict()
    without = client.rendezvous(map_id, s["rover"]["mean"], s["rover"]["cov"], seed=3).to_dict()
    del with_defaults["micros"], without["micros"]
    assert json.dumps(with_defaults) == json.dumps(without)
    d["rho_max"] = 1.0
    assert dyfos.default_params()["rho_max"] == 6.0, "a new dict each call"
