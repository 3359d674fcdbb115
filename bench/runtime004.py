"""Seed 004 as processes: what one agent process per lifting AGV costs against the in-process
run, side by side (the same `fleet run` command line with and without --inprocess,
alternated, each a fresh process, records compared by digest), and whether a large fleet
keeps real time at speed 1 (fleet bench runtime's measure: the p99 of how late the
tracker's instants were handled within 0.1 s; instants more than 0.3 s late are counted
too), with the memory each agent process holds.
"""

from __future__ import annotations

import json
import statistics
import tempfile
import threading
import time
from collections.abc import Callable
from pathlib import Path

from bench.fleet_scale import MAX_P99_LATE_S, _rss_mb
from bench.multiprocess import timed_run
from fleet.dispatching.decision import Strategy
from fleet.mission.spec import ClockMode, Mission, MissionKind
from fleet.runtime.local_run import RunSpec, run_processes

RSS_PERIOD_S = 2.0  # how often the agents' memory is sampled during the real-time run


def _timed(args: list[str]) -> tuple[float, dict]:
    wall, out = timed_run([*args, "--json"])
    return wall, json.loads(out)


def side_by_side(orders: int, vehicles: int, repeats: int,
                 progress: Callable[[str], None] | None = None) -> dict:
    base = ["--layout", "paper004", "--orders", str(orders), "--vehicles", str(vehicles)]
    walls: dict[str, list[float]] = {"inprocess": [], "processes": []}
    digests, summary = set(), {}
    for k in range(repeats):
        for name, extra in (("inprocess", ["--inprocess"]), ("processes", [])):
            wall, summary = _timed(base + extra)
            walls[name].append(wall)
            digests.add(summary["digest"])
            if progress:
                progress(f"run {k + 1}/{repeats} {name}: {wall:.1f} s")
    inproc, procs = statistics.median(walls["inprocess"]), statistics.median(walls["processes"])
    cells = summary["counts"]["cells"]
    return {"orders": orders, "vehicles": vehicles, "repeats": repeats,
            "inprocess_wall_s": round(inproc, 2), "processes_wall_s": round(procs, 2),
            "ratio": round(procs / inproc, 2), "cells_driven": cells,
            # each cell is a take and a release, each a round trip through the AGV's agent
            "processes_ms_per_cell": round(1000 * procs / cells, 2),
            "same_record": len(digests) == 1,
            "passed": summary["verdicts"]["passed"]}


def real_time(vehicles: int, orders: int, speed: float = 1.0,
              progress: Callable[[str], None] | None = None) -> dict:
    """The whole mission on the real-time clock, as processes; every agent's resident
    memory sampled while it runs (the largest kept)."""
    mission = Mission("paper004", MissionKind.ORDERS, Strategy.NEAREST, vehicles, orders=orders)
    rss: dict[str, float] = {}
    done = threading.Event()

    def sample(session, keys, launcher) -> None:
        def loop() -> None:
            while not done.wait(RSS_PERIOD_S):  # the period paces the sampling
                for child in launcher.children:
                    if child.name.startswith("agent") and child.proc.poll() is None:
                        rss[child.name] = max(rss.get(child.name, 0.0), _rss_mb(child.proc.pid))
        threading.Thread(target=loop, daemon=True).start()

    with tempfile.TemporaryDirectory(prefix="fleet-bench-004-rt-") as tmp:
        start = time.perf_counter()
        try:
            outcome = run_processes(RunSpec(mission, vehicles, Path(tmp) / "run",
                                            ClockMode.REALTIME, speed),
                                    on_ready=sample)
        finally:
            done.set()
        wall = time.perf_counter() - start
    if outcome.done is None or not outcome.done.ok:
        why = outcome.error or (outcome.done.error if outcome.done else "no result")
        raise RuntimeError(f"the {vehicles}-AGV real-time run failed: {why}")
    timing = outcome.done.timing
    row = {"vehicles": vehicles, "orders": orders, "speed": speed,
           "end_time_s": outcome.done.record["end_time_s"], "wall_s": round(wall, 1),
           "instants": timing["instants"], "late_instants": timing["late"],
           "worst_late_s": round(timing["worst_late_s"], 3),
           "worst_late_at_s": timing["worst_late_at_s"],
           "lateness_p50_s": timing["lateness_p50_s"],
           "lateness_p99_s": timing["lateness_p99_s"],
           "rss_per_agent_mb": round(statistics.mean(rss.values()), 1) if rss else None,
           "rss_max_agent_mb": round(max(rss.values()), 1) if rss else None,
           # fleet bench runtime's measure: the p99 lateness within 0.1 s
           "keeps_real_time": timing["lateness_p99_s"] <= MAX_P99_LATE_S}
    if progress:
        progress(f"{vehicles} AGVs at speed {speed:g}: {row}")
    return row
