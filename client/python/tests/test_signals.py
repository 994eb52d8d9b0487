"""Signals while a query waits: Ctrl-C ends the call with ``KeyboardInterrupt``
(the client runs Python's signal handlers while it waits, PEP 475); Ctrl-Z and
``fg`` (SIGSTOP, SIGCONT) leave it waiting, and it gets its answer."""

from __future__ import annotations

import signal
import subprocess
from pathlib import Path
from typing import Any, Dict, Tuple

from conftest import PATIENCE, querying_child, slow_scenario, wait_until, write_json

CHILD = """
import signal, sys
import dyfos
# Ctrl-C raises KeyboardInterrupt even if this process was started with SIGINT ignored.
signal.signal(signal.SIGINT, signal.default_int_handler)
prefix, domain, path, deadline = sys.argv[1:5]
s = dyfos.read_scenario(path)
with dyfos.Client(prefix=prefix, domain=domain, timeout=600) as c:
    map_id = c.upload_scenario(s)
    print("querying", flush=True)
    try:
        a = c.rendezvous(map_id, s["rover"]["mean"], s["rover"]["cov"], algorithm="brute",
                         params=s["params"], deadline=float(deadline))
        print("answered", a.stop, flush=True)
    except KeyboardInterrupt:
        print("interrupted", flush=True)
"""


def query_in_child(daemon: Any, tmp_path: Path, deadline: float, signals: Any) -> Tuple[str, Dict[str, Any]]:
    """Runs a slow ``brute`` query (ending at ``deadline`` s) in a child process of
    its own daemon (the counters below are this test's),
    calls ``signals(child)`` once the daemon searches for it; returns what the
    child printed after its query, and the daemon's stats once no search runs."""
    slow = write_json(tmp_path, "slow.json", slow_scenario())
    with daemon.client() as admin:
        with querying_child(daemon, admin, CHILD, str(slow), str(deadline)) as child:
            signals(child)
            out, _ = child.communicate(timeout=PATIENCE)
        # The daemon's worker is free again: an interrupted query is abandoned.
        wait_until(lambda: admin.stats()["running"] == 0)
        return out.strip(), admin.stats()


def test_ctrl_c_ends_a_waiting_query_with_keyboard_interrupt(own_daemon: Any, tmp_path: Path) -> None:
    out, stats = query_in_child(own_daemon(), tmp_path, 600.0, lambda child: child.send_signal(signal.SIGINT))
    assert out == "interrupted"
    # The call ended before the search did: the daemon abandoned it. (A Ctrl-C seen
    # only once the answer came would also print "interrupted", but be served.)
    assert (stats["queries_abandoned"], stats["queries_served"]) == (1, 0), stats


def test_a_query_stopped_and_continued_gets_its_answer(own_daemon: Any, tmp_path: Path) -> None:
    def stop_and_continue(child: subprocess.Popen[str]) -> None:
        child.send_signal(signal.SIGSTOP)
        wait_until(lambda: Path(f"/proc/{child.pid}/stat").read_text().split(") ")[1][0] == "T")
        child.send_signal(signal.SIGCONT)

    out, stats = query_in_child(own_daemon(), tmp_path, 1.5, stop_and_continue)
    assert out == "answered deadline"
    assert (stats["queries_abandoned"], stats["queries_served"]) == (0, 1), stats
