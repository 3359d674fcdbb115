"""Seed 002's per-AGV dynamic map, "literal" mode: Algorithms 1, 2 and 3-1 ... 3-4 of its
Section 3 (2), executed index for index on the `paper002` geometry, with the seed pack
note's errata E1-E7 (A.4.2) applied, and the A* of its Section 4 over the open cells.

**Coordinates.** The listings write `map[row, column]`, rows 0..29 growing upward (Algorithm
3-1: "m2 > m1 (The end point is at the top left of the start point)"), column 0 the packing
stations ("The location of the packing area is designated as (0,0)", "map[(y1 + 1):29,1]"
is the lane beside them) and a point (x, y) with x the column and y the row. The project's
cell (x, y) is (column, row) with row 0 at the bottom of the drawing, so the mapping is the
identity: paper map[r, c] is project cell (c, r). Checked against `paper002`'s drawing: the
stations P are column x = 0; the piles C are the top row y = 30 (the seed: the charging area
"is situated at the topmost part of the map"); row 0 (`h1-east`) runs east, the row above it
west, column 1 south and column 2 north, which is what Algorithm 1 blocks for (it closes
"map[0,3:(x1 - 1)]", the lower lane to the left of the start, and with n1 = 0 "map[(y1 +
1):29,1]", column 1 above a station). Ranges "a: b" are inclusive (the listing's Note) and
empty when a > b.

**Levels and blocks** (the seed's sub-area (m, n), note A.2.2): a slot's level m is the
horizontal channel it is entered from, m = (y + 1) // 4 + 1 (row 2 above h1 is m = 1, rows 3
and 6 around h2 are m = 2, ..., row 27 below h8 is m = 8); the same formula is the note's
CHOICE for a packing station (E6). Its block n = (x - 3) // (L + 2) + 1, 0 for a station. A
pile (row 30, above h8) is a slot of level 8 in block (x - 3) // (L + 2) + 1, which for the
pile columns over the vertical channels (12-13, 23-24, 34-35) is the block to their left.

**Errata** (the note's reading; `ERRATA`):

- E1: the vertical-lane columns are k(L + 2) + 1 / + 2 (1/2, 12/13, 23/24, 34/35), not the
  listings' k(L + 1) + 1 / + 2 (which land on shelf columns 11, 21, 22, 31, 32, 33). The
  note says "Algorithm 3 uses period L + 2"; it does for the shelf spans, but its vertical
  lines (3-1 line 6, 3-2 line 6, ...) write k(L + 1) too, so E1 is applied there as well.
- E2: Algorithm 2 reads (x2, y2), (m2, n2); Algorithms 3-x use both points (no index change).
- E3: the junction reopening of Algorithms 1 and 2 includes k = 3 (the right edge V3).
- E4: the start's and end's columns stay open in both lanes of their channel.
- E5: same block (n1 = n2, m1 != m2): the intermediate double-rows lose their wrong-way
  vertical lanes as in 3-1 (going up) or 3-2 (going down); same level: Algorithms 1, 2 only.
- E6: a packing station's level is m(y) above.
- E7: the start and end cells are always open.

The algorithms are applied in order (1, 2, then the 3-x that matches, each line in turn), so
a later "= 1" may reopen what an earlier line closed; then E4 and E7. `unpatched=True` keeps
only the readings without which the listings cannot run at all (E2, E6, E7) and drops the
index corrections E1, E3, E4 and E5: the listings' raw indices, for the finding of what they
break (docs/planning-002.md).

`literal_route` is the Section 4 A* of the lane mode (`fleet.planning.lane_route`) on a
graph of the open cells: 8 neighbours, a diagonal only when both orthogonal neighbours are
open. It knows nothing of lane directions: whether its routes keep right is for the lane
oracle (`fleet.analysis.lane_rules`, which the tests and the sweep use).

This module imports nothing from `fleet.world` (planning sits below it): a layout is anything
with the attributes of `LaneLayout`, such as `fleet.world.layout.Layout`.
"""

from __future__ import annotations

import itertools
import random
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Protocol

from fleet.planning.geometry import Cell
from fleet.planning.lane_route import DIAGONAL, STRAIGHT, LaneGraph, LaneRoutes, Move, Route

L = 9  # shelving stations per shelf row of a block ("a size of 2*L"), derived (note A.2.1)
PERIOD = L + 2  # a block and the vertical channel right of it
COLS, ROWS = 36, 31  # 30 map rows + the pile row
TOP = 29  # the listings' last map row
RIGHT = 35  # the listings' last column
LEVELS = 8  # horizontal channels h1..h8
BLOCKS = 3

