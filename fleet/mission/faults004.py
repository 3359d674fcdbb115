"""Faults on a seed-004 floor (docs/faults.md, "Seed 004"), applied at their sim times in the
tracker's event order, so a faulty run is the same in one process and as processes. A
broken-down AGV stands, holding its cell, which reads stagnant: empty AGVs go round it,
loaded ones wait; a closed zone is held by ZONE in the store, and the same holds for its
cells. An AGV whose agent is killed, stalled or cut off stands the same way, from the instant
the injector does it to the instant the injector starts a new agent, continues it or
restores its link (if ever): the tracker strikes it as a breakdown told by its cause, and
its seam asks the injector to act when it strikes and when it is over
(dispatcher/remote004.py). A killed reservation service changes nothing the tracker
decides: its seam holds the instant while the injector kills it, and the requests wait for
its successor, which reads the journal. A killed recorder changes nothing either: its
successor asks the dispatcher for the events it did not write (recorder/process.py), nor
does a killed dispatcher: its successor runs the tracker again up to that instant and goes
on from there (dispatcher/remote004.py). A slowed planner (which no seed-004 decision waits
for) is refused by name."""

from __future__ import annotations

from collections.abc import Sequence

from fleet.mission.faults import Fault, FaultKind, Scenario, ScenarioError
from fleet.mission.freeze import CAUSES
from fleet.mission.tracking004 import Tracker
from fleet.planning.rules004 import XY, Kind
from fleet.world.floor004 import Floor004

KINDS004 = (FaultKind.VEHICLE_BREAKDOWN, FaultKind.CLOSE_ZONE, FaultKind.KILL_VEHICLE,
            FaultKind.STALL_VEHICLE, FaultKind.CUT_LINK, FaultKind.KILL_SERVICE)
# what the injector does to the run's processes
INJECTED004 = (FaultKind.KILL_VEHICLE, FaultKind.STALL_VEHICLE, FaultKind.CUT_LINK,
               FaultKind.KILL_SERVICE)
OPEN = (Kind.FLOOR, Kind.SLOT, Kind.LANE)  # where an AGV drives: what a zone may close
AGENT_FAULTS = (FaultKind.KILL_VEHICLE, FaultKind.STALL_VEHICLE, FaultKind.CUT_LINK)


def dispatcher_killed(fault: Fault) -> bool:
    return fault.kind is FaultKind.KILL_SERVICE and fault.service == "dispatcher"


def floor_xy(floor: Floor004, cell: tuple[int, int]) -> XY:
    """A layout cell (col, row; row 0 at the bottom) as the floor's (x, y)."""
    return (cell[0], floor.height - 1 - cell[1])


def taken004(fault: Fault) -> bool:
    """Whether a seed-004 run takes a fault of this kind (the death of any service)."""
    return fault.kind in KINDS004


def check_faults004(faults: Sequence[Fault], floor: Floor004, vehicles: int,
                    scenario: str) -> None:
    """Refuse what a seed-004 run cannot take, naming the fault: another kind, a kill of the
    dispatcher at the instant an agent's fault starts or ends (the injector applies both at
    one tick, and the dispatcher dies at the first), an AGV the run does not have, a cell
    off the floor an AGV drives on."""
    for i, fault in enumerate(faults):
        where = f"scenario {scenario}: fault {i + 1} ({fault.describe('AGV')})"
        if fault.kind not in KINDS004:
            raise ScenarioError(f"{where}: on a seed-004 floor only "
                                f"{', '.join(k.value for k in KINDS004)} are built yet")
        if dispatcher_killed(fault):
            for j, other in enumerate(faults):
                if other.kind in AGENT_FAULTS and fault.at in (other.at, other.until):
                    raise ScenarioError(
                        f"{where}: fault {j + 1} ({other.describe('AGV')}) starts or ends at "
                        f"the same instant, and a new dispatcher could not tell which of the "
                        f"two the injector applied first: give them different times")
        if fault.vehicle is not None and not 1 <= fault.vehicle <= vehicles:
            raise ScenarioError(f"{where}: the run has AGVs 1 to {vehicles}")
        for cell in fault.cells:
            xy = floor_xy(floor, cell)
            inside = 0 <= xy[0] < floor.width and 0 <= xy[1] < floor.height
            if not inside or floor.kind(xy) not in OPEN:
                raise ScenarioError(f"{where}: cell {cell[0]},{cell[1]} is not floor an AGV "
                                    f"of {floor.name} drives on (a zone closes aisles, slots "
                                    f"and station lanes)")


def injected004(scenario: Scenario) -> Scenario | None:
    """The part of a seed-004 scenario the fault injector applies (None: nothing)."""
    faults = tuple(f for f in scenario.faults if f.kind in INJECTED004)
    return Scenario(scenario.name, scenario.description, faults) if faults else None


def apply_faults(tracker: Tracker, faults: Sequence[Fault]) -> None:
    """Schedule each fault in the tracker (checked already: check_faults004)."""
    for fault in faults:
        if fault.kind in CAUSES:  # the AGV stands, whatever befell it or its agent
            assert fault.vehicle is not None
            tracker.break_down(fault.vehicle, fault.at, fault.until,
                               CAUSES[fault.kind])
        elif fault.kind is FaultKind.KILL_SERVICE:
            tracker.service_fault(fault.at)
        elif fault.kind is FaultKind.CLOSE_ZONE:
            tracker.close_zone([floor_xy(tracker.floor, c) for c in fault.cells], fault.at,
                               fault.until)
        else:
            raise AssertionError(f"{fault.kind} passed check_faults004")
