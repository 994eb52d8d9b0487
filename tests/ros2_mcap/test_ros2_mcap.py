"""The ROS 2 profile of the mission MCAP files, read by an independent decoder.

`dyfos demo --mcap-profile foxglove,ros2` writes each run twice from the same
record: Foxglove's JSON and ROS 2's CDR. Foxglove's `mcap-ros2-support` decodes
the ROS 2 file from the definitions it carries (it shares no code with dyfos);
every message must say what the JSON one says: same topics, stamps, poses,
paths, transforms, markers and dyfos records. A run without a viewer declares
no viewer or rendezvous channel in either file.
"""

import json
import math
import os
import subprocess
import tempfile
from pathlib import Path

import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

DYFOS = os.environ.get("DYFOS", "dyfos")
DATA = Path(os.environ.get("DYFOS_TEST_DATA", Path(__file__).resolve().parents[1] / "data"))
VIEWER_TOPICS = {"/viewer/camera", "/dyfos/rendezvous/request", "/dyfos/rendezvous/answer",
                 "/dyfos/rendezvous/measurement"}
# Rows and columns of (x, y, yaw) in geometry_msgs' 6 x 6 covariance.
AXES = (0, 1, 5)


@pytest.fixture(scope="module")
def runs():
    """The demo's two files of each run: {run: (foxglove, ros2)}."""
    with tempfile.TemporaryDirectory(prefix="dyfos-ros2-mcap-") as out:
        done = subprocess.run(
            [DYFOS, "demo", "--time-scale", "0", "--algos", "dyfos", "--mission",
             str(DATA / "mission-example.json"), "--mcap-profile", "foxglove,ros2", "--out", out],
            capture_output=True, text=True, timeout=600)
        assert done.returncode == 0, done.stdout + done.stderr
        files = {}
        for run in ("dyfos-s1", "dead-reckoning-s1"):
            files[run] = (read_json(Path(out, f"mission-{run}.mcap")), read_ros2(Path(out, f"mission-{run}-ros2.mcap")))
        yield files


def read_json(path):
    """Topic -> [(log time, JSON)] of a Foxglove-profile file."""
    with open(path, "rb") as f:
        reader = make_reader(f)
        assert reader.get_header().profile == ""
        out = {}
        for _, channel, message in reader.iter_messages(log_time_order=False):
            assert channel.message_encoding == "json"
            out.setdefault(channel.topic, []).append((message.log_time, json.loads(message.data)))
        assert {c.topic for c in reader.get_summary().channels.values()} == set(out), "a channel without messages"
        return out


def read_ros2(path):
    """Topic -> [(log time, decoded message)] of a ROS 2-profile file, decoded by mcap-ros2-support."""
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        assert reader.get_header().profile == "ros2"
        summary = reader.get_summary()
        for channel in summary.channels.values():
            assert channel.message_encoding == "cdr"
            schema = summary.schemas[channel.schema_id]
            assert schema.encoding == "ros2msg"
            assert "/msg/" in schema.name
        out = {}
        for _, channel, message, decoded in reader.iter_decoded_messages(log_time_order=False):
            assert message.publish_time == message.log_time
            out.setdefault(channel.topic, []).append((message.log_time, decoded))
        assert {c.topic for c in summary.channels.values()} == set(out), "a channel without messages"
        return out


def stamp(t):
    """Nanoseconds of a Foxglove timestamp or a builtin_interfaces/Time."""
    if isinstance(t, dict):
        return t["sec"] * 1_000_000_000 + t["nsec"]
    return t.sec * 1_000_000_000 + t.nanosec


def xyz(v):
    return [v["x"], v["y"], v["z"]] if isinstance(v, dict) else [v.x, v.y, v.z]


def xyzw(q):
    return [q["x"], q["y"], q["z"], q["w"]] if isinstance(q, dict) else [q.x, q.y, q.z, q.w]


def rgba(c):
    return [c["r"], c["g"], c["b"], c["a"]] if isinstance(c, dict) else [c.r, c.g, c.b, c.a]


def same_pose(j, r):
    assert xyz(j["position"]) == xyz(r.position)
    assert xyzw(j["orientation"]) == xyzw(r.orientation)


