"""Conversions between dyfos beliefs and answers and ROS ``geometry_msgs/PoseWithCovariance``.

Frames follow ROS REP 103: x forward/east, y left/north, z up, angles counter-clockwise
about z, in the world frame ``map`` that the dyfos map uses. A rover belief is planar:
mean ``[x, y, θ]`` and a 3×3 covariance over (x, y, θ), θ being the yaw.

``PoseWithCovariance`` carries a position, an orientation quaternion ``x, y, z, w`` and a
6×6 row-major covariance over ``(x, y, z, roll, pitch, yaw)``. The functions here read
either a real ROS message (``msg.pose.position.x``, ``msg.covariance``; a
``PoseWithCovarianceStamped`` too) or plain data of the same shape, with positions and
quaternions as dicts (``{"x": .., "y": .., "z": ..}``) or lists (``[x, y, z]``,
``[x, y, z, w]``)::

    {"pose": {"position": {"x": 1.0, "y": 2.0, "z": 0.0},
              "orientation": {"x": 0.0, "y": 0.0, "z": 0.38, "w": 0.92}},
     "covariance": [... 36 numbers ...]}

and write plain dicts of that shape (the form ``rosidl_runtime_py.set_message_fields``
and rosbridge take). No ROS install is needed.
"""

from __future__ import annotations

import math
from typing import Any, Dict, List, Mapping, Optional, Sequence, Tuple, Union

__all__ = [
    "COVARIANCE_INDEX",
    "belief_from_pose_with_covariance",
    "belief_to_pose_with_covariance",
    "posterior_pose_with_covariance",
    "quaternion_from_yaw",
    "sensor_pose_with_covariance",
    "viewer_pose_with_covariance",
    "yaw_from_quaternion",
]

#: Rows/columns of (x, y, θ) in the 6×6 covariance over (x, y, z, roll, pitch, yaw).
COVARIANCE_INDEX: Tuple[int, int, int] = (0, 1, 5)

PoseDict = Dict[str, Any]


def _field(obj: Any, name: str) -> Any:
    """``obj.name`` for a ROS message, ``obj[name]`` for a dict."""
    if isinstance(obj, Mapping):
        return obj[name]
    return getattr(obj, name)


def _has(obj: Any, name: str) -> bool:
    return name in obj if isinstance(obj, Mapping) else hasattr(obj, name)


def _numbers(value: Any, names: Sequence[str]) -> List[float]:
    """A point or quaternion as floats: from a dict, a message or a list/array."""
    if isinstance(value, Mapping):
        return [float(value[n]) for n in names]
    if hasattr(value, names[0]):
        return [float(getattr(value, n)) for n in names]
    if hasattr(value, "tolist"):
        value = value.tolist()
    out = [float(v) for v in value]
    if len(out) != len(names):
        raise ValueError(f"expected {len(names)} numbers ({', '.join(names)}), got {len(out)}")
    return out


def _covariance36(value: Any) -> List[float]:
    if hasattr(value, "tolist"):
        value = value.tolist()
    flat = [float(v) for v in value]
    if len(flat) != 36:
        raise ValueError(f"a PoseWithCovariance covariance has 36 numbers (6×6 row-major), got {len(flat)}")
    return flat


def yaw_from_quaternion(q: Any) -> float:
    """The yaw (rotation about z, rad, in (-π, π]) of a quaternion ``x, y, z, w``
    (list or dict/message), as ROS ``tf2::getYaw`` computes it."""
    x, y, z, w = _numbers(q, ("x", "y", "z", "w"))
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def quaternion_from_yaw(yaw: float) -> List[float]:
    """The quaternion ``[x, y, z, w]`` of a rotation by ``yaw`` about z."""
    return [0.0, 0.0, math.sin(yaw / 2.0), math.cos(yaw / 2.0)]


def _pose_with_covariance(msg: Any) -> Any:
    """A ``PoseWithCovariance`` (message or dict), looking inside a ``...Stamped`` one."""
    pose = _field(msg, "pose")
    return pose if _has(pose, "covariance") else msg


