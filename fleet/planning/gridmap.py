"""The static drivable grid a planner searches: bounds plus blocked cells."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

from fleet.planning.geometry import Cell


@dataclass(frozen=True)
class GridMap:
    cols: int
    rows: int
    blocked: frozenset[Cell]
    cell_size: float = 2.0

    def free(self, cell: Cell) -> bool:
        return 0 <= cell[0] < self.cols and 0 <= cell[1] < self.rows and cell not in self.blocked

    def all_free(self, cells: Iterable[Cell]) -> bool:
        return all(self.free(c) for c in cells)