def same_or_nan(json_value, ros_values):
    """A JSON value present equals the ROS values; absent, they are NaN."""
    if json_value is None:
        assert all(math.isnan(v) for v in ros_values), ros_values
    else:
        assert list(json_value) == list(ros_values)


def flat(rows):
    return [v for row in rows for v in row]


def check_scene(j, markers):
    """A SceneUpdate says what a MarkerArray says: per entity (namespace), the same
    shapes at the same places, sizes and colours."""
    by_ns = {}
    for m in markers:
        by_ns.setdefault(m.ns, []).append(m)
    for e in j["entities"]:
        ms = [m for m in by_ns.pop(e["id"], []) if m.action == 0]
        for m in ms:
            assert m.header.frame_id == e["frame_id"] and stamp(m.header.stamp) == stamp(e["timestamp"])
            assert m.frame_locked == e["frame_locked"]
        for c in e["cylinders"]:
            m = next(m for m in ms if m.type == 3 and xyz(m.pose.position) == xyz(c["pose"]["position"]))
            assert xyz(m.scale) == xyz(c["size"])
            assert rgba(m.color) == pytest.approx(rgba(c["color"]), abs=1e-7)
        cubes = [m for m in ms if m.type in (1, 6)]
        if e["cubes"]:
            centres = [xyz(m.pose.position) for m in cubes if m.type == 1]
            centres += [xyz(p) for m in cubes if m.type == 6 for p in m.points]
            assert sorted(centres) == sorted(xyz(c["pose"]["position"]) for c in e["cubes"])
            assert all(xyz(m.scale) in [xyz(c["size"]) for c in e["cubes"]] for m in cubes)
        else:
            assert not cubes
        spheres = [xyz(p) for m in ms if m.type == 7 for p in m.points]
        spheres += [xyz(m.pose.position) for m in ms if m.type == 2]
        assert sorted(spheres) == sorted(xyz(s["pose"]["position"]) for s in e["spheres"])
        lines = [m for m in ms if m.type in (4, 5)]
        assert len(lines) == len(e["lines"])
        for m, line in zip(lines, e["lines"]):
            points = [xyz(p) for p in m.points]
            expected = [xyz(p) for p in line["points"]]
            if line["type"] == 1:  # a loop: the strip comes back to its start
                expected.append(expected[0])
            assert points == expected
            assert m.type == (5 if line["type"] == 2 else 4)
            assert m.scale.x == pytest.approx(line["thickness"] * 0.01)
        texts = sorted((m.text, xyz(m.pose.position)) for m in ms if m.type == 9)
        assert texts == sorted((t["text"], xyz(t["pose"]["position"])) for t in e["texts"])
        arrows = [m for m in ms if m.type == 0]
        assert len(arrows) == len(e["arrows"])
        for m, a in zip(arrows, e["arrows"]):
            same_pose(a["pose"], m.pose)
            assert m.scale.x == pytest.approx(a["shaft_length"] + a["head_length"])
    # Namespaces left over hold only deletions of markers drawn before.
    assert all(m.action == 2 for ms in by_ns.values() for m in ms)


