"""Seed 004's improved A* on `paper004`: the binary-heap open list against the plain list on
the same seeded queries of every task type (the note's B-HEAP-1), and the turning cost's effect
on empty fetches over an empty floor (B-TURN-1).

Queries: M1 fetch from a floor cell to a slot, M2 delivery from a slot to a station's
entrance, M3 return from a station's exit point to a slot, M4 from a slot to a pile; each
with a random heading. Heap and list run the same query one after the other, so the machine's
noise falls on both; the ratio is of their total planning times.
"""

from __future__ import annotations

import random
import statistics
import time
from collections.abc import Callable

from fleet.planning.astar004 import Costs, Path, plan
from fleet.planning.rules004 import XY, Direction, Kind, Task
from fleet.world.floor004 import Floor004, paper004

Query = tuple[Task, XY, XY, Direction, XY | None]  # task, start, goal, heading, home slot


def free_cells(floor: Floor004) -> list[XY]:
    """The floor cells a query may start from (no piles), in a fixed order."""
    return sorted(c for c, k in floor.kinds.items() if k is Kind.FLOOR and c not in floor.piles)


def queries(floor: Floor004, free: list[XY], n: int, rng: random.Random) -> list[Query]:
    """n queries of each task type."""
    out: list[Query] = []
    for _ in range(n):
        slot = rng.choice(floor.slots).xy
        station = rng.choice(floor.stations)
        out += [(Task.FETCH, rng.choice(free), slot, rng.choice(list(Direction)), None),
                (Task.DELIVER, slot, station.entrance, rng.choice(list(Direction)), slot),
                (Task.RETURN, station.exit_point, slot, rng.choice(list(Direction)), slot),
                (Task.CHARGE, slot, rng.choice(floor.piles), rng.choice(list(Direction)), None)]
    return out


def _timed(floor: Floor004, q: Query, heap: bool) -> tuple[Path | None, float]:
    task, start, goal, heading, home = q
    t0 = time.perf_counter()
    path = plan(floor.grid, task, start, goal, heading, heap=heap, home=home)
    return path, time.perf_counter() - t0


def run(n: int, seed: int, progress: Callable[[int, int], None] | None = None) -> dict:
    floor = paper004()
    rng = random.Random(seed)
    free = free_cells(floor)
    asked = queries(floor, free, n, rng)
    times: dict[str, list[float]] = {"heap": [], "list": []}
    same, found = 0, 0
    for k, q in enumerate(asked, 1):
        by_heap, t_heap = _timed(floor, q, heap=True)
        by_list, t_list = _timed(floor, q, heap=False)
        times["heap"].append(t_heap)
        times["list"].append(t_list)
        same += by_heap == by_list
        found += by_heap is not None
        if progress is not None:
            progress(k, len(asked) + n)
    turns = {"off": [0, 0], "on": [0, 0]}  # [length, turns] in all
    lengthened = 0
    for k in range(n):
        a, b = rng.choice(free), rng.choice(floor.slots).xy
        off = plan(floor.grid, Task.FETCH, a, b, costs=Costs(turn=0.0))
        on = plan(floor.grid, Task.FETCH, a, b, costs=Costs(turn=1.0))
        assert off is not None and on is not None  # the empty rule graph is connected
        for key, path in (("off", off), ("on", on)):
            turns[key][0] += path.length
            turns[key][1] += path.turns()
        lengthened += on.length > off.length
        if progress is not None:
            progress(len(asked) + k + 1, len(asked) + n)
    heap_s, list_s = sum(times["heap"]), sum(times["list"])
    return {
        "layout": floor.name, "seed": seed, "queries": len(asked), "found": found,
        "same_paths": same,
        "heap_total_s": round(heap_s, 3), "list_total_s": round(list_s, 3),
        "heap_p50_ms": round(1000 * statistics.median(times["heap"]), 3),
        "list_p50_ms": round(1000 * statistics.median(times["list"]), 3),
        "heap_speedup": round(list_s / heap_s, 2) if heap_s > 0 else None,
        "turn_queries": n,
        "turns_off": turns["off"][1], "turns_on": turns["on"][1],
        "length_off": turns["off"][0], "length_on": turns["on"][0],
        "turns_cut": round(1 - turns["on"][1] / turns["off"][1], 3) if turns["off"][1] else 0.0,
        "lengthened": lengthened,
    }