def belief_from_pose_with_covariance(msg: Any) -> Tuple[List[float], List[List[float]]]:
    """A rover belief ``(mean, cov)`` from a ``PoseWithCovariance`` (or ``...Stamped``).

    ``mean`` is ``[x, y, yaw]`` (the position's x and y, the orientation's yaw);
    ``cov`` the (x, y, yaw) 3×3 block of the 6×6 covariance. Pass them to
    :meth:`dyfos.Client.rendezvous` as ``mean`` and ``cov``.
    """
    pwc = _pose_with_covariance(msg)
    pose = _field(pwc, "pose")
    px, py, _pz = _numbers(_field(pose, "position"), ("x", "y", "z"))
    yaw = yaw_from_quaternion(_field(pose, "orientation"))
    c = _covariance36(_field(pwc, "covariance"))
    cov = [[c[6 * i + j] for j in COVARIANCE_INDEX] for i in COVARIANCE_INDEX]
    return [px, py, yaw], cov


def pose_with_covariance(
    position: Sequence[float], quaternion: Sequence[float], covariance: Optional[Sequence[float]] = None
) -> PoseDict:
    """A ``PoseWithCovariance``-shaped dict: ``position`` ``[x, y, z]``, ``quaternion``
    ``[x, y, z, w]``, ``covariance`` 36 numbers (default all 0)."""
    p = _numbers(position, ("x", "y", "z"))
    q = _numbers(quaternion, ("x", "y", "z", "w"))
    return {
        "pose": {
            "position": {"x": p[0], "y": p[1], "z": p[2]},
            "orientation": {"x": q[0], "y": q[1], "z": q[2], "w": q[3]},
        },
        "covariance": [0.0] * 36 if covariance is None else _covariance36(covariance),
    }


def _embed3(cov: Any, unused_variance: float) -> List[float]:
    """A (x, y, yaw) 3×3 covariance inside a 6×6 row-major one; z, roll and pitch get
    ``unused_variance`` on the diagonal and no correlation."""
    if hasattr(cov, "tolist"):
        cov = cov.tolist()
    rows = [[float(v) for v in row] for row in cov]
    if len(rows) != 3 or any(len(r) != 3 for r in rows):
        raise ValueError("the covariance must be 3×3 over (x, y, yaw)")
    out = [0.0] * 36
    for k in (2, 3, 4):
        out[7 * k] = float(unused_variance)
    for i, a in enumerate(COVARIANCE_INDEX):
        for j, b in enumerate(COVARIANCE_INDEX):
            out[6 * a + b] = rows[i][j]
    return out


def belief_to_pose_with_covariance(
    mean: Sequence[float], cov: Any, z: float = 0.0, unused_variance: float = 0.0
) -> PoseDict:
    """A rover belief (mean ``[x, y, yaw]``, 3×3 covariance) as a ``PoseWithCovariance``
    dict at height ``z``. z, roll and pitch are not estimated: their variances are
    ``unused_variance`` (0 by default; a large value such as ``1e6`` tells consumers
    like ``robot_localization`` to ignore them)."""
    m = _numbers(mean, ("x", "y", "yaw"))
    return pose_with_covariance([m[0], m[1], z], quaternion_from_yaw(m[2]), _embed3(cov, unused_variance))


def _answer_field(answer: Any, name: str) -> Any:
    return answer[name] if isinstance(answer, Mapping) else getattr(answer, name)


def viewer_pose_with_covariance(answer: Any) -> PoseDict:
    """Where to fly the viewer: its position and heading (``viewer_yaw`` about z) from
    an :class:`dyfos.Answer` (or its ``to_dict()``), covariance 0."""
    return pose_with_covariance(
        _answer_field(answer, "viewer_position"), quaternion_from_yaw(_answer_field(answer, "viewer_yaw"))
    )


def sensor_pose_with_covariance(answer: Any) -> PoseDict:
    """Where to put the camera: the sensor's position and full orientation
    (``sensor_quaternion``, x y z w, in ``map``) from an answer, covariance 0."""
    return pose_with_covariance(_answer_field(answer, "sensor_position"), _answer_field(answer, "sensor_quaternion"))


def posterior_pose_with_covariance(
    answer: Any, mean: Union[Sequence[float], Any], z: float = 0.0, unused_variance: float = 0.0
) -> PoseDict:
    """The rover's predicted belief after the measurement: the prior ``mean`` ``[x, y,
    yaw]`` with the answer's posterior Σ⁺ as covariance (as
    :func:`belief_to_pose_with_covariance`)."""
    return belief_to_pose_with_covariance(mean, _answer_field(answer, "posterior"), z, unused_variance)
