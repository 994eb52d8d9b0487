"""The ``dyfos`` ROS 2 node: DyFOS sensor poses from a running ``dyfosd``.

Interfaces (names relative to the node, default name ``dyfos``):

- service ``~/find_sensor_pose`` (``dyfos_msgs/srv/FindSensorPose``);
- ``~/belief`` (``geometry_msgs/PoseWithCovarianceStamped``) in, answered with the node's
  ``map_id``, ``algorithm``, ``seed`` and ``deadline`` on ``~/sensor_goal`` and
  ``~/viewer_goal`` (``geometry_msgs/PoseStamped``);
- ``~/markers`` (``visualization_msgs/MarkerArray``) for the newest answer;
- ``/diagnostics`` (``diagnostic_msgs/DiagnosticArray``): the daemon's stats and health,
  the map and the node's queries;
- maps in: ``octomap_topic`` (``octomap_msgs/Octomap``, default ``octomap_binary``) and
  ``cloud_topic`` (``sensor_msgs/PointCloud2`` of occupied-cell centres, off by default).

Every call to the daemon goes through the ``dyfos`` binding, each kind on a thread with
a client of its own. The service is answered on its own thread, outside the executor
(:mod:`dyfos_ros.service`): it takes a request, asks the daemon and sends the response,
with no hand-off on the way. Everything else runs on a single-threaded executor whose
callbacks only hand work to worker threads (:mod:`dyfos_ros.worker`) and return, so a
long search or map upload holds up no topic, timer or parameter service. Markers are
drawn after the response is sent, on a thread of their own (:mod:`dyfos_ros.painter`).
docs/ros2.md documents the parameters.
"""

from __future__ import annotations

import math
from concurrent.futures import Future
import os
import sys
import threading
import time
from typing import Any, Callable, Dict, List, NamedTuple, Optional

import dyfos
import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from dyfos_msgs.srv import FindSensorPose
from geometry_msgs.msg import PoseStamped, PoseWithCovarianceStamped
from octomap_msgs.msg import Octomap
from rcl_interfaces.msg import ParameterDescriptor, SetParametersResult
from rclpy.exceptions import InvalidParameterTypeException, InvalidParameterValueException
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.utilities import remove_ros_args
from sensor_msgs.msg import PointCloud2

from . import convert
from .maps import MapError, MapSync, settings_from
from .painter import Painter
from .service import Handled, ServiceThread
from .worker import SUPERSEDED, Stopped, Worker

NODE_NAME = "dyfos"

#: A map id that fits a ROS integer parameter (int64).
MAX_PARAM_MAP_ID = 2**63 - 1


def _is_int(v: Any) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _is_number(v: Any) -> bool:
    return (isinstance(v, (int, float)) and not isinstance(v, bool)) and math.isfinite(v)


def _numbers(n: int) -> Callable[[Any], Optional[str]]:
    def check(v: Any) -> Optional[str]:
        if isinstance(v, (str, bytes)) or not hasattr(v, "__len__") or len(v) != n or not all(_is_number(x) for x in v):
            return f"must be {n} finite numbers"
        return None

    return check


def _text(what: str, empty: bool = True) -> Callable[[Any], Optional[str]]:
    """A string (not empty unless `empty`)."""
    return lambda v: None if isinstance(v, str) and (empty or v) else f"must be {what}"


def _positive(unit: str) -> Callable[[Any], Optional[str]]:
    """A finite number of `unit` above 0."""
    return lambda v: None if _is_number(v) and v > 0 else f"must be {unit} > 0"


def _not_negative(unit: str) -> Callable[[Any], Optional[str]]:
    """A finite number of `unit`, 0 or more."""
    return lambda v: None if _is_number(v) and v >= 0 else f"must be {unit} >= 0"


def _optional(check: Callable[[Any], Optional[str]]) -> Callable[[Any], Optional[str]]:
    return lambda v: None if v is None else check(v)


