"""Runtime benchmark: the reservation service's commit round trip over real zenoh on loopback.

A service process is started on a free loopback port; one client session sends seeded
commits (four vehicles taking turns, each replacing its reservation from the commit's start
time on, as agents do when they replan) and times each request until its reply arrives.
"""

from __future__ import annotations

import os
import random
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

from bench.stats import percentile
from fleet.runtime.bus import BusConfig, Requester, free_port, open_session, wait_alive
from fleet.wire.protocol import CommitRequest
from fleet.wire.topics import Keys

ROOT = Path(__file__).resolve().parent.parent



def _trajectory(rng: random.Random, vehicle: int, t0: float) -> list:
    """A plausible trajectory: 20 cells in the vehicle's own quarter of an 18 x 12 map,
    2 s each, parked at the last for good."""
    col0 = (vehicle - 1) * 4
    cells = [(col0 + rng.randrange(4), rng.randrange(12)) for _ in range(20)]
    out = [(c, r, t0 + 2 * k, t0 + 2 * k + 2) for k, (c, r) in enumerate(cells[:-1])]
    c, r = cells[-1]
    return [*out, (c, r, t0 + 38, float("inf"))]


def run(commits: int = 2000, seed: int = 2026,
        progress: Callable[[int, int], None] | None = None) -> dict:
    rng = random.Random(seed)
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    keys = Keys(f"bench{os.getpid()}")
    with tempfile.TemporaryDirectory() as tmp:
        service = subprocess.Popen(
            [sys.executable, "-m", "reservation", "--run", keys.run, "--mode", "peer",
             "--listen", endpoint, "--journal", str(Path(tmp) / "journal")],
            cwd=ROOT, stderr=subprocess.DEVNULL, env={**os.environ, "PYTHONPATH": str(ROOT)})
        session = open_session(BusConfig("peer", (endpoint,), ()))
        try:
            if not wait_alive(session, keys.reservation_alive, 60):
                raise RuntimeError("the reservation service did not come up within 60 s")
            requester = Requester(session, "bench")
            times_ms, refused = [], 0
            for k in range(commits):
                vehicle = k % 4 + 1
                t0 = float(k)
                msg = CommitRequest(requester.next_id(), vehicle,
                                    _trajectory(rng, vehicle, t0), t0)
                start = time.perf_counter()
                reply = requester.request(keys.reservation_request(requester.sender), msg).message
                times_ms.append((time.perf_counter() - start) * 1000)
                refused += not reply.ok
                if progress:
                    progress(k + 1, commits)
        finally:
            session.close()
            service.terminate()
            service.wait(timeout=30)
    return {
        "commits": commits,
        "seed": seed,
        "commit_p50_ms": round(statistics.median(times_ms), 3),
        "commit_p99_ms": round(percentile(times_ms, 0.99), 3),
        "commit_max_ms": round(max(times_ms), 3),
        "refused": refused,
    }
