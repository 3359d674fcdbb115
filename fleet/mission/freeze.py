"""Who stops, and where, when a forklift cannot follow its schedule (docs/faults.md).

Pure functions over the reservation table and what each forklift has committed.

A forklift frozen at t keeps the cells of the maneuver it is driving at t (or of its pose at
rest) from t to infinity and gives up everything after. If it can still move it completes
that maneuver and stands at its end pose; if it cannot (dead, stalled, cut off, broken down)
it stands where it was at t, inside the same cells. At the instant t every forklift holds
its own cells, so frozen cells of different forklifts never overlap. A forklift whose later
plan crosses frozen cells (or a closed zone) is frozen at t too, and so on until nobody's
plan conflicts: the cascade ends because every forklift is frozen at most once.
"""

from __future__ import annotations

import math
from collections import defaultdict
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field

from fleet.mission.faults import FaultKind, Scenario
from fleet.planning.geometry import Cell
from fleet.planning.maneuvers import body_cells_at_rest
from fleet.planning.reservations import ReservationTable
from fleet.planning.trajectory import Pose, Step, Trajectory
from fleet.wire.protocol import GOODS


def _forklift_at_rest(pose: Pose) -> Iterable[Cell]:
    return body_cells_at_rest(pose.cell, pose.heading)


@dataclass(frozen=True)
class Motion:
    """What one forklift has committed: it stands at `rest` until its first trajectory, then
    drives them in order (each starts where the previous one ended). `at_rest`: the cells
    its kind's body covers standing at a pose (seed 000's forklift unless said)."""

    vehicle: int
    rest: Pose
    trajectories: tuple[Trajectory, ...] = ()
    at_rest: Callable[[Pose], Iterable[Cell]] = field(default=_forklift_at_rest,
                                                      compare=False)


@dataclass(frozen=True)
class Freeze:
    vehicle: int
    t: float
    cells: frozenset[Cell]  # held from t to infinity
    step: Step | None  # the maneuver in progress at t (None: at rest)
    pose: Pose  # where it stands once that maneuver is over
    t_stand: float  # when it stands there, if it can move


def freeze_of(motion: Motion, t: float) -> Freeze:
    pose = motion.rest
    for traj in motion.trajectories:
        if t < traj.t_start:
            break
        if t >= traj.t_end:
            pose = traj.goal
            continue
        for step in traj.steps:
            if step.t0 < t < step.t1:
                return Freeze(motion.vehicle, t, frozenset(step.cells), step, step.end,
                              step.t1)
            if t <= step.t0:  # exactly between two maneuvers: at rest at this pose
                break
            pose = step.end
        break
    return Freeze(motion.vehicle, t, frozenset(motion.at_rest(pose)), None, pose, t)


@dataclass(frozen=True)
class Cascade:
    freezes: dict[int, Freeze]
    zone: frozenset[Cell]  # the cells a zone closure actually closes (not under a forklift)


def cascade(table: ReservationTable, t: float, motions: dict[int, Motion], first: set[int],
            goods_vehicle: Callable[[Cell], int | None], zone: frozenset[Cell] = frozenset(),
            zone_until: float = -math.inf,
            goods_kept: Callable[[int], Iterable[Cell]] = lambda vehicle: ()) -> Cascade:
    """Freeze `first` at t, close `zone` over [t, zone_until) where no one stands at t, and
    freeze every forklift whose remaining plan then conflicts. `goods_vehicle(cell)` names
    the forklift whose delivery, not yet arrived, reserved goods on the cell (its delivery
    is cancelled with it). `goods_kept(vehicle)` are the stack cells whose goods stay for
    good once the forklift's deliveries not yet arrived are cancelled (an empty mission's
    claims): whoever planned to cross them after the claim is frozen too. `motions` covers
    every forklift that may be frozen; anybody else (a forklift already down) keeps what it
    holds."""
    by_cell: dict[Cell, list[tuple[int, float, float]]] = defaultdict(list)
    occupied: set[Cell] = set()
    for r in table.reservations():
        if r.t1 > t:
            by_cell[r.cell].append((r.vehicle, r.t0, r.t1))
            if r.t0 <= t:
                occupied.add(r.cell)
    freezes: dict[int, Freeze] = {}
    closed = frozenset(zone - occupied)
    todo = sorted(first)
    for cell in sorted(closed):  # the holders of the zone's cells over its window
        todo += [_holder(owner, cell, motions, goods_vehicle)
                 for owner, h0, h1 in by_cell.get(cell, ()) if h0 < zone_until and h1 > t]
    while todo:
        vehicle = todo.pop(0)
        if vehicle in freezes:
            continue
        freeze = freezes[vehicle] = freeze_of(motions[vehicle], t)
        for cell in sorted(freeze.cells):
            todo += [_holder(owner, cell, motions, goods_vehicle)
                     for owner, _, _ in by_cell.get(cell, ())
                     if owner != vehicle and owner not in freezes]
        for cell in sorted(goods_kept(vehicle)):  # the goods' own hold ends with the claim
            todo += [_holder(owner, cell, motions, goods_vehicle)
                     for owner, _, _ in by_cell.get(cell, ())
                     if owner not in (vehicle, GOODS) and owner not in freezes]
    return Cascade(freezes, closed)


