"""Ask the ``dyfosd`` daemon where a viewer should put its camera to localize a rover.

``dyfos`` is the Python binding of the Rust client ``dyfos_client`` (the same code
robot processes link in Rust): requests go to ``dyfosd`` over iceoryx2 shared
memory on this computer, and an answer through Python equals ``dyfos solve``'s
for the same request and seed, bit for bit.

>>> import dyfos
>>> with dyfos.Client(prefix="dyfos/") as client:          # doctest: +SKIP
...     map_id = client.upload_scenario("tests/data/example.json")
...     answer = client.rendezvous(map_id, mean=[0.0, 0.0, 0.3],
...                                cov=[[0.2, 0.05, 0], [0.05, 0.1, 0], [0, 0, 0.05]], seed=1)
...     print(answer.viewer_position, answer.viewer_yaw, answer.cost)

Units are SI (metres, radians, seconds); frames follow ROS REP 103 in the world
frame ``map``; quaternions are ``[x, y, z, w]``. :mod:`dyfos.ros` converts beliefs
and answers to and from ``geometry_msgs/PoseWithCovariance``.

Errors are exceptions: :class:`DyfosError` carries ``.status`` (the daemon's wire
name, e.g. ``"map_version_mismatch"``) and ``.detail`` (its sentence saying what to
change); its subclasses are the families a caller handles differently:

=================================  =========================================================
exception                          ``status``
=================================  =========================================================
:class:`UnknownMapError`           ``unknown_map``
:class:`MapVersionMismatchError`   ``map_version_mismatch``
:class:`InvalidRequestError`       ``malformed_request``, ``invalid_algorithm``,
                                   ``invalid_belief``, ``invalid_params``,
                                   ``unsupported_model``, ``invalid_deadline``,
                                   ``malformed_delta``, ``invalid_delta``, ``map_exists``,
                                   ``chunk_out_of_order``, ``chunk_duplicate``,
                                   ``chunk_incomplete``, ``invalid_scenario``,
                                   ``invalid_prefix``, ``invalid_domain`` (also a
                                   :class:`ValueError`)
:class:`NoFeasiblePoseError`       ``no_feasible_pose``
:class:`DeadlineExceededError`     ``deadline_exceeded``
:class:`BusyError`                 ``busy``, ``over_capacity``, ``shutting_down``
:class:`DaemonGoneError`           ``no_daemon``, ``daemon_gone`` (also a
                                   :class:`ConnectionError`)
:class:`DyfosTimeoutError`         ``timeout``: no reply within the call's timeout (also a
                                   :class:`TimeoutError`)
:class:`DyfosError`                anything else: ``storage_failed``, ``internal_error``,
                                   ``incompatible_daemon``, ``ipc_error``,
                                   ``client_closed``
=================================  =========================================================

``.retryable`` says whether sending the same request again may succeed (the daemon
was missing, restarting or busy); the client reconnects by itself.

Threads: one :class:`Client` may be shared by several threads; their calls go one at
a time (one request in flight per client). Open one client per thread for parallel
queries. Every call releases the GIL while it waits on the daemon.
"""

from __future__ import annotations

import datetime as _dt
import json as _json
import os as _os
from typing import Any, Dict, List, Mapping, Optional, Sequence, Tuple, Type, Union

from . import _dyfos
from .voxels import MAX_DELTAS_PER_BATCH, Voxels, _octomap_bytes

__all__ = [
    "ALGORITHMS",
    "Answer",
    "BusyError",
    "Client",
    "DEFAULT_PREFIX",
    "DaemonGoneError",
    "DeadlineExceededError",
    "DyfosError",
    "DyfosTimeoutError",
    "InvalidRequestError",
    "MapVersionMismatchError",
    "NoFeasiblePoseError",
    "UnknownMapError",
    "read_scenario",
    "default_params",
    "MAX_DELTAS_PER_BATCH",
    "Voxels",
]

#: The service-name prefix ``dyfosd`` uses when given none.
DEFAULT_PREFIX: str = _dyfos.DEFAULT_PREFIX

#: The search algorithms (SPEC §8): ``dyfos`` is differential evolution with a final
#: polish, ``dyfos-scipy`` the paper's SciPy-default search, ``brute`` the exhaustive
#: grid, ``random`` and ``center`` the paper's baselines.
ALGORITHMS: Tuple[str, ...] = ("dyfos", "dyfos-scipy", "brute", "random", "center")

