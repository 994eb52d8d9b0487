"""Between ROS messages and the ``dyfos`` binding: beliefs in, answers out, and SPEC §11
parameters given as ROS parameters (the node's or a request's ``params``).

Every check here gives the status a ROS user reads in the response: ``invalid_frame``
for a belief in another frame than the node's ``frame_id`` (there is no tf2 here),
``invalid_belief`` for a pose that is not one, ``invalid_params`` for a parameter of the
wrong name or type. Everything else (ranges, an SPD covariance) the binding and the
daemon check, as for any client.
"""

from __future__ import annotations

import math
from typing import Any, Dict, Iterable, List, Mapping, Optional, Tuple

import dyfos
from dyfos import ros as dros
from geometry_msgs.msg import PoseStamped
from rclpy.parameter import parameter_value_to_python

#: SPEC §11 parameters at SPEC's defaults, by name (from the binding: one source).
SPEC_DEFAULTS: Dict[str, Any] = dyfos.default_params()


class RequestError(Exception):
    """A request refused by the node before it reaches the daemon."""

    def __init__(self, status: str, message: str) -> None:
        super().__init__(f"{status}: {message}")
        self.status = status
        self.message = message


def _number(name: str, value: Any) -> float:
    # bool is an int in Python; a ROS bool is no number.
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise RequestError("invalid_params", f"{name} must be a number, not {value!r}")
    return float(value)


def spec_value(name: str, value: Any) -> Any:
    """A SPEC §11 parameter's value as ``params`` takes it: a float (an integer is
    taken), ``perimeter_points`` an int, ``t_vs`` three floats, ``model`` a name."""
    if name not in SPEC_DEFAULTS:
        raise RequestError(
            "invalid_params", f"unknown parameter `{name}`; the SPEC §11 names are {', '.join(SPEC_DEFAULTS)}"
        )
    default = SPEC_DEFAULTS[name]
    if isinstance(default, str):
        if not isinstance(value, str):
            raise RequestError("invalid_params", f"{name} must be a string, not {value!r}")
        return value
    if isinstance(default, list):
        if isinstance(value, (str, bytes)) or not hasattr(value, "__len__") or len(value) != len(default):
            raise RequestError("invalid_params", f"{name} must be {len(default)} numbers, not {value!r}")
        return [_number(name, v) for v in value]
    if isinstance(default, int):
        if isinstance(value, bool) or not isinstance(value, int):
            raise RequestError("invalid_params", f"{name} must be an integer, not {value!r}")
        return value
    return _number(name, value)


def params_from_parameters(parameters: Iterable[Any], base: Mapping[str, Any]) -> Dict[str, Any]:
    """``base`` (the node's parameters) with each ``rcl_interfaces/Parameter`` of a
    request overriding the one of its name."""
    out = dict(base)
    for p in parameters:
        try:
            value = parameter_value_to_python(p.value)
        except RuntimeError as e:
            raise RequestError("invalid_params", f"parameter `{p.name}`: {e}") from None
        if value is None:
            raise RequestError("invalid_params", f"parameter `{p.name}` has no value (type NOT_SET)")
        out[p.name] = spec_value(p.name, value)
    return out


def same_frame(frame: str, frame_id: str) -> bool:
    """Whether ``frame`` names ``frame_id`` (a leading ``/``, as ROS 1 wrote, is allowed)."""
    return frame.lstrip("/") == frame_id.lstrip("/") and frame != ""


def belief_from_msg(msg: Any, frame_id: str) -> Tuple[List[float], List[List[float]]]:
    """``(mean, cov)`` of a ``PoseWithCovarianceStamped`` in ``frame_id``: x, y, the
    yaw of the orientation (``atan2`` as ``tf2::getYaw``), and the (x, y, yaw) block
    (rows/columns 0, 1, 5) of the covariance."""
    if not same_frame(msg.header.frame_id, frame_id):
        raise RequestError(
            "invalid_frame",
            f"the belief is in frame `{msg.header.frame_id}`, the node works in `{frame_id}`: transform it "
            f"(tf2's doTransform) or set header.frame_id to `{frame_id}`",
        )
    q = msg.pose.pose.orientation
    norm = math.sqrt(q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w)
    if not (math.isfinite(norm) and abs(norm - 1.0) < 1e-3):
        raise RequestError("invalid_belief", f"the belief's orientation is not a unit quaternion (norm {norm})")
    return dros.belief_from_pose_with_covariance(msg)


