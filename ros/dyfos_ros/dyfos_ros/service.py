"""A ROS service answered on a thread of its own, outside the node's executor.

rclpy's executors rebuild their wait set from every entity of the node in Python on each
turn, and a multi-threaded one hands each callback to a pool thread: on a round trip
that is most of what the node adds to ROS's own cost. :class:`ServiceThread` instead
waits on a wait set holding only its service (and a guard condition that wakes it to
stop), takes a request, answers it on the same thread (with its own ``dyfos.Client``,
so the call to the daemon needs no hand-off) and sends the response from there. The
node's executor never runs the service's callback (its callback group lets no executor
run it), so a long search holds up neither topics, timers, diagnostics nor the
parameter services; requests to this service are answered one at a time, in order.

:meth:`ServiceThread.stop` answers a request still in the daemon's hands with the
``refuse`` response (``shutting_down``) at once, from the stopping thread: nobody waits
for a search the node will not see the end of. Built the way ``rclpy.wait_for_message``
builds its wait set.
"""

from __future__ import annotations

import threading
from contextlib import ExitStack
from typing import Any, Callable, Optional, Tuple

import dyfos
from rclpy.callback_groups import CallbackGroup
from rclpy.guard_condition import GuardCondition
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.node import Node

#: What a request handler gives back: the response, and what to do once it is sent
#: (off the request's path), if anything.
Handled = Tuple[Any, Optional[Callable[[], None]]]


class _NoExecutor(CallbackGroup):
    """A callback group no executor runs: its entities are served elsewhere."""

    def can_execute(self, entity: Any) -> bool:
        return False

    def beginning_execution(self, entity: Any) -> bool:
        return False

    def ending_execution(self, entity: Any) -> None:
        pass


class ServiceThread:
    """Serves ``name`` (of ``srv_type``) on ``node`` from a thread of its own.

    Args:
        node: the node the service belongs to (its name resolves ``~/``).
        srv_type: the service type.
        name: the service's name.
        handle: ``handle(request, client)`` answers a request; ``client()`` returns the
            thread's ``dyfos.Client``, connected on first use (raises
            ``dyfos.DaemonGoneError`` with no daemon). Runs on the service's thread.
        refuse: ``refuse(status, message)`` is a response refusing a request: what a
            request gets when ``handle`` raises (a bug), or when the node stops before
            its answer.
        connect: opens the thread's ``dyfos.Client``.
        thread_name: the thread's name.
    """

    def __init__(
        self,
        node: Node,
        srv_type: Any,
        name: str,
        handle: Callable[[Any, Callable[[], dyfos.Client]], Handled],
        refuse: Callable[[str, str], Any],
        connect: Callable[[], dyfos.Client],
        thread_name: str,
    ) -> None:
        self._srv_type = srv_type
        self._handle = handle
        self._refuse = refuse
        self._connect = connect
        self._client: Optional[dyfos.Client] = None
        self._logger = node.get_logger()
        self._context = node.context
        self._service = node.create_service(srv_type, name, self._never_called, callback_group=_NoExecutor())
        self._name = self._service.service_name
        self._wake = GuardCondition(callback=None, callback_group=None, context=self._context)
        self._context.on_shutdown(self._wake_up)
        self._lock = threading.Lock()
        self._stopping = False
        self._answering: Optional[Any] = None  # the header of the request in hand
        self._thread = threading.Thread(target=self._run, name=thread_name, daemon=True)
        self._thread.start()

    def stop(self) -> None:
        """Takes no more requests; answers the one in hand, if any, with
        ``refuse("shutting_down", ...)`` now. The thread ends after the call it is in."""
        with self._lock:
            if self._stopping:
                return
            self._stopping = True
            header, self._answering = self._answering, None
            if header is not None:
                self._send(self._refuse("shutting_down", "the node is shutting down"), header)
        self._wake_up()

    def join(self, timeout: float) -> bool:
        """Waits up to ``timeout`` s for the thread to end; whether it did."""
        self._thread.join(timeout)
        return not self._thread.is_alive()

    def _wake_up(self) -> None:
        try:
            self._wake.trigger()
        except Exception:  # destroyed with the context: nothing left to wake
            pass

    @staticmethod
    def _never_called(request: Any, response: Any) -> Any:
        raise AssertionError("served by ServiceThread, not by an executor")

    def _client_now(self) -> dyfos.Client:
        # Kept across calls: after a daemon restart the next call reconnects by itself.
        if self._client is None:
            self._client = self._connect()
        return self._client

    def _run(self) -> None:
        try:
            while True:
                try:
                    taken = self._take()
                except Exception as e:  # the node or ROS shut down under the wait, or a bug
                    if not self._stopping and self._context.ok():
                        self._logger.error(f"{self._name}: no longer served: {type(e).__name__}: {e}")
                    return
                if taken is None:
                    if self._stopping or not self._context.ok():
                        return
                    continue
                request, header = taken
                with self._lock:
                    if self._stopping:
                        return
                    self._answering = header
                try:
                    response, then = self._handle(request, self._client_now)
                except Exception as e:  # a bug: say so; the caller still gets an answer
                    self._logger.error(f"{self._name}: {type(e).__name__}: {e}", throttle_duration_sec=5.0)
                    response, then = self._refuse("internal_error", f"{type(e).__name__}: {e}"), None
                with self._lock:
                    if self._answering is not header:  # stop() answered it
                        return
                    self._answering = None
                    self._send(response, header)
                if then is not None:
                    try:
                        then()
                    except Exception as e:  # a bug, or the node shutting down: keep serving
                        self._logger.error(f"{self._name}: after the answer: {type(e).__name__}: {e}")
        finally:
            if self._client is not None:
                self._client.close()

    def _take(self) -> Optional[Tuple[Any, Any]]:
        """Waits for a request or a wake-up; the request and its header, or ``None``."""
        service = self._service
        with ExitStack() as handles:
            for h in (service.handle, self._wake.handle, self._context.handle):
                handles.enter_context(h)
            wait_set = _rclpy.WaitSet(0, 1, 0, 0, 1, 0, self._context.handle)
            wait_set.clear_entities()
            wait_set.add_service(service.handle)
            wait_set.add_guard_condition(self._wake.handle)
            wait_set.wait(-1)
            if service.handle.pointer not in wait_set.get_ready_entities("service"):
                return None
            request, header = service.handle.service_take_request(self._srv_type.Request)
        if header is None:
            return None
        return request, header

    def _send(self, response: Any, header: Any) -> None:
        # Under self._lock: once stop() has returned nothing is sent (the node may be
        # destroyed next).
        try:
            self._service.send_response(response, header)
        except Exception as e:  # the node is shutting down, or a bug: the caller's own timeout ends its wait
            self._logger.warning(f"{self._name}: response not sent: {e}", throttle_duration_sec=5.0)