#: Something numbers can be read from: a list, tuple or numpy array.
Vector = Union[Sequence[float], Any]
#: A 3×3 matrix: nested lists or a numpy array.
Matrix = Union[Sequence[Sequence[float]], Any]
#: A scenario (SPEC §11): a path, JSON text or a dict.
ScenarioLike = Union[str, "_os.PathLike[str]", Mapping[str, Any]]
#: Map deltas as in ``dyfos map apply`` files (``docs/deltas.md``): a list of dicts such as
#: ``{"remove_obstacle": {"id": 3}}``, JSON text or a path.
DeltasLike = Union[Sequence[Mapping[str, Any]], str, "_os.PathLike[str]"]
#: Seconds, or a :class:`datetime.timedelta`.
Seconds = Union[float, _dt.timedelta]


class DyfosError(Exception):
    """A request failed; ``status`` says why and ``detail`` what to do.

    Attributes:
        status: the daemon's wire status name (``"map_version_mismatch"``, ...) or,
            for failures that never reached it, ``no_daemon``, ``daemon_gone``,
            ``timeout``, ``invalid_scenario``, ``client_closed``, ...
        detail: the daemon's (or the client's) sentence: what is wrong and what to change.
        retryable: whether sending the same request again may succeed.
        index: for ``invalid_delta`` / ``malformed_delta``, the failing delta's
            position in its batch; else ``None``.
        map_version: for a refused ``rendezvous``, the version the request left the
            map at: after its inline ``deltas`` when they were applied before the
            search failed (``no_feasible_pose``, ``deadline_exceeded``,
            ``internal_error``), else the map's version as it was; ``None`` if no map
            has the id or the failure never reached the daemon. Retry with
            ``expected_version=error.map_version``.
    """

    status: str
    detail: str
    retryable: bool
    index: Optional[int]
    map_version: Optional[int]

    def __init__(
        self,
        status: str,
        detail: str,
        retryable: bool = False,
        index: Optional[int] = None,
        map_version: Optional[int] = None,
    ) -> None:
        super().__init__(status, detail, retryable, index, map_version)
        self.status = status
        self.detail = detail
        self.retryable = retryable
        self.index = index
        self.map_version = map_version

    def __str__(self) -> str:
        return f"{self.status}: {self.detail}"


class UnknownMapError(DyfosError):
    """No map has this id in the daemon (``unknown_map``): create or upload it first."""


class MapVersionMismatchError(DyfosError):
    """The map is not at ``expected_version`` (``map_version_mismatch``): read the map
    again (:meth:`Client.snapshot`) and decide anew. Nothing changed."""


class InvalidRequestError(DyfosError, ValueError):
    """The request itself is wrong (a belief, parameter, delta, scenario, map id taken,
    upload chunk, ...): sending it again will fail the same way. ``detail`` names the field."""


class NoFeasiblePoseError(DyfosError):
    """No candidate pose passed the constraints (``no_feasible_pose``): the viewer cannot
    see the rover from anywhere in its workspace on this map."""


class DeadlineExceededError(DyfosError):
    """The request's deadline passed before any feasible pose was found
    (``deadline_exceeded``): give it more time."""


class BusyError(DyfosError):
    """The daemon is busy, over capacity or shutting down (``busy``, ``over_capacity``,
    ``shutting_down``): retry later, or send less at once."""


class DaemonGoneError(DyfosError, ConnectionError):
    """No daemon serves the prefix, or it went away mid-request (``no_daemon``,
    ``daemon_gone``): start ``dyfosd --prefix PREFIX``; the next call reconnects."""


class DyfosTimeoutError(DyfosError, TimeoutError):
    """No reply within the call's timeout (``timeout``): raise ``timeout``, or give the
    request a shorter ``deadline`` or ``budget``."""


_FAMILIES: Dict[str, Type[DyfosError]] = {
    "unknown_map": UnknownMapError,
    "map_version_mismatch": MapVersionMismatchError,
    "no_feasible_pose": NoFeasiblePoseError,
    "deadline_exceeded": DeadlineExceededError,
    "timeout": DyfosTimeoutError,
}
for _status in ("busy", "over_capacity", "shutting_down"):
    _FAMILIES[_status] = BusyError
for _status in ("no_daemon", "daemon_gone"):
    _FAMILIES[_status] = DaemonGoneError
