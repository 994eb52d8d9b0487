"""Fixtures for dyfos_ros's tests: real rclpy and Fast DDS, the node in its own process.

Each test gets a ROS domain id no other test on this machine holds (a lock file per id
in 0..101, so parallel runs of the suite do not collide), a ``dyfosd`` of its own
(prefix, iceoryx2 domain and state directory: the Python binding's test fixture, reused),
and starts ``dyfos-ros`` processes with ``start_node``. The test talks to them from this
process through :class:`Ros`, an rclpy context on the test's domain.

``ros/test.sh`` sets the environment: ``DYFOSD``, ``DYFOS`` (the binaries),
``DYFOS_TEST_DATA``, ``DYFOS_ROS`` (the node's executable in the venv), and
``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` and ``ROS_LOG_DIR`` so that nothing leaves
the machine or the build directory.
"""

from __future__ import annotations

import fcntl
import importlib.util
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any, Callable, Dict, Iterator, List, Optional

import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

ROOT = Path(__file__).resolve().parents[3]

# The binding's test fixtures: a dyfosd per test with its own prefix, domain and state
# directory, and the `dyfos` command line. Loaded under another name than `conftest`.
_spec = importlib.util.spec_from_file_location("dyfos_python_conftest", ROOT / "client/python/tests/conftest.py")
assert _spec is not None and _spec.loader is not None
pyconftest = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(pyconftest)
DATA = pyconftest.DATA
dyfos_cli = pyconftest.dyfos_cli

#: How long any wait in these tests may take before the test fails.
PATIENCE = 30.0
#: A service call unanswered this long is sent again (see :meth:`Ros.call`).
RESEND_AFTER = 10.0
DYFOS_ROS = os.environ.get("DYFOS_ROS") or str(Path(sys.executable).parent / "dyfos-ros")
FASTDDS = str(Path(sys.executable).parent / "fastdds")
DOMAIN_LOCKS = Path(tempfile.gettempdir()) / "dyfos-ros-test-domains"
#: ROS domain ids that keep Fast DDS's ports below the ephemeral range (ROS2.md, Q6).
DOMAIN_IDS = range(0, 102)

LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)


def pytest_configure(config: Any) -> None:
    for var in ("ROS_AUTOMATIC_DISCOVERY_RANGE", "ROS_LOG_DIR"):
        if not os.environ.get(var):
            pytest.exit(f"set {var} (ros/test.sh does): tests must stay on this machine and in target/", returncode=2)
    if not os.access(DYFOS_ROS, os.X_OK):
        pytest.exit(f"{DYFOS_ROS} is missing: run ros/install.sh", returncode=2)


def pytest_sessionfinish(session: Any, exitstatus: int) -> None:
    # Segments a killed participant left behind (live ones are left alone).
    if os.access(FASTDDS, os.X_OK):
        subprocess.run([FASTDDS, "shm", "clean"], capture_output=True, timeout=60, check=False)


class Daemon(pyconftest.Daemon):
    """The binding tests' daemon, which can also come back after it was killed."""

    def restart(self, fresh_state: bool = False) -> None:
        """Starts a new dyfosd on the same prefix and domain, and the same state
        directory (its maps come back from disk) or, with ``fresh_state``, an empty one."""
        assert not self.alive()
        if fresh_state:
            for f in Path(self.state_dir).iterdir():
                f.unlink()
        self.process = subprocess.Popen(
            [pyconftest.DYFOSD, "--prefix", self.prefix, "--domain", self.domain, "--state-dir", self.state_dir],
            stdout=subprocess.DEVNULL,
            stderr=self._log,
            env={**os.environ, "RUST_LOG": "info"},
        )
        end = time.monotonic() + PATIENCE
        while True:
            try:
                with self.client(connect_timeout=0.05) as c:
                    c.stats()
                return
            except pyconftest.dyfos.DaemonGoneError:
                if time.monotonic() > end or not self.alive():
                    raise


class DomainId:
    """A ROS domain id held through a lock file until :meth:`release`."""

    def __init__(self) -> None:
        DOMAIN_LOCKS.mkdir(exist_ok=True)
        start = os.getpid() % len(DOMAIN_IDS)
        for k in range(len(DOMAIN_IDS)):
            n = DOMAIN_IDS[(start + k) % len(DOMAIN_IDS)]
            f = open(DOMAIN_LOCKS / f"{n}.lock", "w")
            try:
                fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:
                f.close()
                continue
            self.id, self._file = n, f
            return
        raise RuntimeError("every ROS domain id 0..101 is taken by other tests")

    def release(self) -> None:
        self._file.close()


