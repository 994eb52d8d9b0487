"""A thread with its own ``dyfos.Client``: the node's calls to the daemon for topics and
timers run here, so a map upload or a stream of beliefs holds up neither other callbacks
nor Ctrl-C.

A job is a function of the client; :meth:`Worker.submit` returns a
:class:`concurrent.futures.Future` of its result. Topic and timer callbacks add a done
callback that publishes from the worker's thread, and return at once.

Jobs run one at a time, in order. A job submitted with a ``key`` replaces a job of the
same key that has not started (its future gets :data:`SUPERSEDED`): a stream of beliefs
or maps is served at the pace the daemon answers, newest first, without a backlog.
:meth:`Worker.stop` cancels the queued jobs and fails the running one's future with
:class:`Stopped`, so nobody waits for the daemon once the node is told to stop.

The client connects on first use and is kept: after a daemon restart its next call
reconnects by itself (a call in between fails with ``dyfos.DaemonGoneError``).
"""

from __future__ import annotations

import threading
from concurrent.futures import Future, InvalidStateError
from typing import Any, Callable, List, Optional, Tuple

import dyfos

#: What the future of a job replaced by a newer one of the same key gets.
SUPERSEDED = object()

Job = Callable[[dyfos.Client], Any]


class Stopped(Exception):
    """The node stopped before the job's answer came."""


def _settle(future: Future, result: Any = None, error: Optional[BaseException] = None) -> None:
    """Sets a future that :meth:`Worker.stop` may have failed already."""
    try:
        if error is None:
            future.set_result(result)
        else:
            future.set_exception(error)
    except InvalidStateError:
        pass


class Worker:
    """One daemon thread running jobs on one ``dyfos.Client``.

    Args:
        name: the thread's name.
        connect: opens the client (raises ``dyfos.DaemonGoneError`` with no daemon);
            ``None`` for a worker whose jobs need none (they get ``None``).
    """

    def __init__(self, name: str, connect: Optional[Callable[[], dyfos.Client]]) -> None:
        self._connect = connect
        self._client: Optional[dyfos.Client] = None
        self._lock = threading.Condition()
        self._queue: List[Tuple[Optional[str], Future, Job]] = []
        self._running: Optional[Future] = None
        self._stopping = False
        # A daemon thread: a call stuck in the daemon cannot keep the process alive.
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._thread.start()

    def submit(self, job: Job, key: Optional[str] = None) -> Future:
        """Queues ``job``; returns the future of its result."""
        future: Future = Future()
        with self._lock:
            if self._stopping:
                _settle(future, error=Stopped("the node is shutting down"))
                return future
            if key is not None:
                for i, (k, old, _job) in enumerate(self._queue):
                    if k == key:
                        self._queue[i] = (key, future, job)
                        _settle(old, SUPERSEDED)
                        return future
            self._queue.append((key, future, job))
            self._lock.notify()
        return future

    def stop(self) -> None:
        """Takes no more jobs, fails the queued ones and the running one with
        :class:`Stopped`; the thread closes its client after the call it is in (if any)."""
        with self._lock:
            self._stopping = True
            queued, self._queue = self._queue, []
            running = self._running
            self._lock.notify()
        for _key, future, _job in queued:
            _settle(future, error=Stopped("the node is shutting down"))
        if running is not None:
            _settle(running, error=Stopped("the node is shutting down"))

    def join(self, timeout: float) -> bool:
        """Waits up to ``timeout`` s for the thread to end; whether it did."""
        self._thread.join(timeout)
        return not self._thread.is_alive()

    def _run(self) -> None:
        while True:
            with self._lock:
                while not self._queue and not self._stopping:
                    self._lock.wait()
                if self._stopping:
                    break
                _key, future, job = self._queue.pop(0)
                self._running = future
            try:
                if self._client is None and self._connect is not None:
                    self._client = self._connect()
                result = job(self._client)
            except BaseException as e:  # delivered to whoever waits for the job
                _settle(future, error=e)
            else:
                _settle(future, result)
            finally:
                with self._lock:
                    self._running = None
        if self._client is not None:
            self._client.close()