for _status in (
    "malformed_request",
    "invalid_algorithm",
    "invalid_belief",
    "invalid_params",
    "unsupported_model",
    "invalid_deadline",
    "malformed_delta",
    "invalid_delta",
    "map_exists",
    "chunk_out_of_order",
    "chunk_duplicate",
    "chunk_incomplete",
    "invalid_scenario",
    "invalid_prefix",
    "invalid_domain",
):
    _FAMILIES[_status] = InvalidRequestError


def _make_error(
    status: str, detail: str, retryable: bool, index: Optional[int], map_version: Optional[int] = None
) -> DyfosError:
    """The exception for a failure reported by the extension module."""
    return _FAMILIES.get(status, DyfosError)(status, detail, retryable, index, map_version)


_dyfos.set_error_factory(_make_error)


def _invalid(detail: str) -> InvalidRequestError:
    return InvalidRequestError("malformed_request", detail)


def _floats(value: Vector, n: int, name: str) -> List[float]:
    """``value`` (any sequence or numpy array of ``n`` numbers) as a list of floats."""
    if hasattr(value, "tolist"):
        value = value.tolist()
    try:
        out = [float(v) for v in value]
    except (TypeError, ValueError) as e:
        raise _invalid(f"{name} must be {n} numbers: {e}") from None
    if len(out) != n:
        raise _invalid(f"{name} has {len(out)} numbers; it needs {n}")
    return out


def _seconds(value: Optional[Seconds], name: str) -> Optional[float]:
    if value is None:
        return None
    if isinstance(value, _dt.timedelta):
        return value.total_seconds()
    try:
        return float(value)
    except (TypeError, ValueError):
        raise _invalid(f"{name} must be seconds (a number or a datetime.timedelta), not {value!r}") from None


def _read_text(path: Union[str, "_os.PathLike[str]"], what: str) -> str:
    try:
        with open(path, encoding="utf-8") as f:
            return f.read()
    except OSError as e:
        raise InvalidRequestError(
            "invalid_scenario" if what == "scenario" else "malformed_delta", f"cannot read {what} file {path}: {e}"
        ) from None


def _scenario_json(scenario: ScenarioLike) -> str:
    """A scenario given as a dict, JSON text or a path, as JSON text."""
    if isinstance(scenario, Mapping):
        return _json.dumps(scenario)
    if isinstance(scenario, bytes):
        scenario = scenario.decode("utf-8")
    if isinstance(scenario, str) and scenario.lstrip().startswith("{"):
        return scenario
    if isinstance(scenario, (str, _os.PathLike)):
        return _read_text(scenario, "scenario")
    raise InvalidRequestError(
        "invalid_scenario", f"a scenario is a path, JSON text or a dict, not {type(scenario).__name__}"
    )


def _deltas_json(deltas: DeltasLike) -> str:
    """Map deltas given as a list of dicts, JSON text or a path, as JSON text."""
    if isinstance(deltas, bytes):
        deltas = deltas.decode("utf-8")
    if isinstance(deltas, str):
        return deltas if deltas.lstrip().startswith("[") else _read_text(deltas, "deltas")
    if isinstance(deltas, _os.PathLike):
        return _read_text(deltas, "deltas")
    return _json.dumps(list(deltas))


def read_scenario(scenario: ScenarioLike) -> Dict[str, Any]:
    """A scenario (path, JSON text or dict) as a dict, e.g. to query its ``rover`` belief
    with its ``params``: ``client.rendezvous(map_id, s["rover"]["mean"], s["rover"]["cov"],
    params=s.get("params"))``. Not validated here; the client validates it when used."""
    value = _json.loads(_scenario_json(scenario))
    if not isinstance(value, dict):
        raise InvalidRequestError("invalid_scenario", f"a scenario is a JSON object, not {type(value).__name__}")
    return value


def default_params() -> Dict[str, Any]:
    """Every SPEC §11 parameter at its default, by the names ``params`` takes
    (``{"rover_radius": 0.75, ..., "t_vs": [0.1, 0.0, -0.05], "model": "paper"}``);
    a new dict each call. Passing it as ``params`` is the same as passing none."""
    return _dyfos.default_params()