class Ros:
    """rclpy on one domain id, in this process: service calls, publishers and
    subscriptions, spun by this thread (no executor thread)."""

    def __init__(self, domain: int) -> None:
        self.domain = domain
        self.context = rclpy.Context()
        rclpy.init(context=self.context, domain_id=domain)
        self.node = rclpy.create_node(f"dyfos_test_{os.getpid()}", context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)

    def spin_until(self, done: Callable[[], bool], timeout: float = PATIENCE, what: str = "") -> None:
        """Spins until ``done()``. ``spin_once`` in a loop: jazzy's
        ``spin_until_future_complete`` slows down with every call (ROS2.md, Q2)."""
        end = time.monotonic() + timeout
        while not done():
            if time.monotonic() > end:
                raise AssertionError(f"timed out after {timeout} s waiting for {what or done}")
            self.executor.spin_once(timeout_sec=0.02)

    def spin_for(self, seconds: float) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.executor.spin_once(timeout_sec=0.02)

    def call(self, srv_type: Any, name: str, request: Any, timeout: float = PATIENCE) -> Any:
        """One answer to ``request``. A service is "ready" once it sees our requests, but
        its reply may still find no reader on our side (Fast DDS: "failed to send response
        (timeout): client will not receive response"), so a call unanswered for
        ``RESEND_AFTER`` is sent again; the queries are idempotent."""
        client = self.client(srv_type, name, timeout)
        end = time.monotonic() + timeout
        while True:
            future = client.call_async(request)
            wait = min(RESEND_AFTER, end - time.monotonic())
            try:
                self.spin_until(future.done, max(wait, 0.0), f"the answer of {name}")
                return future.result()
            except AssertionError:
                client.remove_pending_request(future)
                if time.monotonic() >= end:
                    raise AssertionError(f"timed out after {timeout} s waiting for the answer of {name}") from None

    def client(self, srv_type: Any, name: str, timeout: float = PATIENCE) -> Any:
        client = self.node.create_client(srv_type, name)
        self.spin_until(client.service_is_ready, timeout, f"service {name}")
        return client

    def subscribe(self, msg_type: Any, topic: str, qos: Any = 10) -> List[Any]:
        got: List[Any] = []
        self.node.create_subscription(msg_type, topic, got.append, qos)
        return got

    def publisher(self, msg_type: Any, topic: str, qos: Any = 10) -> Any:
        return self.node.create_publisher(msg_type, topic, qos)

    def close(self) -> None:
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)


class NodeProcess:
    """One ``dyfos-ros`` process on a ROS domain; its output goes to a file."""

    def __init__(self, domain: int, daemon: Optional[Any], params: Dict[str, Any], args: List[str]) -> None:
        self.domain = domain
        self.log_file = tempfile.NamedTemporaryFile(prefix="dyfos-ros-node-", suffix=".log", delete=False)
        cmd = [DYFOS_ROS, "--ros-args"]
        if daemon is not None:
            params = {"prefix": daemon.prefix, "domain": daemon.domain, **params}
        for k, v in params.items():
            cmd += ["-p", f"{k}:={ros_value(v)}"]
        cmd += args
        self.process = subprocess.Popen(
            cmd, stdout=self.log_file, stderr=subprocess.STDOUT, env={**os.environ, "ROS_DOMAIN_ID": str(domain)}
        )

    def log(self) -> str:
        return Path(self.log_file.name).read_text(errors="replace")

    def alive(self) -> bool:
        return self.process.poll() is None

    def interrupt(self, timeout: float = PATIENCE) -> int:
        """Ctrl-C; returns the exit code."""
        if self.alive():
            self.process.send_signal(signal.SIGINT)
        return self.process.wait(timeout=timeout)

    def stop(self) -> None:
        try:
            self.interrupt(10.0)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()
            if os.access(FASTDDS, os.X_OK):
                subprocess.run([FASTDDS, "shm", "clean"], capture_output=True, timeout=60, check=False)
        os.unlink(self.log_file.name)


def ros_value(v: Any) -> str:
    """A parameter value as ``-p name:=value`` takes it (YAML)."""
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, float):
        return repr(v)
    if isinstance(v, (list, tuple)):
        return "[" + ",".join(ros_value(x) for x in v) + "]"
    return str(v)


def _ros_on_a_domain_of_its_own() -> Iterator[Ros]:
    domain = DomainId()
    r = Ros(domain.id)
    yield r
    r.close()
    domain.release()


@pytest.fixture
def ros() -> Iterator[Ros]:
    yield from _ros_on_a_domain_of_its_own()


@pytest.fixture
def other_ros() -> Iterator[Ros]:
    """A second domain, for tests of two nodes that must not see each other."""
    yield from _ros_on_a_domain_of_its_own()


@pytest.fixture
def daemon() -> Iterator[Any]:
    d = Daemon("ros")
    yield d
    d.stop()


@pytest.fixture
def start_daemon() -> Iterator[Callable[..., Any]]:
    yield from pyconftest.daemons_started_by(lambda *extra: Daemon("ros", *extra))


@pytest.fixture
def start_node(request: Any) -> Iterator[Callable[..., NodeProcess]]:
    """``start_node(ros, daemon, **params)`` starts ``dyfos-ros`` on ``ros``'s domain."""
    started: List[NodeProcess] = []

    def start(ros: Ros, daemon: Optional[Any], *args: str, **params: Any) -> NodeProcess:
        n = NodeProcess(ros.domain, daemon, params, list(args))
        started.append(n)
        return n

    yield start
    failed = getattr(request.node, "rep_call", None) is not None and request.node.rep_call.failed
    for n in started:
        if failed:
            print(f"--- dyfos-ros log ---\n{n.log()}")
        n.stop()


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item: Any, call: Any) -> Iterator[None]:
    outcome = yield
    rep = outcome.get_result()
    setattr(item, f"rep_{rep.when}", rep)
