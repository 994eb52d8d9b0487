"""What the tests of dyfos_ros share: requests built from scenario files, the
reference answer (``dyfos solve``), and bit-for-bit comparisons."""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any, Callable, Dict, List, Optional

import dyfos
from conftest import DATA, PATIENCE, dyfos_cli
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from dyfos import ros as dros
from dyfos_msgs.srv import FindSensorPose
from geometry_msgs.msg import PoseWithCovarianceStamped
from rcl_interfaces.msg import Parameter as ParameterMsg
from rclpy.parameter import Parameter

SERVICE = "/dyfos/find_sensor_pose"

#: Every scenario of tests/data whose map is in the file (geb079's OctoMap has its own test).
REFERENCE = [
    DATA / "example.json",
    DATA / "anisotropic-mirror-basin.json",
    *sorted((DATA / "golden" / "scenarios").glob("*/*.json")),
]


def hexes(values: Any) -> Any:
    """Floats as their exact bits (``float.hex``): equal means bit for bit."""
    if isinstance(values, float):
        return values.hex()
    return [hexes(v) for v in values]


def belief_msg(mean: List[float], cov: Any, frame_id: str = "map") -> PoseWithCovarianceStamped:
    d = dros.belief_to_pose_with_covariance(mean, cov)
    msg = PoseWithCovarianceStamped()
    msg.header.frame_id = frame_id
    msg.header.stamp.sec = 1234
    msg.header.stamp.nanosec = 5678
    p, q = d["pose"]["position"], d["pose"]["orientation"]
    msg.pose.pose.position.x, msg.pose.pose.position.y, msg.pose.pose.position.z = p["x"], p["y"], p["z"]
    o = msg.pose.pose.orientation
    o.x, o.y, o.z, o.w = q["x"], q["y"], q["z"], q["w"]
    msg.pose.covariance = d["covariance"]
    return msg


def parameters(params: Optional[Dict[str, Any]]) -> List[ParameterMsg]:
    return [Parameter(k, value=v).to_parameter_msg() for k, v in (params or {}).items()]


def request(map_id: int, scenario: Dict[str, Any], algorithm: str = "", seed: int = 0, **fields: Any) -> Any:
    r = FindSensorPose.Request(map_id=map_id, algorithm=algorithm, seed=seed)
    r.belief = belief_msg(scenario["rover"]["mean"], scenario["rover"]["cov"])
    r.params = parameters(scenario.get("params"))
    for k, v in fields.items():
        setattr(r, k, v)
    return r


def as_seen_by_the_node(scenario: Dict[str, Any]) -> Dict[str, Any]:
    """The scenario with the rover's yaw as the node reads it back from the belief's
    quaternion (``atan2``, as tf2::getYaw), which may differ from the file's in the last bit."""
    s = json.loads(json.dumps(scenario))
    q = dros.quaternion_from_yaw(s["rover"]["mean"][2])
    s["rover"]["mean"][2] = dros.yaw_from_quaternion(q)
    return s


def solve(tmp_path: Path, scenario: Dict[str, Any], algorithm: str, seed: int) -> Dict[str, Any]:
    path = tmp_path / "scenario.json"
    path.write_text(json.dumps(as_seen_by_the_node(scenario)))
    return dyfos_cli("solve", str(path), "--algo", algorithm, "--seed", str(seed))


def assert_answer_is(response: Any, expected: Dict[str, Any], belief: PoseWithCovarianceStamped) -> None:
    """``response`` carries ``expected`` (``dyfos solve``'s JSON), bit for bit."""
    assert response.success, f"{response.status}: {response.message}"
    assert (response.status, response.message) == ("", "")
    assert hexes(list(response.x)) == hexes(expected["x"])
    assert hexes(response.cost) == hexes(expected["cost"])
    s = response.sensor_pose
    assert (s.header.frame_id, s.header.stamp) == ("map", belief.header.stamp)
    assert hexes([s.pose.position.x, s.pose.position.y, s.pose.position.z]) == hexes(expected["sensor_position"])
    o = s.pose.orientation
    assert hexes([o.x, o.y, o.z, o.w]) == hexes(expected["sensor_quaternion"])
    v = response.viewer_pose
    assert hexes([v.pose.position.x, v.pose.position.y, v.pose.position.z]) == hexes(expected["viewer_position"])
    o = v.pose.orientation
    assert hexes([o.x, o.y, o.z, o.w]) == hexes(dros.quaternion_from_yaw(expected["viewer_yaw"]))
    assert hexes(response.x[3]) == hexes(expected["viewer_yaw"])
    assert hexes(list(response.measurement_covariance)) == hexes([*expected["R"][0], *expected["R"][1]])
    cov = list(response.posterior.covariance)
    block = [[cov[6 * i + j] for j in (0, 1, 5)] for i in (0, 1, 5)]
    assert hexes(block) == hexes(expected["posterior"])
    assert sum(abs(c) for k, c in enumerate(cov) if k // 6 in (2, 3, 4) or k % 6 in (2, 3, 4)) == 0.0
    assert response.posterior.pose == belief.pose.pose
    assert response.evaluations == expected["evaluations"]["total"]
    assert response.map_version == expected["map_version"]
    assert response.stop == expected["stop"]


def infeasible_map(client: dyfos.Client, map_id: int) -> None:
    """A map filled by one tall box: the viewer collides wherever it goes."""
    client.create_map(map_id, [-10, -10, 10, 10], (0.7, 2.1))
    wall = {"upsert_obstacle": {"id": 1, "box": {"min": [-10.0, -10.0, 0.0], "max": [10.0, 10.0, 100.0]}}}
    client.apply(map_id, [wall])


def level_of(array: DiagnosticArray, part: str) -> Optional[bytes]:
    for status in array.status:
        if status.name.endswith(f": {part}"):
            return status.level
    return None


def status_of(array: DiagnosticArray, part: str) -> Optional[DiagnosticStatus]:
    for status in array.status:
        if status.name.endswith(f": {part}"):
            return status
    return None


def eventually(done: Callable[[], bool], what: str, spin: Optional[Any] = None, timeout: float = PATIENCE) -> None:
    """Waits until ``done()``, spinning ``spin`` (a :class:`conftest.Ros`) meanwhile."""
    end = time.monotonic() + timeout
    while not done():
        if time.monotonic() > end:
            raise AssertionError(f"timed out after {timeout} s waiting for {what}")
        if spin is not None:
            spin.spin_for(0.05)
        else:
            time.sleep(0.05)
