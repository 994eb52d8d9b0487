"""Keeps the daemon's map ``map_id`` in step with the robot's mapping stack.

Maps arrive as ``octomap_msgs/Octomap`` (octomap_server's ``octomap_binary``: a binary
``OcTree``) or as a ``sensor_msgs/PointCloud2`` of occupied-cell centres
(``octomap_point_cloud_centers``). The first map is uploaded whole (replacing whatever
the id held); each later one is sent as the cells that changed, one atomic batch of
map deltas, when they fit one batch, else uploaded whole again (also atomic). An
upload also follows a change of ``bounds``, ``sun``, ``origin`` or the grid, a map that
someone else changed (``map_version_mismatch``), and a daemon that came back without
the map. All of it runs on the map worker's thread (:class:`MapSync` methods are jobs).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any, Callable, List, Optional, Sequence

import dyfos

from .convert import clip

# sensor_msgs/PointField datatypes, as numpy dtypes.
_FIELD_TYPES = {1: "i1", 2: "u1", 3: "i2", 4: "u2", 5: "i4", 6: "u4", 7: "f4", 8: "f8"}


class MapError(Exception):
    """A map message that cannot be used (what is wrong with it)."""


def points_of_cloud(msg: Any) -> Any:
    """The finite (x, y, z) points of a ``PointCloud2`` as an N × 3 float64 array."""
    import numpy as np

    fields = {f.name: f for f in msg.fields}
    if not all(k in fields for k in "xyz"):
        raise MapError(f"the cloud has no x, y, z fields (it has {', '.join(fields) or 'none'})")
    formats, offsets = [], []
    for k in "xyz":
        f = fields[k]
        if f.datatype not in _FIELD_TYPES or f.count != 1:
            raise MapError(f"field {k} has datatype {f.datatype} and count {f.count}; need one number")
        fmt = (">" if msg.is_bigendian else "<") + _FIELD_TYPES[f.datatype]
        if f.offset + np.dtype(fmt).itemsize > msg.point_step:
            raise MapError(f"field {k} at byte {f.offset} does not fit a point of {msg.point_step} bytes")
        formats.append(fmt)
        offsets.append(f.offset)
    dtype = np.dtype({"names": ["x", "y", "z"], "formats": formats, "offsets": offsets, "itemsize": msg.point_step})
    width, height, row_step = int(msg.width), int(msg.height), int(msg.row_step)
    data = bytes(msg.data)
    if width * msg.point_step > row_step or len(data) < row_step * height:
        raise MapError(
            f"the cloud's sizes disagree: {width} × {height} points of {msg.point_step} bytes, "
            f"rows of {row_step} bytes, {len(data)} bytes of data"
        )
    rows = [np.frombuffer(data, dtype=dtype, count=width, offset=r * row_step) for r in range(height)]
    cloud = np.concatenate(rows) if rows else np.zeros(0, dtype=dtype)
    points = np.stack([cloud["x"], cloud["y"], cloud["z"]], axis=1).astype(np.float64)
    return points[np.isfinite(points).all(axis=1)]


@dataclass
class MapSettings:
    """What the map is made with (the node's parameters)."""

    map_id: int
    bounds: Optional[List[float]]
    sun: Optional[List[float]]
    origin: List[float]
    cloud_resolution: float


@dataclass
class MapState:
    """What the daemon holds, as far as the node knows; read by diagnostics."""

    version: Optional[int] = None
    cells: int = 0
    source: str = ""
    updates: int = 0
    uploads: int = 0
    last_update: float = 0.0
    error: str = ""
    pending: bool = False


class MapSync:
    """The map worker's side: turns map messages into the daemon's map ``map_id``.

    Args:
        settings: reads the node's current map parameters.
        log: logs a line (info) about each change of the map.
    """

    def __init__(self, settings: Callable[[], MapSettings], log: Callable[[str], None]) -> None:
        self._settings = settings
        self._log = log
        self._voxels: Optional[dyfos.Voxels] = None  # what the daemon holds
        self._made_with: Optional[tuple] = None  # (map_id, bounds, sun, origin) of that upload
        self._source: Optional[Callable[[MapSettings], dyfos.Voxels]] = None  # rebuilds the last map
        self.state = MapState()

    def octomap(self, msg: Any) -> Callable[[dyfos.Client], None]:
        """The job for an ``octomap_msgs/Octomap``."""
        return self._job(lambda s: dyfos.Voxels.from_octomap_message(msg, s.origin), "octomap")

    def cloud(self, msg: Any) -> Callable[[dyfos.Client], None]:
        """The job for a ``PointCloud2`` of occupied-cell centres."""

        def build(s: MapSettings) -> dyfos.Voxels:
            return dyfos.Voxels.from_points(points_of_cloud(msg), s.cloud_resolution, s.origin)

        return self._job(build, "cloud")

    def resync(self) -> Callable[[dyfos.Client], None]:
        """The job that uploads the last map again, whole, with the current parameters
        (after they changed, or the daemon came back without it)."""

        def job(client: dyfos.Client) -> None:
            if self._source is not None:
                self._voxels = None
                self._sync(client, self._source, self.state.source)

        return job

    def _job(self, build: Callable[[MapSettings], dyfos.Voxels], kind: str) -> Callable[[dyfos.Client], None]:
        self.state.pending = True

        def job(client: dyfos.Client) -> None:
            self._sync(client, build, kind)

        return job

    def _sync(self, client: dyfos.Client, build: Callable[[MapSettings], dyfos.Voxels], kind: str) -> None:
        s = self._settings()
        self.state.pending = False
        try:
            self._source = build
            self.state.source = kind
            voxels = build(s)
            if s.bounds is None or s.sun is None:
                raise MapError("set the parameters `bounds` and `sun`: the map needs them (an OctoMap has neither)")
            self._send(client, s, voxels)
            self.state.error = ""
        except (MapError, dyfos.DyfosError) as e:
            self.state.error = clip(str(e))
            raise

    def _send(self, client: dyfos.Client, s: MapSettings, voxels: dyfos.Voxels) -> None:
        made_with = (s.map_id, tuple(s.bounds or ()), tuple(s.sun or ()), tuple(s.origin))
        previous = self._voxels if self._made_with == made_with else None
        records = None if previous is None else voxels.change_records(previous)
        version = None
        if previous is not None and records is not None and records <= dyfos.MAX_DELTAS_PER_BATCH:
            try:
                new = client.update_voxels(s.map_id, previous, voxels, expected_version=self.state.version)
                version = self.state.version if new is None else new
                if new is not None:
                    self.state.updates += 1
                    self._log(f"map {s.map_id}: {records} delta records, version {version}, {len(voxels)} cells")
            except (dyfos.MapVersionMismatchError, dyfos.UnknownMapError) as e:
                self._log(f"map {s.map_id}: {e.status}; uploading it whole")
        if version is None:
            version = client.upload_voxels(
                s.map_id, voxels, s.bounds, s.sun, replace=True, timeout=max(30.0, client.timeout)
            )
            self.state.uploads += 1
            self._log(f"map {s.map_id}: uploaded, version {version}, {len(voxels)} cells at {voxels.resolution} m")
        self._voxels, self._made_with = voxels, made_with
        self.state.version = version
        self.state.cells = len(voxels)
        self.state.last_update = time.time()


def settings_from(
    map_id: int, bounds: Sequence[float], sun: Sequence[float], origin: Sequence[float], res: float
) -> MapSettings:
    """Map settings from parameter values; an empty ``bounds`` / ``sun`` is not set."""
    return MapSettings(
        map_id=int(map_id),
        bounds=[float(v) for v in bounds] if len(bounds) else None,
        sun=[float(v) for v in sun] if len(sun) else None,
        origin=[float(v) for v in origin],
        cloud_resolution=float(res),
    )
