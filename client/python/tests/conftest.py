"""Fixtures: a real ``dyfosd`` per test session (own prefix, iceoryx2 domain and state
directory), killed at the end, and the ``dyfos`` command line for reference answers.

``DYFOSD`` and ``DYFOS`` name the binaries (``test.sh`` points them at
``target/debug``); ``DYFOS_TEST_DATA`` the repository's ``tests/data``.
"""

from __future__ import annotations

import contextlib
import itertools
import json
import math
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any, Callable, Dict, Iterator, List, Optional

import pytest

import dyfos

ROOT = Path(__file__).resolve().parents[3]
#: How long any wait in these tests may take before the test fails.
PATIENCE = 30.0

_counter = itertools.count()


def _binary(var: str, name: str) -> str:
    path = os.environ.get(var) or str(ROOT / "target" / "debug" / name)
    if not os.access(path, os.X_OK):
        pytest.exit(f"{path} is missing: run `cargo build --workspace --all-targets` or set {var}", returncode=2)
    return path


DYFOSD = _binary("DYFOSD", "dyfosd")
DYFOS = _binary("DYFOS", "dyfos")
DATA = Path(os.environ.get("DYFOS_TEST_DATA") or ROOT / "tests" / "data")


class Daemon:
    """One ``dyfosd`` with its own prefix, domain and state directory."""

    def __init__(self, name: str, *extra: str) -> None:
        n = next(_counter)
        pid = os.getpid()
        self.prefix = f"py-{name}-{pid}-{n}/"
        self.domain = f"dyp{pid}_{n}_"
        self.state_dir = tempfile.mkdtemp(prefix=f"dyfos-py-{name}-")
        self.log_path = Path(self.state_dir + ".log")
        self._log = open(self.log_path, "wb")
        self.process = subprocess.Popen(
            [DYFOSD, "--prefix", self.prefix, "--domain", self.domain, "--state-dir", self.state_dir, *extra],
            stdout=subprocess.DEVNULL,
            stderr=self._log,
            env={**os.environ, "RUST_LOG": "info"},
        )
        deadline = time.monotonic() + PATIENCE
        while True:
            if self.process.poll() is not None:
                raise RuntimeError(f"dyfosd exited at start:\n{self.log()}")
            try:
                with self.client(connect_timeout=0.05) as c:
                    c.stats()
                break
            except dyfos.DaemonGoneError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.01)

    def client(self, timeout: float = PATIENCE, connect_timeout: Optional[float] = None) -> dyfos.Client:
        return dyfos.Client(
            prefix=self.prefix, domain=self.domain, timeout=timeout, connect_timeout=connect_timeout or timeout
        )

    def flags(self) -> List[str]:
        return ["--prefix", self.prefix, "--domain", self.domain]

    def log(self) -> str:
        return self.log_path.read_text(errors="replace")

    def alive(self) -> bool:
        return self.process.poll() is None

    def kill(self, sig: int = signal.SIGKILL) -> None:
        if self.alive():
            self.process.send_signal(sig)
        self.process.wait(timeout=PATIENCE)

    def stop(self) -> None:
        """SIGTERM (a clean stop), SIGKILL if it does not exit; removes what it left."""
        if self.alive():
            self.process.terminate()
            try:
                self.process.wait(timeout=PATIENCE)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
        self._log.close()
        shutil.rmtree(self.state_dir, ignore_errors=True)
        self.log_path.unlink(missing_ok=True)
        _remove_domain_files(self.domain)


def _remove_domain_files(domain: str) -> None:
    """Shared memory and iceoryx2 state files of a domain that a killed process left."""
    for root in (Path("/dev/shm"), Path("/tmp/iceoryx2")):
        if not root.is_dir():
            continue
        for path in list(root.rglob(f"{domain}*")):
            try:
                if path.is_file() or path.is_symlink() or path.is_socket():
                    path.unlink()
            except OSError:
                pass


@pytest.fixture(scope="session")
def daemon() -> Iterator[Daemon]:
    """The session's daemon; tests that kill or stop a daemon start their own."""
    d = Daemon("session")
    yield d
    d.stop()