def _spec(name: str) -> Callable[[Any], Optional[str]]:
    def check(v: Any) -> Optional[str]:
        try:
            convert.spec_value(name, v)
        except convert.RequestError as e:
            return e.message
        return None

    return check


class Param(NamedTuple):
    """A ROS parameter of the node."""

    default: Any  # None: not set
    read_only: bool  # set at start only
    check: Callable[[Any], Optional[str]]  # what is wrong with a value, or None
    description: str


PARAMETERS: Dict[str, Param] = {
    "prefix": Param(dyfos.DEFAULT_PREFIX, True, _text("a service prefix", empty=False), "the daemon's --prefix"),
    "domain": Param("", True, _text("a string"), "the daemon's --domain (iceoryx2 domain); empty: the default"),
    "map_id": Param(
        1,
        False,
        lambda v: None if _is_int(v) and 0 <= v <= MAX_PARAM_MAP_ID else "must be an integer in [0, 2^63 - 1]",
        "the map ~/belief is answered on, and that maps from topics are kept in",
    ),
    "algorithm": Param(
        "dyfos",
        False,
        lambda v: None if v in dyfos.ALGORITHMS else f"must be one of {', '.join(dyfos.ALGORITHMS)}",
        "search algorithm for ~/belief",
    ),
    "seed": Param(
        0,
        False,
        lambda v: None if _is_int(v) and 0 <= v < 2**63 else "must be an integer >= 0",
        "search seed for ~/belief",
    ),
    "deadline": Param(
        0.0, False, _not_negative("seconds"), "seconds the daemon may search for ~/belief; 0: no deadline"
    ),
    "timeout": Param(
        60.0,
        False,
        _positive("seconds"),
        "how long the node waits for the daemon's answer beyond a request's deadline",
    ),
    "frame_id": Param(
        "map", False, _text("a frame name", empty=False), "the world frame beliefs, answers, maps and markers are in"
    ),
    "octomap_topic": Param("octomap_binary", True, _text("a topic name"), "octomap_msgs/Octomap maps; empty: none"),
    "cloud_topic": Param(
        "", True, _text("a topic name"), "sensor_msgs/PointCloud2 of occupied-cell centres; empty: none"
    ),
    "cloud_resolution": Param(0.05, False, _positive("metres"), "the cell side of maps from cloud_topic"),
    "bounds": Param(
        None, False, _optional(_numbers(4)), "x_min, y_min, x_max, y_max of maps from topics (required for them)"
    ),
    "sun": Param(
        None, False, _optional(_numbers(2)), "elevation, azimuth (rad) of maps from topics (required for them)"
    ),
    "origin": Param([0.0, 0.0, 0.0], False, _numbers(3), "where OctoMap's cell (0, 0, 0) lies in frame_id (m)"),
    "diagnostics_period": Param(1.0, True, _positive("seconds"), "seconds between /diagnostics messages"),
}
for _name, _default in convert.SPEC_DEFAULTS.items():
    PARAMETERS[_name] = Param(
        _default, False, _spec(_name), f"SPEC §11 `{_name}` of every request unless it names its own"
    )

MAP_PARAMETERS = ("map_id", "bounds", "sun", "origin", "cloud_resolution")

#: Map topics: reliable and transient local (latched), as octomap_server publishes them.
MAP_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)

CONNECT_TIMEOUT = 0.25
#: Seconds between two drawings of ~/markers at most (the newest answer is drawn).
MARKERS_PERIOD = 0.1


