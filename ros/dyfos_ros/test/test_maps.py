"""Maps from the robot's mapping stack: octomap_server's ``octomap_msgs/Octomap`` and its
point cloud of occupied-cell centres, kept in the daemon's map ``map_id`` and updated as
deltas."""

from __future__ import annotations

import struct
from pathlib import Path
from typing import Any, Dict, List, Tuple

import dyfos
from conftest import DATA, LATCHED, Ros, dyfos_cli
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from dyfos_msgs.srv import FindSensorPose
from helpers import SERVICE, as_seen_by_the_node, assert_answer_is, eventually, request, solve, status_of
from octomap_msgs.msg import Octomap
from rcl_interfaces.srv import SetParameters
from rclpy.parameter import Parameter
from sensor_msgs.msg import PointCloud2, PointField

GEB079 = DATA / "octomap" / "geb079.bt"
SCENARIO = DATA / "octomap" / "geb079-scenario.json"
#: What an OctoMap lacks, from the scenario that names geb079.bt.
MAP_PARAMS = {"bounds": [-12.0, -8.0, 31.0, 10.0], "sun": [0.6, 2.4], "origin": [0.0, 0.0, 0.32]}


def geb079() -> Dict[str, Any]:
    """geb079's scenario, naming its .bt by an absolute path (solved from elsewhere)."""
    s = dyfos.read_scenario(SCENARIO)
    s["octomap"]["file"] = str(GEB079)
    return s


def tree(bt: bytes) -> Tuple[float, bytes]:
    """A ``.bt`` file's resolution and tree stream (what an Octomap message carries)."""
    at = bt.index(b"\ndata\n") + len(b"\ndata\n")
    res = next(line.split()[1] for line in bt[:at].decode().splitlines() if line.startswith("res "))
    return float(res), bt[at:]


def octomap_msg(bt: bytes, frame_id: str = "map") -> Octomap:
    """What octomap_server publishes on octomap_binary (octomap_msgs::binaryMapToMsg)."""
    res, data = tree(bt)
    msg = Octomap(binary=True, id="OcTree", resolution=res)
    msg.header.frame_id = frame_id
    msg.data = struct.unpack(f"{len(data)}b", data)
    return msg


def without_one_leaf(bt: bytes) -> bytes:
    """The same file with its last occupied node marked free: a valid tree, some cells fewer."""
    _res, data = tree(bt)
    head = bt[: len(bt) - len(data)]
    out = bytearray(data)
    for at in range(len(out) - 1, -1, -1):
        for child in range(3, -1, -1):
            if (out[at] >> (2 * child)) & 3 == 2:
                out[at] = out[at] & ~(3 << (2 * child)) | (1 << (2 * child))
                return head + bytes(out)
    raise AssertionError("no occupied node")


def cloud_msg(cells: List[List[int]], resolution: float, frame_id: str = "map") -> PointCloud2:
    """Occupied-cell centres as octomap_server's octomap_point_cloud_centers (PCL's
    PointXYZ: three float32 and 4 bytes of padding)."""
    msg = PointCloud2(height=1, width=len(cells), is_bigendian=False, point_step=16, is_dense=True)
    msg.header.frame_id = frame_id
    msg.row_step = 16 * len(cells)
    msg.fields = [PointField(name=n, offset=4 * k, datatype=PointField.FLOAT32, count=1) for k, n in enumerate("xyz")]
    msg.data = b"".join(struct.pack("<fff4x", *[(c + 0.5) * resolution for c in cell]) for cell in cells)
    return msg


def map_values(diagnostics: List[DiagnosticArray]) -> Dict[str, str]:
    if not diagnostics:
        return {}
    return {v.key: v.value for v in status_of(diagnostics[-1], "map").values}


def upload_with_the_cli(daemon: Any, map_id: int, bt: Path) -> None:
    args = ["--bounds", *map(str, MAP_PARAMS["bounds"]), "--sun", *map(str, MAP_PARAMS["sun"])]
    dyfos_cli(
        "map",
        "upload",
        str(map_id),
        "--octomap",
        str(bt),
        "--origin",
        *map(str, MAP_PARAMS["origin"]),
        *args,
        *daemon.flags(),
    )


def cells_of(client: dyfos.Client, map_id: int) -> List[List[int]]:
    return sorted(client.snapshot(map_id)["voxels"]["occupied"])


