"""~/find_sensor_pose against real rclpy and Fast DDS: the node runs as ``dyfos-ros`` in
its own process with its own ``dyfosd``; this process calls it over ROS 2."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import dyfos
from conftest import DATA, PATIENCE, ROOT, Ros
from dyfos_msgs.srv import FindSensorPose
from rcl_interfaces.srv import SetParameters
from helpers import REFERENCE, SERVICE, assert_answer_is, infeasible_map, parameters, request, solve


def test_answers_equal_dyfos_solve_bit_for_bit(ros: Ros, daemon: Any, start_node: Any, tmp_path: Path) -> None:
    """Every reference scenario through ~/find_sensor_pose equals ``dyfos solve`` of the
    same belief, algorithm, seed and parameters (given per request)."""
    start_node(ros, daemon)
    cases = [(path, "dyfos", 3 + i) for i, path in enumerate(REFERENCE)]
    cases += [(DATA / "example.json", algorithm, 5) for algorithm in ("dyfos-scipy", "brute", "random", "center")]
    with daemon.client() as client:
        for path, algorithm, seed in cases:
            s = dyfos.read_scenario(path)
            map_id = client.upload_scenario(path)
            req = request(map_id, s, algorithm if algorithm != "dyfos" else "", seed)
            response = ros.call(FindSensorPose, SERVICE, req)
            assert_answer_is(response, solve(tmp_path, s, algorithm, seed), req.belief)


def test_node_parameters_apply_and_a_request_overrides_them(
    ros: Ros, daemon: Any, start_node: Any, tmp_path: Path
) -> None:
    """The node's SPEC parameters (``-p lambda:=1.5``) apply to every request; a request's
    ``params`` override them by name; unknown names and wrong types are refused."""
    start_node(ros, daemon, model="anisotropic", **{"lambda": 1.5})
    path = DATA / "example.json"
    s = dyfos.read_scenario(path)
    with daemon.client() as client:
        map_id = client.upload_scenario(path)
    req = request(map_id, {**s, "params": {}}, seed=2)
    got = ros.call(FindSensorPose, SERVICE, req)
    node_params = {"model": "anisotropic", "lambda": 1.5}
    assert_answer_is(got, solve(tmp_path, {**s, "params": node_params}, "dyfos", 2), req.belief)
    own = {"lambda": 2.5, "t_vs": [0.2, 0.0, -0.1], "perimeter_points": 4}
    req = request(map_id, {**s, "params": own}, seed=2)
    got = ros.call(FindSensorPose, SERVICE, req)
    assert_answer_is(got, solve(tmp_path, {**s, "params": {**node_params, **own}}, "dyfos", 2), req.belief)
    # A parameter set at run time applies to the next request.
    set_lambda = SetParameters.Request(parameters=parameters({"lambda": 0.5}))
    assert ros.call(SetParameters, "/dyfos/set_parameters", set_lambda).results[0].successful
    req = request(map_id, {**s, "params": {}}, seed=2)
    got = ros.call(FindSensorPose, SERVICE, req)
    assert_answer_is(got, solve(tmp_path, {**s, "params": {**node_params, "lambda": 0.5}}, "dyfos", 2), req.belief)
    for params, needle in (
        ({"lambda_": 1.0}, "unknown parameter `lambda_`"),
        ({"perimeter_points": 4.0}, "integer"),
        ({"t_vs": [1.0, 2.0]}, "3 numbers"),
        ({"model": 3}, "string"),
        ({"rho_min": 7.0}, "rho_min"),
    ):
        bad = ros.call(FindSensorPose, SERVICE, request(map_id, {**s, "params": params}))
        assert (bad.success, bad.status) == (False, "invalid_params"), params
        assert needle in bad.message, bad.message


def test_every_error_status(ros: Ros, daemon: Any, start_node: Any) -> None:
    """Each way a request fails comes back as ``success`` false with its status name and a
    sentence; the node keeps serving."""
    start_node(ros, daemon)
    s = dyfos.read_scenario(DATA / "example.json")
    with daemon.client() as client:
        good = client.upload_scenario(DATA / "example.json")
        infeasible_map(client, 0xF00)

    def refused(req: Any) -> Any:
        r = ros.call(FindSensorPose, SERVICE, req)
        assert not r.success and r.message, r
        return r

    assert refused(request(0xDEAD, s)).status == "unknown_map"
    other_frame = request(good, s)
    other_frame.belief.header.frame_id = "odom"
    r = refused(other_frame)
    assert r.status == "invalid_frame" and "`odom`" in r.message and "`map`" in r.message
    no_frame = request(good, s)
    no_frame.belief.header.frame_id = ""
    assert refused(no_frame).status == "invalid_frame"
    not_spd = request(good, s)
    not_spd.belief.pose.covariance[0] = -1.0
    assert refused(not_spd).status == "invalid_belief"
    no_rotation = request(good, s)
    no_rotation.belief.pose.pose.orientation.w = 0.0
    no_rotation.belief.pose.pose.orientation.z = 0.0
    assert refused(no_rotation).status == "invalid_belief"
    assert refused(request(good, s, algorithm="gradient")).status == "invalid_algorithm"
    long = refused(request(good, s, algorithm="x" * 100_000))
    assert long.status == "invalid_algorithm" and len(long.message) <= 400, "a request cannot make the answer long"
    assert refused(request(good, s, params=parameters({"kappa": -1.0}))).status == "invalid_params"
    assert refused(request(good, s, deadline=-1.0)).status == "invalid_deadline"
    r = refused(request(0xF00, s))
    assert (r.status, r.map_version) == ("no_feasible_pose", 1)
    assert refused(request(0xF00, s, algorithm="brute", deadline=0.001)).status == "deadline_exceeded"
    assert ros.call(FindSensorPose, SERVICE, request(good, s)).success, "still serving"


def test_the_documented_client_runs(ros: Ros, daemon: Any, start_node: Any, tmp_path: Path) -> None:
    """docs/ros2.md's 10-line client, as printed there, gets an answer from the node."""
    page = (ROOT / "docs" / "ros2.md").read_text()
    section = page[page.index("## A client") :]
    code = section[section.index("```python\n") + len("```python\n") :]
    code = code[: code.index("```")]
    with daemon.client() as client:
        client.upload_scenario(DATA / "example.json", map_id=7)
    start_node(ros, daemon)
    script = tmp_path / "client.py"
    script.write_text(code)
    out = subprocess.run(
        [sys.executable, str(script)],
        capture_output=True,
        text=True,
        timeout=PATIENCE,
        env={**os.environ, "ROS_DOMAIN_ID": str(ros.domain)},
    )
    assert out.returncode == 0, out.stderr
    assert "geometry_msgs.msg.Pose(position=geometry_msgs.msg.Point(x=" in out.stdout, out.stdout