class DyfosNode(Node):
    """The node; see the module's docstring."""

    def __init__(self, node_name: str = NODE_NAME, **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        self.add_on_set_parameters_callback(self._check_parameters)
        for name, p in PARAMETERS.items():
            self.declare_parameter(
                name,
                p.default,
                ParameterDescriptor(description=p.description, read_only=p.read_only, dynamic_typing=True),
            )
        self._spec = self._read_spec_params()
        self.add_post_set_parameters_callback(self._parameters_set)
        self._prefix = self._param("prefix")
        self._domain = self._param("domain") or None

        def connect() -> dyfos.Client:
            return dyfos.Client(prefix=self._prefix, domain=self._domain, timeout=10.0, connect_timeout=CONNECT_TIMEOUT)

        # One client each: a map upload holds up neither a query nor the diagnostics.
        self._workers = {name: Worker(f"dyfos-{name}", connect) for name in ("stream", "map", "stats")}
        self._maps = MapSync(self._map_settings, lambda line: self.get_logger().info(line))
        self._counts_lock = threading.Lock()
        self._served = 0
        self._failed: Dict[str, int] = {}
        self._daemon_pid: Optional[int] = 0  # not yet asked: the first answer is logged
        self._daemon_error = ""
        # The service's answers are filled into this one response (on the service's
        # thread): building a response costs more than filling one, and send_response
        # has serialized it when it returns. A refusal gets a new one (numbers at zero).
        self._answered = FindSensorPose.Response()

        self._sensor_goal = self.create_publisher(PoseStamped, "~/sensor_goal", 10)
        self._viewer_goal = self.create_publisher(PoseStamped, "~/viewer_goal", 10)
        self._painter = Painter(self, "~/markers", MARKERS_PERIOD)
        self._workers["markers"] = self._painter.worker
        self._diagnostics = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        # The executor's callbacks only hand work to a worker and return.
        self.create_subscription(PoseWithCovarianceStamped, "~/belief", self._belief, 10)
        if self._param("octomap_topic"):
            self.create_subscription(Octomap, self._param("octomap_topic"), self._octomap, MAP_QOS)
        if self._param("cloud_topic"):
            self.create_subscription(PointCloud2, self._param("cloud_topic"), self._cloud, MAP_QOS)
        self.create_timer(float(self._param("diagnostics_period")), self._diagnose)
        # Last: the service on the graph means the node is ready.
        self._service = ServiceThread(
            self,
            FindSensorPose,
            "~/find_sensor_pose",
            self._find_sensor_pose,
            lambda status, message: convert.fill_error(FindSensorPose.Response(), status, convert.clip(message)),
            connect,
            "dyfos-query",
        )
        self.get_logger().info(
            f"serving ~/find_sensor_pose from dyfosd prefix={self._prefix!r} domain={self._domain!r}, "
            f"map_id={self._param('map_id')}, frame {self._param('frame_id')!r}"
        )

    # Parameters -----------------------------------------------------------------

    def _param(self, name: str) -> Any:
        return self.get_parameter(name).value

    def _check_parameters(self, parameters: List[Parameter]) -> SetParametersResult:
        for p in parameters:
            param = PARAMETERS.get(p.name)
            if param is None:
                continue
            problem = param.check(p.value)
            if problem is not None:
                return SetParametersResult(successful=False, reason=f"{p.name} = {p.value!r}: {problem}")
        return SetParametersResult(successful=True)

    def _parameters_set(self, parameters: List[Parameter]) -> None:
        if any(p.name in convert.SPEC_DEFAULTS for p in parameters):
            self._spec = self._read_spec_params()
        if any(p.name in MAP_PARAMETERS for p in parameters) and self.executor is not None:
            self._workers["map"].submit(self._logged(self._maps.resync(), "map"), key="map")

    def _read_spec_params(self) -> Dict[str, Any]:
        return {name: convert.spec_value(name, self._param(name)) for name in convert.SPEC_DEFAULTS}

    def _spec_params(self) -> Dict[str, Any]:
        """The node's SPEC §11 parameters (kept up to date by ``_parameters_set``; not to
        be changed by the caller)."""
        return self._spec

    def _map_settings(self):
        return settings_from(
            self._param("map_id"),
            self._param("bounds") or [],
            self._param("sun") or [],
            self._param("origin"),
            self._param("cloud_resolution"),
        )

    def _timeout(self, deadline: float) -> float:
        return deadline + float(self._param("timeout"))

    # Queries --------------------------------------------------------------------

    def _query(
        self,
        map_id: int,
        belief: PoseWithCovarianceStamped,
        algorithm: str,
        seed: int,
        deadline: float,
        params: Dict[str, Any],
        budget: Optional[int],
    ):
        """Validates a query: returns ``(job, mean)``, the job asking a client for it."""
        mean, cov = convert.belief_from_msg(belief, self._param("frame_id"))
        if not (math.isfinite(deadline) and deadline >= 0):
            raise convert.RequestError("invalid_deadline", f"deadline = {deadline} s must be >= 0 (0: none)")
        timeout = self._timeout(deadline)

        def job(client: dyfos.Client) -> dyfos.Answer:
            return client.rendezvous(
                map_id,
                mean,
                cov,
                algorithm=algorithm,
                seed=seed,
                params=params,
                budget=budget,
                deadline=deadline if deadline > 0 else None,
                timeout=timeout,
            )

        return job, mean

    def _count(self, status: str) -> None:
        with self._counts_lock:
            if status:
                self._failed[status] = self._failed.get(status, 0) + 1
            else:
                self._served += 1

    def _find_sensor_pose(self, request: Any, client: Callable[[], dyfos.Client]) -> Handled:
        # On the service's thread (ServiceThread): asks the daemon itself.
        frame_id = self._param("frame_id")
        try:
            params = convert.params_from_parameters(request.params, self._spec_params())
            job, mean = self._query(
                request.map_id,
                request.belief,
                request.algorithm or "dyfos",
                request.seed,
                request.deadline,
                params,
                request.budget or None,
            )
            answer = job(client())
        except Exception as e:
            status, message, version = convert.error_of(e)
            self._count(status)
            return convert.fill_error(FindSensorPose.Response(), status, message, version), None
        self._count("")
        stamp = request.belief.header.stamp
        return (
            convert.fill_response(self._answered, answer, request.belief, frame_id),
            lambda: self._painter.draw(answer, mean, params, frame_id, stamp),
        )

    def _belief(self, msg: PoseWithCovarianceStamped) -> None:
        frame_id = self._param("frame_id")
        try:
            params = self._spec_params()
            job, mean = self._query(
                self._param("map_id"),
                msg,
                self._param("algorithm"),
                self._param("seed"),
                float(self._param("deadline")),
                params,
                None,
            )
        except Exception as e:
            self._belief_failed(e)
            return
        future = self._workers["stream"].submit(job, key="belief")

        def publish(done: Future) -> None:
            # On the worker's thread, when the answer comes.
            try:
                answer = done.result()
            except Stopped:
                return
            except Exception as e:
                self._belief_failed(e)
                return
            if answer is SUPERSEDED:
                return
            self._count("")
            stamp = msg.header.stamp
            self._sensor_goal.publish(convert.sensor_pose(answer, frame_id, stamp))
            self._viewer_goal.publish(convert.viewer_pose(answer, frame_id, stamp))
            self._painter.draw(answer, mean, params, frame_id, stamp)

        future.add_done_callback(publish)

    def _belief_failed(self, e: BaseException) -> None:
        status, message, _version = convert.error_of(e)
        self._count(status)
        self.get_logger().warning(f"~/belief: {status}: {message}", throttle_duration_sec=5.0)

    # Maps -----------------------------------------------------------------------

    def _logged(self, job: Callable[[dyfos.Client], None], what: str) -> Callable[[dyfos.Client], None]:
        def run(client: dyfos.Client) -> None:
            try:
                job(client)
            except (MapError, dyfos.DyfosError) as e:
                self.get_logger().warning(convert.clip(f"{what}: {e}"), throttle_duration_sec=5.0)
            except Exception as e:  # a bug: say so, keep the node
                self.get_logger().error(f"{what}: {type(e).__name__}: {e}")

        return run

    def _map_frame_ok(self, msg: Any, topic: str) -> bool:
        frame_id = self._param("frame_id")
        if convert.same_frame(msg.header.frame_id, frame_id):
            return True
        self._maps.state.error = convert.clip(
            f"a map on {topic} is in frame `{msg.header.frame_id}`, the node works in `{frame_id}`: "
            f"publish it in `{frame_id}` (octomap_server's frame_id)"
        )
        self.get_logger().warning(self._maps.state.error, throttle_duration_sec=5.0)
        return False

    def _octomap(self, msg: Octomap) -> None:
        if self._map_frame_ok(msg, self._param("octomap_topic")):
            self._workers["map"].submit(self._logged(self._maps.octomap(msg), "octomap"), key="map")

    def _cloud(self, msg: PointCloud2) -> None:
        if self._map_frame_ok(msg, self._param("cloud_topic")):
            self._workers["map"].submit(self._logged(self._maps.cloud(msg), "cloud"), key="map")

    def _verify_map(self) -> Callable[[dyfos.Client], None]:
        """After the daemon (re)started: is the map still there, at the version we made?"""

        def job(client: dyfos.Client) -> None:
            s, version = self._map_settings(), self._maps.state.version
            if version is None:
                return
            try:
                client.check(
                    s.map_id,
                    [0.0, 0.0, 0.0],
                    [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
                    expected_version=version,
                )
            except (dyfos.UnknownMapError, dyfos.MapVersionMismatchError) as e:
                self.get_logger().info(f"map {s.map_id} after the daemon restarted: {e.status}; uploading it again")
                self._maps.resync()(client)

        return job

    # Diagnostics ----------------------------------------------------------------

    def _diagnose(self) -> None:
        self._workers["stats"].submit(lambda c: c.stats(), key="stats").add_done_callback(self._diagnosed)

    def _diagnosed(self, done: Future) -> None:
        # On the stats worker's thread.
        try:
            stats = done.result()
            if stats is SUPERSEDED:
                return
            error = ""
        except Stopped:
            return
        except Exception as e:
            status, detail, _version = convert.error_of(e)
            stats, error = None, f"{status}: {detail}"
        pid = None if stats is None else stats.get("pid")
        if pid != self._daemon_pid:
            if pid is None:
                self.get_logger().warning(f"dyfosd (prefix {self._prefix!r}) is gone: {error}")
            else:
                self.get_logger().info(f"connected to dyfosd pid {pid} (prefix {self._prefix!r})")
                self._workers["map"].submit(self._logged(self._verify_map(), "map"), key="map")
            self._daemon_pid = pid
        self._diagnostics.publish(self._diagnostic_array(stats, error))

    def _diagnostic_array(self, stats: Optional[Dict[str, Any]], error: str) -> DiagnosticArray:
        hardware = f"dyfosd {self._prefix}" + (f" domain {self._domain}" if self._domain else "")
        name = self.get_fully_qualified_name()
        daemon = DiagnosticStatus(name=f"{name}: daemon", hardware_id=hardware)
        if stats is None:
            daemon.level, daemon.message = DiagnosticStatus.ERROR, f"no daemon: {error}"
        else:
            daemon.level = DiagnosticStatus.OK
            lat = stats.get("latency_us", {})
            daemon.message = (
                f"pid {stats.get('pid')}, {stats.get('maps')} maps, {stats.get('queries_served')} queries served, "
                f"p50 {lat.get('p50')} µs"
            )
            daemon.values = [KeyValue(key=k, value=str(v)) for k, v in _flatten(stats)]
        m = self._maps.state
        s = self._map_settings()
        topics = [t for t in (self._param("octomap_topic"), self._param("cloud_topic")) if t]
        map_status = DiagnosticStatus(name=f"{name}: map", hardware_id=hardware)
        if m.error:
            map_status.level, map_status.message = DiagnosticStatus.ERROR, m.error
        elif m.version is None:
            map_status.level = DiagnosticStatus.WARN if topics else DiagnosticStatus.OK
            map_status.message = (
                f"no map from {' or '.join(topics)} yet" if topics else "no map topics (map_id is kept by others)"
            )
        else:
            map_status.level = DiagnosticStatus.OK
            map_status.message = f"map {s.map_id} version {m.version}, {m.cells} cells from {m.source}"
        map_status.values = [
            KeyValue(key=k, value=str(v))
            for k, v in (
                ("map_id", s.map_id),
                ("version", m.version),
                ("cells", m.cells),
                ("source", m.source),
                ("updates", m.updates),
                ("uploads", m.uploads),
                ("pending", m.pending),
                ("age_s", round(time.time() - m.last_update, 3) if m.last_update else None),
                ("topics", ", ".join(topics)),
            )
        ]
        queries = DiagnosticStatus(name=f"{name}: queries", hardware_id=hardware, level=DiagnosticStatus.OK)
        with self._counts_lock:
            served, failed = self._served, dict(self._failed)
        queries.message = f"{served} answered, {sum(failed.values())} refused"
        queries.values = [KeyValue(key="answered", value=str(served))] + [
            KeyValue(key=f"refused.{k}", value=str(v)) for k, v in sorted(failed.items())
        ]
        array = DiagnosticArray(status=[daemon, map_status, queries])
        array.header.stamp = self.get_clock().now().to_msg()
        return array

    # Shutdown -------------------------------------------------------------------

    def stop_workers(self, wait: float = 0.5) -> bool:
        """Stops the service's thread (a request it holds is answered ``shutting_down``)
        and the workers; whether every one ended within ``wait`` s (a call still in the
        daemon keeps one, which must not hold the process up)."""
        threads = [self._service, *self._workers.values()]
        for t in threads:
            t.stop()
        end = time.monotonic() + wait
        return all(t.join(max(0.0, end - time.monotonic())) for t in threads)


def _flatten(d: Dict[str, Any], prefix: str = ""):
    for k, v in d.items():
        if isinstance(v, dict):
            yield from _flatten(v, f"{prefix}{k}.")
        else:
            yield f"{prefix}{k}", v


USAGE = """usage: dyfos-ros [--ros-args -p NAME:=VALUE ...]

The dyfos ROS 2 node (also `ros2 run dyfos_ros dyfos_node`): asks a running dyfosd
where a viewer should put its camera to localize a rover. Parameters (docs/ros2.md):
"""


def main(args: Optional[List[str]] = None) -> None:
    argv = sys.argv if args is None else args
    rest = remove_ros_args(argv)[1:]
    if rest:
        if rest[0] in ("-h", "--help"):
            print(USAGE + "".join(f"  {n:20} {p.description} (default {p.default!r})\n" for n, p in PARAMETERS.items()))
            return
        print(
            f"dyfos-ros: unknown argument {rest[0]!r}; parameters go after --ros-args (-p NAME:=VALUE)", file=sys.stderr
        )
        sys.exit(2)
    rclpy.init(args=argv)
    node: Optional[DyfosNode] = None
    executor = SingleThreadedExecutor()
    clean, status = True, 0
    try:
        node = DyfosNode()
        executor.add_node(node)
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except (InvalidParameterValueException, InvalidParameterTypeException) as e:
        print(f"dyfos-ros: {e}", file=sys.stderr)
        clean, status = True, 2
    except Exception:
        if rclpy.ok():
            raise
        # Ctrl-C or SIGTERM while the node was being made: a stop, not an error.
    finally:
        if node is not None:
            # First the service and the workers: a request in the daemon's hands is
            # answered at once (shutting_down).
            clean = node.stop_workers()
        executor.shutdown(timeout_sec=10.0)
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    if not clean:
        # A worker is inside a call to the daemon: ROS is shut down cleanly already;
        # leave without waiting for the call (the daemon abandons it).
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(status)
    if status:
        sys.exit(status)


if __name__ == "__main__":
    main()
