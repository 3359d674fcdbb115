"""Seed 002's route planning on a lane layout: the A* of its Section 4 over the lanes.

The search is the paper's: f(n) = g(n) + h(n), g(n) = g(n-1) + d/v with d = 1 for a
straight move and 1.4 for a diagonal one, h(n) = Manhattan distance to the goal / v. The
moves are the lane mode of the seed pack note (A.4.2), the reference form of the paper's
per-AGV dynamic map: an orthogonal move along a lane, turning only on junction cells
(`lanes.allowed_moves`); a diagonal move only where both orthogonal neighbours are lane cells
and one way round the corner is allowed (`lanes.diagonal_moves`). A slot, packing station or
pile is entered and left only at the route's two ends, through its access cell, and straight
on across one cell more onto the far lane: the only place a route crosses the opposite lane
(Algorithms 1 and 2 leave exactly that opening, in the start's and end's own column).

Other AGVs are not obstacles: "the proposed method only allows for individual route planning
of each AGV"; conflicts are found and resolved afterwards on the timed route. On a
unidirectional layout (`paper002-uni`) the same search is the plain directed A* the paper
compares against: its lanes run one way each, so no dynamic map is needed.

Choices where the text is silent or garbled (the note's A.4.3): a node still open whose g can
be lowered through the current node is re-parented (standard A*); a closed node is never
reopened; ties in f break by smaller h, then by insertion order, so a query always gives the
same route. The Manhattan heuristic is not admissible with 1.4-cell diagonals, so a route may
be slightly longer than the shortest; it is the paper's, and kept (`octile` is the admissible
option, off by default).
"""

from __future__ import annotations

import heapq
import itertools
from collections.abc import Iterator
from dataclasses import dataclass
from enum import Enum

from fleet.planning.geometry import Cell
from fleet.world.lanes import allowed_moves, diagonal_moves, direction_between, places, step
from fleet.world.layout import Layout

STRAIGHT, DIAGONAL = 1.0, 1.4  # the paper's d, in cells


class Heuristic(Enum):
    MANHATTAN = "manhattan"  # the paper's Equation (4)
    OCTILE = "octile"  # admissible with 1.4-cell diagonals


@dataclass(frozen=True)
class Route:
    """A route from its first cell to its last, with the paper's cost g at the end."""

    cells: tuple[Cell, ...]
    cost_s: float  # g(end) = sum of d / v over the moves
    expansions: int  # nodes taken from the open list

    def distances(self) -> list[float]:
        """Each move's d, in cells."""
        return [DIAGONAL if a[0] != b[0] and a[1] != b[1] else STRAIGHT
                for a, b in itertools.pairwise(self.cells)]


@dataclass(frozen=True)
class _Edge:
    to: Cell
    d: float
    via: tuple[Cell, ...] = ()  # cells passed between (straight across the near lane)


