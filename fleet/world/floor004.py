"""Seed 004's kind of floor (Yang, Zhao, Li, Cheng 2024): blocks of 2 x 5 shelf slots between
one-cell aisles, queued packing stations along the bottom, charging piles in the side walls
and a parking area at the top, generated from a few numbers (`Floor004Shape`); `paper004` is
the shape the seed pack note reconstructs (B.2.2: 100 x 50 cells, 1 920 slots, 8 stations,
20 piles).

The seed draws its map with the origin top left and y growing downwards, and states its
traffic rules in those coordinates; this module keeps them (x = column, y = row from the top)
so every rule and test reads as the seed and the note write it. `cell(x, y)` converts to the
project's cells (row counted from the bottom).

What the seed gives and what is chosen here is in ../shared/notes/seed-packs-002-004.md,
Part B; docs/agv-004.md says it for users.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

from fleet.errors import UserError
from fleet.planning.rules004 import XY, Grid004, Kind

# The six popularity classes, hottest first (B.2.1: red, orange, yellow, green, blue, black).
CLASSES = ("red", "orange", "yellow", "green", "blue", "black")
CLASS_SYMBOLS = "ROYGBK"
GOODS_PER_CLASS = 3


@dataclass(frozen=True)
class Floor004Shape:
    """The numbers a seed-004 floor is made from (the defaults are `paper004`'s)."""

    blocks_across: int = 16  # blocks of slots per double row
    double_rows: int = 12  # double rows of blocks, between horizontal aisles
    stations: int = 8
    station_pitch: int = 12  # columns from one station to the next
    piles_per_side: int = 10
    block_width: int = 5  # slots along a block
    parking_rows: int = 3  # the top area where AGVs start
    transit_rows: int = 6  # below the last aisle, down to the stations' entrance row

    def check(self) -> None:
        """A shape that cannot be built is refused, naming the number."""
        for name in ("blocks_across", "double_rows", "stations", "station_pitch",
                     "block_width"):
            if getattr(self, name) < 1:
                raise UserError(f"floor shape: {name} must be 1 or more, not "
                                f"{getattr(self, name)}")
        if self.parking_rows < 2:
            raise UserError("floor shape: parking_rows must be 2 or more (the AGVs park on the "
                            "top two rows)")
        if self.transit_rows < 2:
            raise UserError("floor shape: transit_rows must be 2 or more (an open row and the "
                            "stations' entrance row)")
        if self.piles_per_side > self.double_rows - 1 or self.piles_per_side < 0:
            raise UserError(f"floor shape: piles_per_side must be 0..{self.double_rows - 1} "
                            f"(one on each inner aisle row), not {self.piles_per_side}")
        if self.station_pitch < 3:
            raise UserError("floor shape: station_pitch must be 3 or more (a station is three "
                            "columns wide)")
        last = self.block_width + 1 + self.station_pitch * (self.stations - 1) + 2
        if last > self.width - 2:
            raise UserError(f"floor shape: {self.stations} stations {self.station_pitch} "
                            f"columns apart do not fit a floor {self.width} wide")

    @property
    def width(self) -> int:
        return 2 + (self.block_width + 1) * self.blocks_across + 2

    @property
    def aisle_rows(self) -> tuple[int, ...]:
        """The horizontal aisles' y, top to bottom (the last below the last double row)."""
        return tuple(self.parking_rows + 3 * k for k in range(self.double_rows + 1))

    @property
    def entrance_row(self) -> int:
        return self.aisle_rows[-1] + self.transit_rows

    @property
    def height(self) -> int:
        return self.entrance_row + 5  # three waiting rows, the work row, the workers' row


@dataclass(frozen=True)
class Station:
    """A queued station: planning ends at its entrance; from there a fixed U-route leads
    through the waiting cells to the work cell (the worker picks there) and out through the
    exit cells to the exit point, where the return is planned from (B.2.1, B.2.2)."""

    name: str
    entrance: XY
    waiting: tuple[XY, ...]  # in queue order
    work: XY
    worker: XY
    exits: tuple[XY, ...]  # in driving order
    exit_point: XY

    @property
    def route(self) -> tuple[XY, ...]:
        """The fixed route from the entrance to the exit point."""
        return (self.entrance, *self.waiting, self.work, *self.exits, self.exit_point)


@dataclass(frozen=True)
class Slot:
    name: str  # s-<col>-<row> in the project's cells, the id of its home shelf too
    xy: XY
    goods: str  # e.g. "red-2": the goods its shelf holds
    block: tuple[int, int]  # (j, k): block column and double row


@dataclass(frozen=True)
class Floor004:
    name: str
    shape: Floor004Shape
    kinds: dict[XY, Kind] = field(hash=False, compare=False)
    slots: tuple[Slot, ...]
    stations: tuple[Station, ...]
    piles: tuple[XY, ...]
    parking: tuple[XY, ...]  # where AGVs start, in the order they are placed (B.3)

    @property
    def width(self) -> int:
        return self.shape.width

    @property
    def height(self) -> int:
        return self.shape.height

    def kind(self, xy: XY) -> Kind:
        """A cell's static kind; outside the floor is wall."""
        return self.grid.kind(xy)

    def cell(self, xy: XY) -> tuple[int, int]:
        """The project's cell (column, row from the bottom) of a seed cell."""
        return (xy[0], self.height - 1 - xy[1])

    @cached_property
    def grid(self) -> Grid004:
        """The floor as the rules and the planner read it: the vertical aisles with the
        approach columns beside the piles (the note's A = {1, 7, 13, ..., 97, 98})."""
        s = self.shape
        inner = [1 + (s.block_width + 1) * (j + 1) for j in range(s.blocks_across)]
        return Grid004(self.width, self.height, self.kinds,
                       tuple(sorted({1, *inner, self.width - 2})), s.aisle_rows)

    @cached_property
    def goods(self) -> dict[str, tuple[Slot, ...]]:
        """Every goods with the slots whose shelves hold it."""
        out: dict[str, list[Slot]] = {}
        for slot in self.slots:
            out.setdefault(slot.goods, []).append(slot)
        return {g: tuple(s) for g, s in out.items()}

    def drawing(self) -> str:
        """The floor as the note draws it (B.2.2), top row first: C pile, # wall, R O Y G B K
        slots of each class, . floor, E entrance, q waiting, w work, x exit, X exit point,
        W station structure and worker."""
        grid = [["#" if self.kind((x, y)) is Kind.WALL else "." for x in range(self.width)]
                for y in range(self.height)]
        for slot in self.slots:
            grid[slot.xy[1]][slot.xy[0]] = CLASS_SYMBOLS[CLASSES.index(slot.goods.split("-")[0])]
        for x, y in self.piles:
            grid[y][x] = "C"
        for s in self.stations:
            marks = [(s.entrance, "E"), (s.work, "w"), (s.exit_point, "X")]
            marks += [(c, "q") for c in s.waiting] + [(c, "x") for c in s.exits]
            for (x, y), mark in marks:
                grid[y][x] = mark
        for (x, y), kind in self.kinds.items():
            if kind is Kind.STRUCTURE:
                grid[y][x] = "W"
        return "\n".join("".join(row) for row in grid)


def class_of(k: int, double_rows: int) -> int:
    """The popularity class (0 hottest) of double row k: the rows nearest the stations (the
    largest k) hold the hottest goods, six bands of equal depth (B.2.2, DERIVED)."""
    return (double_rows - 1 - k) * len(CLASSES) // double_rows


def build(shape: Floor004Shape = Floor004Shape(), name: str = "generated004") -> Floor004:
    """The floor of this shape: every cell's kind, the slots with their goods, the stations,
    piles and parking places."""
    shape.check()
    width, height = shape.width, shape.height
    kinds: dict[XY, Kind] = {}
    for y in range(shape.entrance_row + 1):  # walls left and right, floor between
        for x in range(width):
            kinds[(x, y)] = Kind.FLOOR if 0 < x < width - 1 else Kind.WALL
    slots = []
    for k in range(shape.double_rows):
        for j in range(shape.blocks_across):
            colour = CLASSES[class_of(k, shape.double_rows)]
            goods = f"{colour}-{(j + k) % GOODS_PER_CLASS}"
            for dy in (1, 2):
                for dx in range(shape.block_width):
                    xy = (2 + (shape.block_width + 1) * j + dx, shape.aisle_rows[k] + dy)
                    kinds[xy] = Kind.SLOT
                    slots.append(Slot(f"s-{xy[0]}-{height - 1 - xy[1]}", xy, goods, (j, k)))
    piles = []
    for k in range(1, shape.piles_per_side + 1):
        for x in (0, width - 1):
            xy = (x, shape.aisle_rows[k])
            kinds[xy] = Kind.FLOOR
            piles.append(xy)
    stations = []
    e = shape.entrance_row
    for s in range(shape.stations):
        c = shape.block_width + 1 + shape.station_pitch * s
        station = Station(f"station-{s + 1}", (c, e), ((c, e + 1), (c, e + 2), (c, e + 3)),
                          (c + 1, e + 3), (c + 1, e + 4),
                          ((c + 2, e + 3), (c + 2, e + 2), (c + 2, e + 1)), (c + 2, e))
        for xy in (*station.waiting, station.work, *station.exits):
            kinds[xy] = Kind.LANE
        for xy in ((c + 1, e + 1), (c + 1, e + 2), station.worker):
            kinds[xy] = Kind.STRUCTURE
        stations.append(station)
    parking = [(x, 1) for x in range(2, width - 3, 2)] + \
        [(x, 0) for x in range(2, width - 3, 2)]
    slots.sort(key=lambda s: (s.xy[1], s.xy[0]))
    return Floor004(name, shape, kinds, tuple(slots), tuple(stations), tuple(sorted(piles)),
                    tuple(parking))


def paper004() -> Floor004:
    """Seed 004's warehouse as the note reconstructs it (B.2.2)."""
    return build(Floor004Shape(), "paper004")
