"""Seed 004's improved A* (Section 1.3, Equations (1)-(4); seed pack note B.4.2, B.4.4,
B.4.5, B.4.7): a global path on the multi-valued grid that ignores the other AGVs' positions
(they are met while tracking), with the expansion filters and the traffic rules of its task,
a turning cost and a heat cost in G, and the open list as a plain list or a binary heap.

Nodes are cells, as in the seed: the turning cost then depends on the parent a cell was
reached from, so the search is not exact (the note's CHOICE; `heading_states` would be).
The search stops as soon as the goal enters the open list (step 5, GIVEN). Start and goal
are exempt from the value filter (CHOICE: an M3 goal and an M2 start are slots).

Both open lists order nodes by (F, the order they were first opened in), so they return the
same path; the heap only finds the minimum faster. It is Python's binary heap (heapq) with
stale entries skipped when popped, the usual stand-in for the decrease-key the seed's sift-up
describes.
"""

from __future__ import annotations

import heapq
import itertools
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

from fleet.planning.rules004 import (
    ALL,
    STEP,
    XY,
    Direction,
    Grid004,
    Task,
    at_home,
    direction_code,
    perpendicular,
    planning_filter,
    rules_for,
    value,
)

Values = Callable[[XY], int]  # a cell's grid value now (the static kind when nothing moves)


@dataclass(frozen=True)
class Costs:
    """G's terms beyond one per cell (note B.4.2: G_N = G_C + 1 + w_turn [turn] +
    w_heat T_value(N)); 0 switches a term off."""

    turn: float = 1.0  # t_turn / t_cell
    heat: float = 0.0  # w_heat: 2 in the seed's runs with heat, 0 without
    t_value: Mapping[XY, float] = field(default_factory=dict)  # heat in 0..1 per cell


@dataclass(frozen=True)
class Path:
    cells: tuple[XY, ...]  # start first
    expansions: int  # nodes taken from the open list

    @property
    def length(self) -> int:
        return len(self.cells) - 1

    def turns(self, heading: Direction | None = None) -> int:
        """Quarter turns along the path (a reversal counts as none: the AGV drives back)."""
        return count_turns(self.cells, heading)


def heading_of(a: XY, b: XY) -> Direction:
    """The direction of the step from a to b, by the seed's code (Equation (3))."""
    dx, dy = b[0] - a[0], b[1] - a[1]
    if abs(dx) + abs(dy) != 1:
        raise ValueError(f"{a} -> {b} is not one step")
    return Direction(direction_code(dx, dy))


def count_turns(cells: tuple[XY, ...], heading: Direction | None = None) -> int:
    turns = 0
    for a, b in itertools.pairwise(cells):
        d = heading_of(a, b)
        if heading is not None and perpendicular(heading, d):
            turns += 1
        heading = d
    return turns


class _ListOpen:
    """The baseline: an unordered list scanned for the smallest (F, order)."""

    def __init__(self) -> None:
        self.items: dict[XY, tuple[float, int]] = {}

    def push(self, cell: XY, key: tuple[float, int]) -> None:
        self.items[cell] = key

    def pop(self) -> XY | None:
        if not self.items:
            return None
        cell = min(self.items, key=self.items.__getitem__)
        del self.items[cell]
        return cell


class _HeapOpen:
    """A binary heap of (F, order, cell); an entry whose key has since fallen is stale."""

    def __init__(self) -> None:
        self.heap: list[tuple[float, int, XY]] = []
        self.keys: dict[XY, tuple[float, int]] = {}

    def push(self, cell: XY, key: tuple[float, int]) -> None:
        self.keys[cell] = key
        heapq.heappush(self.heap, (*key, cell))

    def pop(self) -> XY | None:
        while self.heap:
            f, order, cell = heapq.heappop(self.heap)
            if self.keys.get(cell) == (f, order):
                del self.keys[cell]
                return cell
        return None


def plan(grid: Grid004, task: Task, start: XY, goal: XY, heading: Direction | None = None,
         costs: Costs = Costs(), values: Values | None = None, heap: bool = True,
         relaxed: bool = False, home: XY | None = None) -> Path | None:
    """The improved A* from start to goal for an AGV on `task` (None: no path under the
    filters and rules). `values`: the grid now (default: every cell free); `relaxed`: the
    traffic rules lifted (an empty AGV after repeated failures, B.4.1); `home`: a loaded
    AGV's own slot."""
    if start == goal:
        return Path((start,), 0)
    if values is None:
        def values(xy: XY) -> int:
            return value(grid.kind(xy))
    open_list = _HeapOpen() if heap else _ListOpen()
    order = itertools.count()
    g: dict[XY, float] = {start: 0.0}
    parent: dict[XY, XY] = {}
    # whether each node was entered driving vertically (None: the start, heading unknown):
    # a step is a quarter turn when it changes that (a reversal is none, `perpendicular`)
    vertical: dict[XY, bool | None] = {
        start: None if heading is None else heading in _VERTICAL}
    opened: dict[XY, int] = {start: next(order)}
    closed: set[XY] = set()
    enterable: dict[XY, bool] = {goal: True}  # a cell's filter, read once a plan: values
    # stand still while one plan is made
    heat, turn = costs.heat, costs.turn
    passable = planning_filter(task)
    rules_at = None if relaxed and not task.loaded else rules_for(grid, task)
    open_list.push(start, (_h(start, goal), opened[start]))
    expansions = 0
    while (current := open_list.pop()) is not None:
        closed.add(current)
        expansions += 1
        came = vertical[current]
        rules = None if rules_at is None else \
            ALL if at_home(grid, task, current, home) else rules_at[current]
        for d, dx, dy, upright in _STEPS:
            n = (current[0] + dx, current[1] + dy)
            if n in closed or (rules is not None and d not in rules):
                continue
            ok = enterable.get(n)
            if ok is None:
                ok = enterable[n] = values(n) in passable
            if not ok:
                continue
            step = 1.0 + (turn if came is not None and came != upright else 0.0)
            if heat:
                step += heat * costs.t_value.get(n, 0.0)
            if n in g and g[current] + step >= g[n]:
                continue
            g[n], parent[n], vertical[n] = g[current] + step, current, upright
            opened.setdefault(n, next(order))
            if n == goal:  # step 5: the goal has entered the open list
                return Path(_trace(parent, start, goal), expansions)
            open_list.push(n, (g[n] + _h(n, goal), opened[n]))
    return None


_VERTICAL = frozenset({Direction.UP, Direction.DOWN})
_STEPS = tuple((d, dx, dy, d in _VERTICAL) for d, (dx, dy) in STEP.items())


def _h(a: XY, b: XY) -> float:
    """Equation (2): the Manhattan distance, obstacles ignored."""
    return abs(a[0] - b[0]) + abs(a[1] - b[1])


def _trace(parent: dict[XY, XY], start: XY, goal: XY) -> tuple[XY, ...]:
    cells = [goal]
    while cells[-1] != start:
        cells.append(parent[cells[-1]])
    return tuple(reversed(cells))