def check_message(topic, j, r):
    if topic == "/tf":
        (t,) = r.transforms
        assert stamp(t.header.stamp) == stamp(j["timestamp"])
        assert (t.header.frame_id, t.child_frame_id) == (j["parent_frame_id"], j["child_frame_id"])
        assert xyz(t.transform.translation) == xyz(j["translation"])
        assert xyzw(t.transform.rotation) == xyzw(j["rotation"])
    elif topic in ("/rover/pose", "/viewer/pose"):
        assert stamp(r.header.stamp) == stamp(j["timestamp"]) and r.header.frame_id == j["frame_id"]
        same_pose(j["pose"], r.pose)
    elif topic == "/rover/estimate/pose":
        assert stamp(r.header.stamp) == stamp(j["timestamp"]) and r.header.frame_id == j["frame_id"]
        same_pose(j["pose"], r.pose.pose)
        cov = r.pose.covariance
        assert cov[0] > 0 and cov[7] > 0 and cov[35] > 0
    elif topic in ("/rover/path", "/rover/estimate/path"):
        assert stamp(r.header.stamp) == stamp(j["timestamp"]) and r.header.frame_id == j["frame_id"]
        assert len(r.poses) == len(j["poses"])
        for p, q in zip(j["poses"], r.poses):
            same_pose(p, q.pose)
            assert stamp(q.header.stamp) <= stamp(r.header.stamp)
    elif topic in ("/map", "/rover/estimate/covariance", "/viewer/camera"):
        check_scene(j, r.markers)
    elif topic == "/dyfos/rendezvous/request":
        assert stamp(r.header.stamp) == stamp(j["timestamp"])
        p = r.pose.pose
        assert [p.position.x, p.position.y] == j["mean"][:2]
        yaw = 2 * math.atan2(p.orientation.z, p.orientation.w)
        assert math.remainder(yaw - j["mean"][2], math.tau) == pytest.approx(0, abs=1e-12)
        cov = r.pose.covariance
        assert [[cov[a * 6 + b] for b in AXES] for a in AXES] == j["cov"]
    elif topic == "/dyfos/rendezvous/answer":
        assert stamp(r.header.stamp) == stamp(j["timestamp"])
        assert (r.step, r.algorithm, list(r.x), r.cost, r.stop) == (j["step"], j["algorithm"], j["x"], j["E"], j["stop"])
        assert list(r.measurement_covariance) == flat(j["R"])
        assert list(r.posterior_covariance) == flat(j["sigma_plus"])
        assert (xyz(r.viewer_position), r.viewer_yaw) == (j["viewer_position"], j["viewer_yaw"])
        assert xyz(r.sensor_pose.position) == j["sensor_position"]
        assert xyzw(r.sensor_pose.orientation) == j["sensor_quaternion"]
        e = j["evaluations"]
        assert (r.evaluations, r.rejected_workspace, r.rejected_collision, r.rejected_occlusion) == \
            (e["total"], e["workspace"], e["collision"], e["occlusion"])
        assert (r.micros, r.map_version) == (j["micros"], j["map_version"])
    elif topic == "/dyfos/rendezvous/measurement":
        assert stamp(r.header.stamp) == stamp(j["timestamp"])
        assert (r.step, r.status) == (j["step"], j["status"])
        same_or_nan(j.get("position"), [r.position.x, r.position.y])
        if "position" in j:
            assert r.position.z == 0
        same_or_nan(flat(j["R"]) if "R" in j else None, r.measurement_covariance)
        same_or_nan(j.get("viewer_position"), xyz(r.viewer_position))
        same_or_nan([j["viewer_yaw"]] if "viewer_yaw" in j else None, [r.viewer_yaw])
        same_or_nan([j["predicted_E"]] if "predicted_E" in j else None, [r.predicted_cost])
    elif topic == "/dyfos/ape":
        assert stamp(r.header.stamp) == stamp(j["timestamp"])
        assert (r.sample, r.step, r.updated, r.ape_m) == (j["sample"], j["step"], j["updated"], j["ape_m"])
    else:
        raise AssertionError(f"unexpected topic {topic}")


@pytest.mark.parametrize("run", ["dyfos-s1", "dead-reckoning-s1"])
def test_the_ros2_file_says_what_the_foxglove_file_says(runs, run):
    fox, ros = runs[run]
    assert sorted(ros) == sorted(fox)
    for topic in fox:
        assert [t for t, _ in ros[topic]] == [t for t, _ in fox[topic]], topic
        for (_, j), (_, r) in zip(fox[topic], ros[topic]):
            check_message(topic, j, r)


def test_a_run_has_a_channel_only_where_it_has_messages(runs):
    fox, ros = runs["dead-reckoning-s1"]
    assert not VIEWER_TOPICS & (set(fox) | set(ros))
    fox, ros = runs["dyfos-s1"]
    assert VIEWER_TOPICS <= set(fox) and VIEWER_TOPICS <= set(ros)
    # The rendezvous of the mission: 4 waypoints, one request and answer each.
    assert len(ros["/dyfos/rendezvous/request"]) == len(ros["/dyfos/rendezvous/answer"]) == 4