def test_an_octomap_message_is_the_map_dyfos_map_upload_makes_and_updates_as_deltas(
    ros: Ros, daemon: Any, start_node: Any, tmp_path: Path
) -> None:
    """geb079.bt as octomap_server publishes it: the node's map answers as the same file
    uploaded with ``dyfos map upload --octomap``, bit for bit; a later map with one node
    freed goes as deltas and leaves the cells that file has."""
    s = geb079()
    start_node(ros, daemon, map_id=0xC7, diagnostics_period=0.2, **MAP_PARAMS)
    diagnostics = ros.subscribe(DiagnosticArray, "/diagnostics")
    maps = ros.publisher(Octomap, "/octomap_binary", LATCHED)
    bt = GEB079.read_bytes()
    maps.publish(octomap_msg(bt))
    eventually(lambda: map_values(diagnostics).get("version") == "0", "the map to be uploaded", spin=ros)
    upload_with_the_cli(daemon, 0xC8, GEB079)
    with daemon.client() as client:
        seen = as_seen_by_the_node(s)["rover"]
        expected = client.rendezvous(0xC8, seen["mean"], seen["cov"], params=s["params"], seed=6).to_dict()
        req = request(0xC7, s, seed=6)
        assert_answer_is(ros.call(FindSensorPose, SERVICE, req), expected, req.belief)
        assert_answer_is(ros.call(FindSensorPose, SERVICE, req), solve(tmp_path, s, "dyfos", 6), req.belief)

        smaller = tmp_path / "smaller.bt"
        smaller.write_bytes(without_one_leaf(bt))
        maps.publish(octomap_msg(smaller.read_bytes()))
        eventually(lambda: map_values(diagnostics).get("updates") == "1", "the change to go as deltas", spin=ros)
        upload_with_the_cli(daemon, 0xC9, smaller)
        assert cells_of(client, 0xC7) == cells_of(client, 0xC9)
        assert len(cells_of(client, 0xC9)) < 185_673
        v = map_values(diagnostics)
        assert (v["uploads"], v["source"]) == ("1", "octomap")
        expected = client.rendezvous(0xC9, seen["mean"], seen["cov"], params=s["params"], seed=6).to_dict()
        got = ros.call(FindSensorPose, SERVICE, req)
        assert_answer_is(got, {**expected, "map_version": got.map_version}, req.belief)
        assert got.map_version > 0


def test_a_cloud_of_cell_centres_is_the_same_map_and_updates_as_deltas(
    ros: Ros, daemon: Any, start_node: Any, tmp_path: Path
) -> None:
    """octomap_point_cloud_centers of geb079's cells gives the map of the scenario; a
    cloud with cells removed and added goes as deltas, and answers as the scenario of
    exactly those cells (``dyfos solve``)."""
    s = geb079()
    res, _data = tree(GEB079.read_bytes())
    with daemon.client() as client:
        client.upload_octomap(0xC1, GEB079, MAP_PARAMS["bounds"], MAP_PARAMS["sun"], MAP_PARAMS["origin"])
        cells = cells_of(client, 0xC1)
    start_node(
        ros,
        daemon,
        map_id=0xC2,
        octomap_topic="",
        cloud_topic="/cloud",
        cloud_resolution=res,
        diagnostics_period=0.2,
        **MAP_PARAMS,
    )
    diagnostics = ros.subscribe(DiagnosticArray, "/diagnostics")
    clouds = ros.publisher(PointCloud2, "/cloud", LATCHED)
    clouds.publish(cloud_msg(cells, res))
    eventually(lambda: map_values(diagnostics).get("version") == "0", "the map to be uploaded", spin=ros)
    req = request(0xC2, s, seed=2)
    assert_answer_is(ros.call(FindSensorPose, SERVICE, req), solve(tmp_path, s, "dyfos", 2), req.belief)

    changed = cells[300:] + [[20, 20, 2], [21, 20, 2], [22, 20, 2]]
    clouds.publish(cloud_msg(changed, res))
    eventually(lambda: map_values(diagnostics).get("updates") == "1", "the change to go as deltas", spin=ros)
    with daemon.client() as client:
        assert cells_of(client, 0xC2) == sorted(changed)
    scenario = {k: v for k, v in s.items() if k != "octomap"}
    scenario["voxels"] = {"resolution": res, "origin": MAP_PARAMS["origin"], "occupied": changed}
    got = ros.call(FindSensorPose, SERVICE, req)
    expected = solve(tmp_path, scenario, "dyfos", 2)
    assert_answer_is(got, {**expected, "map_version": got.map_version}, req.belief)