ERRATA = frozenset({"E1", "E2", "E3", "E4", "E5", "E6", "E7"})
READINGS = frozenset({"E2", "E6", "E7"})  # kept by `unpatched`: the listings cannot run without
DIRECTIONS: dict[str, Cell] = {"E": (1, 0), "N": (0, 1), "W": (-1, 0), "S": (0, -1)}


class _Place(Protocol):
    @property
    def cell(self) -> Cell: ...
    @property
    def access(self) -> tuple[Cell, ...]: ...


class LaneLayout(Protocol):
    """What this module reads of a lane layout (`fleet.world.layout.Layout` has it)."""

    @property
    def name(self) -> str: ...
    @property
    def cols(self) -> int: ...
    @property
    def rows(self) -> int: ...
    @property
    def lane_directions(self) -> Mapping[Cell, frozenset[str]]: ...
    @property
    def slots(self) -> Sequence[_Place]: ...
    @property
    def packing(self) -> Sequence[_Place]: ...
    @property
    def piles(self) -> Sequence[_Place]: ...


# -- the geometry the arithmetic fits ------------------------------------------------------

def lane_columns() -> tuple[int, ...]:
    """The vertical lanes' columns: V_k is k(L + 2) + 1 (south) and k(L + 2) + 2 (north)."""
    return tuple(k * PERIOD + j for k in range(BLOCKS + 1) for j in (1, 2))


def lane_rows() -> tuple[int, ...]:
    """The horizontal lanes' rows: h_m is 4(m - 1) (east) and 4(m - 1) + 1 (west)."""
    return tuple(4 * (m - 1) + j for m in range(1, LEVELS + 1) for j in (0, 1))


def block_columns(n: int) -> range:
    """Block n's shelf columns, 3 + (n - 1)(L + 2) .. + L - 1 (Algorithm 3's spans)."""
    first = 3 + (n - 1) * PERIOD
    return range(first, first + L)


def expected_lane_cells() -> frozenset[Cell]:
    rows, cols = lane_rows(), lane_columns()
    return frozenset({(x, y) for y in rows for x in range(1, RIGHT + 1)}
                     | {(x, y) for x in cols for y in range(TOP + 1)})


def check_geometry(layout: LaneLayout) -> None:
    """Raise ValueError unless `layout` is paper002-shaped: 36 x 31 cells, L = 9, the lanes,
    slots, stations and piles where the listings' index arithmetic puts them."""
    problems = []
    if (layout.cols, layout.rows) != (COLS, ROWS):
        problems.append(f"{layout.cols} x {layout.rows} cells, not {COLS} x {ROWS}")
    elif set(layout.lane_directions) != expected_lane_cells():
        problems.append("its lanes are not the 16 rows 4(m-1), 4(m-1)+1 and the 8 columns "
                        f"k(L+2)+1, k(L+2)+2 of L = {L}")
    else:
        shelf_rows = [y for k in range(7) for y in (4 * k + 2, 4 * k + 3)]
        slot_cells = {(x, y) for y in shelf_rows for n in range(1, BLOCKS + 1)
                      for x in block_columns(n)}
        if {s.cell for s in layout.slots} != slot_cells:
            problems.append(f"its slots are not the {len(slot_cells)} cells of 3 blocks of "
                            f"L = {L} columns in 14 shelf rows")
        if not {p.cell for p in layout.packing} <= {(0, y) for y in range(TOP + 1)}:
            problems.append("a packing station is not in column 0")
        if not {p.cell for p in layout.piles} <= {(x, ROWS - 1) for x in range(3, RIGHT + 1)}:
            problems.append(f"a pile is not in row {ROWS - 1}, columns 3..{RIGHT}")
    if problems:
        raise ValueError(f"layout {layout.name} is not paper002-shaped (seed 002's Algorithms "
                         f"1-3 index only that geometry): {'; '.join(problems)}")


def level(cell: Cell) -> int:
    """The level m of a slot, pile or packing station: the horizontal channel it belongs to
    (note A.2.2; for a station the note's CHOICE m(y), E6; a pile is above h8)."""
    _, y = cell
    if y >= ROWS - 1:
        return LEVELS
    return (y + 1) // 4 + 1


