"""Faults on a seed-004 floor (docs/faults.md, "Seed 004"): the two kinds its tracker takes,
applied at their sim times in the tracker's event order, so a faulty run is the same in one
process and as processes. A broken-down AGV stands, holding its cell, which reads stagnant:
empty AGVs go round it, loaded ones wait; a closed zone is held by ZONE in the store, and
the same holds for its cells. The other kinds act on processes and services, which a
seed-004 run does not recover from yet: they are refused by name."""

from __future__ import annotations

from collections.abc import Sequence

from fleet.mission.faults import Fault, FaultKind, ScenarioError
from fleet.mission.tracking004 import Tracker
from fleet.planning.rules004 import XY, Kind
from fleet.world.floor004 import Floor004

KINDS004 = (FaultKind.VEHICLE_BREAKDOWN, FaultKind.CLOSE_ZONE)
OPEN = (Kind.FLOOR, Kind.SLOT, Kind.LANE)  # where an AGV drives: what a zone may close


def floor_xy(floor: Floor004, cell: tuple[int, int]) -> XY:
    """A layout cell (col, row; row 0 at the bottom) as the floor's (x, y)."""
    return (cell[0], floor.height - 1 - cell[1])


def check_faults004(faults: Sequence[Fault], floor: Floor004, vehicles: int,
                    scenario: str) -> None:
    """Refuse what a seed-004 run cannot take, naming the fault: another kind, an AGV the
    run does not have, a cell off the floor an AGV drives on."""
    for i, fault in enumerate(faults):
        where = f"scenario {scenario}: fault {i + 1} ({fault.describe()})"
        if fault.kind not in KINDS004:
            raise ScenarioError(f"{where}: on a seed-004 floor only "
                                f"{' and '.join(k.value for k in KINDS004)} are built yet")
        if fault.vehicle is not None and not 1 <= fault.vehicle <= vehicles:
            raise ScenarioError(f"{where}: the run has AGVs 1 to {vehicles}")
        for cell in fault.cells:
            xy = floor_xy(floor, cell)
            inside = 0 <= xy[0] < floor.width and 0 <= xy[1] < floor.height
            if not inside or floor.kind(xy) not in OPEN:
                raise ScenarioError(f"{where}: cell {cell[0]},{cell[1]} is not floor an AGV "
                                    f"of {floor.name} drives on (a zone closes aisles, slots "
                                    f"and station lanes)")


def apply_faults(tracker: Tracker, faults: Sequence[Fault]) -> None:
    """Schedule each fault in the tracker (checked already: check_faults004)."""
    for fault in faults:
        if fault.kind is FaultKind.VEHICLE_BREAKDOWN:
            assert fault.vehicle is not None
            tracker.break_down(fault.vehicle, fault.at, fault.until)
        else:
            tracker.close_zone([floor_xy(tracker.floor, c) for c in fault.cells], fault.at,
                               fault.until)
