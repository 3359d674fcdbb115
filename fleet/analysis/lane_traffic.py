"""Seed 002's traffic as the recording shows it: where each unit AGV drove, cell by cell, and
the verdicts on it: every executed route keeps the lanes (the lane oracle,
fleet/analysis/lane_rules.py), and no two AGVs meet at a node, swap along an edge or cross
diagonals of one 2 x 2 block (the paper's three collision classes, Section 5.2).

Everything here comes from the AGVs' published states (the centre of the body), with this
module's own arithmetic: nothing of the planner, the schedules or the reservation table is
used, so a verdict does not repeat their mistakes.

- **Paths.** Between two states of an AGV no further apart than the state gap allowed, its
  centre moves along the straight line joining them. An AGV drives at one speed from node to
  node, crossing a cell's edge half a move from either node, and turns only on a node, where
  the line between two states stays inside the node's cell; so the instants the line crosses
  cell edges are the instants the AGV did. A track is cut where states are further apart
  (lost or unrecorded states), and nothing is assumed across the cut.
- **Visits.** An AGV visits a cell over the open interval its centre is inside the cell.
- **Executed routes.** A track is cut into routes at the places (slot, packing station,
  pile) the AGV stopped at: it stood there, turned back there, or its track ends there. A
  place driven straight through stays inside a route, and the oracle calls it
  `through-place`.
- **Node.** Two AGVs inside one cell at once (a follower one cell behind only touches).
- **Swap.** Two AGVs crossing one edge in opposite directions less than one move apart:
  they passed through each other.
- **Crossing diagonals.** Two diagonal moves over the two diagonals of one 2 x 2 block whose
  crossings of the block's centre are less than one diagonal move apart (the seed's d = 1.4
  cells, Section 4).
"""

from __future__ import annotations

import itertools
import math
from collections import defaultdict
from collections.abc import Iterable
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

from fleet.analysis.lane_rules import lane_violations

if TYPE_CHECKING:  # the layout is only read, through its attributes
    from fleet.world.layout import Layout

Cell = tuple[int, int]
EPS_S = 1e-6  # two instants closer than this are one (a follower's entry at the leader's exit)
DIAGONAL = 1.4  # a diagonal move's length in cells (the seed's d, Section 4)


@dataclass(frozen=True)
class Seen:
    """One state, as the traffic checks read it."""

    vehicle: int
    t: float
    x: float  # the body's centre, world metres
    y: float


@dataclass(frozen=True)
class Visit:
    vehicle: int
    cell: Cell
    t_in: float  # when the centre came inside the cell (the track's first state: then)
    t_out: float  # when it left (the track's last state: then)
    stood: bool  # it stood still inside the cell a while


@dataclass(frozen=True)
class Grid:
    origin: tuple[float, float]  # world position of the centre of cell (0, 0)
    size: float

    def local(self, x: float, y: float) -> tuple[float, float]:
        """Cell (i, j) spans [i, i + 1) x [j, j + 1) here."""
        return ((x - self.origin[0]) / self.size + 0.5, (y - self.origin[1]) / self.size + 0.5)

    def cell_of(self, x: float, y: float) -> Cell | None:
        """The cell the point is inside; None on a cell's edge."""
        u, v = self.local(x, y)
        if u == math.floor(u) or v == math.floor(v):
            return None
        return (math.floor(u), math.floor(v))

    def passed(self, a: Seen, b: Seen) -> list[tuple[Cell, float, float]]:
        """The cells the centre is inside between states a and b, with the open interval of
        each, in order; an AGV standing on a cell's edge is inside none."""
        (ax, ay), (bx, by) = self.local(a.x, a.y), self.local(b.x, b.y)
        cuts = {0.0, 1.0}
        for p, q in ((ax, bx), (ay, by)):
            if p != q:
                lo, hi = sorted((p, q))
                cuts.update((k - p) / (q - p) for k in range(math.ceil(lo), math.floor(hi) + 1))
        out: list[tuple[Cell, float, float]] = []
        for s0, s1 in itertools.pairwise(sorted(c for c in cuts if 0.0 <= c <= 1.0)):
            t0, t1 = a.t + s0 * (b.t - a.t), a.t + s1 * (b.t - a.t)
            if t1 - t0 < EPS_S:
                continue  # through a corner: rounding, not a visit of the cells beside it
            mid = (s0 + s1) / 2
            u, v = ax + mid * (bx - ax), ay + mid * (by - ay)
            if u == math.floor(u) or v == math.floor(v):
                continue  # along an edge
            out.append(((math.floor(u), math.floor(v)), t0, t1))
        return out


