"""Seed 004's traffic: the direction code, the task types, the traffic rule table D_M(x, y),
the multi-valued grid and the expansion filters (3) and (4) of its improved A* (seed pack note
B.2.3, B.4.1, B.4.2), as pure functions of a `Grid004` in the seed's coordinates (y down):
what the rules read of a floor (fleet/world/floor004.py makes one).

The grid value of a cell is not stored: it is the static kind of the cell with what stands or
moves on it (`value`), so whoever holds the occupancy (the reservation store, the vehicles'
states) gives the grid the seed's planner and tracker read.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping
from dataclasses import dataclass, field
from enum import Enum, IntEnum
from functools import cached_property

XY = tuple[int, int]  # (x, y) with y growing downwards, as the seed writes cells


class Kind(Enum):
    """A cell's static kind: with its occupancy it gives the seed's grid value."""

    FLOOR = "floor"  # aisles, parking, transit, piles, station entrances and exit points
    SLOT = "slot"  # a shelf's home: stays a slot while its shelf is away (assumption 5)
    LANE = "lane"  # a station's waiting, work and exit cells: its fixed route only
    STRUCTURE = "structure"  # a station's body and its worker: never entered
    WALL = "wall"


@dataclass(frozen=True)
class Grid004:
    """What the rules and the planner read of a floor: each cell's static kind, and where
    its aisles run."""

    width: int
    height: int
    kinds: Mapping[XY, Kind] = field(hash=False, compare=False)
    aisle_columns: tuple[int, ...]  # vertical aisles and the columns beside the piles
    aisle_rows: tuple[int, ...]  # horizontal aisles, top to bottom

    def kind(self, xy: XY) -> Kind:
        """A cell's static kind; outside the floor is wall."""
        return self.kinds.get(xy, Kind.WALL)

    @cached_property
    def shelf_rows(self) -> range:
        """The rows of the shelf area, from the first aisle to the last (B.4.1)."""
        return range(self.aisle_rows[0], self.aisle_rows[-1] + 1)


class Direction(IntEnum):
    """The seed's direction code: "上、左、下、右分别为1,2,3,4" (up, left, down, right)."""

    UP = 1
    LEFT = 2
    DOWN = 3
    RIGHT = 4


STEP: dict[Direction, XY] = {Direction.UP: (0, -1), Direction.LEFT: (-1, 0),
                             Direction.DOWN: (0, 1), Direction.RIGHT: (1, 0)}
ALL = frozenset(Direction)


def perpendicular(a: Direction, b: Direction) -> bool:
    """Whether going from a to b is a quarter turn (a reversal is none: the AGV drives back)."""
    return (a in (Direction.UP, Direction.DOWN)) != (b in (Direction.UP, Direction.DOWN))


def direction_code(dx: int, dy: int) -> int:
    """Equation (3)'s code of a move (dx, dy) with y down: dx + 3|dx| + dy + 2|dy|, which is
    4, 2, 3, 1 for right, left, down, up (note B.4.2, decoded)."""
    return dx + 3 * abs(dx) + dy + 2 * abs(dy)


class Task(Enum):
    """The task types M1-M4 (Section 1.2)."""

    FETCH = "M1"  # to the shelf, empty
    DELIVER = "M2"  # the shelf to a station's entrance, loaded
    RETURN = "M3"  # the shelf home, loaded
    CHARGE = "M4"  # to a pile, empty

    @property
    def loaded(self) -> bool:
        return self in (Task.DELIVER, Task.RETURN)


class Occupancy(Enum):
    FREE = "free"
    MOVING = "moving"  # a moving AGV holds the cell (the one it leaves or enters)
    STAGNANT = "stagnant"  # an AGV has stood there longer than the stagnation time


# Table 2 as the note reconstructs it (B.2.3): (static kind, occupancy) -> value.
WALL_VALUE = 9  # not in the seed: the pack's own value for what is no floor
_VALUES = {
    (Kind.FLOOR, Occupancy.FREE): 0, (Kind.FLOOR, Occupancy.MOVING): 1,
    (Kind.FLOOR, Occupancy.STAGNANT): 5,
    (Kind.SLOT, Occupancy.FREE): 3, (Kind.SLOT, Occupancy.MOVING): 4,
    (Kind.SLOT, Occupancy.STAGNANT): 6,
    (Kind.LANE, Occupancy.FREE): 7, (Kind.LANE, Occupancy.MOVING): 8,
    (Kind.LANE, Occupancy.STAGNANT): 8,  # no stagnation inside a station
    (Kind.STRUCTURE, Occupancy.FREE): 2,
}
EMPTY_PLANNING = frozenset({0, 1, 3, 4})  # filter (3): M1, M4
LOADED_PLANNING = frozenset({0, 1, 5})  # filter (4): M2, M3
ENTERABLE = frozenset({0, 3, 7})  # tracking may enter the next cell (Section 2)


