"""The lane-layout part of the layout loader (docs/layouts.md, "Lane layouts"): directed
lanes, the junctions they make, shelf areas of slots, packing stations, charging piles and
access cells, read and checked into a Layout.

A mixin of `layout_file._Builder`: it uses the builder's `fail`, `keys`, `get`, `cells`,
`claim`, `element` and `owner`, so errors read the same as the rest of the loader's.
"""

from __future__ import annotations

import dataclasses

from fleet.planning.geometry import Cell
from fleet.vehicles import registry
from fleet.world.lanes import step
from fleet.world.layout import (
    DIRECTIONS,
    Junction,
    Lane,
    Layout,
    PackingStation,
    Pile,
    ShelfArea,
    Slot,
)

LANE_TABLES = ("lane", "shelf_area", "packing", "pile", "access")
NOT_IN_LANE_LAYOUTS = ("cluster", "station", "passage", "starts")
DEFAULT_DWELL_S = 10.0  # seed 002: "The residence time of AGVs in the packing area ... 10 s"
KIND_BY_ARMS = {4: "crossroad", 3: "t"}


class LaneParts:
    """Reads a lane layout's elements; `lane_layout` returns the layout with them."""

    owner: dict[Cell, str]

    def is_lane_layout(self) -> bool:
        return any(key in self.data for key in LANE_TABLES)

    def lane_layout(self, base: Layout) -> Layout:
        data = self.data
        self.sides: dict[str, tuple[str, ...]] = {}  # access sides by element or area name
        if "lane" not in data:
            key = next(k for k in LANE_TABLES if k in data)
            raise self.fail(f"{key}: shelf areas, packing stations, piles and access cells "
                            f"belong to a lane layout, which has lanes ([[lane]])")
        for key in NOT_IN_LANE_LAYOUTS:
            if key in data:
                raise self.fail(f"{key}: a lane layout has shelf areas, packing stations and "
                                f"piles, not clusters, stations, passages or start poses "
                                f"(a forklift layout's)")
        if base.vehicle.kind not in registry.DRIVES_LANES:
            raise self.fail(f"vehicle: kind {base.vehicle.kind!r} does not drive lanes; a "
                            f"lane layout names one that does: "
                            f"{', '.join(sorted(registry.DRIVES_LANES))}")
        packing = [self.packing_station(t, i) for i, t in enumerate(self.tables("packing"))]
        piles = [self.pile(t, i) for i, t in enumerate(self.tables("pile"))]
        areas, slots = [], []
        for i, table in enumerate(self.tables("shelf_area")):
            area, area_slots = self.shelf_area(table, i)
            areas.append(area)
            slots.extend(area_slots)
        access_names, access = [], set()
        for i, table in enumerate(self.tables("access")):
            name, cells = self.access_way(table, i)
            access_names.append(name)
            access |= cells
        lanes: list[Lane] = []
        for i, table in enumerate(self.tables("lane")):
            lanes.append(self.lane(table, i, lanes))
        self.unique_names(base.obstacles, lanes, areas, packing, piles, slots,
                          [_Named(n) for n in access_names])
        channel = {c for lane in lanes for c in lane.cells}
        junctions = self.junctions(lanes, channel)
        sides = self.sides
        placed = [dataclasses.replace(p, access=self.access_of(f"station {p.name}", p.cell,
                                                               sides[p.name], channel, access))
                  for p in packing]
        piled = [dataclasses.replace(p, access=self.access_of(f"pile {p.name}", p.cell,
                                                             sides[p.name], channel, access))
                 for p in piles]
        slotted = [dataclasses.replace(s, access=self.access_of(f"slot {s.name}", s.cell,
                                                               sides[s.area], channel, access))
                   for s in slots]
        used = {c for p in [*placed, *piled, *slotted] for c in p.access}
        for cell in sorted(access - used, key=lambda c: (c[1], c[0])):
            raise self.fail(f"{self.owner[cell]}: cell {cell} serves no slot, station or pile "
                            f"(an access cell lies between one and a lane)")
        return dataclasses.replace(
            base, lanes=tuple(lanes), junctions=tuple(junctions), shelf_areas=tuple(areas),
            slots=tuple(slotted), packing=tuple(placed), piles=tuple(piled),
            access_cells=frozenset(access))

    # -- the elements --------------------------------------------------------------------------
    def one_cell(self, table: dict, element: str) -> Cell:
        cells = self.cells(self.get(table, "cell", str, element), element)
        if len(cells) != 1:
            raise self.fail(f"{element}: cell must be one cell")
        return cells[0]

    def access_sides(self, table: dict, element: str) -> tuple[str, ...]:
        sides = table.get("access", list(DIRECTIONS))
        if isinstance(sides, str):
            sides = [sides]
        if (not isinstance(sides, list) or not sides
                or not all(isinstance(s, str) and s in DIRECTIONS for s in sides)):
            raise self.fail(f"{element}: access must list sides among E, N, W, S (the sides "
                            f"it is entered from), not {sides!r}")
        return tuple(dict.fromkeys(sides))

    def packing_station(self, table: dict, i: int) -> PackingStation:
        element = self.element(table, "packing", i)
        self.keys(table, {"name", "cell", "dwell", "access"}, element)
        name = self.get(table, "name", str, element)
        element = f"station {name}"
        cell = self.one_cell(table, element)
        dwell = self.get(table, "dwell", float, element, DEFAULT_DWELL_S)
        if dwell < 0:
            raise self.fail(f"{element}: dwell must be seconds, zero or more, not {dwell:g}")
        self.sides[name] = self.access_sides(table, element)
        self.claim([cell], element)
        return PackingStation(name, cell, dwell, ())

    def pile(self, table: dict, i: int) -> Pile:
        element = self.element(table, "pile", i)
        self.keys(table, {"name", "cell", "access"}, element)
        name = self.get(table, "name", str, element)
        element = f"pile {name}"
        cell = self.one_cell(table, element)
        self.sides[name] = self.access_sides(table, element)
        self.claim([cell], element)
        return Pile(name, cell, ())

    def shelf_area(self, table: dict, i: int) -> tuple[ShelfArea, list[Slot]]:
        element = self.element(table, "shelf_area", i)
        self.keys(table, {"name", "cells", "access"}, element)
        name = self.get(table, "name", str, element)
        element = f"shelf area {name}"
        sides = self.access_sides(table, element)
        self.sides[name] = sides
        cells = self.cells(table.get("cells", []), element)
        if not cells:
            raise self.fail(f"{element}: has no cells")
        slots = []
        for cell in cells:
            slot = f"s-{cell[0]}-{cell[1]}"
            self.claim([cell], f"slot {slot}")
            slots.append(Slot(slot, name, cell, ()))
        return ShelfArea(name, sides), slots

    def access_way(self, table: dict, i: int) -> tuple[str, set[Cell]]:
        element = self.element(table, "access", i)
        self.keys(table, {"name", "cells"}, element)
        name = self.get(table, "name", str, element)
        element = f"access {name}"
        cells = self.cells(table.get("cells", []), element)
        if not cells:
            raise self.fail(f"{element}: has no cells")
        self.claim(cells, element)
        return name, set(cells)

    def lane(self, table: dict, i: int, before: list[Lane]) -> Lane:
        element = self.element(table, "lane", i)
        self.keys(table, {"name", "direction", "cells"}, element)
        name = self.get(table, "name", str, element)
        element = f"lane {name}"
        direction = self.get(table, "direction", str, element)
        if direction not in DIRECTIONS:
            raise self.fail(f"{element}: direction {direction!r} is not one of E, N, W, S")
        cells = self.cells(table.get("cells", []), element)
        if not cells:
            raise self.fail(f"{element}: has no cells")
        axis = 1 if direction in "EW" else 0  # a row runs east-west, a column north-south
        if len({c[axis] for c in cells}) > 1:
            line = "row" if axis else "column"
            raise self.fail(f"{element}: runs {direction}, so its cells must lie in one "
                            f"{line}")
        if len(set(cells)) != len(cells):
            raise self.fail(f"{element}: lists a cell twice")
        dx, dy = DIRECTIONS[direction]
        cells.sort(key=lambda c: c[0] * dx + c[1] * dy)
        for cell in cells:
            for other in before:
                if (other.direction in "EW") == (direction in "EW") and cell in other.cells:
                    raise self.fail(f"{element} overlaps lane {other.name} at cell {cell}")
            owner = self.owner.get(cell)
            if owner is not None and not owner.startswith("lane "):
                raise self.fail(f"{element} overlaps {owner} at cell {cell}")
            self.owner.setdefault(cell, element)
        return Lane(name, direction, tuple(cells))

    def junctions(self, lanes: list[Lane], channel: set[Cell]) -> list[Junction]:
        """The blocks of cells where a horizontal and a vertical lane cross, each with the
        kind its sides make: lanes leading on to four sides, a crossroad; three, a T; two at
        right angles, a corner."""
        across = {c for lane in lanes if lane.direction in "EW" for c in lane.cells}
        crossing = across & {c for lane in lanes if lane.direction in "NS" for c in lane.cells}
        found, seen = [], set()
        for first in sorted(crossing, key=lambda c: (c[1], c[0])):
            if first in seen:
                continue
            block, todo = {first}, [first]
            while todo:
                cell = todo.pop()
                for d in DIRECTIONS:
                    n = step(cell, d)
                    if n in crossing and n not in block:
                        block.add(n)
                        todo.append(n)
            seen |= block
            name = f"j-{first[0]}-{first[1]}"
            arms = [d for d in DIRECTIONS
                    if any(step(c, d) in channel and step(c, d) not in block for c in block)]
            kind = KIND_BY_ARMS.get(len(arms))
            if len(arms) == 2 and set(arms) & {"E", "W"} and set(arms) & {"N", "S"}:
                kind = "corner"
            if kind is None:
                raise self.fail(f"junction {name}: the lanes crossing at {first} lead on to "
                                f"{', '.join(arms) or 'no side'} only; a junction joins two "
                                f"channels at a corner, three (a T) or four (a crossroad)")
            for cell in block:
                self.owner[cell] = f"junction {name}"
            found.append(Junction(name, kind, frozenset(block)))
        return found

    def access_of(self, element: str, cell: Cell, sides: tuple[str, ...], channel: set[Cell],
                  access: set[Cell]) -> tuple[Cell, ...]:
        """The cells beside `cell`, on its access sides, that a vehicle enters it from: lane
        cells, or access cells with a lane cell straight beyond them."""
        found = []
        for side in sides:
            near = step(cell, side)
            if near in access:
                beyond = step(near, side)
                if beyond not in channel:
                    raise self.fail(f"{element}: access cell {near} leads to no lane (cell "
                                    f"{beyond} beyond it is none)")
                found.append(near)
            elif near in channel:
                found.append(near)
        if not found:
            raise self.fail(f"{element}: no lane or access cell beside it on its access sides "
                            f"({', '.join(sides)})")
        return tuple(found)


@dataclasses.dataclass(frozen=True)
class _Named:
    name: str
