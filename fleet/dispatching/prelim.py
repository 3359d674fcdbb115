"""Time-expanded preliminary A* of the dispatcher (seed 000, Section 3.2, Figure 4).

A virtual vehicle is one point on the coarse node grid (one node per cell; the heading is not a
dimension). Five expansion patterns: one node east, north, west or south, and waiting in place
(pattern 5, time only). Walls and filled stacks are static obstacles; other vehicles are the
reservation table's cells over time. The search answers how long the virtual vehicle needs to
reach the nearest of a set of target nodes, within iter_pre expansions.

Timing (our choice, the seed does not give it): one node step takes T3 (straight at v_mid, the
cruise level a loaded forklift keeps between turns) and a wait takes T12, so the preliminary time
is on the same scale as the kinodynamic one without its turns and speed changes.
"""

from __future__ import annotations

import heapq
from collections.abc import Iterable
from dataclasses import dataclass

from fleet.planning.geometry import Cell
from fleet.planning.gridmap import GridMap
from fleet.planning.reservations import ReservationView

NEIGHBOURS = ((1, 0), (0, 1), (-1, 0), (0, -1), (0, 0))  # the five patterns of Figure 4
STEP_TIME = 1.25  # one node step (T3)
WAIT_TIME = 1.0  # one wait (T12)


@dataclass(frozen=True)
class PrelimResult:
    found: bool
    t_find: float  # arrival instant at the target (t_i when not found)
    target: Cell | None
    expansions: int


def preliminary_astar(grid: GridMap, store: ReservationView, vehicle: int, start: Cell,
                      t_i: float, targets: Iterable[Cell], iter_pre: int = 500,
                      step_time: float = STEP_TIME, wait_time: float = WAIT_TIME
                      ) -> PrelimResult:
    """Earliest arrival at any target node, avoiding other vehicles' reserved cells."""
    goal = set(targets)
    if not goal or (start not in goal and all(
            store.parked_from(vehicle, g) < t_i + travel_floor(start, (g,), step_time)
            for g in goal)):
        # Every target is taken for good before the virtual vehicle could reach it: the
        # search could only fail, after iter_pre expansions.
        return PrelimResult(False, t_i, None, 0)

    def h(cell: Cell) -> float:  # travel_floor, inline: the search's hottest line
        return step_time * min(abs(cell[0] - g[0]) + abs(cell[1] - g[1]) for g in goal)

    open_heap: list[tuple[float, int, Cell, float]] = [(h(start), 0, start, t_i)]
    seen: set[tuple[Cell, float]] = {(start, t_i)}
    counter = 1
    expansions = 0
    while open_heap and expansions < iter_pre:
        _, _, cell, t = heapq.heappop(open_heap)
        expansions += 1
        if cell in goal:
            return PrelimResult(True, t, cell, expansions)
        for dx, dy in NEIGHBOURS:
            nxt = (cell[0] + dx, cell[1] + dy)
            dt = wait_time if (dx, dy) == (0, 0) else step_time
            tn = t + dt
            if (nxt, tn) in seen or not (grid.free(nxt) or nxt in goal):
                continue
            if store.conflict(vehicle, nxt, t, tn) is not None:
                continue
            seen.add((nxt, tn))
            heapq.heappush(open_heap, (tn - t_i + h(nxt), counter, nxt, tn))
            counter += 1
    return PrelimResult(False, t_i, None, expansions)


def travel_floor(start: Cell, targets: Iterable[Cell], step_time: float = STEP_TIME) -> float:
    """No preliminary trajectory reaches a target sooner: a step per cell of the Manhattan
    distance to the nearest (the search's heuristic, and a bound on any score it gives)."""
    return step_time * min(abs(start[0] - g[0]) + abs(start[1] - g[1]) for g in targets)


def cover_time(store: ReservationView, vehicle: int, cells: Iterable[Cell], t0: float,
               window: float, step: float = 0.25) -> float:
    """Delta t_cover: how long, within [t0, t0 + window), other vehicles hold any of the
    entrance cells (sampled on the 0.25 s lattice all maneuver times live on)."""
    cells = tuple(cells)
    covered = 0.0
    n = int(window / step)
    for k in range(n):
        t = t0 + k * step
        if any(store.conflict(vehicle, c, t, t + step) is not None for c in cells):
            covered += step
    return covered