def daemons_started_by(make: Callable[..., Any]) -> Iterator[Callable[..., Any]]:
    """The body of a fixture that starts daemons for one test: yields ``start(*flags)``,
    which makes one with ``make(*flags)``, and stops every one it made after the test."""
    started: List[Any] = []

    def start(*extra: str) -> Any:
        d = make(*extra)
        started.append(d)
        return d

    yield start
    for d in started:
        d.stop()


@pytest.fixture
def own_daemon() -> Iterator[Callable[..., Daemon]]:
    """Starts daemons for one test (``own_daemon(*flags)``); stops them after it."""
    yield from daemons_started_by(lambda *extra: Daemon("own", *extra))


@pytest.fixture
def client(daemon: Daemon) -> Iterator[dyfos.Client]:
    with daemon.client() as c:
        yield c


def dyfos_cli(*args: str) -> Dict[str, Any]:
    """Runs the ``dyfos`` command line and returns its JSON output."""
    out = subprocess.run([DYFOS, *args], check=True, capture_output=True, text=True, timeout=300)
    return json.loads(out.stdout)


def slow_scenario() -> Dict[str, Any]:
    """A scenario whose ``brute`` search takes seconds (about 6 s on 2 cores, release
    or debug build): 4096 perimeter points per occlusion test instead of 8, rings of
    boxes 10 cm tall around the rover and a floor of voxels, every other 0.1 m cell
    over 8 x 8 m. Both stand below the marker (20 cm), so no sight line touches them,
    but they surround it in every direction: the daemon's per-query indexes list some
    boxes for every candidate, and the floor's 0.8 m bricks lie in every candidate's
    sight box, so each of its 4097 sight lines is walked through the grid. (Cylinders
    alone, or boxes alone, are settled by their distances without the lines.)"""
    s = json.loads((DATA / "anisotropic-mirror-basin.json").read_text())
    mx, my = s["rover"]["mean"][0], s["rover"]["mean"][1]
    half = 0.2
    for radius, count in ((1.5, 20), (2.5, 32), (3.5, 44)):
        for k in range(count):
            a = 2 * math.pi * k / count
            x, y = mx + radius * math.cos(a), my + radius * math.sin(a)
            box = {"min": [x - half, y - half, 0.0], "max": [x + half, y + half, 0.1]}
            s["obstacles"].append({"id": 100 + len(s["obstacles"]), "box": box})
    cx, cy = math.floor(mx / 0.1), math.floor(my / 0.1)
    floor = [[cx + i, cy + j, 0] for i in range(-40, 41, 2) for j in range(-40, 41, 2)]
    s["voxels"] = {"resolution": 0.1, "origin": [0, 0, 0], "occupied": floor}
    s["params"] = {"perimeter_points": 4096}
    return s


def write_json(tmp_path: Path, name: str, value: Any) -> Path:
    path = tmp_path / name
    path.write_text(json.dumps(value))
    return path


def wait_until(condition: Callable[[], Any], show: Optional[Callable[[], Any]] = None) -> None:
    """Polls ``condition`` until it holds; fails after ``PATIENCE`` s, with ``show()``."""
    deadline = time.monotonic() + PATIENCE
    while not condition():
        assert time.monotonic() < deadline, f"timed out waiting; {show() if show else ''}"
        time.sleep(0.005)


@contextlib.contextmanager
def querying_child(daemon: Daemon, admin: dyfos.Client, code: str, *args: str) -> Iterator["subprocess.Popen[str]"]:
    """A Python child running ``code`` with ``daemon``'s prefix and domain and ``args``
    as its arguments, once it printed ``querying`` and the daemon searches for it
    (``admin``'s stats say so); killed on exit if it still runs."""
    child = subprocess.Popen(
        [sys.executable, "-c", code, daemon.prefix, daemon.domain, *args],
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert child.stdout is not None
        assert child.stdout.readline().strip() == "querying"
        wait_until(lambda: admin.stats()["running"] >= 1)
        yield child
    finally:
        if child.poll() is None:
            child.kill()
            child.wait()
