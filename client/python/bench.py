"""What Python adds to a query: the same requests through ``dyfos`` and through the
Rust client alone, against one ``dyfosd``, in one run.

    python client/python/bench.py [--dyfosd target/release/dyfosd] [--rounds 10]

Starts its own ``dyfosd`` (own prefix, iceoryx2 domain and state directory), uploads
``tests/data/example.json`` and sends, in alternating blocks so that drifting machine
load hits both sides alike:

- *check mode* (validated by the daemon, not searched: the round-trip floor), and
- ``dyfos`` queries (seed 0, SPEC parameters),

once from Python (``client.check(...)`` / ``client.rendezvous(...)``, each call timed
with ``time.perf_counter_ns`` around it, so conversions, the answer object and the GIL
hand-over are all counted) and once from Rust with no Python in the loop (the
extension's ``_rust_round_trips``: ``dyfos_client::Client::check`` / ``rendezvous`` on
the same request, timed with ``Instant``). Prints a markdown table of p50/p99 and the
differences; ``--json FILE`` also writes the samples' summary.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any, Dict, List

import dyfos

ROOT = Path(__file__).resolve().parents[2]


def percentile(samples: List[float], q: float) -> float:
    s = sorted(samples)
    return s[min(len(s) - 1, int(q * len(s)))]


def summary(samples_s: List[float]) -> Dict[str, float]:
    us = [x * 1e6 for x in samples_s]
    return {
        "n": len(us),
        "p50_us": percentile(us, 0.5),
        "p90_us": percentile(us, 0.9),
        "p99_us": percentile(us, 0.99),
        "mean_us": statistics.fmean(us),
    }


def start_daemon(dyfosd: str) -> Any:
    pid = os.getpid()
    prefix, domain = f"pybench-{pid}/", f"dypb{pid}_"
    state = tempfile.mkdtemp(prefix="dyfos-pybench-")
    proc = subprocess.Popen(
        [dyfosd, "--prefix", prefix, "--domain", domain, "--state-dir", state],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    deadline = time.monotonic() + 30
    while True:
        try:
            client = dyfos.Client(prefix=prefix, domain=domain, timeout=10.0, connect_timeout=0.05)
            client.stats()
            return proc, client, state
        except dyfos.DaemonGoneError:
            if time.monotonic() > deadline or proc.poll() is not None:
                proc.kill()
                raise
            time.sleep(0.01)


def python_block(call: Any, count: int) -> List[float]:
    out = []
    clock = time.perf_counter_ns
    for _ in range(count):
        t0 = clock()
        call()
        out.append((clock() - t0) * 1e-9)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--dyfosd", default=str(ROOT / "target" / "release" / "dyfosd"))
    ap.add_argument("--scenario", default=str(ROOT / "tests" / "data" / "example.json"))
    ap.add_argument("--rounds", type=int, default=10, help="alternating Python/Rust blocks per workload")
    ap.add_argument("--check-count", type=int, default=2000, help="check-mode requests per block")
    ap.add_argument("--query-count", type=int, default=200, help="`dyfos` queries per block")
    ap.add_argument("--json", help="write the summaries here")
    args = ap.parse_args()

    proc, client, state = start_daemon(args.dyfosd)
    try:
        s = dyfos.read_scenario(args.scenario)
        map_id = client.upload_scenario(s)
        mean, cov = s["rover"]["mean"], s["rover"]["cov"]
        raw = client._raw
        # The two sides send the same request: the answer must be the same.
        a = client.rendezvous(map_id, mean, cov).to_dict()
        b = client.rendezvous(map_id, mean, cov).to_dict()
        del a["micros"], b["micros"]
        assert a == b
        workloads = {
            "check": (lambda: client.check(map_id, mean, cov), True, args.check_count),
            "dyfos": (lambda: client.rendezvous(map_id, mean, cov), False, args.query_count),
        }
        results: Dict[str, Dict[str, List[float]]] = {}
        # Per round (adjacent blocks, alike in load): Python p50 − Rust p50, and the ratio.
        per_round: Dict[str, List[Any]] = {"check": [], "dyfos": []}
        for name, (call, check, count) in workloads.items():
            # Warm up both paths (connections, caches, the daemon's spin).
            python_block(call, count // 4)
            raw._rust_round_trips(map_id, mean, cov, check, count // 4)
            py: List[float] = []
            rs: List[float] = []
            for _ in range(args.rounds):
                p = python_block(call, count)
                r = raw._rust_round_trips(map_id, mean, cov, check, count)
                py += p
                rs += r
                per_round[name].append((percentile(p, 0.5) - percentile(r, 0.5), percentile(p, 0.5) / percentile(r, 0.5)))
            results[name] = {"python": py, "rust": rs}
        stats = client.stats()
    finally:
        client.close()
        proc.terminate()
        proc.wait(30)
        shutil.rmtree(state, ignore_errors=True)

    table = {name: {side: summary(v) for side, v in r.items()} for name, r in results.items()}
    print("| workload | path | requests | p50 µs | p90 µs | p99 µs | mean µs |")
    print("|---|---|---:|---:|---:|---:|---:|")
    for name, sides in table.items():
        label = "check mode (round-trip floor)" if name == "check" else "`dyfos` query"
        for side in ("rust", "python"):
            t = sides[side]
            who = "Rust client (`dyfos_client::Client`)" if side == "rust" else "Python (`dyfos.Client`)"
            print(
                f"| {label} | {who} | {t['n']} | {t['p50_us']:.1f} | {t['p90_us']:.1f} | {t['p99_us']:.1f} | {t['mean_us']:.1f} |"
            )
    c, q = table["check"], table["dyfos"]
    added = c["python"]["p50_us"] - c["rust"]["p50_us"]
    ratio = q["python"]["p50_us"] / q["rust"]["p50_us"]
    print()
    round_added = statistics.median(d for d, _ in per_round["check"]) * 1e6
    round_ratio = statistics.median(q for _, q in per_round["dyfos"])
    print(f"check mode: Python adds {added:+.1f} µs to the Rust client's p50 (target ≤ 20 µs);"
          f" median over {args.rounds} rounds of the per-round difference {round_added:+.1f} µs")
    print(f"`dyfos` query: Python p50 / Rust p50 = {ratio:.3f} ({(ratio - 1) * 100:+.1f} %, target within 5 %);"
          f" median over {args.rounds} rounds of the per-round ratio {round_ratio:.3f}")
    print(f"daemon: {stats['queries_served']} queries served, {stats['requests_failed']} failed")
    if args.json:
        out = {"summary": table, "check_added_us": added, "dyfos_ratio": ratio, "per_round": per_round}
        Path(args.json).write_text(json.dumps(out, indent=2))
    sys.exit(0)


if __name__ == "__main__":
    main()
