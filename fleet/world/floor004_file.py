"""The seed-004 part of the layout loader (docs/layouts.md, "Seed 004 floors"): a layout
whose `[floor004]` table gives the numbers its floor is generated from
(fleet/world/floor004.py), checked against the file's bounds, vehicle and drawing.

A mixin of `layout_file._Builder`, so errors read as the rest of the loader's.
"""

from __future__ import annotations

import dataclasses

from fleet.errors import UserError
from fleet.world.floor004 import Floor004Shape, build
from fleet.world.layout import Layout

FLOOR_TABLE = "floor004"
NOT_IN_FLOORS = ("cluster", "station", "passage", "starts", "obstacle", "lane", "shelf_area",
                 "packing", "pile", "access")
FLOOR_VEHICLE = "lifting-agv"


class FloorParts:
    """Reads a seed-004 floor; `floor_layout` returns the layout with it."""

    def is_floor004(self) -> bool:
        return FLOOR_TABLE in self.data

    def floor_layout(self, layout: Layout) -> Layout:
        table = self.data[FLOOR_TABLE]
        if not isinstance(table, dict):
            raise self.fail(f"{FLOOR_TABLE}: must be a table [{FLOOR_TABLE}] of the floor's "
                            f"numbers")
        fields = [f.name for f in dataclasses.fields(Floor004Shape)]
        self.keys(table, set(fields), FLOOR_TABLE)
        for key in NOT_IN_FLOORS:
            if key in self.data:
                raise self.fail(f"{key}: a seed-004 floor is generated from [{FLOOR_TABLE}]; "
                                f"it takes no [[{key}]]")
        defaults = Floor004Shape()
        shape = Floor004Shape(**{f: self.get(table, f, int, FLOOR_TABLE, getattr(defaults, f))
                                 for f in fields})
        try:
            floor = build(shape, layout.name)
        except UserError as exc:  # the number that cannot be built
            raise self.fail(f"{FLOOR_TABLE}: {exc}".replace("floor shape: ", "")) from None
        if (layout.cols, layout.rows) != (floor.width, floor.height):
            raise self.fail(f"bounds: the map is {layout.cols} x {layout.rows} cells, but the "
                            f"floor of [{FLOOR_TABLE}] is {floor.width} x {floor.height}")
        if layout.vehicle.kind != FLOOR_VEHICLE:
            raise self.fail(f"vehicle: a seed-004 floor is driven by {FLOOR_VEHICLE} vehicles, "
                            f"not {layout.vehicle.kind}")
        drawn = self.data.get("drawing")
        if drawn is not None:
            self.same_drawing(drawn, floor.drawing())
        return dataclasses.replace(layout, floor=floor, drawing=floor.drawing())

    def same_drawing(self, drawn: object, floor: str) -> None:
        """The file's drawing must be the floor's, row for row (top row first)."""
        if not isinstance(drawn, str):
            raise self.fail("drawing: must be a string")
        rows, want = drawn.strip("\n").splitlines(), floor.splitlines()
        if len(rows) != len(want):
            raise self.fail(f"drawing: has {len(rows)} rows, the floor {len(want)}")
        for y, (row, floor_row) in enumerate(zip(rows, want, strict=True)):
            if row != floor_row:
                x = next((i for i, (a, b) in enumerate(zip(row, floor_row, strict=False))
                          if a != b), min(len(row), len(floor_row)))
                raise self.fail(f"drawing: row {y} from the top differs from the floor at "
                                f"column {x}: {row[x:x + 1]!r} drawn, {floor_row[x:x + 1]!r} "
                                f"generated")
