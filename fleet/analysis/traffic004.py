"""Seed 004's traffic rules checked on what AGVs did (B-RUL-1, B-RUL-2, B-SAF-2), written from
the seed pack note's Table 3 reconstruction (B.4.1) and sharing nothing with the planner or
its rule module: the directions allowed out of each cell are derived here again.

- Empty AGVs (M1 fetch, M4 charge) keep the row rule and the column rule everywhere; loaded
  ones (M2 deliver, M3 return) keep them in the aisles and open areas, and are free across an
  aisle inside the shelf area; their own slot is left and entered in any direction.
- Pile columns are only left, outward; going to charge, the columns beside the piles run
  toward them.
- A loaded AGV enters no slot but its own shelf's home; only a delivering AGV drives a
  station's lane, and only along its fixed route; nobody drives into a wall or a station's
  structure.
- Moves made in relaxed mode (logged as such) are exempt from the directions, and only an
  empty AGV may make them.
- In a head-on conflict between an empty and a loaded AGV, the empty one replans.

Coordinates are the seed's: x to the right, y down; rows 0 up to the first aisle are the open
area at the top, the last aisle down to the stations the one at the bottom.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass

Cell = tuple[int, int]
UP, LEFT, DOWN, RIGHT = 1, 2, 3, 4  # the seed's direction code
LOADED_TASKS = ("M2", "M3")


@dataclass(frozen=True)
class Floor:
    """What the rules read of a floor."""

    width: int
    aisle_columns: tuple[int, ...]  # vertical aisles, with the columns beside the piles
    aisle_rows: tuple[int, ...]  # horizontal aisles, top to bottom
    slots: frozenset[Cell]
    lanes: frozenset[Cell]  # stations' waiting, work and exit cells
    drivable: frozenset[Cell]  # floor, slots and lanes: not walls nor station structure
    route_steps: frozenset[tuple[Cell, Cell]]  # each station's fixed route, step by step


@dataclass(frozen=True)
class Drive:
    """One move as it was made."""

    vehicle: int
    t: float
    origin: Cell
    to: Cell
    task: str  # M1..M4
    loaded: bool
    relaxed: bool
    home: Cell | None  # a loaded AGV's shelf's home (where it lifted it)


@dataclass(frozen=True)
class Breach:
    vehicle: int
    t: float
    what: str


STEPS = {(0, -1): UP, (-1, 0): LEFT, (0, 1): DOWN, (1, 0): RIGHT}


def code(origin: Cell, to: Cell) -> int | None:
    """The direction code of a one-cell move (None: not one)."""
    return STEPS.get((to[0] - origin[0], to[1] - origin[1]))


def directions(floor: Floor, task: str, cell: Cell, home: Cell | None) -> frozenset[int]:
    """D_M(x, y) of the note's Table 3."""
    x, y = cell
    if x == 0:
        return frozenset({RIGHT})
    if x == floor.width - 1:
        return frozenset({LEFT})
    row = RIGHT if y % 2 == 0 else LEFT
    if x in floor.aisle_columns:
        column = UP if floor.aisle_columns.index(x) % 2 == 0 else DOWN
    else:
        column = UP if x % 2 == 0 else DOWN
    if task == "M4" and x == 1:
        row = LEFT
    elif task == "M4" and x == floor.width - 2:
        row = RIGHT
    if task not in LOADED_TASKS:
        return frozenset({row, column})
    if cell == home:
        return frozenset({UP, LEFT, DOWN, RIGHT})
    shelf_area = floor.aisle_rows[0] <= y <= floor.aisle_rows[-1]
    across_row, across_column = y in floor.aisle_rows, x in floor.aisle_columns
    if not shelf_area or (across_row and across_column):
        return frozenset({row, column})
    if across_row:
        return frozenset({row, UP, DOWN})
    if across_column:
        return frozenset({column, LEFT, RIGHT})
    return frozenset({row, column})


def breaches(floor: Floor, drives: Iterable[Drive]) -> list[Breach]:
    """Every move against the rules, the slots or the lanes."""
    out = []
    for d in drives:
        if d.relaxed and d.loaded:
            out.append(Breach(d.vehicle, d.t, f"{d.origin} -> {d.to} relaxed while loaded"))
        if d.loaded and d.to in floor.slots and d.to != d.home:
            out.append(Breach(d.vehicle, d.t, f"loaded into slot {d.to}, not its shelf's "
                                              f"home {d.home}"))
        if d.to not in floor.drivable:
            out.append(Breach(d.vehicle, d.t, f"{d.origin} -> {d.to}: not a cell to drive on"))
        if d.to in floor.lanes and not (d.loaded and d.task == "M2"):
            out.append(Breach(d.vehicle, d.t, f"into station lane {d.to} on {d.task}"))
        if (d.origin in floor.lanes or d.to in floor.lanes) and \
                (d.origin, d.to) not in floor.route_steps:
            out.append(Breach(d.vehicle, d.t, f"{d.origin} -> {d.to} is not along a "
                                              f"station's route"))
        if code(d.origin, d.to) is None:
            out.append(Breach(d.vehicle, d.t, f"{d.origin} -> {d.to} is not one cell"))
            continue
        if d.origin in floor.lanes or d.to in floor.lanes or d.relaxed:
            continue  # a station's fixed route; relaxed: no directions
        if code(d.origin, d.to) not in directions(floor, d.task, d.origin, d.home):
            out.append(Breach(d.vehicle, d.t, f"{d.origin} -> {d.to} on {d.task} against "
                                              f"the rules there"))
    return out


def loaded_at(loads: Mapping[int, list[tuple[float, bool]]], v: int, t: float) -> bool:
    """Whether AGV v carried a shelf at t, from its loads over time ((t, loaded) from then
    on, in time order)."""
    state = False
    for since, value in loads.get(v, []):
        if since > t:
            break
        state = value
    return state


def yielding_breaches(head_ons: Iterable[tuple[float, int, int]],
                      replans: Iterable[tuple[float, int]],
                      loads: Mapping[int, list[tuple[float, bool]]]) -> list[Breach]:
    """Replans to give way (t, vehicle) made by a loaded AGV for an empty one: each is
    matched with the vehicle's last head-on meeting (t, vehicle, other) at or before it."""
    met: dict[int, list[tuple[float, int]]] = {}
    for t, v, other in sorted(head_ons):
        met.setdefault(v, []).append((t, other))
    out = []
    for t, v in replans:
        before = [other for since, other in met.get(v, []) if since <= t]
        if before and loaded_at(loads, v, t) and not loaded_at(loads, before[-1], t):
            out.append(Breach(v, t, f"loaded, gave way to empty AGV {before[-1]}"))
    return out