def tracks(states: Iterable[Seen], grid: Grid, max_gap: float) -> dict[int, list[list[Visit]]]:
    """Each AGV's visits, in time order, in pieces cut where its states are further apart
    than `max_gap` seconds."""
    by_vehicle: dict[int, list[Seen]] = defaultdict(list)
    for s in states:
        by_vehicle[s.vehicle].append(s)
    out: dict[int, list[list[Visit]]] = {}
    for vehicle, seen in sorted(by_vehicle.items()):
        seen.sort(key=lambda s: s.t)
        pieces: list[list[Visit]] = []
        for a, b in itertools.pairwise(seen):
            if b.t - a.t > max_gap or not pieces:
                pieces.append([])
                if b.t - a.t > max_gap:
                    continue
            still = (a.x, a.y) == (b.x, b.y)
            piece = pieces[-1]
            for cell, t0, t1 in grid.passed(a, b):
                if piece and piece[-1].cell == cell and piece[-1].t_out >= t0 - EPS_S:
                    piece[-1] = replace(piece[-1], t_out=t1, stood=piece[-1].stood or still)
                else:
                    piece.append(Visit(vehicle, cell, t0, t1, still))
        out[vehicle] = [p for p in pieces if p]
    return out


def cell_names(layout: Layout) -> dict[Cell, str]:
    """What each lane, access or place cell is, for a finding's text."""
    names: dict[Cell, str] = {}
    for lane in layout.lanes:
        for cell in lane.cells:
            names[tuple(cell)] = f"lane {lane.name}"
    for cell in layout.access_cells:
        names[tuple(cell)] = "an access cell"
    for kind, group in (("slot", layout.slots), ("packing station", layout.packing),
                        ("pile", layout.piles)):
        for place in group:
            names[tuple(place.cell)] = f"{kind} {place.name}"
    return names


@dataclass(frozen=True)
class ExecutedViolation:
    """A move an AGV drove against the lane rules."""

    vehicle: int
    t: float  # when it left the cell the move starts from
    move: tuple[Cell, Cell]
    rule: str
    detail: str


@dataclass(frozen=True)
class Meeting:
    """Two AGVs where the paper's collision classes say they must not be at once."""

    kind: str  # "node", "swap" or "diagonal"
    vehicles: tuple[int, int]
    cells: tuple[Cell, ...]  # the node; the edge's two cells; the block's lower-left cell
    t: float  # when it began
    where: str  # what the cell is (a lane, packing station p3, ...)


def executed_routes(piece: list[Visit], places: set[Cell]) -> list[list[Visit]]:
    """A piece of track cut into routes at the places the AGV stopped at (stood, turned back,
    or the piece ends there); a place passed straight through stays inside its route."""
    routes: list[list[Visit]] = [[]]
    for i, v in enumerate(piece):
        routes[-1].append(v)
        if v.cell not in places or i in (0, len(piece) - 1):
            continue
        if v.stood or piece[i - 1].cell == piece[i + 1].cell:
            routes.append([v])
    return [r for r in routes if len(r) > 1]


UNSEEN_DOOR_MOVES = 2  # a door's moves: onto the access cell, and across the channel


def lane_breaches(layout: Layout, pieces: dict[int, list[list[Visit]]]
                  ) -> list[ExecutedViolation]:
    """Every executed move that breaks the lane rules, by AGV and time. Where a piece of
    track begins after (or ends before) a window the AGV's states were not recorded in, its
    first (last) route may have begun (ended) at a place unseen: its first (last) two moves,
    which a door would allow, are not judged."""
    places = {tuple(p.cell) for group in (layout.slots, layout.packing, layout.piles)
              for p in group}
    out = []
    for vehicle, vehicle_pieces in pieces.items():
        for k, piece in enumerate(vehicle_pieces):
            routes = executed_routes(piece, places)
            for r, route in enumerate(routes):
                moves = len(route) - 1
                first = UNSEEN_DOOR_MOVES if k > 0 and r == 0 else 0
                last = moves - UNSEEN_DOOR_MOVES if k < len(vehicle_pieces) - 1 and \
                    r == len(routes) - 1 else moves
                for v in lane_violations(layout, [visit.cell for visit in route]):
                    if first <= v.index < last:
                        out.append(ExecutedViolation(vehicle, route[v.index].t_out, v.move,
                                                     v.rule, v.detail))
    return sorted(out, key=lambda e: (e.t, e.vehicle))


