"""The node's life: a daemon that goes and comes back, Ctrl-C, two nodes on two ROS
domains, parameters refused at start and at run time, ``--help``."""

from __future__ import annotations

import signal
import subprocess
from typing import Any

import dyfos
from conftest import DATA, DYFOS_ROS, PATIENCE, Ros, pyconftest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from dyfos_msgs.srv import FindSensorPose
from helpers import SERVICE, eventually, level_of, request, status_of
from rcl_interfaces.srv import SetParameters
from rclpy.parameter import Parameter


def test_no_daemon_is_reported_and_the_node_outlives_a_dyfosd_restart(
    ros: Ros, start_daemon: Any, start_node: Any
) -> None:
    """While the daemon is gone the node answers ``no_daemon`` and its diagnostics say so;
    when a new dyfosd serves the prefix again the node answers again, by itself."""
    d = start_daemon()
    node = start_node(ros, d)
    s = dyfos.read_scenario(DATA / "example.json")
    with d.client() as client:
        map_id = client.upload_scenario(DATA / "example.json")
    assert ros.call(FindSensorPose, SERVICE, request(map_id, s)).success
    diagnostics = ros.subscribe(DiagnosticArray, "/diagnostics")
    d.kill(signal.SIGKILL)
    for _ in range(2):  # the call that finds it gone, and the next one, which tries to reconnect
        r = ros.call(FindSensorPose, SERVICE, request(map_id, s))
        assert (r.success, r.status) == (False, "no_daemon"), r
        assert r.message
    ros.spin_until(
        lambda: any(level_of(m, "daemon") == DiagnosticStatus.ERROR for m in diagnostics),
        what="a diagnostic saying the daemon is gone",
    )
    d.restart()  # the same prefix, domain and state directory: the map comes back from disk
    eventually(lambda: ros.call(FindSensorPose, SERVICE, request(map_id, s)).success, "answers again")
    diagnostics.clear()
    ros.spin_until(
        lambda: any(level_of(m, "daemon") == DiagnosticStatus.OK for m in diagnostics),
        what="a diagnostic saying the daemon is back",
    )
    pid = d.process.pid
    assert any(
        ("pid", str(pid)) in [(v.key, v.value) for v in status_of(m, "daemon").values]
        for m in diagnostics
        if level_of(m, "daemon") == DiagnosticStatus.OK
    )
    assert node.alive()


def test_ctrl_c_ends_the_node_during_a_long_search(ros: Ros, daemon: Any, start_node: Any) -> None:
    """SIGINT while the daemon searches for the node (seconds of ``brute``): the node
    answers the request ``shutting_down`` and exits 0 without waiting for the search; the
    daemon abandons it."""
    node = start_node(ros, daemon)
    slow = pyconftest.slow_scenario()
    with daemon.client() as client:
        map_id = client.upload_scenario(slow)
        client_req = request(map_id, slow, algorithm="brute")
        future = ros.client(FindSensorPose, SERVICE).call_async(client_req)
        eventually(lambda: client.stats()["running"] >= 1, "the search to run", spin=ros)
        node.process.send_signal(signal.SIGINT)
        # Well before the search could end: the node did not wait for it.
        assert node.process.wait(timeout=5.0) == 0, node.log()
        ros.spin_until(future.done, timeout=5.0, what="the answer to the request in hand")
        r = future.result()
        assert (r.success, r.status) == (False, "shutting_down"), r
        eventually(lambda: client.stats()["queries_abandoned"] >= 1, "the daemon to abandon the search")
        assert client.stats()["queries_served"] == 0


def test_ctrl_c_and_sigterm_end_an_idle_node(ros: Ros, daemon: Any, start_node: Any) -> None:
    for sig in (signal.SIGINT, signal.SIGTERM):
        node = start_node(ros, daemon)
        ros.client(FindSensorPose, SERVICE)  # up and serving
        node.process.send_signal(sig)
        assert node.process.wait(timeout=PATIENCE) == 0, node.log()
        eventually(
            lambda: ros.node.count_publishers("/dyfos/sensor_goal") == 0, "the node to leave the graph", spin=ros
        )


def test_two_nodes_on_two_domain_ids_do_not_see_each_other(
    ros: Ros, other_ros: Ros, start_daemon: Any, start_node: Any
) -> None:
    """Two nodes of the same name, each on its own ROS domain with its own dyfosd: a
    client on one domain reaches only its own node (its daemon's maps)."""
    a, b = start_daemon(), start_daemon()
    start_node(ros, a)
    start_node(other_ros, b)
    s = dyfos.read_scenario(DATA / "example.json")
    with a.client() as ca, b.client() as cb:
        only_a = ca.upload_scenario(DATA / "example.json", map_id=0xA)
        only_b = cb.upload_scenario(DATA / "example.json", map_id=0xB)
    for mine, theirs, r in ((only_a, only_b, ros), (only_b, only_a, other_ros)):
        assert r.call(FindSensorPose, SERVICE, request(mine, s)).success
        assert r.call(FindSensorPose, SERVICE, request(theirs, s)).status == "unknown_map"
        r.spin_for(0.5)
        assert r.node.count_subscribers("/dyfos/belief") == 1
        assert r.node.count_publishers("/dyfos/sensor_goal") == 1
        assert [n for n, _ns in r.node.get_node_names_and_namespaces() if n == "dyfos"] == ["dyfos"]


def test_parameters_are_checked_at_start_and_when_set(ros: Ros, daemon: Any, start_node: Any) -> None:
    """A wrong parameter at start ends the node with exit code 2 and a line naming it; one
    set at run time is refused with the reason, and the old value stays. A map id up to
    2^63 - 1 is accepted."""
    for bad, needle in (
        ("seed:=-1", "seed"),
        ("bounds:=[1.0,2.0]", "bounds"),
        ("algorithm:=gradient", "algorithm"),
        ("lambda:=fast", "lambda"),
        ("perimeter_points:=8.5", "perimeter_points"),
    ):
        out = subprocess.run(
            [DYFOS_ROS, "--ros-args", "-p", bad], capture_output=True, text=True, timeout=PATIENCE, env=ros_env(ros)
        )
        assert out.returncode == 2, (bad, out.stdout, out.stderr)
        assert needle in out.stderr, out.stderr
    start_node(ros, daemon, map_id=2**63 - 1, rho_max=7)  # an integer for a float is taken

    def set_(name: str, value: Any) -> Any:
        # `ros.call` sends again a request whose reply found no reader yet (setting is idempotent).
        request = SetParameters.Request(parameters=[Parameter(name, value=value).to_parameter_msg()])
        return ros.call(SetParameters, "/dyfos/set_parameters", request).results[0]

    refused = set_("map_id", -3)
    assert not refused.successful and "map_id" in refused.reason
    assert not set_("prefix", "elsewhere/").successful  # read-only: set at start
    assert set_("lambda", 2).successful
    assert set_("deadline", 0.5).successful


def test_help_lists_the_parameters() -> None:
    out = subprocess.run([DYFOS_ROS, "--help"], capture_output=True, text=True, timeout=PATIENCE)
    assert out.returncode == 0
    for name in (
        "prefix",
        "domain",
        "map_id",
        "algorithm",
        "seed",
        "deadline",
        "frame_id",
        "octomap_topic",
        "cloud_topic",
        "bounds",
        "sun",
        "origin",
        "lambda",
        "rho_min",
        "z_max",
        "model",
    ):
        assert f"  {name} " in out.stdout, name


def ros_env(ros: Ros) -> dict:
    import os

    return {**os.environ, "ROS_DOMAIN_ID": str(ros.domain)}