def block(cell: Cell) -> int:
    """The block n of a slot or pile (a pile over a vertical channel: the block to its left);
    0 for a packing station (column 0), as the seed's "(0,0)" packing area."""
    x, _ = cell
    if x == 0:
        return 0
    if x < 3:
        raise ValueError(f"cell {cell} is in no block")
    return min(BLOCKS, (x - 3) // PERIOD + 1)


def sub_area(cell: Cell) -> tuple[int, int]:
    """The seed's (m, n) of a start or end point."""
    return level(cell), block(cell)


# -- the map and the listings ---------------------------------------------------------------

class _Map:
    """The paper's 0/1 map, kept as the set of cells that are 1, written map[rows, cols]."""

    def __init__(self, open_cells: Iterable[Cell]):
        self.open = set(open_cells)

    def set(self, rows: tuple[int, int] | int, cols: tuple[int, int] | int, value: int) -> None:
        r0, r1 = (rows, rows) if isinstance(rows, int) else rows
        c0, c1 = (cols, cols) if isinstance(cols, int) else cols
        for r in range(r0, r1 + 1):
            for c in range(c0, c1 + 1):
                if value:
                    self.open.add((c, r))
                else:
                    self.open.discard((c, r))


@dataclass(frozen=True)
class _Point:
    x: int
    y: int
    m: int
    n: int


def _algorithm_1(mp: _Map, p: _Point, col, reopen_ks) -> None:
    """Algorithm 1, the starting area. `col(k, j)` is the listing's k(L + 1) + j (E1: + 2)."""
    x1, y1, m1, n1 = p.x, p.y, p.m, p.n
    if n1 == 0:
        mp.set((y1 + 1, TOP), 1, 0)
        mp.set((0, y1 - 1), 2, 0)
        for k in range(8):
            mp.set((4 * k, 4 * k + 1), 2, 1)
    if m1 == 1 and n1 != 0:
        for k in (1, 2, 3):
            mp.set((2, 3), col(k, 1), 0)
        mp.set(0, (3, x1 - 1), 0)
        mp.set(1, (x1 + 1, RIGHT), 0)
        for k in reopen_ks:
            mp.set(1, (col(k, 1), col(k, 2)), 1)
    if 2 <= m1 <= 7 and n1 != 0:
        row = 2 + (m1 - 2) * 4
        for k in (0, 1, 2, 3):
            mp.set((row, row + 1), col(k, 2), 0)
        for k in (1, 2, 3):
            mp.set((row + 4, row + 5), col(k, 1), 0)
        mp.set(row + 2, (3, x1 - 1), 0)
        mp.set(row + 3, (x1 + 1, RIGHT), 0)
        for k in reopen_ks:
            for q in (2, 3):
                mp.set(row + q, (col(k, 1), col(k, 2)), 1)
    if m1 == 8 and n1 != 0:
        for k in (0, 1, 2, 3):
            mp.set((26, 27), col(k, 2), 0)
        mp.set(28, (3, x1 - 1), 0)
        mp.set(29, (x1 + 1, RIGHT), 0)
        for k in reopen_ks:
            mp.set(28, (col(k, 1), col(k, 2)), 1)


def _algorithm_2(mp: _Map, p: _Point, col, reopen_ks) -> None:
    """Algorithm 2, the ending area (E2: its input is (x2, y2), (m2, n2))."""
    x2, y2, m2, n2 = p.x, p.y, p.m, p.n
    if n2 == 0:
        mp.set((y2 + 1, TOP), 2, 0)
        mp.set((0, y2 - 1), 1, 0)
        for k in range(8):
            mp.set((4 * k, 4 * k + 1), 2, 1)
    if m2 == 1 and n2 != 0:
        for k in (0, 1, 2, 3):
            mp.set((2, 3), col(k, 2), 0)
        mp.set(1, (3, x2 - 1), 0)
        mp.set(0, (x2 + 1, RIGHT), 0)
        for k in reopen_ks:
            mp.set(1, (col(k, 1), col(k, 2)), 1)
    if 2 <= m2 <= 7 and n2 != 0:
        row = 2 + (m2 - 2) * 4
        for k in (1, 2, 3):
            mp.set((row, row + 1), col(k, 1), 0)
        for k in (0, 1, 2, 3):
            mp.set((row + 4, row + 5), col(k, 2), 0)
        mp.set(row + 3, (3, x2 - 1), 0)
        mp.set(row + 2, (x2 + 1, RIGHT), 0)
        for k in reopen_ks:
            for q in (2, 3):
                mp.set(row + q, (col(k, 1), col(k, 2)), 1)
    if m2 == 8 and n2 != 0:
        for k in (1, 2, 3):
            mp.set((26, 27), col(k, 1), 0)
        mp.set(29, (3, x2 - 1), 0)
        mp.set(28, (x2 + 1, RIGHT), 0)
        for k in reopen_ks:
            mp.set(28, (col(k, 1), col(k, 2)), 1)


def _close_spans(mp: _Map, row: int) -> None:
    """map[row, 3 + k(L + 2): 3 + k(L + 2) + (L - 1)] = 0, k = 0, 1, 2: a lane along the
    shelf blocks, its junction cells left alone."""
    for k in range(BLOCKS):
        mp.set(row, (3 + k * PERIOD, 3 + k * PERIOD + L - 1), 0)


def _algorithm_3(mp: _Map, s: _Point, e: _Point, col, same_block_rule: bool) -> None:
    """Algorithms 3-1 ... 3-4, the middle area, by the end's quadrant; with `same_block_rule`
    (E5) the vertical half of 3-1 / 3-2 for a start and end in one block."""
    m1, n1, m2, n2 = s.m, s.n, e.m, e.n
    if n2 < n1 and m2 > m1:  # 3-1: top left
        last = m2 - 1 if n2 != 0 else m2
        for i in range(m1 + 1, last + 1):
            a = 4 * (i - 1)
            _close_spans(mp, a)
            for k in (1, 2, 3):
                mp.set((a - 2, a - 1), col(k, 1), 0)
    if n2 < n1 and m2 < m1:  # 3-2: bottom left
        first, ks = (m2 + 1, (1, 2, 3)) if n2 != 0 else (m2, (0, 1, 2, 3))
        for i in range(first, m1):
            a = 4 * (i - 1)
            _close_spans(mp, a)
            for k in ks:
                mp.set((a + 2, a + 3), col(k, 2), 0)
    if n2 > n1 and m2 > m1:  # 3-3: top right
        first = m1 + 1 if n1 != 0 else m1
        for i in range(first, m2):
            a = 4 * (i - 1) + 1
            _close_spans(mp, a)
            for k in (1, 2, 3):
                mp.set((a + 1, a + 2), col(k, 1), 0)
    if n2 > n1 and m2 < m1:  # 3-4: bottom right
        last = m1 - 1 if n1 != 0 else m1
        for i in range(m2 + 1, last + 1):
            a = 4 * (i - 1) + 1
            _close_spans(mp, a)
            for k in (1, 2, 3):
                mp.set((a - 3, a - 2), col(k, 2), 0)
    if same_block_rule and n1 == n2 and m1 != m2:  # E5
        if m2 > m1:
            for i in range(m1 + 1, m2):
                a = 4 * (i - 1)
                for k in (1, 2, 3):
                    mp.set((a - 2, a - 1), col(k, 1), 0)
        else:
            for i in range(m2 + 1, m1):
                a = 4 * (i - 1)
                for k in (1, 2, 3):
                    mp.set((a + 2, a + 3), col(k, 2), 0)


def literal_open_cells(layout: LaneLayout, start: Cell, end: Cell, *,
                       unpatched: bool = False,
                       errata: Iterable[str] | None = None) -> frozenset[Cell]:
    """The cells open (1) on the AGV's own map for a route from `start` to `end` (each a slot,
    packing station or pile cell of paper002-shaped layouts), after Algorithms 1, 2 and 3-x
    with errata E1-E7 applied; start and end always open (E7).

    `unpatched=True` applies the listings' raw indices (only E2, E6, E7 kept); `errata`
    names the errata to apply instead (a subset of `ERRATA`, for finding which one matters).
    """
    check_geometry(layout)
    applied = frozenset(errata) if errata is not None else (READINGS if unpatched else ERRATA)
    unknown = applied - ERRATA
    if unknown:
        raise ValueError(f"no such erratum: {', '.join(sorted(unknown))}")
    places = {p.cell for p in (*layout.slots, *layout.packing, *layout.piles)}
    for cell in (start, end):
        if cell not in places:
            raise ValueError(f"cell {cell} is no slot, packing station or pile of {layout.name}")
    if start == end:
        raise ValueError(f"start and end are both {start}")
    s, e = (_Point(c[0], c[1], *sub_area(c)) for c in (start, end))
    if s.n == 0 and e.n == 0:
        raise ValueError("the listings have no rule for a route from a packing station to one")
    period = PERIOD if "E1" in applied else L + 1

    def col(k: int, j: int) -> int:
        return k * period + j

    reopen_ks = (1, 2, 3) if "E3" in applied else (1, 2)
    mp = _Map(layout.lane_directions)  # the channels are 1, everything else 0
    _algorithm_1(mp, s, col, reopen_ks)
    _algorithm_2(mp, e, col, reopen_ks)
    _algorithm_3(mp, s, e, col, same_block_rule="E5" in applied)
    if "E4" in applied:
        for p in (s, e):
            if p.n != 0:
                low = 4 * (p.m - 1)
                mp.set((low, low + 1), p.x, 1)
    if "E7" in applied:
        mp.set(start[1], start[0], 1)
        mp.set(end[1], end[0], 1)
    return frozenset(mp.open)


def closed_lane_cells(layout: LaneLayout, start: Cell, end: Cell, **options) -> frozenset[Cell]:
    """The lane cells the dynamic map closes for this route (the algorithms' new obstacles)."""
    return frozenset(layout.lane_directions) - literal_open_cells(layout, start, end, **options)


# -- the A* of Section 4, on the literal map ---------------------------------------------------

def literal_graph(layout: LaneLayout, start: Cell, end: Cell, *, unpatched: bool = False,
                  errata: Iterable[str] | None = None, via_access: bool = True) -> LaneGraph:
    """The AGV's literal dynamic map for a route from `start` to `end` as the route search's
    graph: any of the 8 neighbours among the open cells, a diagonal only when both
    orthogonal neighbours are open (the map knows no directions).

    With `via_access` (the default) the start is left, and the end entered, only through the
    layout's access cells of that place: the seed's map has no access sides, but `paper002`
    enters a slot from its horizontal channel only (its sub-area's), a station from column
    1 and a pile from row 29. Without it a slot beside a vertical channel may be left sideways
    (or diagonally) onto it, and two slots back to back reach each other directly."""
    cells = literal_open_cells(layout, start, end, unpatched=unpatched, errata=errata)
    moves: dict[Cell, tuple[Move, ...]] = {}
    for x, y in cells:
        found = []
        for dx, dy in itertools.product((-1, 0, 1), repeat=2):
            to = (x + dx, y + dy)
            if to == (x, y) or to not in cells:
                continue
            if dx and dy:
                if (x + dx, y) in cells and (x, y + dy) in cells:
                    found.append(Move(to, DIAGONAL))
            else:
                found.append(Move(to, STRAIGHT))
        moves[(x, y)] = tuple(found)
    ways_out: dict[Cell, tuple[Move, ...]] = {}
    ways_in: dict[Cell, dict[Cell, Move]] = {}
    if via_access:
        access = {p.cell: p.access for p in (*layout.slots, *layout.packing, *layout.piles)}
        ways_out[start] = tuple(m for m in moves.get(start, ()) if m.to in access[start])
        ways_in[end] = {c: Move(end, STRAIGHT) for c in access[end] if c in cells}
        moves = {c: tuple(m for m in ms if m.to != end) for c, ms in moves.items()}
    return LaneGraph(layout.name, 1.0, moves, ways_out, ways_in)


def literal_route(layout: LaneLayout, start: Cell, end: Cell, speed: float = 1.0,
                  **options) -> Route | None:
    """The Section 4 A* (`LaneRoutes`, the lane mode's search) on the literal map from
    `start` to `end`, at `speed` cells per second; None when the map has no route (a start
    or end the map closes, too: E7 off)."""
    graph = literal_graph(layout, start, end, **options)
    if start not in graph.moves or end not in graph.moves:
        return None
    return LaneRoutes(graph, speed_mps=speed).route(start, end)


# -- sweeps, for the tests and the benchmark ------------------------------------------------------

def all_pairs(layout: LaneLayout) -> list[tuple[Cell, Cell]]:
    """Every slot <-> station, slot <-> pile and slot -> slot pair: the full sweep, 190 134
    pairs on paper002, about two minutes; the tests take samples."""
    slots = [s.cell for s in layout.slots]
    ends = [p.cell for p in (*layout.packing, *layout.piles)]
    pairs = [(s, e) for s in slots for e in ends] + [(e, s) for e in ends for s in slots]
    return pairs + [(a, b) for a in slots for b in slots if a != b]


def sample_slot_pairs(layout: LaneLayout, count: int, seed: int) -> list[tuple[Cell, Cell]]:
    """`count` distinct random slot -> slot pairs (seeded)."""
    slots = sorted(s.cell for s in layout.slots)
    rng = random.Random(seed)
    pairs: set[tuple[Cell, Cell]] = set()
    while len(pairs) < count:
        a, b = rng.sample(slots, 2)
        pairs.add((a, b))
    return sorted(pairs)
