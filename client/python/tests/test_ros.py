"""ROS helpers, with plain lists and dicts (no ROS install)."""

from __future__ import annotations

import math
from types import SimpleNamespace
from typing import Any, List

import pytest

import dyfos
from dyfos import ros


def covariance36(cov3: List[List[float]], z: float = 0.0) -> List[float]:
    """A 6×6 row-major covariance with ``cov3`` over (x, y, yaw), written out by hand."""
    c = [0.0] * 36
    idx = [0, 1, 5]
    for i in range(3):
        for j in range(3):
            c[6 * idx[i] + idx[j]] = cov3[i][j]
    c[6 * 2 + 2] = z
    return c


COV3 = [[0.2, 0.05, 0.01], [0.05, 0.1, 0.02], [0.01, 0.02, 0.05]]


@pytest.mark.parametrize("yaw", [0.0, 0.3, -2.5, math.pi / 2, 3.0])
def test_yaw_round_trips_through_the_quaternion(yaw: float) -> None:
    q = ros.quaternion_from_yaw(yaw)
    assert math.isclose(sum(v * v for v in q), 1.0)
    assert math.isclose(ros.yaw_from_quaternion(q), yaw, abs_tol=1e-12)
    assert math.isclose(ros.yaw_from_quaternion({"x": q[0], "y": q[1], "z": q[2], "w": q[3]}), yaw, abs_tol=1e-12)


def test_yaw_of_a_tilted_quaternion() -> None:
    # Yaw 0.7 after roll 0.2 and pitch -0.1 (ZYX): tf2's getYaw gives 0.7 back.
    r, p, y = 0.2, -0.1, 0.7
    cr, sr, cp, sp, cy, sy = math.cos(r / 2), math.sin(r / 2), math.cos(p / 2), math.sin(p / 2), math.cos(y / 2), math.sin(y / 2)
    q = [sr * cp * cy - cr * sp * sy, cr * sp * cy + sr * cp * sy, cr * cp * sy - sr * sp * cy, cr * cp * cy + sr * sp * sy]
    assert math.isclose(ros.yaw_from_quaternion(q), y, abs_tol=1e-12)


def test_belief_from_plain_pose_with_covariance() -> None:
    msg = {
        "pose": {"position": [1.0, 2.0, 0.4], "orientation": ros.quaternion_from_yaw(0.3)},
        "covariance": covariance36(COV3, z=9.0),
    }
    mean, cov = ros.belief_from_pose_with_covariance(msg)
    assert mean[:2] == [1.0, 2.0]
    assert math.isclose(mean[2], 0.3, abs_tol=1e-12)
    assert cov == COV3


def test_belief_from_message_objects_and_stamped() -> None:
    point = SimpleNamespace(x=-1.0, y=0.5, z=0.0)
    q = ros.quaternion_from_yaw(-1.2)
    orientation = SimpleNamespace(x=q[0], y=q[1], z=q[2], w=q[3])
    pwc = SimpleNamespace(pose=SimpleNamespace(position=point, orientation=orientation), covariance=tuple(covariance36(COV3)))
    stamped = SimpleNamespace(header=SimpleNamespace(frame_id="map"), pose=pwc)
    for msg in (pwc, stamped):
        mean, cov = ros.belief_from_pose_with_covariance(msg)
        assert mean[:2] == [-1.0, 0.5] and math.isclose(mean[2], -1.2, abs_tol=1e-12)
        assert cov == COV3


def test_belief_round_trip_and_layout() -> None:
    out = ros.belief_to_pose_with_covariance([3.0, -4.0, 1.0], COV3, z=0.2, unused_variance=1e6)
    assert out["pose"]["position"] == {"x": 3.0, "y": -4.0, "z": 0.2}
    assert out["covariance"][6 * 0 + 5] == COV3[0][2]  # x–yaw at row 0, column 5
    assert out["covariance"][6 * 5 + 1] == COV3[2][1]  # yaw–y at row 5, column 1
    assert [out["covariance"][7 * k] for k in (2, 3, 4)] == [1e6] * 3
    mean, cov = ros.belief_from_pose_with_covariance(out)
    assert mean[:2] == [3.0, -4.0] and math.isclose(mean[2], 1.0, abs_tol=1e-12)
    assert cov == COV3


def test_bad_shapes_are_refused() -> None:
    with pytest.raises(ValueError):
        ros.belief_from_pose_with_covariance({"pose": {"position": [0, 0, 0], "orientation": [0, 0, 0, 1]}, "covariance": [0.0] * 9})
    with pytest.raises(ValueError):
        ros.belief_to_pose_with_covariance([0, 0, 0], [[1, 0], [0, 1]])


def test_answer_poses(client: dyfos.Client) -> None:
    """The viewer's and the sensor's poses and the posterior, from a real answer."""
    from conftest import DATA

    s = dyfos.read_scenario(DATA / "example.json")
    map_id = client.upload_scenario(s)
    answer = client.rendezvous(map_id, s["rover"]["mean"], s["rover"]["cov"], seed=1, params=s["params"])
    for a in (answer, answer.to_dict()):
        viewer = ros.viewer_pose_with_covariance(a)
        p = viewer["pose"]["position"]
        assert [p["x"], p["y"], p["z"]] == answer.viewer_position
        assert math.isclose(ros.yaw_from_quaternion(viewer["pose"]["orientation"]), answer.viewer_yaw, abs_tol=1e-12)
        sensor = ros.sensor_pose_with_covariance(a)
        o = sensor["pose"]["orientation"]
        assert [o["x"], o["y"], o["z"], o["w"]] == answer.sensor_quaternion
        assert sensor["covariance"] == [0.0] * 36
        posterior = ros.posterior_pose_with_covariance(a, s["rover"]["mean"])
        mean, cov = ros.belief_from_pose_with_covariance(posterior)
        assert cov == answer.posterior
        assert mean[:2] == s["rover"]["mean"][:2]
