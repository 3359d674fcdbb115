"""Seed 002's route planning on a lane layout: the A* of its Section 4 over the lanes.

The search is the paper's: f(n) = g(n) + h(n), g(n) = g(n-1) + d/v with d = 1 for a
straight move and 1.4 for a diagonal one, h(n) = Manhattan distance to the goal / v. The
moves are the lane mode of the seed pack note (A.4.2), the reference form of the paper's
per-AGV dynamic map: an orthogonal move along a lane, turning only on junction cells; a
diagonal move only where both orthogonal neighbours are lane cells and one way round the
corner is allowed. The layout's `LaneGraph` (built by `fleet.world.lanes.lane_graph`) holds
them; this module only searches it. A slot, packing station or
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
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass
from enum import Enum

from fleet.planning.geometry import Cell

STRAIGHT, DIAGONAL = 1.0, 1.4  # the paper's d, in cells


def move_length(a: Cell, b: Cell) -> float:
    """The paper's d of a move to one of the eight neighbours, in cells."""
    return DIAGONAL if a[0] != b[0] and a[1] != b[1] else STRAIGHT


def touched(cell: Cell, move: Move) -> set[Cell]:
    """The cells a move from `cell` touches: where it goes, what it crosses, and a
    diagonal's two corners (its body sweeps them)."""
    cells = {move.to, *move.via}
    if move.to[0] != cell[0] and move.to[1] != cell[1]:
        cells |= {(cell[0], move.to[1]), (move.to[0], cell[1])}
    return cells


class Heuristic(Enum):
    MANHATTAN = "manhattan"  # the paper's Equation (4)
    OCTILE = "octile"  # admissible with 1.4-cell diagonals


@dataclass(frozen=True)
class Move:
    """One move of the lane graph: to `to`, `d` cells long, passing `via` (straight across
    the near lane, out of or into a place)."""

    to: Cell
    d: float
    via: tuple[Cell, ...] = ()


@dataclass(frozen=True)
class LaneGraph:
    """A lane layout's moves as the search sees them: from each lane cell along the lanes,
    out of each place (slot, packing station, pile) onto the lanes, and into each place
    from the lane cells its ways in start on."""

    name: str
    cell_size: float
    moves: Mapping[Cell, tuple[Move, ...]]
    ways_out: Mapping[Cell, tuple[Move, ...]]
    ways_in: Mapping[Cell, Mapping[Cell, Move]]  # place -> lane cell -> the move into it


@dataclass(frozen=True)
class Route:
    """A route from its first cell to its last, with the paper's cost g at the end."""

    cells: tuple[Cell, ...]
    cost_s: float  # g(end) = sum of d / v over the moves
    expansions: int  # nodes taken from the open list

    def distances(self) -> list[float]:
        """Each move's d, in cells."""
        return [move_length(a, b) for a, b in itertools.pairwise(self.cells)]


class LaneRoutes:
    """Routes on one lane graph, searched per query."""

    def __init__(self, graph: LaneGraph, speed_mps: float = 1.0,
                 heuristic: Heuristic = Heuristic.MANHATTAN):
        if speed_mps <= 0:
            raise ValueError(f"speed must be positive, not {speed_mps}")
        self.graph = graph
        self.seconds_per_cell = graph.cell_size / speed_mps
        self.heuristic = heuristic

    def _h(self, cell: Cell, goal: Cell) -> float:
        dx, dy = abs(cell[0] - goal[0]), abs(cell[1] - goal[1])
        if self.heuristic is Heuristic.OCTILE:
            return (DIAGONAL * min(dx, dy) + STRAIGHT * abs(dx - dy)) * self.seconds_per_cell
        return (dx + dy) * self.seconds_per_cell

    def route(self, start: Cell, goal: Cell,
              blocked: Callable[[Cell], bool] | None = None) -> Route | None:
        """The route from `start` to `goal` (a lane cell, slot, packing station or pile
        each); None when the lanes lead from one to the other by no way. With `blocked`, no
        move touches a cell it says is blocked (something stands there for good), a
        diagonal's corners included; the start and the goal are the caller's to judge."""
        graph = self.graph
        for name, cell in (("start", start), ("goal", goal)):
            if cell not in graph.ways_out and cell not in graph.moves:
                raise ValueError(f"{name} {cell} is neither on a lane nor a slot, packing "
                                 f"station or pile of layout {graph.name}")
        if start == goal:
            return Route((start,), 0.0, 0)
        ways_in = graph.ways_in.get(goal, {})
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
            for move in self.moves_from(cell, start, ways_in):
                if move.to in closed or (blocked is not None and any(
                        blocked(c) for c in touched(cell, move) - {goal})):
                    continue
                cost = g[cell] + move.d * self.seconds_per_cell
                if cost < g.get(move.to, float("inf")):
                    g[move.to] = cost
                    parent[move.to] = (cell, move.via)
                    counter += 1
                    h = self._h(move.to, goal)
                    heapq.heappush(open_heap, (cost + h, h, counter, move.to))
        return None

    def moves_from(self, cell: Cell, start: Cell, ways_in: Mapping[Cell, Move]
                   ) -> Iterator[Move]:
        """The moves a route from `start` may make from `cell`: out of the start place
        only by its ways out; along the lanes (which lead onto lane cells only); and into
        the goal place by its ways in."""
        if cell == start and cell in self.graph.ways_out:
            yield from self.graph.ways_out[cell]
            return
        yield from self.graph.moves.get(cell, ())
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
