"""``~/markers`` for the newest answer, drawn off the answers' path.

Building a ``MarkerArray`` is Python work that holds the GIL for a while; done for every
answer it would delay the next request's response. So the painter draws on a thread of
its own, only while someone subscribes, at most once every ``period`` seconds, and
always the newest answer: an answer that comes while one is waiting replaces it. A
subscriber that joins later gets the newest answer's markers at once (the publisher is
transient local, and a new match redraws).
"""

from __future__ import annotations

import threading
import time
from typing import Any, Dict, List, Optional, Tuple

import dyfos
from rclpy.event_handler import PublisherEventCallbacks, QoSPublisherMatchedInfo
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from visualization_msgs.msg import MarkerArray

from . import markers
from .worker import Worker

MARKER_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)

#: An answer to draw: the answer, the belief's mean, the request's parameters, the
#: frame and the belief's stamp.
Drawing = Tuple[dyfos.Answer, List[float], Dict[str, Any], str, Any]


class Painter:
    """Publishes ``topic`` (``MarkerArray``) of ``node`` for the newest answer drawn."""

    def __init__(self, node: Node, topic: str, period: float) -> None:
        self._period = period
        self._logger = node.get_logger()
        self._lock = threading.Lock()
        self._newest: Optional[Drawing] = None
        self._last_drawn = float("-inf")
        self._worker = Worker("dyfos-markers", None)
        self._publisher = node.create_publisher(
            MarkerArray, topic, MARKER_QOS, event_callbacks=PublisherEventCallbacks(matched=self._matched)
        )

    @property
    def worker(self) -> Worker:
        return self._worker

    def draw(self, answer: dyfos.Answer, mean: List[float], params: Dict[str, Any], frame_id: str, stamp: Any) -> None:
        """Keeps ``answer`` as the newest; draws it soon if anyone subscribes."""
        with self._lock:
            self._newest = (answer, mean, params, frame_id, stamp)
        if self._publisher.get_subscription_count() > 0:
            self._worker.submit(self._paint, key="markers")

    def _matched(self, info: QoSPublisherMatchedInfo) -> None:
        # On the executor: a new subscriber gets the newest answer's markers.
        if info.current_count_change > 0:
            self._worker.submit(self._paint, key="markers")

    def _paint(self, _client: None) -> None:
        # On the painter's thread. Waits out the period first: answers that come
        # meanwhile replace this job, and only the newest is drawn.
        wait = self._last_drawn + self._period - time.monotonic()
        if wait > 0:
            time.sleep(wait)
        with self._lock:
            drawing, self._newest = self._newest, None
        if drawing is None:
            return
        try:
            self._publisher.publish(markers.markers(*drawing))
        except Exception as e:  # a bug, or the node shutting down: say so, keep serving
            self._logger.error(f"~/markers: {type(e).__name__}: {e}", throttle_duration_sec=5.0)
        self._last_drawn = time.monotonic()
