"""The ROS 2 layer's cost: the same rendezvous query through ``~/find_sensor_pose`` (a
client in this process, the ``dyfos-ros`` node in another, Fast DDS between them) and
through the ``dyfos`` binding's direct call, in alternating blocks against one
``dyfosd``, so both see the same machine load.

    VENV/bin/python ros/bench.py --dyfosd target/release/dyfosd [--rounds 20 --count 50]

Starts its own dyfosd (own prefix, iceoryx2 domain and state directory) and node (own
ROS domain id, discovery on this machine only), uploads ``tests/data/example.json``, and
prints per algorithm the median and p99 of each path and the difference of the
medians. The direct call sends what the node sends (every SPEC §11 parameter, at its
default), back to back, and again with 1 ms between calls ("direct 1 ms apart": the
pace the daemon is asked at through ROS, where it sleeps between requests and must be
woken). Another path is ROS's own floor: the same request to a server in another
process that answers at once without asking any daemon. ``--json FILE`` keeps the raw
samples. Run it in the venv of ``ros/install.sh``
(with a release binding: ``DYFOS_BINDING=target/release/lib_dyfos.so``).

``--node [LABEL=]COMMAND`` names the node's executable (default: the venv's
``dyfos-ros``); given more than once, every node runs (each under its own node name)
and each is a path of its own in the same alternating blocks: two versions of the
node compared on the same machine load. ``--markers`` adds a process that subscribes to
every node's ``~/markers`` (RViz open), so that the nodes draw them.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any, Dict, List, Tuple

import dyfos
from dyfos import ros as dros

ROOT = Path(__file__).resolve().parents[1]
PACED = "direct 1 ms apart"


def percentile(samples: List[float], q: float) -> float:
    s = sorted(samples)
    return s[min(len(s) - 1, int(q * len(s)))]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--dyfosd", default=str(ROOT / "target" / "release" / "dyfosd"))
    ap.add_argument(
        "--node",
        action="append",
        help="[LABEL=]COMMAND of a node to time; repeat to compare nodes (default: the venv's dyfos-ros)",
    )
    ap.add_argument("--algorithms", default="center,dyfos")
    ap.add_argument("--rounds", type=int, default=20, help="blocks of each path per algorithm")
    ap.add_argument("--count", type=int, default=50, help="queries per block")
    ap.add_argument("--domain-id", type=int, default=int(os.environ.get("ROS_DOMAIN_ID", "87")))
    ap.add_argument("--json", help="write every sample (seconds) here")
    ap.add_argument("--markers", action="store_true", help="subscribe to every node's ~/markers meanwhile")
    ap.add_argument("--serve-echo", action="store_true", help=argparse.SUPPRESS)  # the floor's server
    ap.add_argument("--watch", nargs="*", help=argparse.SUPPRESS)  # the markers' subscriber
    args = ap.parse_args()
    if args.serve_echo:
        serve_echo()
        return
    if args.watch is not None:
        watch(args.watch)
        return

    os.environ["ROS_DOMAIN_ID"] = str(args.domain_id)
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    os.environ.setdefault("ROS_LOG_DIR", str(ROOT / "target" / "ros-log"))
    import rclpy
    from dyfos_msgs.srv import FindSensorPose

    pid = os.getpid()
    prefix, domain = f"rosbench-{pid}/", f"rb{pid}_"
    state = tempfile.mkdtemp(prefix="dyfos-rosbench-")
    daemon = subprocess.Popen(
        [args.dyfosd, "--prefix", prefix, "--domain", domain, "--state-dir", state], stderr=subprocess.DEVNULL
    )
    nodes = node_commands(args.node or [str(Path(sys.executable).parent / "dyfos-ros")])
    started: List[subprocess.Popen] = []
    echo = None
    try:
        client = dyfos.Client(prefix=prefix, domain=domain, timeout=30.0, connect_timeout=30.0)
        scenario = dyfos.read_scenario(ROOT / "tests" / "data" / "example.json")
        map_id = client.upload_scenario(scenario)
        for label, (command, name) in nodes.items():
            started.append(
                subprocess.Popen(
                    [command, "--ros-args", "-r", f"__node:={name}", "-p", f'prefix:="{prefix}"']
                    + ["-p", f'domain:="{domain}"', "--log-level", "warn"]
                )
            )
        echo = subprocess.Popen([sys.executable, __file__, "--serve-echo"])
        if args.markers:
            topics = [f"/{name}/markers" for _c, name in nodes.values()]
            started.append(subprocess.Popen([sys.executable, __file__, "--watch", *topics]))
        rclpy.init()
        ros = rclpy.create_node(f"rosbench_{pid}")
        services = {
            label: ros.create_client(FindSensorPose, f"/{name}/find_sensor_pose") for label, (_c, name) in nodes.items()
        }
        floor = ros.create_client(FindSensorPose, "/rosbench_echo/find_sensor_pose")
        end = time.monotonic() + 30.0
        watched = [f"/{name}/markers" for _c, name in nodes.values()] if args.markers else []
        while not (
            all(s.service_is_ready() for s in services.values())
            and floor.service_is_ready()
            and all(ros.count_subscribers(t) >= 1 for t in watched)
        ):
            if time.monotonic() > end:
                raise SystemExit("the nodes' services (and markers' subscriber) did not appear within 30 s")
            rclpy.spin_once(ros, timeout_sec=0.05)

        belief = dros.belief_to_pose_with_covariance(scenario["rover"]["mean"], scenario["rover"]["cov"])
        yaw = dros.yaw_from_quaternion(belief["pose"]["orientation"])
        mean, cov = [scenario["rover"]["mean"][0], scenario["rover"]["mean"][1], yaw], scenario["rover"]["cov"]

        def ros_call(algorithm: str, to: Any) -> float:
            req = FindSensorPose.Request(map_id=map_id, algorithm=algorithm, seed=1)
            req.belief.header.frame_id = "map"
            p, o = belief["pose"]["position"], belief["pose"]["orientation"]
            req.belief.pose.pose.position.x, req.belief.pose.pose.position.y = p["x"], p["y"]
            q = req.belief.pose.pose.orientation
            q.x, q.y, q.z, q.w = o["x"], o["y"], o["z"], o["w"]
            req.belief.pose.covariance = belief["covariance"]
            start = time.perf_counter()
            future = to.call_async(req)
            while not future.done():  # jazzy: not spin_until_future_complete (ROS2.md, Q2)
                rclpy.spin_once(ros, timeout_sec=1.0)
            took = time.perf_counter() - start
            assert future.result().success, future.result().message
            return took

        # What the node sends: its parameters, at SPEC's defaults here.
        params = dyfos.default_params()

        def direct_call(algorithm: str, pause: float = 0.0) -> float:
            if pause:
                time.sleep(pause)
            start = time.perf_counter()
            client.rendezvous(map_id, mean, cov, algorithm=algorithm, seed=1, params=params)
            return time.perf_counter() - start

        load = f"{os.getloadavg()[0]:.1f}"
        samples: Dict[str, Dict[str, List[float]]] = {}
        for algorithm in args.algorithms.split(","):
            got = samples[algorithm] = {"direct": [], PACED: [], **{label: [] for label in services}, "ros floor": []}
            for _ in range(args.count):  # warm up every path
                for to in services.values():
                    ros_call(algorithm, to)
                ros_call(algorithm, floor)
                direct_call(algorithm)
            for _ in range(args.rounds):
                got["direct"] += [direct_call(algorithm) for _ in range(args.count)]
                got[PACED] += [direct_call(algorithm, 0.001) for _ in range(args.count)]
                for label, to in services.items():
                    got[label] += [ros_call(algorithm, to) for _ in range(args.count)]
                got["ros floor"] += [ros_call(algorithm, floor) for _ in range(args.count)]

        print(f"load average before: {load}, after: {os.getloadavg()[0]:.1f}")
        print(f"machine: {platform.node()}, {os.cpu_count()} cores, {cpu_model()}; {time.strftime('%Y-%m-%d')}")
        print(f"{args.rounds} alternating blocks of {args.count} queries per path and algorithm")
        print("markers subscribed: the nodes draw them\n" if args.markers else "nobody subscribes to ~/markers\n")
        print("| algorithm | path | median (ms) | p99 (ms) |")
        print("|---|---|---|---|")
        for algorithm, got in samples.items():
            for path, s in got.items():
                print(f"| {algorithm} | {path} | {statistics.median(s) * 1e3:.3f} | {percentile(s, 0.99) * 1e3:.3f} |")
            med = {path: statistics.median(s) for path, s in got.items()}
            for label in services:
                print(f"| {algorithm} | {label} − direct (medians) | {(med[label] - med['direct']) * 1e3:.3f} | |")
                extra = med[label] - med["direct"] - med["ros floor"]
                print(f"| {algorithm} | {label} − direct − ros floor | {extra * 1e3:.3f} | |")
                extra = med[label] - med[PACED] - med["ros floor"]
                print(f"| {algorithm} | {label} − {PACED} − ros floor | {extra * 1e3:.3f} | |")
        if args.json:
            Path(args.json).write_text(json.dumps(samples))
        ros.destroy_node()
        rclpy.try_shutdown()
        client.close()
    finally:
        for p in [*started, echo]:
            if p is not None:
                p.send_signal(signal.SIGINT)
                p.wait(timeout=30)
        daemon.terminate()
        daemon.wait(timeout=30)
        shutil.rmtree(state, ignore_errors=True)


def node_commands(specs: List[str]) -> Dict[str, Tuple[str, str]]:
    """``[LABEL=]COMMAND`` each → {label: (command, node name)}. One node keeps the
    default name and the label ``ros``; several are ``dyfos``, ``dyfos_2``, ... with
    their commands' names (or the labels given) as labels."""
    nodes: Dict[str, Tuple[str, str]] = {}
    for i, spec in enumerate(specs):
        label, _eq, command = spec.rpartition("=")
        if not label:
            label = "ros" if len(specs) == 1 else f"ros {Path(command).name}"
        if label in nodes:
            label = f"{label} #{i + 1}"
        nodes[label] = (command, "dyfos" if i == 0 else f"dyfos_{i + 1}")
    return nodes


def spin_until_interrupted(node: Any) -> None:
    """Spins ``node`` until SIGINT (or ROS shuts down), then destroys it and shuts rclpy down."""
    import rclpy
    from rclpy.executors import ExternalShutdownException

    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    node.destroy_node()
    rclpy.try_shutdown()


def serve_echo() -> None:
    """A FindSensorPose server that answers at once (success, all else zero)."""
    import rclpy
    from dyfos_msgs.srv import FindSensorPose

    def answer(request: Any, response: Any) -> Any:
        response.success = True
        return response

    rclpy.init()
    node = rclpy.create_node("rosbench_echo")
    node.create_service(FindSensorPose, "~/find_sensor_pose", answer)
    spin_until_interrupted(node)


def watch(topics: List[str]) -> None:
    """Subscribes to ``topics`` (MarkerArray, as RViz does) until SIGINT."""
    import rclpy
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    from visualization_msgs.msg import MarkerArray

    qos = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    rclpy.init()
    node = rclpy.create_node("rosbench_markers")
    for topic in topics:
        node.create_subscription(MarkerArray, topic, lambda _msg: None, qos)
    spin_until_interrupted(node)


def cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


if __name__ == "__main__":
    main()