def _holder(owner: int, cell: Cell, motions: dict[int, Motion],
            goods_vehicle: Callable[[Cell], int | None]) -> int:
    """The forklift to freeze for a conflicting holding of `owner` on `cell`."""
    if owner in motions:
        return owner
    vehicle = goods_vehicle(cell)
    if vehicle is not None and vehicle in motions:
        return vehicle  # goods a delivery will place: cancel the delivery
    raise AssertionError(f"holder {owner} of cell {cell} after t cannot be frozen: the "
                         f"table breaks the frozen-cells invariant")


# -- what the engine hears: disruptions of the schedule, in sim time ---------------------------
@dataclass(frozen=True)
class VehicleDown:
    """The forklift cannot move from t on (dead, stalled, cut off, broken down)."""

    vehicle: int
    t: float
    cause: str


@dataclass(frozen=True)
class VehicleUp:
    """The forklift can move again from t (restarted, resumed, link back, repaired)."""

    vehicle: int
    t: float


@dataclass(frozen=True)
class ZoneClosure:
    cells: frozenset[Cell]
    t: float
    until: float


Disruption = VehicleDown | VehicleUp | ZoneClosure
BREAKDOWN = "breakdown"  # the one cause whose forklift still hears: it is told to stand
CAUSES = {FaultKind.KILL_VEHICLE: "agent killed", FaultKind.STALL_VEHICLE: "agent stalled",
          FaultKind.CUT_LINK: "link lost", FaultKind.VEHICLE_BREAKDOWN: BREAKDOWN}


def scheduled_at(scenario: Scenario, t: float) -> list[Disruption]:
    """What a scenario does to the schedule at instant t: forklifts back first, then those
    going down, then zones closing. Slow planners and killed services change no sim time."""
    ups: list[Disruption] = []
    downs: list[Disruption] = []
    zones: list[Disruption] = []
    for fault in scenario.faults:
        if fault.kind in CAUSES and fault.vehicle is not None:
            if fault.at == t:
                downs.append(VehicleDown(fault.vehicle, t, CAUSES[fault.kind]))
            if fault.until == t:
                ups.append(VehicleUp(fault.vehicle, t))
        elif fault.kind is FaultKind.CLOSE_ZONE and fault.at == t:
            zones.append(ZoneClosure(frozenset(fault.cells), t, fault.until))
    return ups + downs + zones


class ScheduledPacer:
    """The in-process reference of a fault run: no clock to wait for, and the scenario's
    disruptions exactly at their instants (what the distributed run detects, it must detect
    at the same sim times for the two records to agree)."""

    def __init__(self, scenario: Scenario) -> None:
        self.scenario = scenario
        self.pending = scenario.instants()

    def before_decision(self, t_next: float, t_free: dict[int, float]) -> dict[int, float]:
        return t_free

    def finish(self, t_end: float) -> None:
        pass

    def instant(self, t: float) -> float:
        return t

    def resumed(self, vehicle: int) -> None:
        pass

    def disruptions(self, t_next: float, down: frozenset[int]) -> list[Disruption]:
        while self.pending and self.pending[0] <= t_next:
            found = scheduled_at(self.scenario, self.pending.pop(0))
            if found:
                return found
        return []