def value(kind: Kind, occupancy: Occupancy = Occupancy.FREE) -> int:
    """A cell's grid value from its static kind and what is on it."""
    return _VALUES.get((kind, occupancy), WALL_VALUE)


def plannable(task: Task, v: int) -> bool:
    """Whether the A* may expand into a cell of value v for this task (filters (3), (4))."""
    return v in planning_filter(task)


def planning_filter(task: Task) -> frozenset[int]:
    """The values filter (3) or (4) lets the A* expand into for this task."""
    return LOADED_PLANNING if task.loaded else EMPTY_PLANNING


def row_rule(y: int) -> Direction:
    """R_yr: even rows run right, odd rows left, so adjacent aisles (3 apart) alternate."""
    return Direction.RIGHT if y % 2 == 0 else Direction.LEFT


def column_rule(grid: Grid004, x: int) -> Direction:
    """R_xc: the aisle columns alternate up and down by their number from the left; every
    other column by the parity of x."""
    aisles = grid.aisle_columns
    if x in aisles:
        return Direction.UP if aisles.index(x) % 2 == 0 else Direction.DOWN
    return Direction.UP if x % 2 == 0 else Direction.DOWN


def allowed(grid: Grid004, task: Task, xy: XY, home: XY | None = None) -> frozenset[Direction]:
    """D_M(x, y): the directions an AGV on this task may leave `xy` in (Table 3 as the note
    reconstructs it, B.4.1). `home`: a loaded AGV's own slot, which it leaves or enters in
    any direction."""
    if at_home(grid, task, xy, home):
        return ALL
    return rules_for(grid, task)[xy]


def at_home(grid: Grid004, task: Task, xy: XY, home: XY | None) -> bool:
    """Whether `xy` is the loaded AGV's own slot, left and entered in any direction."""
    return home is not None and xy == home and task.loaded and 0 < xy[0] < grid.width - 1


class _Rules(dict[XY, frozenset[Direction]]):
    """One task's D_M on one grid, each cell's worked out when first asked."""

    def __init__(self, grid: Grid004, task: Task) -> None:
        super().__init__()
        self.grid, self.task = grid, task

    def __missing__(self, xy: XY) -> frozenset[Direction]:
        rules = self[xy] = _allowed(self.grid, self.task, xy)
        return rules


@functools.cache
def rules_for(grid: Grid004, task: Task) -> Mapping[XY, frozenset[Direction]]:
    """`allowed` of every cell but a loaded AGV's own slot (`at_home`), kept: the planner
    asks it of every cell it expands. It reads the grid's size and aisles only, which the
    grid's hash and equality are made of."""
    return _Rules(grid, task)


def _allowed(grid: Grid004, task: Task, xy: XY) -> frozenset[Direction]:
    x, y = xy
    if x == 0:
        return frozenset({Direction.RIGHT})  # a pile column is only ever left, outward
    if x == grid.width - 1:
        return frozenset({Direction.LEFT})
    horizontal, vertical = row_rule(y), column_rule(grid, x)
    if task is Task.CHARGE and x in (1, grid.width - 2):
        horizontal = Direction.LEFT if x == 1 else Direction.RIGHT  # toward the piles
    if not task.loaded:
        return frozenset({horizontal, vertical})
    in_aisle_row = y in grid.aisle_rows
    in_aisle_column = x in grid.aisle_columns
    if y not in grid.shelf_rows or (in_aisle_row and in_aisle_column):
        return frozenset({horizontal, vertical})  # open areas and aisle crossings
    if in_aisle_row:  # free across the aisle, into and out of the slots beside it
        return frozenset({horizontal, Direction.UP, Direction.DOWN})
    if in_aisle_column:
        return frozenset({vertical, Direction.LEFT, Direction.RIGHT})
    return frozenset({horizontal, vertical})  # under a shelf: only its own slot is entered