def _stamped(
    msg: PoseStamped, frame_id: str, stamp: Any, position: List[float], quaternion: List[float]
) -> PoseStamped:
    # In place: building message objects costs more than setting their fields.
    msg.header.frame_id = frame_id
    msg.header.stamp = stamp
    p, o = msg.pose.position, msg.pose.orientation
    p.x, p.y, p.z = position
    o.x, o.y, o.z, o.w = quaternion
    return msg


def sensor_pose(answer: dyfos.Answer, frame_id: str, stamp: Any, into: Optional[PoseStamped] = None) -> PoseStamped:
    """Where to put the camera: ``sensor_position`` and ``sensor_quaternion`` (x along
    the optical axis, y left, z up); written into ``into`` if given."""
    msg = PoseStamped() if into is None else into
    return _stamped(msg, frame_id, stamp, answer.sensor_position, answer.sensor_quaternion)


def viewer_pose(answer: dyfos.Answer, frame_id: str, stamp: Any, into: Optional[PoseStamped] = None) -> PoseStamped:
    """Where to fly the viewer: ``viewer_position`` and a rotation by ``viewer_yaw``."""
    msg = PoseStamped() if into is None else into
    return _stamped(msg, frame_id, stamp, answer.viewer_position, dros.quaternion_from_yaw(answer.viewer_yaw))


def fill_response(response: Any, answer: dyfos.Answer, belief: Any, frame_id: str) -> Any:
    """A ``FindSensorPose`` response from an answer to ``belief``; poses stamped with
    the belief's time (the rendezvous) in ``frame_id``. Sets every field, so that
    ``response`` may be one filled before."""
    stamp = belief.header.stamp
    response.success = True
    response.status = ""
    response.message = ""
    response.x = answer.x
    response.cost = answer.cost
    sensor_pose(answer, frame_id, stamp, into=response.sensor_pose)
    viewer_pose(answer, frame_id, stamp, into=response.viewer_pose)
    (r00, r01), (r10, r11) = answer.R
    response.measurement_covariance = [r00, r01, r10, r11]
    response.posterior.pose = belief.pose.pose
    cov = [0.0] * 36
    for i, a in enumerate(dros.COVARIANCE_INDEX):
        for j, b in enumerate(dros.COVARIANCE_INDEX):
            cov[6 * a + b] = answer.posterior[i][j]
    response.posterior.covariance = cov
    response.evaluations = min(int(answer.evaluations["total"]), 2**32 - 1)
    response.map_version = answer.map_version
    response.stop = answer.stop
    return response


def fill_error(response: Any, status: str, message: str, map_version: Optional[int] = None) -> Any:
    """A refused ``FindSensorPose``: ``success`` false, the status and what to do."""
    response.success = False
    response.status = status
    response.message = message
    if map_version is not None:
        response.map_version = map_version
    return response


#: Longest message the node returns or logs: a request's own text (a frame name, an
#: algorithm) comes back in it, and a client must not make the node's log grow by much.
MAX_MESSAGE = 400


def error_of(e: BaseException) -> Tuple[str, str, Optional[int]]:
    """``(status, message, map_version)`` of a failed request. A daemon that is not there,
    or went away during the call, is ``no_daemon``: the node reconnects by itself."""
    if isinstance(e, RequestError):
        status, message, version = e.status, e.message, None
    elif isinstance(e, dyfos.DaemonGoneError):
        status, message, version = "no_daemon", e.detail, None
    elif isinstance(e, dyfos.DyfosError):
        status, message, version = e.status, e.detail, e.map_version
    else:
        status, message, version = "internal_error", f"{type(e).__name__}: {e}", None
    return status, clip(message), version


def clip(message: str) -> str:
    """``message`` cut to :data:`MAX_MESSAGE` characters."""
    return message if len(message) <= MAX_MESSAGE else message[: MAX_MESSAGE - 1] + "…"
