"""A layout as a vehicle kind's planners read it (`fleet.vehicles.kind.Site`): its static map
for forklifts, its lanes and their collision areas for seed 002's AGVs. The vehicles wing sits
below this one, so the world hands the kind what only it can work out."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from functools import cached_property

from fleet.planning.geometry import Cell
from fleet.planning.gridmap import GridMap
from fleet.planning.lane_conflicts import Area
from fleet.planning.lane_route import LaneGraph
from fleet.vehicles.kind import Planners
from fleet.world.lanes import collision_areas, lane_graph
from fleet.world.layout import Layout


@dataclass(frozen=True)
class LayoutSite:
    layout: Layout

    @property
    def name(self) -> str:
        return self.layout.name

    @property
    def cell_size(self) -> float:
        return self.layout.cell_size

    def grid_map(self, filled: Iterable[Cell] = (), under_shelves: bool = False) -> GridMap:
        return self.layout.grid_map(filled, under_shelves)

    @cached_property
    def lane_graph(self) -> LaneGraph:
        return lane_graph(self.layout)

    @cached_property
    def cell_areas(self) -> dict[Cell, Area]:
        return collision_areas(self.layout)


def planners_for(layout: Layout) -> Planners:
    """The layout's vehicle kind's planners and conflict policy, for this warehouse."""
    return layout.vehicle_kind.planners(LayoutSite(layout))
