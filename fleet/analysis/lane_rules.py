"""The lane oracle (seed 002): does a route of unit-AGV cells keep to the lanes?

The rules are the seed pack note's `lanes` mode (A.4.2) as docs/layouts.md states them, judged
from the layout's data alone: each cell's directions come from `layout.lanes` here, and
nothing is imported from the code that plans or checks lane routes (`fleet.world.lanes`,
`fleet.world.lane_reachability`, `fleet.planning`), so a verdict on a route does not repeat
the planner's mistakes (docs/recording.md, "The lane oracle is independent"). The layout
is only read, through its attributes; this module imports nothing of the project at run time.

A route is a sequence of cells (column, row); move i goes from cells[i] to cells[i + 1]. The
first cell is where the vehicle starts, the last where it ends. The rules, in the order a
move is judged (a move breaking several gets the first rule it breaks, so one violation a
move at most):

- A cell repeated is a **wait**, never a violation; waits are skipped, so "the route's first
  (last) cell" means the first (last) cell it stands on, however long.
- `not-adjacent`: a move to a cell that is not one of the 8 neighbours (a jump).
- `through-place`: a slot, packing station or pile entered that is not the route's last cell
  (such a place may only be the route's first or last cell).
- `place-access`: a place left, or the end place entered, other than straight from or to one
  of its access cells (`place.access`): so never diagonally, never from the wrong side.
- Doors, the only exemptions: right after leaving the start place onto its access cell, the
  next move may go straight on, in the same direction, onto a lane cell: across the channel
  onto its far lane, though that crosses the opposite lane (from an `[[access]]` cell, this
  step onto the lane beyond is the one way on). Mirrored, the move before the last access
  cell may come straight across onto it. Only these two moves are exempt, only straight,
  and only when the route starts (ends) on the place itself. A route may also start or end
  on an `[[access]]` cell (a vehicle stopped while crossing it); the move off (onto) it is
  then exempt when it is the straight step between the place it serves and the lane beyond.
- `access-cell`: any other move onto or off an `[[access]]` cell (driving along them,
  crossing them diagonally, or not between a place at the route's end and the lane).
- `off-lanes`: a move from or to a cell that is none of lane, place or access cell (floor,
  wall, shelf-area floor, outside the map).
- Orthogonal lane-to-lane moves in direction d from c to c': legal iff d is a direction of
  c's lane(s) and of c''s; so a vehicle turns only on a junction cell, where two lanes cross.
  Otherwise:
  - `wrong-way`: the opposite of d is a direction of c or c' (driving against a lane);
  - `crossing-lane`: d is across every lane of c and of c' (a sidestep onto the parallel
    lane: crossing the opposite lane away from the start's and end's doors, or a U-turn in
    the middle of a channel);
  - `turn-off-junction`: else: the move changes between a horizontal and a vertical lane
    where no junction is (a lane ending beside the side of another).
- Diagonal moves (d = 1.4) between lane cells:
  - `corner-cut`: one of the two orthogonal neighbours it passes is not a lane cell (past a
    shelf, a station, an access cell, the wall);
  - legal iff one of its two orthogonal decompositions (x first or y first) is legal step by
    step under the orthogonal rule (no door exemption inside a diagonal);
  - else the rule of the decomposition that fails later (its first step legal), x first
    when both fail at the same step.

`lane_violations` returns every violation, in route order; an empty list is a legal route.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # only for the type: the layout is read through its attributes
    from fleet.world.layout import Layout

Cell = tuple[int, int]

_STEPS: dict[str, Cell] = {"E": (1, 0), "N": (0, 1), "W": (-1, 0), "S": (0, -1)}
_NAMES: dict[Cell, str] = {step: name for name, step in _STEPS.items()}
_OPPOSITE = {"E": "W", "W": "E", "N": "S", "S": "N"}
_HORIZONTAL = frozenset("EW")


@dataclass(frozen=True)
class LaneViolation:
    index: int  # the move's index in the route (move i goes cells[i] -> cells[i + 1])
    move: tuple[Cell, Cell]
    rule: str  # see the module docstring for the names
    detail: str  # a sentence naming the cells and why


@dataclass(frozen=True)
class _Place:
    kind: str  # "slot", "packing station", "pile"
    name: str
    access: tuple[Cell, ...]


@dataclass(frozen=True)
class _Map:
    """What the oracle reads of a layout: each lane cell's directions and lane names, the
    places with their access cells, and the access cells."""

    directions: dict[Cell, frozenset[str]]
    lane_names: dict[Cell, tuple[str, ...]]
    places: dict[Cell, _Place]
    access_cells: frozenset[Cell]

    @classmethod
    def of(cls, layout: Layout) -> _Map:
        directions: dict[Cell, set[str]] = {}
        names: dict[Cell, list[str]] = {}
        for lane in layout.lanes:
            for cell in lane.cells:
                cell = (int(cell[0]), int(cell[1]))
                directions.setdefault(cell, set()).add(lane.direction)
                names.setdefault(cell, []).append(lane.name)
        places: dict[Cell, _Place] = {}
        for kind, group in (
            ("slot", layout.slots),
            ("packing station", layout.packing),
            ("pile", layout.piles),
        ):
            for place in group:
                places[tuple(place.cell)] = _Place(
                    kind, place.name, tuple(tuple(a) for a in place.access)
                )
        return cls(
            {cell: frozenset(d) for cell, d in directions.items()},
            {cell: tuple(n) for cell, n in names.items()},
            places,
            frozenset(tuple(c) for c in layout.access_cells),
        )

    def describe(self, cell: Cell) -> str:
        if cell in self.places:
            place = self.places[cell]
            return f"{place.kind} {place.name} {cell}"
        if cell in self.lane_names:
            return f"{cell} (lane {', '.join(self.lane_names[cell])})"
        if cell in self.access_cells:
            return f"access cell {cell}"
        return f"{cell}"


def lane_violations(layout: Layout, cells: Sequence[Cell]) -> list[LaneViolation]:
    """Every move of a route (first cell: where it starts, last: where it ends) that breaks the
    lane rules: the rules and their names are in this module's docstring. A repeated cell is
    a wait, not a violation; a jump is `not-adjacent`."""
    grid = _map_of(layout)
    route = [(int(c[0]), int(c[1])) for c in cells]
    # The cells stood on, waits merged, each with the index of the move that leaves it.
    stops: list[Cell] = []
    leaving: list[int] = []
    for i, cell in enumerate(route):
        if stops and stops[-1] == cell:
            leaving[-1] = i
            continue
        stops.append(cell)
        leaving.append(i)
    found = []
    for k in range(len(stops) - 1):
        a, b = stops[k], stops[k + 1]
        broken = _judge(grid, stops, k)
        if broken is not None:
            found.append(LaneViolation(leaving[k], (a, b), *broken))
    return found


_last: list[tuple[Layout, _Map]] = []  # the last layout read: routes come many to a layout


def _map_of(layout: Layout) -> _Map:
    if not _last or _last[0][0] is not layout:
        _last[:] = [(layout, _Map.of(layout))]
    return _last[0][1]


def _judge(grid: _Map, stops: list[Cell], k: int) -> tuple[str, str] | None:
    """The rule move k of the waitless route breaks and why, or None."""
    a, b = stops[k], stops[k + 1]
    last = len(stops) - 1
    dx, dy = b[0] - a[0], b[1] - a[1]
    if max(abs(dx), abs(dy)) != 1:
        return "not-adjacent", f"{a} -> {b} is not a move to one of the 8 neighbours"
    if b in grid.places:
        place = grid.places[b]
        if k + 1 != last:
            return "through-place", (
                f"{a} -> {b} enters {grid.describe(b)}, which is not the route's end: a "
                "place is only ever a route's first or last cell"
            )
        if a not in place.access:
            return "place-access", (
                f"{a} -> {b} enters {grid.describe(b)} from {a}, not straight from one of "
                f"its access cells {list(place.access)}"
            )
        return None
    if a in grid.places:
        place = grid.places[a]
        if b not in place.access:
            return "place-access", (
                f"{a} -> {b} leaves {grid.describe(a)} to {b}, not straight to one of its "
                f"access cells {list(place.access)}"
            )
        return None
    if _door(grid, stops, k):
        return None
    for cell in (a, b):
        if cell in grid.access_cells:
            return "access-cell", (
                f"{a} -> {b} drives on access cell {cell}, which is only crossed straight "
                "between a place at the route's start or end and the lane beyond"
            )
    for cell in (a, b):
        if cell not in grid.directions:
            return "off-lanes", (
                f"{a} -> {b}: {cell} is no lane cell (nor a place at the route's end, nor an "
                "access cell)"
            )
    if dx == 0 or dy == 0:
        return _orthogonal(grid, a, b)
    corners = ((b[0], a[1]), (a[0], b[1]))  # x first, then y first
    for corner in corners:
        if corner not in grid.directions:
            return "corner-cut", (
                f"{a} -> {b} cuts the corner past {grid.describe(corner)}: a diagonal needs "
                "lane cells on both sides"
            )
    failures = []
    for corner in corners:
        first = _orthogonal(grid, a, corner)
        if first is not None:
            failures.append((0, first, corner))
            continue
        second = _orthogonal(grid, corner, b)
        if second is None:
            return None
        failures.append((1, second, corner))
    _, (rule, why), corner = max(failures, key=lambda f: f[0])  # max keeps the first
    return rule, f"{a} -> {b}: neither way round the corner is legal; via {corner}: {why}"


def _orthogonal(grid: _Map, a: Cell, b: Cell) -> tuple[str, str] | None:
    """The rule a lane-to-lane step between orthogonal neighbours breaks, or None."""
    d = _NAMES[(b[0] - a[0], b[1] - a[1])]
    here, there = grid.directions[a], grid.directions[b]
    if d in here and d in there:
        return None
    where = f"{a} -> {b} ({d}) from {grid.describe(a)} to {grid.describe(b)}"
    if _OPPOSITE[d] in here | there:
        return "wrong-way", f"{where} drives against the lane"
    horizontal = d in _HORIZONTAL
    if all((x in _HORIZONTAL) != horizontal for x in here | there):
        return "crossing-lane", (
            f"{where} steps sideways across onto the parallel lane, away from the start's "
            "and end's doors"
        )
    return "turn-off-junction", f"{where} turns between lanes where no junction is"


def _door(grid: _Map, stops: list[Cell], k: int) -> bool:
    """Whether move k is a door's straight step: off the start place's access cell onto the
    lane beyond, onto the end place's access cell from the lane before it, or the same step
    off (onto) an access cell the route starts (ends) on."""
    a, b = stops[k], stops[k + 1]
    step = (b[0] - a[0], b[1] - a[1])
    if step not in _NAMES:
        return False
    last = len(stops) - 1
    behind = (a[0] - step[0], a[1] - step[1])  # the place a door leads out of
    ahead = (b[0] + step[0], b[1] + step[1])  # the place a door leads into
    if b in grid.directions:
        if k == 1 and stops[0] == behind and _serves(grid, behind, a):
            return True
        if k == 0 and a in grid.access_cells and _serves(grid, behind, a):
            return True
    if a in grid.directions:
        if k + 1 == last - 1 and stops[last] == ahead and _serves(grid, ahead, b):
            return True
        if k + 1 == last and b in grid.access_cells and _serves(grid, ahead, b):
            return True
    return False


def _serves(grid: _Map, place: Cell, access: Cell) -> bool:
    return place in grid.places and access in grid.places[place].access
