"""Type stub of the private extension module ``dyfos._dyfos`` (use ``dyfos`` instead)."""

from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple

DEFAULT_PREFIX: str

def set_error_factory(factory: Callable[[str, str, bool, Optional[int]], BaseException]) -> None:
    """Registers the callable that makes the exception to raise for a failure."""

class RawAnswer:
    """An answer, as the JSON object ``dyfos solve`` prints."""

    def to_dict(self) -> Dict[str, Any]: ...
    def to_json(self) -> str: ...

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
    def create_map(
        self, map_id: int, bounds: Sequence[float], sun: Tuple[float, float], timeout: Optional[float] = None
    ) -> int: ...
    def apply(
        self, map_id: int, deltas_json: str, expected_version: Optional[int] = None, timeout: Optional[float] = None
    ) -> int: ...
    def snapshot(self, map_id: int, timeout: Optional[float] = None) -> Dict[str, Any]: ...
    def delete_map(self, map_id: int, expected_version: Optional[int] = None, timeout: Optional[float] = None) -> None: ...
    def rendezvous(
        self,
        map_id: int,
        mean: Sequence[float],
        cov: Sequence[Sequence[float]],
        algorithm: str,
        seed: int,
        params: Optional[str],
        budget: Optional[int],
        deadline: Optional[float],
        expected_version: Optional[int],
        deltas: Optional[str],
        timeout: Optional[float],
    ) -> RawAnswer: ...
    def check(
        self,
        map_id: int,
        mean: Sequence[float],
        cov: Sequence[Sequence[float]],
        algorithm: str,
        seed: int,
        params: Optional[str],
        budget: Optional[int],
        deadline: Optional[float],
        expected_version: Optional[int],
        deltas: Optional[str],
        timeout: Optional[float],
    ) -> int: ...
    def _rust_round_trips(
        self,
        map_id: int,
        mean: Sequence[float],
        cov: Sequence[Sequence[float]],
        check: bool,
        count: int,
        timeout: Optional[float] = None,
    ) -> List[float]: ...