def test_a_map_is_refused_without_bounds_or_in_another_frame_and_follows_parameter_changes(
    ros: Ros, daemon: Any, start_node: Any
) -> None:
    start_node(ros, daemon, map_id=0xC3, diagnostics_period=0.2, cloud_topic="/cloud")
    diagnostics = ros.subscribe(DiagnosticArray, "/diagnostics")

    def map_status() -> DiagnosticStatus:
        return status_of(diagnostics[-1], "map")

    clouds = ros.publisher(PointCloud2, "/cloud", LATCHED)
    for bad, needle in (
        (PointCloud2(height=1, width=1, point_step=16, row_step=16, data=bytes(16)), "no x, y, z fields"),
        (cloud_msg([[0, 0, 0]], 0.1), "`bounds` and `sun`"),
    ):
        bad.header.frame_id = "map"
        if not bad.fields:
            bad.fields = [PointField(name="x", offset=0, datatype=PointField.FLOAT32, count=1)]
        clouds.publish(bad)
        eventually(lambda: diagnostics and needle in map_status().message, f"a cloud refused: {needle}", spin=ros)
    short = cloud_msg([[0, 0, 0], [1, 0, 0]], 0.1)
    short.data = short.data[:20]
    clouds.publish(short)
    eventually(lambda: "sizes disagree" in map_status().message, "a short cloud refused", spin=ros)
    maps = ros.publisher(Octomap, "/octomap_binary", LATCHED)
    bt = GEB079.read_bytes()
    maps.publish(octomap_msg(bt, frame_id="odom"))

    eventually(lambda: diagnostics and "`odom`" in map_status().message, "the frame to be refused", spin=ros)
    assert map_status().level == DiagnosticStatus.ERROR
    maps.publish(octomap_msg(bt))
    eventually(lambda: "`bounds` and `sun`" in map_status().message, "a map without bounds refused", spin=ros)
    assert map_status().level == DiagnosticStatus.ERROR
    params = [Parameter(k, value=v).to_parameter_msg() for k, v in MAP_PARAMS.items()]
    set_map = ros.call(SetParameters, "/dyfos/set_parameters", SetParameters.Request(parameters=params))
    assert all(r.successful for r in set_map.results)
    # The last map is sent again with the parameters, without a new message.
    eventually(
        lambda: map_values(diagnostics).get("version") is not None and map_status().level == DiagnosticStatus.OK,
        "the map to be uploaded with the new parameters",
        spin=ros,
    )
    with daemon.client() as client:
        snapshot = client.snapshot(0xC3)
        assert snapshot["bounds"] == MAP_PARAMS["bounds"]
        assert len(snapshot["voxels"]["occupied"]) == 185_673
        set_sun = SetParameters.Request(parameters=[Parameter("sun", value=[0.5, 1.0]).to_parameter_msg()])
        ros.call(SetParameters, "/dyfos/set_parameters", set_sun)
        eventually(lambda: client.snapshot(0xC3)["sun"] == {"elevation": 0.5, "azimuth": 1.0}, "the new sun")


def test_a_daemon_that_lost_the_map_gets_it_again(ros: Ros, start_daemon: Any, start_node: Any) -> None:
    """After a dyfosd restart without its state, the node uploads its last map again by
    itself: queries on map_id answer without a new map message."""
    d = start_daemon()
    start_node(ros, d, map_id=0xC4, diagnostics_period=0.2, **MAP_PARAMS)
    diagnostics = ros.subscribe(DiagnosticArray, "/diagnostics")
    maps = ros.publisher(Octomap, "/octomap_binary", LATCHED)
    maps.publish(octomap_msg(GEB079.read_bytes()))
    eventually(lambda: map_values(diagnostics).get("version") == "0", "the map to be uploaded", spin=ros)
    s = geb079()
    assert ros.call(FindSensorPose, SERVICE, request(0xC4, s)).success
    d.kill()
    d.restart(fresh_state=True)
    eventually(lambda: ros.call(FindSensorPose, SERVICE, request(0xC4, s)).success, "the map to be back")
    eventually(lambda: map_values(diagnostics)["uploads"] == "2", "diagnostics counting the upload", spin=ros)