class Answer:
    """The answer to a rendezvous query (SPEC §8): where to put the camera, and the
    predicted uncertainty there. :meth:`to_dict` is what ``dyfos solve`` prints.

    Attributes:
        algorithm: the search algorithm used.
        x: the sensor state ``[ρ, ψ, φ, ψ_v]`` (m, rad, rad, rad).
        cost: ``E = ln det Σ⁺``, the predicted posterior's log-determinant.
        R: the predicted measurement noise, 2×2 (m²).
        posterior: the predicted posterior Σ⁺ over (x, y, θ), 3×3.
        sensor_position: the camera's position ``[x, y, z]`` in ``map`` (m).
        sensor_quaternion: the camera's orientation ``[x, y, z, w]`` in ``map``.
        viewer_position: the viewer's position ``[x, y, z]`` in ``map`` (m).
        viewer_yaw: the viewer's heading ψ_v (rad).
        evaluations: candidates evaluated: ``{"total", "workspace", "collision", "occlusion"}``.
        map_version: the map version searched: after the request's ``deltas``, one
            version each (the version counts deltas, not batches).
        stop: why the search stopped: ``finished``, ``max_generations``, ``budget`` or
            ``deadline`` (the best pose found in time, not converged).
        micros: the search's compute time in the daemon, µs.
    """

    __slots__ = (
        "_raw",
        "algorithm",
        "x",
        "cost",
        "R",
        "posterior",
        "sensor_position",
        "sensor_quaternion",
        "viewer_position",
        "viewer_yaw",
        "evaluations",
        "map_version",
        "stop",
        "micros",
    )

    algorithm: str
    x: List[float]
    cost: float
    R: List[List[float]]
    posterior: List[List[float]]
    sensor_position: List[float]
    sensor_quaternion: List[float]
    viewer_position: List[float]
    viewer_yaw: float
    evaluations: Dict[str, int]
    map_version: int
    stop: str
    micros: int

    def __init__(self, raw: "_dyfos.RawAnswer") -> None:
        self._raw = raw
        self.algorithm = raw.algorithm
        self.x = raw.x
        self.cost = raw.cost
        self.R = raw.R
        self.posterior = raw.posterior
        self.sensor_position = raw.sensor_position
        self.sensor_quaternion = raw.sensor_quaternion
        self.viewer_position = raw.viewer_position
        self.viewer_yaw = raw.viewer_yaw
        self.evaluations = raw.evaluations
        self.map_version = raw.map_version
        self.stop = raw.stop
        self.micros = raw.micros

    def to_dict(self) -> Dict[str, Any]:
        """The answer as ``json.loads`` of ``dyfos solve``'s output: the same keys, and
        the same numbers bit for bit (a new dict each call)."""
        return self._raw.to_dict()

    def to_json(self) -> str:
        """The answer as the JSON text ``dyfos solve`` prints, on one line."""
        return self._raw.to_json()

    def __repr__(self) -> str:
        return (
            f"Answer(algorithm={self.algorithm!r}, cost={self.cost!r}, viewer_position={self.viewer_position!r}, "
            f"viewer_yaw={self.viewer_yaw!r}, stop={self.stop!r}, map_version={self.map_version!r})"
        )


