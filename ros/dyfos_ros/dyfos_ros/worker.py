"""A thread with its own ``dyfos.Client``: the node's calls to the daemon run here, never
on the executor's thread, so a long search or map upload holds up neither other
callbacks nor Ctrl-C.

A job is a function of the client; :meth:`Worker.submit` returns an rclpy
:class:`~rclpy.task.Future` that a coroutine callback awaits on the executor's thread.
Jobs run one at a time, in order. A job submitted with a ``key`` replaces a job of
the same key that has not started (its future gets :data:`SUPERSEDED`): a stream of
beliefs or maps is served at the pace the daemon answers, newest first, without a
backlog.

The client connects on first use and is kept: after a daemon restart its next call
reconnects by itself (a call in between fails with ``dyfos.DaemonGoneError``).
"""

from __future__ import annotations

import threading
from typing import Any, Callable, List, Optional, Tuple

import dyfos
from rclpy.executors import Executor
from rclpy.task import Future

#: What the future of a job replaced by a newer one of the same key gets.
SUPERSEDED = object()

Job = Callable[[dyfos.Client], Any]


class Worker:
    """One daemon thread running jobs on one ``dyfos.Client``.

    Args:
        name: the thread's name.
        connect: opens the client (raises ``dyfos.DaemonGoneError`` with no daemon).
    """

    def __init__(self, name: str, connect: Callable[[], dyfos.Client]) -> None:
        self._connect = connect
        self._client: Optional[dyfos.Client] = None
        self._lock = threading.Condition()
        self._queue: List[Tuple[Optional[str], Future, Job]] = []
        self._stopping = False
        self._busy = False
        # A daemon thread: a call stuck in the daemon cannot keep the process alive.
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._thread.start()

    def submit(self, job: Job, executor: Optional[Executor], key: Optional[str] = None) -> Future:
        """Queues ``job``; its future (done on this worker's thread) wakes ``executor``."""
        future = Future(executor=executor)
        # A done callback makes set_result schedule a task on the executor, which wakes
        # it, so a coroutine awaiting the future resumes at once.
        future.add_done_callback(lambda _f: None)
        with self._lock:
            if self._stopping:
                future.cancel()
                return future
            if key is not None:
                for i, (k, old, _job) in enumerate(self._queue):
                    if k == key:
                        self._queue[i] = (key, future, job)
                        old.set_result(SUPERSEDED)
                        return future
            self._queue.append((key, future, job))
            self._lock.notify()
        return future

    def stop(self) -> None:
        """Takes no more jobs and cancels the queued ones; the thread closes its client
        after the job it runs (if any)."""
        with self._lock:
            self._stopping = True
            queued, self._queue = self._queue, []
            self._lock.notify()
        for _key, future, _job in queued:
            future.cancel()

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
                self._busy = True
            try:
                if self._client is None:
                    self._client = self._connect()
                result = job(self._client)
            except BaseException as e:  # delivered to the awaiting callback
                if not future.done():
                    future.set_exception(e)
            else:
                if not future.done():
                    future.set_result(result)
            finally:
                with self._lock:
                    self._busy = False
        if self._client is not None:
            self._client.close()