class LaneRoutes:
    """The moves of one lane layout, worked out once; `route` searches them per query."""

    def __init__(self, layout: Layout, speed_mps: float = 1.0,
                 heuristic: Heuristic = Heuristic.MANHATTAN):
        if not layout.has_lanes:
            raise ValueError(f"layout {layout.name} has no lanes: routes on lanes need a "
                             f"lane layout")
        if speed_mps <= 0:
            raise ValueError(f"speed must be positive, not {speed_mps}")
        self.layout = layout
        self.seconds_per_cell = 1.0 / (speed_mps / layout.cell_size)
        self.heuristic = heuristic
        self.places = {place.cell: place for _, place in places(layout)}
        self.moves: dict[Cell, tuple[_Edge, ...]] = {
            cell: tuple(self._lane_moves(cell)) for cell in sorted(layout.lane_directions)}

    def _lane_moves(self, cell: Cell) -> Iterator[_Edge]:
        for d in sorted(allowed_moves(self.layout, cell)):
            yield _Edge(step(cell, d), STRAIGHT)
        for d in sorted(diagonal_moves(self.layout, cell)):
            yield _Edge(step(step(cell, d[0]), d[1]), DIAGONAL)

    def _ways_out(self, start: Cell) -> Iterator[_Edge]:
        """Out of a place onto its access cell, and straight on across one cell more."""
        lanes = self.layout.lane_directions
        for near in self.places[start].access:
            beyond = step(near, direction_between(start, near))
            if near in lanes:
                yield _Edge(near, STRAIGHT)
            if beyond in lanes:
                yield _Edge(beyond, 2 * STRAIGHT, (near,))

    def _ways_in(self, goal: Cell) -> dict[Cell, _Edge]:
        """Into a place, by lane cell: from its access cell, or from straight across it."""
        lanes = self.layout.lane_directions
        found: dict[Cell, _Edge] = {}
        for near in self.places[goal].access:
            beyond = step(near, direction_between(goal, near))
            if near in lanes:
                found[near] = _Edge(goal, STRAIGHT)
            if beyond in lanes and beyond not in found:
                found[beyond] = _Edge(goal, 2 * STRAIGHT, (near,))
        return found

    def _h(self, cell: Cell, goal: Cell) -> float:
        dx, dy = abs(cell[0] - goal[0]), abs(cell[1] - goal[1])
        if self.heuristic is Heuristic.OCTILE:
            return (DIAGONAL * min(dx, dy) + STRAIGHT * abs(dx - dy)) * self.seconds_per_cell
        return (dx + dy) * self.seconds_per_cell

    def route(self, start: Cell, goal: Cell) -> Route | None:
        """The route from `start` to `goal` (a lane cell, slot, packing station or pile
        each); None when the lanes lead from one to the other by no way."""
        for name, cell in (("start", start), ("goal", goal)):
            if cell not in self.places and cell not in self.moves:
                raise ValueError(f"{name} {cell} is neither on a lane nor a slot, packing "
                                 f"station or pile of layout {self.layout.name}")
        if start == goal:
            return Route((start,), 0.0, 0)
        ways_in = self._ways_in(goal) if goal in self.places else {}
        g = {start: 0.0}
        parent: dict[Cell, tuple[Cell, tuple[Cell, ...]]] = {}
        closed: set[Cell] = set()
        counter = 0
        h0 = self._h(start, goal)
        open_heap = [(h0, h0, counter, start)]
        expansions = 0
        while open_heap:
            _, _, _, cell = heapq.heappop(open_heap)
            if cell in closed:
                continue  # an entry left behind when the node was re-parented
            closed.add(cell)
            expansions += 1
            if cell == goal:
                return Route(self._cells(parent, goal), g[goal], expansions)
            for edge in self._edges(cell, start, goal, ways_in):
                if edge.to in closed:
                    continue
                cost = g[cell] + edge.d * self.seconds_per_cell
                if cost < g.get(edge.to, float("inf")):
                    g[edge.to] = cost
                    parent[edge.to] = (cell, edge.via)
                    counter += 1
                    h = self._h(edge.to, goal)
                    heapq.heappush(open_heap, (cost + h, h, counter, edge.to))
        return None

    def _edges(self, cell: Cell, start: Cell, goal: Cell,
               ways_in: dict[Cell, _Edge]) -> Iterator[_Edge]:
        if cell == start and cell in self.places:
            yield from self._ways_out(cell)
            return
        yield from self.moves.get(cell, ())  # lane moves land on lane cells only
        if cell in ways_in:
            yield ways_in[cell]

    @staticmethod
    def _cells(parent: dict[Cell, tuple[Cell, tuple[Cell, ...]]], goal: Cell
               ) -> tuple[Cell, ...]:
        cells = [goal]
        while cells[-1] in parent:
            before, via = parent[cells[-1]]
            cells.extend(reversed(via))
            cells.append(before)
        return tuple(reversed(cells))