class Client:
    """A connection to the ``dyfosd`` serving ``prefix``.

    Args:
        prefix: the daemon's ``--prefix`` (default ``dyfos/``).
        domain: the daemon's ``--domain`` (iceoryx2 file prefix); ``None`` for the default.
        timeout: every call's default time limit in seconds; each method also takes
            ``timeout=``. Connecting waits up to ``connect_timeout`` (default: ``timeout``).

    Raises:
        DaemonGoneError: no daemon serves ``prefix`` within ``connect_timeout``.
        InvalidRequestError: the prefix or domain cannot name services.

    Use it as a context manager (``with dyfos.Client() as client:``) or call
    :meth:`close`. One client may be shared by threads; their calls go one at a time.
    If the daemon restarts, a call fails with :class:`DaemonGoneError` and the next
    one reconnects.
    """

    __slots__ = ("_raw", "prefix", "domain", "timeout")

    def __init__(
        self,
        prefix: str = DEFAULT_PREFIX,
        domain: Optional[str] = None,
        timeout: Seconds = 1.0,
        connect_timeout: Optional[Seconds] = None,
    ) -> None:
        t = _seconds(timeout, "timeout")
        if t is None:
            raise _invalid("timeout must be seconds (a number or a datetime.timedelta), not None")
        ct = _seconds(connect_timeout, "connect_timeout")
        self.prefix = prefix
        self.domain = domain
        self.timeout = t
        self._raw = _dyfos.RawClient(prefix, domain, t, t if ct is None else ct)

    def __enter__(self) -> "Client":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def close(self) -> None:
        """Closes the connection; later calls raise :class:`DyfosError` ``client_closed``."""
        self._raw.close()

    @property
    def closed(self) -> bool:
        """Whether :meth:`close` was called."""
        return self._raw.closed

    def __repr__(self) -> str:
        state = "closed" if self.closed else "open"
        return f"dyfos.Client(prefix={self.prefix!r}, domain={self.domain!r}, timeout={self.timeout!r}) ({state})"

    def stats(self, timeout: Optional[Seconds] = None) -> Dict[str, Any]:
        """The daemon's health and counters, as ``dyfos stats`` prints them: ``pid``,
        ``uptime_s``, ``queries_served``, ``queries_abandoned``, ``requests_failed``,
        ``map_requests``, ``maps``, ``queued``, ``running``, ``workers``,
        ``latency_us`` (p50, p90, p99, max, samples) and ``errors`` by status."""
        return self._raw.stats(_seconds(timeout, "timeout"))

    def upload_scenario(
        self,
        scenario: ScenarioLike,
        map_id: Optional[int] = None,
        replace: bool = False,
        timeout: Optional[Seconds] = None,
    ) -> int:
        """Makes sure the daemon holds the map of a SPEC §11 scenario and returns its id.

        Args:
            scenario: a path to a scenario file, its JSON text, or the dict; or a map as
                :meth:`snapshot` returns it (any object without ``rover``).
            map_id: the id to use; by default one derived from the map's content, so
                uploading the same scenario again reuses its map (as ``dyfos query``).
            replace: if ``map_id`` holds other content, replace it (else ``map_exists``).

        Raises:
            InvalidRequestError: the scenario is invalid (``invalid_scenario``, naming
                the field) or ``map_id`` holds another map (``map_exists``).
        """
        map_id, _version = self._raw.upload_scenario(
            _scenario_json(scenario), map_id, replace, _seconds(timeout, "timeout")
        )
        return map_id

    def upload_octomap(
        self,
        map_id: int,
        octomap: Union[str, "_os.PathLike[str]", bytes],
        bounds: Vector,
        sun: Vector,
        origin: Vector = (0.0, 0.0, 0.0),
        replace: bool = False,
        timeout: Optional[Seconds] = None,
    ) -> int:
        """Creates (or, with ``replace``, replaces) map ``map_id`` from an OctoMap
        ``.bt`` file (``OcTree::writeBinary``, octomap_server's saved maps) and returns
        its version. Update it later with :meth:`apply` and ``set_voxels`` /
        ``set_voxel_blocks`` deltas of the same resolution and origin.

        Args:
            octomap: the ``.bt`` file's path, or its bytes.
            bounds: ``[x_min, y_min, x_max, y_max]`` of the map, metres.
            sun: ``(elevation, azimuth)`` in radians.
            origin: where the minimum corner of OctoMap's cell (0, 0, 0) lies in the
                map frame (default: OctoMap's frame is the map frame); see docs/octomap.md.

        Raises:
            InvalidRequestError: not a readable ``.bt`` (``invalid_delta``, naming what
                is wrong), or ``map_id`` holds another map (``map_exists``).
            DyfosError: ``over_capacity`` when the map has too many cells.
        """
        return self._raw.upload_octomap(
            map_id,
            _octomap_bytes(octomap),
            _floats(bounds, 4, "bounds"),
            tuple(_floats(sun, 2, "sun")),
            _floats(origin, 3, "origin"),
            replace,
            _seconds(timeout, "timeout"),
        )

    def upload_voxels(
        self,
        map_id: int,
        voxels: "Voxels",
        bounds: Vector,
        sun: Vector,
        replace: bool = False,
        timeout: Optional[Seconds] = None,
    ) -> int:
        """Creates (or, with ``replace``, replaces whole) map ``map_id`` with the cells of
        ``voxels`` (:class:`dyfos.Voxels`), ``bounds`` ``[x_min, y_min, x_max, y_max]`` and
        ``sun`` ``(elevation, azimuth)``; returns its version. As :meth:`upload_octomap`."""
        return _dyfos.upload_voxels(
            self._raw,
            map_id,
            voxels._raw,
            _floats(bounds, 4, "bounds"),
            tuple(_floats(sun, 2, "sun")),
            replace,
            _seconds(timeout, "timeout"),
        )

    def update_voxels(
        self,
        map_id: int,
        previous: "Voxels",
        voxels: "Voxels",
        expected_version: Optional[int] = None,
        timeout: Optional[Seconds] = None,
    ) -> Optional[int]:
        """Sends the cells that changed from ``previous`` (what map ``map_id`` holds) to
        ``voxels`` as one atomic batch of ``SetVoxelBlocks`` deltas (freed cells, then
        occupied ones); returns the new version, or ``None`` when nothing changed
        (nothing is sent).

        Raises:
            MapVersionMismatchError: the map is not at ``expected_version``; nothing changed.
            InvalidRequestError: ``invalid_delta`` if the two differ in resolution or
                origin (:meth:`Voxels.change_records` is ``None``): upload the new one.
            BusyError: ``over_capacity`` if the change needs more than
                :data:`MAX_DELTAS_PER_BATCH` records: upload the new one whole.
        """
        return _dyfos.update_voxels(
            self._raw, map_id, previous._raw, voxels._raw, expected_version, _seconds(timeout, "timeout")
        )

    def create_map(
        self, map_id: int, bounds: Vector, sun: Vector, timeout: Optional[Seconds] = None
    ) -> int:
        """Creates an empty map at version 0 and returns that version.

        Args:
            bounds: ``[x_min, y_min, x_max, y_max]`` in metres.
            sun: ``(elevation, azimuth)`` in radians.

        Raises:
            InvalidRequestError: ``map_exists`` if the id is taken, or bad bounds/sun.
        """
        b = _floats(bounds, 4, "bounds")
        s = _floats(sun, 2, "sun")
        return self._raw.create_map(map_id, b, (s[0], s[1]), _seconds(timeout, "timeout"))

    def apply(
        self,
        map_id: int,
        deltas: DeltasLike,
        expected_version: Optional[int] = None,
        timeout: Optional[Seconds] = None,
    ) -> int:
        """Applies map deltas as one atomic batch (all or none) and returns the new version.

        The version counts deltas, not batches: each delta adds 1, so a batch of 5
        deltas moves version 3 to 8 (a voxel run with its cells is one delta; an empty
        batch changes nothing).

        Args:
            deltas: as in ``dyfos map apply`` files (``docs/deltas.md``): a list, JSON text
                or a path. Each delta is a dict with one key, its kind; obstacles, voxels,
                sun and bounds are written as in a scenario::

                    {"upsert_obstacle": {"id": 1, "cylinder": {"x": 2.0, "y": 1.0, "radius": 0.5, "height": 10.0}}}
                    {"upsert_obstacle": {"id": 2, "box": {"min": [4.0, 4.0, 0.0], "max": [5.0, 6.0, 3.0]}}}
                    {"remove_obstacle": {"id": 2}}
                    {"set_voxels": {"resolution": 0.1, "origin": [0.0, 0.0, 0.0], "occupied": [[1, 2, 3]]}}
                    {"set_voxels": {"resolution": 0.1, "origin": [0.0, 0.0, 0.0], "free": [[1, 2, 3]]}}
                    {"set_voxel_blocks": {"resolution": 0.1, "origin": [0.0, 0.0, 0.0],
                                          "occupied": [{"min": [0, 0, 4], "mask": 7}]}}
                    {"set_sun": {"elevation": 0.5, "azimuth": 1.0}}
                    {"set_bounds": [-20.0, -20.0, 20.0, 20.0]}
                    {"clear": {}}

            expected_version: the map must be at this version first (else
                :class:`MapVersionMismatchError`); ``None`` accepts any.

        Raises:
            InvalidRequestError: ``malformed_delta`` (not of that form: ``.detail`` names
                the field and shows a valid example of its kind) / ``invalid_delta`` (a
                value the map refuses); ``.index`` is the failing delta; the map is unchanged.
        """
        return self._raw.apply(map_id, _deltas_json(deltas), expected_version, _seconds(timeout, "timeout"))

    def snapshot(self, map_id: int, timeout: Optional[Seconds] = None) -> Dict[str, Any]:
        """The map as it is now, as ``dyfos map snapshot`` prints it: ``map``, ``version``,
        then ``bounds``, ``sun``, ``obstacles`` and ``voxels`` (if any) as a scenario writes
        them. :meth:`upload_scenario` takes it back; each obstacle is a valid
        ``upsert_obstacle`` value."""
        return self._raw.snapshot(map_id, _seconds(timeout, "timeout"))

    def delete_map(
        self, map_id: int, expected_version: Optional[int] = None, timeout: Optional[Seconds] = None
    ) -> None:
        """Deletes the map (and its file in the daemon's state directory)."""
        self._raw.delete_map(map_id, expected_version, _seconds(timeout, "timeout"))

    def list_maps(self, timeout: Optional[Seconds] = None) -> List[Dict[str, Any]]:
        """Every map the daemon holds, in id order, as ``dyfos map list`` prints them: one
        dict a map with ``map`` (its id), ``version``, ``generation`` (another one if the
        map was deleted and made again under its id), ``bounds`` and ``sun`` as a scenario
        writes them. One request per map, all within ``timeout``; maps made or deleted
        while it lists may or may not be in the list."""
        return self._raw.list_maps(_seconds(timeout, "timeout"))

    def _request(
        self,
        params: Optional[Mapping[str, Any]],
        deadline: Optional[Seconds],
        deltas: Optional[DeltasLike],
    ) -> Tuple[Optional[str], Optional[float], Optional[str]]:
        return (
            None if params is None else _json.dumps(dict(params)),
            None if deadline is None else _seconds(deadline, "deadline"),
            None if deltas is None else _deltas_json(deltas),
        )

    def rendezvous(
        self,
        map_id: int,
        mean: Vector,
        cov: Matrix,
        algorithm: str = "dyfos",
        seed: int = 0,
        params: Optional[Mapping[str, Any]] = None,
        budget: Optional[int] = None,
        deadline: Optional[Seconds] = None,
        expected_version: Optional[int] = None,
        deltas: Optional[DeltasLike] = None,
        timeout: Optional[Seconds] = None,
    ) -> Answer:
        """Asks where to put the camera for the rover's belief at the rendezvous.

        Args:
            map_id: the map to search (:meth:`upload_scenario`, :meth:`create_map`).
            mean: the belief mean ``[x, y, θ]`` (m, m, rad), list or numpy array.
            cov: its 3×3 covariance Σ⁻ (symmetric positive definite).
            algorithm: one of :data:`ALGORITHMS`.
            seed: the search's seed; the same request and seed give the same answer.
            params: SPEC §11 parameters by name (``{"lambda": 2.0, "model": "paper"}``);
                anything left out is the SPEC default.
            budget: most candidates to evaluate; ``None`` for the algorithm's own limits.
            deadline: seconds from receipt; when it passes the daemon answers with the
                best pose so far (``stop == "deadline"``) or raises
                :class:`DeadlineExceededError`. Keep it below ``timeout``.
            expected_version: the map must be at this version (before ``deltas``).
            deltas: map deltas applied atomically before the search (they change the
                stored map, each adding 1 to its version), as for :meth:`apply`.
            timeout: this call's time limit in seconds (default: the client's).

        Raises:
            UnknownMapError, MapVersionMismatchError, InvalidRequestError,
            NoFeasiblePoseError, DeadlineExceededError, BusyError, DaemonGoneError,
            DyfosTimeoutError: see the module's table.
        """
        p, d, ds = self._request(params, deadline, deltas)
        raw = self._raw.rendezvous(
            False, map_id, mean, cov, algorithm, seed, p, budget, d, expected_version, ds, None if timeout is None else _seconds(timeout, "timeout")
        )
        return Answer(raw)

    def check(
        self,
        map_id: int,
        mean: Vector,
        cov: Matrix,
        algorithm: str = "dyfos",
        seed: int = 0,
        params: Optional[Mapping[str, Any]] = None,
        budget: Optional[int] = None,
        deadline: Optional[Seconds] = None,
        expected_version: Optional[int] = None,
        deltas: Optional[DeltasLike] = None,
        timeout: Optional[Seconds] = None,
    ) -> int:
        """Sends the same request as :meth:`rendezvous` in check mode: the daemon validates
        everything (map id and version, belief, parameters, inline deltas on a copy of
        the map) and answers at once without searching or changing the map. Returns
        the map version the query would search. Raises as :meth:`rendezvous`."""
        p, d, ds = self._request(params, deadline, deltas)
        return self._raw.rendezvous(
            True, map_id, mean, cov, algorithm, seed, p, budget, d, expected_version, ds, None if timeout is None else _seconds(timeout, "timeout")
        )
