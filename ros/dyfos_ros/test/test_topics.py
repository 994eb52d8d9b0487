"""The streaming side: ~/belief in, ~/sensor_goal and ~/viewer_goal out, ~/markers, and
/diagnostics with the daemon's stats."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Dict

import dyfos
from conftest import DATA, LATCHED, Ros, pyconftest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from dyfos import ros as dros
from dyfos_msgs.srv import FindSensorPose
from geometry_msgs.msg import PoseStamped, PoseWithCovarianceStamped
from helpers import SERVICE, belief_msg, eventually, hexes, parameters, request, solve, status_of
from rcl_interfaces.srv import SetParameters
from visualization_msgs.msg import Marker, MarkerArray


def values(status: DiagnosticStatus) -> Dict[str, str]:
    return {v.key: v.value for v in status.values}


def test_a_belief_on_the_topic_gives_goals_and_markers(ros: Ros, daemon: Any, start_node: Any, tmp_path: Path) -> None:
    """A belief on ~/belief is answered with the node's map_id, algorithm and seed: the
    goals carry ``dyfos solve``'s poses bit for bit, stamped with the belief's time; the
    markers draw that answer. A belief in another frame gets no goal."""
    path = DATA / "anisotropic-mirror-basin.json"
    s = dyfos.read_scenario(path)
    with daemon.client() as client:
        map_id = client.upload_scenario(path, map_id=0xB1)
    start_node(ros, daemon, map_id=map_id, algorithm="dyfos-scipy", seed=9, **s.get("params", {}))
    sensor_goals = ros.subscribe(PoseStamped, "/dyfos/sensor_goal")
    viewer_goals = ros.subscribe(PoseStamped, "/dyfos/viewer_goal")
    markers = ros.subscribe(MarkerArray, "/dyfos/markers", LATCHED)
    beliefs = ros.publisher(PoseWithCovarianceStamped, "/dyfos/belief")
    ros.spin_until(lambda: beliefs.get_subscription_count() == 1, what="the node to subscribe to ~/belief")
    wrong = belief_msg(s["rover"]["mean"], s["rover"]["cov"], frame_id="odom")
    wrong.header.stamp.sec = 1
    beliefs.publish(wrong)
    belief = belief_msg(s["rover"]["mean"], s["rover"]["cov"])
    beliefs.publish(belief)
    ros.spin_until(lambda: sensor_goals and viewer_goals and markers, what="goals and markers")
    ros.spin_for(0.3)
    assert len(sensor_goals) == len(viewer_goals) == 1, "the belief in `odom` got no goal"
    expected = solve(tmp_path, s, "dyfos-scipy", 9)
    sensor, viewer = sensor_goals[0], viewer_goals[0]
    for goal in (sensor, viewer):
        assert (goal.header.frame_id, goal.header.stamp) == ("map", belief.header.stamp)
    p, o = sensor.pose.position, sensor.pose.orientation
    assert hexes([p.x, p.y, p.z, o.x, o.y, o.z, o.w]) == hexes(
        expected["sensor_position"] + expected["sensor_quaternion"]
    )
    p, o = viewer.pose.position, viewer.pose.orientation
    assert hexes([p.x, p.y, p.z]) == hexes(expected["viewer_position"])
    assert hexes([o.x, o.y, o.z, o.w]) == hexes(dros.quaternion_from_yaw(expected["viewer_yaw"]))

    drawn = {m.id: m for m in markers[-1].markers}
    assert sorted(drawn) == [0, 1, 2, 3]
    assert all((m.ns, m.header.frame_id, m.action) == ("dyfos", "map", Marker.ADD) for m in drawn.values())
    frustum, sight, arrow, ellipse = drawn[0], drawn[1], drawn[2], drawn[3]
    assert (frustum.type, sight.type, arrow.type, ellipse.type) == (
        Marker.LINE_LIST,
        Marker.LINE_STRIP,
        Marker.ARROW,
        Marker.CYLINDER,
    )
    # The line of sight runs from the camera to the rover's marker (SPEC §4's p_t, at the
    # marker's height above the belief's mean).
    start, end = sight.points
    assert [start.x, start.y, start.z] == expected["sensor_position"]
    marker_height = dyfos.default_params()["marker_height"]
    mean = dros.belief_from_pose_with_covariance(belief)[0]
    assert math.dist([end.x, end.y, end.z], [mean[0], mean[1], marker_height]) < 1e-9
    assert len(frustum.points) == 24 and all(math.isfinite(q.x) for q in frustum.points)
    assert [arrow.pose.position.x, arrow.pose.position.y, arrow.pose.position.z] == expected["viewer_position"]
    # The ellipse's area is the posterior's: π·a·b with a·b = χ²·sqrt(det Σ⁺_xy).
    post = expected["posterior"]
    det = post[0][0] * post[1][1] - post[0][1] * post[1][0]
    assert math.isclose(ellipse.scale.x * ellipse.scale.y / 4.0, 5.991464547107979 * math.sqrt(det), rel_tol=1e-9)
    assert (ellipse.pose.position.x, ellipse.pose.position.y) == (mean[0], mean[1])


def test_diagnostics_carry_the_daemons_stats_and_health(ros: Ros, daemon: Any, start_node: Any) -> None:
    s = dyfos.read_scenario(DATA / "example.json")
    with daemon.client() as client:
        map_id = client.upload_scenario(DATA / "example.json")
    start_node(ros, daemon, diagnostics_period=0.2)
    diagnostics = ros.subscribe(DiagnosticArray, "/diagnostics")
    assert ros.call(FindSensorPose, SERVICE, request(map_id, s)).success
    assert ros.call(FindSensorPose, SERVICE, request(0xDEAD, s)).status == "unknown_map"

    def counted(m: DiagnosticArray) -> bool:
        node_side, daemon_side = values(status_of(m, "queries")), values(status_of(m, "daemon"))
        return node_side.get("refused.unknown_map") == "1" and daemon_side.get("errors.unknown_map") == "1"

    ros.spin_until(lambda: diagnostics and counted(diagnostics[-1]), what="diagnostics counting the queries")
    last = diagnostics[-1]
    daemon_status = status_of(last, "daemon")
    assert daemon_status.level == DiagnosticStatus.OK, daemon_status.message
    assert daemon_status.name == "/dyfos: daemon"
    assert daemon.prefix in daemon_status.hardware_id
    v = values(daemon_status)
    assert v["pid"] == str(daemon.process.pid)
    assert int(v["queries_served"]) >= 1 and int(v["maps"]) == 1
    assert "latency_us.p50" in v
    q = values(status_of(last, "queries"))
    assert (q["answered"], q["refused.unknown_map"]) == ("1", "1")
    map_status = status_of(last, "map")
    assert map_status.level == DiagnosticStatus.WARN and "octomap_binary" in map_status.message


def test_a_long_search_holds_up_no_topic_timer_or_parameter_service(ros: Ros, daemon: Any, start_node: Any) -> None:
    """While ~/find_sensor_pose waits for a search of seconds (``brute``), a belief on
    ~/belief is answered, /diagnostics keep coming, and the parameter services answer:
    the service's wait blocks nothing else of the node."""
    slow = pyconftest.slow_scenario()
    s = dyfos.read_scenario(DATA / "example.json")
    with daemon.client() as client:
        slow_map = client.upload_scenario(slow, map_id=0x51)
        fast_map = client.upload_scenario(DATA / "example.json", map_id=0x52)
        start_node(ros, daemon, map_id=fast_map, diagnostics_period=0.2)
        sensor_goals = ros.subscribe(PoseStamped, "/dyfos/sensor_goal")
        diagnostics = ros.subscribe(DiagnosticArray, "/diagnostics")
        beliefs = ros.publisher(PoseWithCovarianceStamped, "/dyfos/belief")
        setter = ros.client(SetParameters, "/dyfos/set_parameters")
        ros.spin_until(lambda: beliefs.get_subscription_count() == 1, what="the node to subscribe to ~/belief")
        searching = ros.client(FindSensorPose, SERVICE).call_async(request(slow_map, slow, algorithm="brute"))
        eventually(lambda: client.stats()["running"] >= 1, "the search to run", spin=ros)

        diagnostics.clear()
        beliefs.publish(belief_msg(s["rover"]["mean"], s["rover"]["cov"]))
        set_seed = setter.call_async(SetParameters.Request(parameters=parameters({"seed": 4})))
        ros.spin_until(lambda: sensor_goals and len(diagnostics) >= 2 and set_seed.done(), what="the node's answers")
        assert set_seed.result().results[0].successful
        assert not searching.done(), "the search ended before the node answered the rest: nothing was shown"
        assert client.stats()["running"] >= 1


def test_markers_of_an_answer_reach_a_subscriber_that_comes_later(ros: Ros, daemon: Any, start_node: Any) -> None:
    """Markers are drawn only while someone subscribes; one who subscribes after the
    answer still gets that answer's markers (transient local), not nothing."""
    s = dyfos.read_scenario(DATA / "example.json")
    with daemon.client() as client:
        map_id = client.upload_scenario(DATA / "example.json", map_id=0x53)
    start_node(ros, daemon)
    answer = ros.call(FindSensorPose, SERVICE, request(map_id, s))
    assert answer.success
    markers = ros.subscribe(MarkerArray, "/dyfos/markers", LATCHED)
    ros.spin_until(lambda: markers, what="the markers of the answer given before")
    sight = {m.id: m for m in markers[-1].markers}[1]
    p = answer.sensor_pose.pose.position
    assert [sight.points[0].x, sight.points[0].y, sight.points[0].z] == [p.x, p.y, p.z]
