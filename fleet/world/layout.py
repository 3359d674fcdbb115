"""Warehouse layouts as data: the map, its clusters of stacks in fill order, stations,
obstacles, passages, the vehicle and its start poses, as frozen dataclasses; or, for a lane
layout (seed 002), its directed lanes, junctions, shelf slots, packing stations and piles.

A layout comes from a TOML file (docs/layouts.md), read and checked by
`fleet.world.layout_file`; whether every stack can be reached in fill order is a search on
the pose graph and lives in `fleet.world.reachability`.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from functools import cached_property

from fleet.errors import UserError
from fleet.params import VehicleDims
from fleet.planning.geometry import Cell
from fleet.planning.gridmap import GridMap
from fleet.planning.trajectory import Pose
from fleet.vehicles import registry
from fleet.vehicles.kind import VehicleKind
from fleet.world.floor004 import Floor004

# The drawing's symbols (docs/layouts.md): clusters and obstacles bring their own.
FREE, PASSAGE, NOTCH, STATION = ".", ":", "n", "P"
SLOT, PILE, ACCESS = "S", "C", "a"  # a lane layout's; its packing stations are drawn P

# Directions on the grid: x grows east with the column, y north with the row.
DIRECTIONS: dict[str, Cell] = {"E": (1, 0), "N": (0, 1), "W": (-1, 0), "S": (0, -1)}
LANE_SYMBOLS = {"E": ">", "N": "^", "W": "<", "S": "v"}
JUNCTION_SYMBOLS = {"crossroad": "X", "t": "T", "corner": "L"}


class LayoutError(UserError):
    """A layout file that cannot be used; the message names the element and why."""


@dataclass(frozen=True)
class Stack:
    cluster: str
    index: int  # 1-based position in the cluster's fill order
    cell: Cell


@dataclass(frozen=True)
class Cluster:
    name: str
    symbol: str
    notches: frozenset[Cell]  # cells kept free inside the cluster so forklifts can turn


@dataclass(frozen=True)
class Station:
    name: str
    cell: Cell
    dock: Pose  # the picking pose, working the station


@dataclass(frozen=True)
class Obstacle:
    name: str
    kind: str  # "firewall", "wall", "pillar", ...
    cells: frozenset[Cell]
    symbol: str = "#"


@dataclass(frozen=True)
class Passage:
    name: str
    kind: str  # "wide" (seed 000) or "channel" (seed 002: bidirectional, keep right)
    cells: frozenset[Cell]


@dataclass(frozen=True)
class Lane:
    """A one-way lane: a straight run of cells driven in one direction."""

    name: str
    direction: str  # E, N, W or S
    cells: tuple[Cell, ...]  # in driving order


@dataclass(frozen=True)
class Junction:
    """Cells where a horizontal and a vertical lane cross: the only cells where a vehicle
    turns. Derived from the lanes; its kind from how many sides lanes lead on to."""

    name: str  # j-<col>-<row> of its first cell, bottom row first
    kind: str  # "crossroad" (four sides), "t" (three) or "corner" (two, at right angles)
    cells: frozenset[Cell]


@dataclass(frozen=True)
class Slot:
    """A shelf's home: it holds the shelf of its own name when the mission starts."""

    name: str  # s-<col>-<row>, which is also the id of the shelf whose home it is
    area: str
    cell: Cell
    access: tuple[Cell, ...]  # the neighbouring lane or access cells it is entered from


@dataclass(frozen=True)
class ShelfArea:
    name: str
    sides: tuple[str, ...]  # the sides (from a slot) its slots are entered from


@dataclass(frozen=True)
class PackingStation:
    name: str
    cell: Cell  # the vehicle drives onto it with the shelf and stands `dwell` seconds
    dwell: float
    access: tuple[Cell, ...]


@dataclass(frozen=True)
class Pile:
    """A charging pile: one vehicle at a time stands on its cell to charge."""

    name: str
    cell: Cell
    access: tuple[Cell, ...]


@dataclass(frozen=True)
class VehicleSpec:
    kind: str = "forklift"  # a name in fleet.vehicles.registry
    dims: VehicleDims = field(default_factory=VehicleDims)
    passes_under_shelves: bool = False  # seed 004: lifting AGVs drive under shelves when empty


