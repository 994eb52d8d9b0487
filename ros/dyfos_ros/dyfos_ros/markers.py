"""RViz / Foxglove markers of one answer: the camera frustum, the line of sight to the
rover's marker, the viewer's pose and the predicted posterior's 95 % ellipse.

The geometry follows SPEC §3/§4: the sensor frame has x along the optical axis, y left,
z up; the target is ``p_t = p_s + ρ·R_ws·d_s`` with ``d_s = normalize(1, tan ψ, tan φ)``;
the frustum spans the field of view ``f_h × f_v`` between ``rho_min`` and ``rho_max``.
"""

from __future__ import annotations

import math
from typing import Any, List, Mapping, Sequence

import dyfos
from builtin_interfaces.msg import Duration
from geometry_msgs.msg import Point, Pose, Quaternion, Vector3
from std_msgs.msg import ColorRGBA, Header
from visualization_msgs.msg import Marker, MarkerArray

NAMESPACE = "dyfos"
FRUSTUM, LINE_OF_SIGHT, VIEWER, ELLIPSE = 0, 1, 2, 3

#: χ²(2) at 95 %: the ellipse's half-axes are sqrt(this · eigenvalue).
CHI2_95 = 5.991464547107979


def _rotate(q: Sequence[float], v: Sequence[float]) -> List[float]:
    """``v`` rotated by the unit quaternion ``q`` = (x, y, z, w)."""
    x, y, z, w = q
    # v + 2w (u × v) + 2 u × (u × v), u = (x, y, z)
    cx, cy, cz = y * v[2] - z * v[1], z * v[0] - x * v[2], x * v[1] - y * v[0]
    ddx, ddy, ddz = y * cz - z * cy, z * cx - x * cz, x * cy - y * cx
    return [v[0] + 2 * (w * cx + ddx), v[1] + 2 * (w * cy + ddy), v[2] + 2 * (w * cz + ddz)]


def _point(p: Sequence[float]) -> Point:
    return Point(x=float(p[0]), y=float(p[1]), z=float(p[2]))


def _along(origin: Sequence[float], direction: Sequence[float], length: float) -> List[float]:
    return [origin[k] + length * direction[k] for k in range(3)]


def target(answer: dyfos.Answer) -> List[float]:
    """The rover's marker point p_t the camera looks at."""
    rho, psi, phi, _yaw = answer.x
    d = [1.0, math.tan(psi), math.tan(phi)]
    n = math.sqrt(sum(c * c for c in d))
    return _along(answer.sensor_position, _rotate(answer.sensor_quaternion, [c / n for c in d]), rho)


def ellipse(cov2: Sequence[Sequence[float]]) -> tuple:
    """Half-axes (major, minor) and the major axis's angle of the 95 % ellipse of a
    2 × 2 covariance."""
    a, b, c = cov2[0][0], cov2[0][1], cov2[1][1]
    mid, half = (a + c) / 2.0, math.hypot((a - c) / 2.0, b)
    major, minor = max(mid + half, 0.0), max(mid - half, 0.0)
    angle = 0.5 * math.atan2(2.0 * b, a - c)
    return math.sqrt(CHI2_95 * major), math.sqrt(CHI2_95 * minor), angle


def _marker(header: Header, id_: int, kind: int, color: Sequence[float]) -> Marker:
    m = Marker(header=header, ns=NAMESPACE, id=id_, type=kind, action=Marker.ADD)
    m.pose.orientation.w = 1.0
    m.color = ColorRGBA(r=color[0], g=color[1], b=color[2], a=color[3])
    m.lifetime = Duration()  # until replaced
    return m


def markers(
    answer: dyfos.Answer, mean: Sequence[float], params: Mapping[str, Any], frame_id: str, stamp: Any
) -> MarkerArray:
    """The markers of ``answer`` to a belief with mean ``mean`` = (x, y, yaw), drawn with
    the request's parameters (``f_h``, ``f_v``, ``rho_min``, ``rho_max``)."""
    header = Header(frame_id=frame_id, stamp=stamp)
    s, q = answer.sensor_position, answer.sensor_quaternion
    th, tv = math.tan(params["f_h"] / 2.0), math.tan(params["f_v"] / 2.0)
    corners = []
    for sy, sz in ((1, 1), (-1, 1), (-1, -1), (1, -1)):
        d = [1.0, sy * th, sz * tv]
        n = math.sqrt(sum(c * c for c in d))
        corners.append(_rotate(q, [c / n for c in d]))
    near = [_along(s, d, params["rho_min"]) for d in corners]
    far = [_along(s, d, params["rho_max"]) for d in corners]
    frustum = _marker(header, FRUSTUM, Marker.LINE_LIST, (0.2, 0.6, 1.0, 0.9))
    frustum.scale.x = 0.02
    for i in range(4):
        j = (i + 1) % 4
        for a, b in ((near[i], far[i]), (near[i], near[j]), (far[i], far[j])):
            frustum.points += [_point(a), _point(b)]

    sight = _marker(header, LINE_OF_SIGHT, Marker.LINE_STRIP, (0.1, 0.9, 0.2, 1.0))
    sight.scale.x = 0.03
    sight.points = [_point(s), _point(target(answer))]

    viewer = _marker(header, VIEWER, Marker.ARROW, (1.0, 0.6, 0.0, 1.0))
    yq = dyfos.ros.quaternion_from_yaw(answer.viewer_yaw)
    viewer.pose = Pose(
        position=_point(answer.viewer_position), orientation=Quaternion(x=yq[0], y=yq[1], z=yq[2], w=yq[3])
    )
    viewer.scale = Vector3(x=0.6, y=0.1, z=0.1)

    major, minor, angle = ellipse([row[:2] for row in answer.posterior[:2]])
    ell = _marker(header, ELLIPSE, Marker.CYLINDER, (0.9, 0.2, 0.9, 0.5))
    eq = dyfos.ros.quaternion_from_yaw(angle)
    ell.pose = Pose(
        position=Point(x=float(mean[0]), y=float(mean[1]), z=0.01),
        orientation=Quaternion(x=eq[0], y=eq[1], z=eq[2], w=eq[3]),
    )
    # RViz draws a cylinder's diameters; a degenerate axis stays visible.
    ell.scale = Vector3(x=max(2.0 * major, 1e-3), y=max(2.0 * minor, 1e-3), z=0.02)
    return MarkerArray(markers=[frustum, sight, viewer, ell])
