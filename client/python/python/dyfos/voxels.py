"""Voxel maps as a robot's mapping stack sends them, for :meth:`dyfos.Client.upload_voxels`
and :meth:`dyfos.Client.update_voxels`.

A :class:`Voxels` is the occupied cells of one map: from an OctoMap ``.bt`` file, from
an ``octomap_msgs/Octomap`` message (octomap_server's ``octomap_binary``), or from the
centres of occupied cells (octomap_server's ``octomap_point_cloud_centers``). Keep the
one the daemon has, and send the next as the cells that changed::

    first = dyfos.Voxels.from_octomap_message(msg, origin=[0, 0, 0.32])
    version = client.upload_voxels(7, first, bounds=[-12, -8, 31, 10], sun=[0.6, 2.4], replace=True)
    later = dyfos.Voxels.from_octomap_message(newer_msg, origin=[0, 0, 0.32])
    if later.change_records(first) <= dyfos.MAX_DELTAS_PER_BATCH:
        version = client.update_voxels(7, first, later, expected_version=version) or version
    else:
        version = client.upload_voxels(7, later, bounds=..., sun=..., replace=True)

Cells follow SPEC §1: OctoMap's cell (i, j, k) is the closed cube of side ``resolution``
whose minimum corner is ``origin + resolution·(i, j, k)`` in the map frame (see the
docs/octomap.md for choosing ``origin``).
"""

from __future__ import annotations

import array as _array
import os as _os
from typing import Any, List, Sequence, Union

from . import _dyfos

__all__ = ["MAX_DELTAS_PER_BATCH", "Voxels"]

#: Most delta records one atomic batch (:meth:`dyfos.Client.update_voxels`) carries.
MAX_DELTAS_PER_BATCH: int = _dyfos.MAX_DELTAS_PER_BATCH


def _point3(value: Any, name: str) -> List[float]:
    if hasattr(value, "tolist"):
        value = value.tolist()
    out = [float(v) for v in value]
    if len(out) != 3:
        from . import InvalidRequestError

        raise InvalidRequestError("malformed_request", f"{name} has {len(out)} numbers; it needs 3 (x, y, z)")
    return out


def _field(msg: Any, name: str) -> Any:
    return msg[name] if isinstance(msg, dict) else getattr(msg, name)


class Voxels:
    """The occupied cells of a voxel map, its ``resolution`` (m) and ``origin`` (the
    minimum corner of cell (0, 0, 0) in the map frame). ``len()`` counts the cells.

    Raises (from the constructors): :class:`dyfos.InvalidRequestError` ``invalid_delta``
    naming what is wrong with the input, or :class:`dyfos.BusyError` ``over_capacity``
    for more cells than a map holds.
    """

    __slots__ = ("_raw",)

    def __init__(self, raw: "_dyfos.RawVoxels") -> None:
        self._raw = raw

    @classmethod
    def from_octomap(
        cls, octomap: Union[str, "_os.PathLike[str]", bytes], origin: Sequence[float] = (0.0, 0.0, 0.0)
    ) -> "Voxels":
        """The occupied cells of an OctoMap ``.bt`` file (its path or bytes)."""
        return cls(_dyfos.RawVoxels.from_octomap(_octomap_bytes(octomap), _point3(origin, "origin")))

    @classmethod
    def from_octomap_message(cls, msg: Any, origin: Sequence[float] = (0.0, 0.0, 0.0)) -> "Voxels":
        """The occupied cells of an ``octomap_msgs/Octomap`` message (or a dict with its
        fields ``binary``, ``id``, ``resolution``, ``data``), as octomap_server publishes
        on ``octomap_binary``: ``binary`` true, ``id`` ``OcTree``. A full-probability map
        (``octomap_full``) is refused."""
        from . import InvalidRequestError

        if not _field(msg, "binary"):
            raise InvalidRequestError(
                "invalid_delta",
                "this Octomap message holds a full-probability tree (binary = false, octomap_server's "
                "octomap_full); send the binary one (octomap_binary)",
            )
        data = _field(msg, "data")
        if not isinstance(data, (bytes, bytearray)):
            # rclpy gives int8[] as array('b'); plain lists of -128..127 work too.
            data = data.tobytes() if hasattr(data, "tobytes") else _array.array("b", data).tobytes()
        return cls(
            _dyfos.RawVoxels.from_octomap_data(
                str(_field(msg, "id")), float(_field(msg, "resolution")), bytes(data), _point3(origin, "origin")
            )
        )

    @classmethod
    def from_points(cls, points: Any, resolution: float, origin: Sequence[float] = (0.0, 0.0, 0.0)) -> "Voxels":
        """The cells containing ``points`` (an N×3 numpy array or a sequence of ``[x, y,
        z]``, in the OctoMap's frame, e.g. occupied-cell centres): the point ``p`` marks
        cell ``floor(p / resolution)``."""
        if hasattr(points, "astype"):
            import numpy

            data = numpy.ascontiguousarray(points, dtype=numpy.float64).reshape(-1).tobytes()
        else:
            data = _array.array("d", [float(v) for p in points for v in _point3(p, "a point")]).tobytes()
        return cls(_dyfos.RawVoxels.from_points(data, float(resolution), _point3(origin, "origin")))

    @property
    def resolution(self) -> float:
        """Cell side, m."""
        return self._raw.resolution

    @property
    def origin(self) -> List[float]:
        """The minimum corner of cell (0, 0, 0) in the map frame, m."""
        return list(self._raw.origin)

    def __len__(self) -> int:
        return len(self._raw)

    def change_records(self, previous: "Voxels") -> Union[int, None]:
        """How many delta records :meth:`dyfos.Client.update_voxels` sends to turn
        ``previous`` into this map (0: nothing changed), or ``None`` if it cannot: the
        two differ in resolution or origin, so upload this one whole."""
        return self._raw.change_records(previous._raw)

    def __repr__(self) -> str:
        return f"dyfos.Voxels({len(self)} cells, resolution={self.resolution!r}, origin={self.origin!r})"


def _octomap_bytes(octomap: Union[str, "_os.PathLike[str]", bytes, bytearray, memoryview]) -> bytes:
    """An OctoMap ``.bt`` file's bytes, given them or its path; a file that cannot be
    read is ``InvalidRequestError`` (``invalid_delta``)."""
    if isinstance(octomap, (bytes, bytearray, memoryview)):
        return bytes(octomap)
    try:
        with open(octomap, "rb") as f:
            return f.read()
    except OSError as e:
        from . import InvalidRequestError

        raise InvalidRequestError("invalid_delta", f"cannot read OctoMap file {octomap}: {e}") from e
