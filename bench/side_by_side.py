"""Two checkouts' speed side by side, alternated: `fleet bench planner` (p50, p95) and the
wall time of an in-process ANN fill of paper, with medians and ratios (docs/benchmarks.md).

    python bench/side_by_side.py BEFORE_DIR AFTER_DIR [ROUNDS] [QUERIES]
"""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import tempfile
import time


def measure(tree: str, queries: str) -> tuple[float, float, float, str]:
    env = {**os.environ, "PYTHONPATH": tree}
    fleet = [sys.executable, "-m", "fleet"]
    bench = json.loads(subprocess.run([*fleet, "bench", "planner", "--json", "--queries", queries],
                                      cwd=tree, env=env, capture_output=True, text=True,
                                      check=True).stdout)
    out = tempfile.mkdtemp()
    started = time.perf_counter()
    run = subprocess.run([*fleet, "run", "--inprocess", "--json", "--out", f"{out}/run"],
                         cwd=tree, env=env, capture_output=True, text=True, check=True)
    wall = time.perf_counter() - started
    return bench["p50_ms"], bench["p95_ms"], wall, json.loads(run.stdout)["digest"]


def main(argv: list[str]) -> int:
    before, after = argv[0], argv[1]
    rounds = int(argv[2]) if len(argv) > 2 else 3
    queries = argv[3] if len(argv) > 3 else "240"
    results: dict[str, list[tuple[float, float, float]]] = {before: [], after: []}
    for r in range(rounds):
        for tree in (before, after) if r % 2 == 0 else (after, before):
            p50, p95, wall, digest = measure(tree, queries)
            results[tree].append((p50, p95, wall))
            print(f"round {r} {tree}: p50 {p50:.2f} ms, p95 {p95:.1f} ms, fill {wall:.2f} s, "
                  f"digest {digest[:16]}", flush=True)
    for i, name in enumerate(("planner p50 ms", "planner p95 ms", "fill wall s")):
        b = statistics.median(x[i] for x in results[before])
        a = statistics.median(x[i] for x in results[after])
        print(f"{name}: before {b:.3f}, after {a:.3f}, after/before {a / b:.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
