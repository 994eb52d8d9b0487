"""Type stub of the private extension module ``dyfos._dyfos`` (use ``dyfos`` instead)."""

from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple, Union

DEFAULT_PREFIX: str
MAX_DELTAS_PER_BATCH: int

def default_params() -> Dict[str, Any]:
    """Every SPEC §11 parameter at its default, by name."""

def set_error_factory(factory: Callable[[str, str, bool, Optional[int], Optional[int]], BaseException]) -> None:
    """Registers the callable that makes the exception to raise for a failure."""

class RawAnswer:
    """An answer, as the JSON object ``dyfos solve`` prints."""

    def to_dict(self) -> Dict[str, Any]: ...
    def to_json(self) -> str: ...
    @property
    def algorithm(self) -> str: ...
    @property
    def x(self) -> List[float]: ...
    @property
    def cost(self) -> float: ...
    @property
    def R(self) -> List[List[float]]: ...
    @property
    def posterior(self) -> List[List[float]]: ...
    @property
    def sensor_position(self) -> List[float]: ...
    @property
    def sensor_quaternion(self) -> List[float]: ...
    @property
    def viewer_position(self) -> List[float]: ...
    @property
    def viewer_yaw(self) -> float: ...
    @property
    def evaluations(self) -> Dict[str, int]: ...
    @property
    def map_version(self) -> int: ...
    @property
    def stop(self) -> str: ...
    @property
    def micros(self) -> int: ...

class RawClient:
    """``dyfos_client::Client`` behind a mutex; every call releases the GIL while it waits."""

    def __init__(self, prefix: str, domain: Optional[str], timeout: float, connect_timeout: float) -> None: ...
    def close(self) -> None: ...
    @property
    def closed(self) -> bool: ...
    def stats(self, timeout: Optional[float] = None) -> Dict[str, Any]: ...
    def upload_scenario(
        self, scenario_json: str, map_id: Optional[int] = None, replace: bool = False, timeout: Optional[float] = None
    ) -> Tuple[int, int]: ...
    def upload_octomap(
        self,
        map_id: int,
        bt: bytes,
        bounds: Sequence[float],
        sun: Tuple[float, float],
        origin: Sequence[float] = ...,
        replace: bool = False,
        timeout: Optional[float] = None,
    ) -> int: ...
    def create_map(
        self, map_id: int, bounds: Sequence[float], sun: Tuple[float, float], timeout: Optional[float] = None
    ) -> int: ...
    def apply(
        self, map_id: int, deltas_json: str, expected_version: Optional[int] = None, timeout: Optional[float] = None
    ) -> int: ...
    def snapshot(self, map_id: int, timeout: Optional[float] = None) -> Dict[str, Any]: ...
    def delete_map(self, map_id: int, expected_version: Optional[int] = None, timeout: Optional[float] = None) -> None: ...
    def list_maps(self, timeout: Optional[float] = None) -> List[Dict[str, Any]]: ...
    def rendezvous(
        self,
        check: bool,
        map_id: int,
        mean: Any,
        cov: Any,
        algorithm: str,
        seed: int,
        params: Optional[str],
        budget: Optional[int],
        deadline: Optional[float],
        expected_version: Optional[int],
        deltas: Optional[str],
        timeout: Optional[float],
    ) -> Union[RawAnswer, int]:
        """With ``check`` false the answer; with ``check`` true the map version the
        request would search (check mode: validated, not searched)."""
    def _rust_round_trips(
        self,
        map_id: int,
        mean: Sequence[float],
        cov: Sequence[Sequence[float]],
        check: bool,
        count: int,
        timeout: Optional[float] = None,
    ) -> List[float]: ...

class RawVoxels:
    """The occupied cells of a voxel map (``dyfos_shared::world::VoxelGrid``)."""

    @staticmethod
    def from_octomap(bt: bytes, origin: Sequence[float]) -> RawVoxels: ...
    @staticmethod
    def from_octomap_data(tree_id: str, resolution: float, data: bytes, origin: Sequence[float]) -> RawVoxels: ...
    @staticmethod
    def from_points(points: bytes, resolution: float, origin: Sequence[float]) -> RawVoxels: ...
    def __len__(self) -> int: ...
    @property
    def resolution(self) -> float: ...
    @property
    def origin(self) -> List[float]: ...
    def change_records(self, previous: RawVoxels) -> Optional[int]: ...

def upload_voxels(
    client: RawClient,
    map_id: int,
    voxels: RawVoxels,
    bounds: Sequence[float],
    sun: Tuple[float, float],
    replace: bool = False,
    timeout: Optional[float] = None,
) -> int: ...
def update_voxels(
    client: RawClient,
    map_id: int,
    previous: RawVoxels,
    voxels: RawVoxels,
    expected_version: Optional[int] = None,
    timeout: Optional[float] = None,
) -> Optional[int]: ...