@dataclass(frozen=True)
class Layout:
    name: str
    description: str
    cols: int
    rows: int
    cell_size: float
    origin: tuple[float, float]  # world position (metres) of the centre of cell (0, 0)
    clusters: tuple[Cluster, ...]
    stacks: tuple[Stack, ...]
    stations: tuple[Station, ...]
    obstacles: tuple[Obstacle, ...]
    passages: tuple[Passage, ...]
    vehicle: VehicleSpec
    vehicle_starts: tuple[Pose, ...]
    drawing: str
    # A lane layout's elements (docs/layouts.md); a forklift layout has none of them.
    lanes: tuple[Lane, ...] = ()
    junctions: tuple[Junction, ...] = ()
    shelf_areas: tuple[ShelfArea, ...] = ()
    slots: tuple[Slot, ...] = ()
    packing: tuple[PackingStation, ...] = ()
    piles: tuple[Pile, ...] = ()
    access_cells: frozenset[Cell] = frozenset()  # crossed straight, element to lane only
    # A seed-004 floor (docs/layouts.md, "Seed 004 floors"): generated, with its own cells.
    floor: Floor004 | None = None

    @property
    def has_lanes(self) -> bool:
        return bool(self.lanes)

    @cached_property
    def lane_directions(self) -> dict[Cell, frozenset[str]]:
        """Each lane cell's directions: its lane's, and at a junction the crossing lane's."""
        found: dict[Cell, set[str]] = {}
        for lane in self.lanes:
            for cell in lane.cells:
                found.setdefault(cell, set()).add(lane.direction)
        return {cell: frozenset(d) for cell, d in found.items()}

    @cached_property
    def shelves(self) -> dict[str, Slot]:
        """Every shelf by id, with its home slot: one shelf per slot, named after it."""
        return {slot.name: slot for slot in self.slots}

    @cached_property
    def vehicle_kind(self) -> VehicleKind:
        """The kind of vehicle the layout is for: its motion, planner and conflict policy."""
        return registry.vehicle_kind(self.vehicle.kind, self.vehicle.dims, self.cell_size)

    @cached_property
    def static_blocked(self) -> frozenset[Cell]:
        """Cells no vehicle may ever enter: obstacles and stations."""
        cells = {c for o in self.obstacles for c in o.cells}
        return frozenset(cells | {s.cell for s in self.stations})

    def grid_map(self, filled: Iterable[Cell] = (), under_shelves: bool = False) -> GridMap:
        """The drivable grid with the given stacks filled; a vehicle that passes under shelves
        (and carries nothing) drives through filled stacks."""
        blocked = self.static_blocked if under_shelves else self.static_blocked | set(filled)
        return GridMap(self.cols, self.rows, frozenset(blocked), self.cell_size)

    def cluster(self, name: str) -> Cluster:
        for cluster in self.clusters:
            if cluster.name == name:
                return cluster
        names = ", ".join(c.name for c in self.clusters)
        raise UserError(f"layout {self.name} has no cluster {name!r} (it has {names})")

    def cluster_stacks(self, name: str) -> tuple[Stack, ...]:
        """The stacks of a cluster in fill order."""
        return tuple(s for s in self.stacks if s.cluster == name)

    def station(self, name: str) -> Station:
        for station in self.stations:
            if station.name == name:
                return station
        raise UserError(f"layout {self.name} has no station {name!r}")

    def cell_center(self, cell: Cell) -> tuple[float, float]:
        return (self.origin[0] + cell[0] * self.cell_size,
                self.origin[1] + cell[1] * self.cell_size)

    def unload_poses(self, cell: Cell, filled: Iterable[Cell] = ()) -> list[Pose]:
        """The vehicle kind's poses that work `cell` with the whole body on free cells."""
        grid = self.grid_map(filled)
        kind = self.vehicle_kind
        return [pose for pose in kind.handling_poses(cell)
                if grid.all_free(kind.body_cells_at_rest(pose))]

    def render_drawing(self) -> str:
        """The ASCII drawing the data implies, top row first (docs/layouts.md has the legend)."""
        if self.floor is not None:
            return self.floor.drawing()
        grid = [[FREE] * self.cols for _ in range(self.rows)]
        for cell, symbol in self._symbols():
            grid[cell[1]][cell[0]] = symbol
        return "\n".join("".join(grid[r]) for r in reversed(range(self.rows)))

    def _symbols(self) -> Iterator[tuple[Cell, str]]:
        for passage in self.passages:
            for cell in passage.cells:
                yield cell, PASSAGE
        for cluster in self.clusters:
            for cell in cluster.notches:
                yield cell, NOTCH
        symbol_of = {c.name: c.symbol for c in self.clusters}
        for stack in self.stacks:
            yield stack.cell, symbol_of[stack.cluster]
        for obstacle in self.obstacles:
            for cell in obstacle.cells:
                yield cell, obstacle.symbol
        for station in self.stations:
            yield station.cell, STATION
        for lane in self.lanes:
            for cell in lane.cells:
                yield cell, LANE_SYMBOLS[lane.direction]
        for junction in self.junctions:
            for cell in junction.cells:
                yield cell, JUNCTION_SYMBOLS[junction.kind]
        for cell in self.access_cells:
            yield cell, ACCESS
        for slot in self.slots:
            yield slot.cell, SLOT
        for packing in self.packing:
            yield packing.cell, STATION
        for pile in self.piles:
            yield pile.cell, PILE