def meetings(pieces: dict[int, list[list[Visit]]], move_s: float,
             describe: dict[Cell, str]) -> list[Meeting]:
    """Nodes shared, swaps and crossing diagonals between AGVs (this module's docstring);
    `move_s`: how long a move to a neighbouring cell takes, a diagonal DIAGONAL times that. A swap
    is reported as such, not also as the node the two shared while passing."""
    crossings = _crossings(pieces)
    swaps = _swaps(crossings, move_s)
    passing = {(m.vehicles, cell) for m in swaps for cell in m.cells}
    nodes = [m for m in _nodes(pieces, describe) if (m.vehicles, m.cells[0]) not in passing]
    found = nodes + swaps + _crossed_diagonals(crossings, DIAGONAL * move_s)
    return sorted(found, key=lambda m: (m.t, m.vehicles, m.kind))


def _pair(a: int, b: int) -> tuple[int, int]:
    return (min(a, b), max(a, b))


def _nodes(pieces: dict[int, list[list[Visit]]], describe: dict[Cell, str]) -> list[Meeting]:
    on: dict[Cell, list[Visit]] = defaultdict(list)
    for vehicle_pieces in pieces.values():
        for piece in vehicle_pieces:
            for v in piece:
                on[v.cell].append(v)
    found = []
    for cell, visits in on.items():
        visits.sort(key=lambda v: v.t_in)
        for i, a in enumerate(visits):
            for b in visits[i + 1:]:
                if b.t_in >= a.t_out - EPS_S:
                    break
                if a.vehicle != b.vehicle:
                    found.append(Meeting("node", _pair(a.vehicle, b.vehicle), (cell,), b.t_in,
                                         describe.get(cell, "a cell off the lanes")))
    return found


@dataclass(frozen=True)
class _Crossing:
    vehicle: int
    left: Cell
    entered: Cell
    t: float


def _crossings(pieces: dict[int, list[list[Visit]]]) -> list[_Crossing]:
    """Every move from one cell into a neighbour, at the instant the centre crossed."""
    return [_Crossing(a.vehicle, a.cell, b.cell, b.t_in)
            for vehicle_pieces in pieces.values() for piece in vehicle_pieces
            for a, b in itertools.pairwise(piece)]


def _swaps(crossings: list[_Crossing], move_s: float) -> list[Meeting]:
    by_edge: dict[frozenset[Cell], list[_Crossing]] = defaultdict(list)
    for c in crossings:
        by_edge[frozenset((c.left, c.entered))].append(c)
    found = []
    for edge, crossed in by_edge.items():
        crossed.sort(key=lambda c: c.t)
        diagonal = len({cell[0] for cell in edge}) == 2 and len({cell[1] for cell in edge}) == 2
        window = move_s * (DIAGONAL if diagonal else 1.0)
        for i, a in enumerate(crossed):
            for b in crossed[i + 1:]:
                if b.t - a.t >= window - EPS_S:
                    break
                if b.vehicle != a.vehicle and b.left == a.entered:
                    found.append(Meeting("swap", _pair(a.vehicle, b.vehicle),
                                         tuple(sorted(edge)), a.t, "the edge between them"))
    return found


def _crossed_diagonals(crossings: list[_Crossing], diagonal_s: float) -> list[Meeting]:
    by_block: dict[Cell, list[tuple[float, int, int]]] = defaultdict(list)
    for c in crossings:
        dx, dy = c.entered[0] - c.left[0], c.entered[1] - c.left[1]
        if abs(dx) == 1 and abs(dy) == 1:
            block = (min(c.left[0], c.entered[0]), min(c.left[1], c.entered[1]))
            by_block[block].append((c.t, int(dx != dy), c.vehicle))  # 0: SW-NE, 1: SE-NW
    found = []
    for block, crossed in by_block.items():
        crossed.sort()
        for i, (t, diagonal, vehicle) in enumerate(crossed):
            for t2, diagonal2, vehicle2 in crossed[i + 1:]:
                if t2 - t >= diagonal_s - EPS_S:
                    break
                if diagonal2 != diagonal and vehicle2 != vehicle:
                    found.append(Meeting("diagonal", _pair(vehicle, vehicle2), (block,), t,
                                         f"the 2 x 2 block from {block}"))
    return found
