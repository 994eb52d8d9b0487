"""A client process killed mid-query disturbs no one."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import dyfos
from conftest import DATA, PATIENCE, dyfos_cli, querying_child, slow_scenario, wait_until, write_json

CHILD = """
import json, sys
import dyfos
prefix, domain, path = sys.argv[1:4]
s = dyfos.read_scenario(path)
with dyfos.Client(prefix=prefix, domain=domain, timeout=600) as c:
    map_id = c.upload_scenario(s)
    print("querying", flush=True)
    c.rendezvous(map_id, s["rover"]["mean"], s["rover"]["cov"], algorithm="brute", params=s["params"])
    print("answered", flush=True)
"""


def test_client_killed_mid_query_disturbs_no_one(daemon: Any, tmp_path: Path) -> None:
    s = slow_scenario()
    slow = write_json(tmp_path, "slow.json", s)
    example = DATA / "example.json"
    expected = dyfos_cli("solve", str(example), "--seed", "1")
    del expected["micros"]

    with daemon.client() as other:
        before = other.stats()
        with querying_child(daemon, other, CHILD, str(slow)) as child:
            child.kill()
            child.wait(PATIENCE)

        # Another client's queries are answered, right, while the search is abandoned.
        map_id = other.upload_scenario(example)
        e = dyfos.read_scenario(example)
        for _ in range(3):
            got = other.rendezvous(map_id, e["rover"]["mean"], e["rover"]["cov"], seed=1, params=e["params"]).to_dict()
            del got["micros"]
            assert json.dumps(got) == json.dumps(expected)
        # A long wait of its own: a waiting client also clears dead processes' iceoryx2
        # resources (every 200 ms), so the daemon sees the killed client's request go
        # without waiting for its own 5 s sweep.
        slow_id = other.upload_scenario(s)
        answer = other.rendezvous(slow_id, s["rover"]["mean"], s["rover"]["cov"], algorithm="brute", params=s["params"], deadline=1.0)
        assert answer.stop == "deadline"
        # The daemon notices the dead client, abandons its search and frees the worker
        # (no reply to send). Its counters move one after the other: wait for both.
        def abandoned() -> bool:
            now = other.stats()
            return now["running"] == 0 and now["queries_abandoned"] > before["queries_abandoned"]

        wait_until(abandoned, other.stats)
        after = other.stats()
        assert after["pid"] == before["pid"], "the same daemon, still serving"
        assert daemon.alive()
