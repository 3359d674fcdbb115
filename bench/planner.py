"""Planner benchmark: seeded station <-> stack queries on a layout with three other forklifts'
trajectories committed in the reservation table.

Each query draws a fill state (the first k stacks of every cluster filled), gives the four
forklifts distinct stations and distinct clusters, and a task each: deliver (station dock to
the next stack of its cluster) or return (from that stack's unload pose to its station). The
first three are planned and committed in turn; the fourth is the timed query. Only `plan()`
is timed; building the planner for a fill state (static cache, pose-graph components) is
reported separately as setup time, since a vehicle does it once per fill state, not per query.
"""

from __future__ import annotations

import random
import statistics
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass

from bench.stats import percentile
from fleet.errors import UserError
from fleet.planning.reservations import ReservationTable
from fleet.planning.trajectory import Pose, Trajectory
from fleet.world.layout import Layout
from fleet.world.layout_file import load_layout


@dataclass(frozen=True)
class Task:
    vehicle: int
    start: Pose
    goals: tuple[Pose, ...]
    t_start: float


FORKLIFTS = 4  # per query: each at its own station, serving its own cluster
MAX_UNUSABLE_DRAWS = 1000  # in a row: the layout gives no usable query (never, in the shipped)


def check_layout(layout: Layout) -> None:
    """A layout the benchmark can draw queries on: enough stations and clusters."""
    stations, clusters = len(layout.stations), len(layout.clusters)
    if stations < FORKLIFTS or clusters < FORKLIFTS:
        raise UserError(f"layout {layout.name} has {stations} stations and {clusters} "
                        f"clusters; the planner benchmark needs at least {FORKLIFTS} of each "
                        f"(its {FORKLIFTS} forklifts each start at their own station and "
                        f"serve their own cluster)")


def draw_scene(layout: Layout, rng: random.Random) -> tuple[set, list[Task]] | None:
    """A fill state and four tasks, or None when the draw is unusable (overlapping starts)."""
    clusters = [c.name for c in layout.clusters]
    fill = {}
    for name in clusters:
        n = len([s for s in layout.stacks if s.cluster == name])
        fill[name] = rng.randrange(n)  # at least one stack of each cluster still empty
    filled = {s.cell for s in layout.stacks if s.index <= fill[s.cluster]}
    stations = rng.sample(layout.stations, 4)
    chosen = rng.sample(clusters, 4)
    tasks, taken = [], set()
    for v, (station, cluster) in enumerate(zip(stations, chosen, strict=True), start=1):
        target = next(s for s in layout.stacks
                      if s.cluster == cluster and s.index == fill[cluster] + 1)
        unload = layout.unload_poses(target.cell, filled)
        if not unload:
            return None
        if rng.random() < 0.5:
            start, goals = station.dock, tuple(unload)
        else:
            start, goals = unload[0], (station.dock,)
        cells = set(layout.vehicle_kind.body_cells_at_rest(start))
        if cells & taken:
            return None
        taken |= cells
        tasks.append(Task(v, start, goals, rng.choice([0.0, 2.5, 5.0, 10.0, 15.0])))
    return filled, tasks


def run(layout_name: str = "paper", queries: int = 240, seed: int = 2026,
        progress: Callable[[int, int], None] | None = None) -> dict:
    layout = load_layout(layout_name)
    check_layout(layout)
    rng = random.Random(seed)
    times_ms, setup_ms, expansions, found_ms = [], [], [], []
    outcomes: Counter[str] = Counter()
    done = unusable = 0
    while done < queries:
        scene = draw_scene(layout, rng)
        if scene is None:
            unusable += 1
            if unusable == MAX_UNUSABLE_DRAWS:
                raise UserError(f"layout {layout.name}: no usable planner query in "
                                f"{MAX_UNUSABLE_DRAWS} draws (the forklifts' starts overlap, "
                                f"or no pose points at the next stack)")
            continue
        unusable = 0
        filled, tasks = scene
        t0 = time.perf_counter()
        planner = layout.vehicle_kind.planner(layout.grid_map(filled))
        planner.component(tasks[0].start)
        setup_ms.append((time.perf_counter() - t0) * 1000)
        table = ReservationTable()
        for task in tasks:
            table.park(task.vehicle, layout.vehicle_kind.body_cells_at_rest(task.start), 0)
        for task in tasks[:3]:
            other = planner.plan(task.vehicle, task.start, task.t_start, task.goals, table)
            if isinstance(other, Trajectory):
                table.commit(task.vehicle, other.intervals, release_from=other.t_start)
        query = tasks[3]
        t0 = time.perf_counter()
        result = planner.plan(query.vehicle, query.start, query.t_start, query.goals, table)
        times_ms.append((time.perf_counter() - t0) * 1000)
        expansions.append(result.expansions)
        outcomes["found" if isinstance(result, Trajectory) else result.reason.value] += 1
        if isinstance(result, Trajectory):
            found_ms.append(times_ms[-1])
        done += 1
        if progress:
            progress(done, queries)
    return {
        "layout": layout_name,
        "queries": queries,
        "seed": seed,
        "p50_ms": round(statistics.median(times_ms), 3),
        "p95_ms": round(percentile(times_ms, 0.95), 3),
        "max_ms": round(max(times_ms), 3),
        "mean_ms": round(statistics.fmean(times_ms), 3),
        "success_rate": round(outcomes["found"] / queries, 4),
        "found_p50_ms": round(statistics.median(found_ms), 3) if found_ms else None,
        "found_p95_ms": round(percentile(found_ms, 0.95), 3) if found_ms else None,
        "over_100ms": sum(t > 100 for t in times_ms),
        "outcomes": dict(sorted(outcomes.items())),
        "expansions_p50": statistics.median(expansions),
        "expansions_p95": percentile(expansions, 0.95),
        "expansions_max": max(expansions),
        "setup_p50_ms": round(statistics.median(setup_ms), 3),
    }

