"""The seam between the dispatching loop and the forklifts (one interface, whatever holds
the reservations): the engine decides subtasks; an `Executor` plans and commits them, and a
`Pacer` holds the loop to a clock.

In one process, `LocalExecutor` plans with the vehicle kind's planner against a
`ReservationTable` it owns and `NoPacer` lets the loop run flat out. The distributed runtime
implements the same two interfaces over zenoh (`dispatcher.remote`): a task goes to the
forklift's agent process, which plans against its mirror of the reservation service and
commits there; the pacer publishes the clock. Everything the engine decides is therefore the
same code in both, which is what makes a fast-mode run of processes equal, bit for bit, the
in-process run.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

from fleet.dispatching.decision import TaskKind
from fleet.errors import UserError
from fleet.mission.freeze import Disruption, Freeze
from fleet.planning.geometry import Cell
from fleet.planning.reservations import Interval, ReservationTable
from fleet.planning.trajectory import PlanFailure, Pose, Trajectory
from fleet.vehicles.kind import Planners, VehicleKind
from fleet.wire.protocol import GOODS, ZONE


class VehicleLost(UserError):
    """A forklift went away in the middle of a request (its agent's liveliness is gone)."""

    def __init__(self, vehicle: int, message: str) -> None:
        super().__init__(message)
        self.vehicle = vehicle


@dataclass(frozen=True)
class Task:
    """One subtask for one forklift: drive from `start` at rest at `t_i` to any of `goals`,
    on the static map of the warehouse with the stacks in `filled` occupied."""

    vehicle: int
    kind: TaskKind
    start: Pose
    t_i: float
    goals: tuple[Pose, ...]
    filled: frozenset[Cell]
    loaded: bool  # carrying goods on this trip
    # What it carries once arrived, when that changes at the arrival (seed 002's AGVs lift
    # and drop shelves at once); None: as on the trip, until its next (a forklift unloads
    # over a handling time, then drives on).
    after: bool | None = None


class Executor(Protocol):
    @property
    def store(self) -> ReservationTable:
        """The reservation table as the dispatcher sees it (current after every call below)."""

    def park(self, vehicle: int, pose: Pose) -> None:
        """The vehicle stands at its start pose, reserved to infinity."""

    def execute(self, task: Task) -> Trajectory | PlanFailure:
        """Plan the task and commit its trajectory (releasing the vehicle's parking from t_i);
        a failure commits nothing."""

    def take_amended(self) -> list[Trajectory]:
        """Other vehicles' committed legs that the commits since the last call postponed
        (seed 002's collision rules), each as the vehicle now drives it."""

    def reserve_goods(self, intervals: Sequence[Interval]) -> None:
        """Reserve stack cells for the goods on them (owner GOODS); refused silently where a
        vehicle holds the cell, exactly as the table refuses a conflicting commit."""

    def freeze(self, t: float, freezes: list[Freeze], goods: list[Cell], zone: frozenset[Cell],
               zone_until: float, moving: list[int], standing: list[int]) -> None:
        """Make the table say what the freezes say: each frozen forklift holds its cells from
        t to infinity and nothing else after t, the goods of cancelled deliveries go, the zone
        is held by ZONE until `zone_until`; the `moving` forklifts are told to stop after
        their maneuver in progress, the `standing` ones (broken down) to stand where they
        are at t."""

    def resume(self, vehicle: int, freeze: Freeze, t: float, loaded: bool,
               battery: float | None = None) -> None:
        """A vehicle that was down moves again from t, completing its interrupted maneuver
        (`battery`: its charge when it stopped, for an agent that knows nothing of itself)."""


class Pacer(Protocol):
    def before_decision(self, t_next: float, t_free: dict[int, float]) -> dict[int, float]:
        """Called before each dispatching decision with the earliest instant the next decision
        can be for and each active vehicle's free time; returns the free times to decide with
        (a real-time clock moves those that already passed to a reachable instant)."""

    def finish(self, t_end: float) -> None:
        """The mission is over at sim time t_end."""

    def disruptions(self, t_next: float, down: frozenset[int]) -> list[Disruption]:
        """Hold the clock at each fault instant up to t_next and say what happened to the
        schedule there (forklifts down or back, zones closed; [] if nothing did). `down` are
        the forklifts the engine holds as down: nobody waits for them."""

    def resumed(self, vehicle: int) -> None:
        """The engine has just told the forklift to move again (its `ResumeRequest` was
        answered), before it does anything else. A clock that tells the forklifts who is
        down stops listing it at once: one resumed must not hear afterwards that it is down
        at an instant after its resumption, or it stands for good."""

    def instant(self, t: float) -> float:
        """The first sim instant at which a change decided now, while deciding for t, can
        still take effect (a freeze every forklift must hear of before it): t where sim
        time stands still at the decision; in real time a margin after now, which may come
        before t (decisions are taken a lead ahead: those beyond it are undone with it)."""


class LocalExecutor:
    """Plans in this process against a table this process owns, and writes it directly (the
    table is a `ReservationWriter`, as the reservation service's client is across processes).
    The table's change log is what a reservation service would have published."""

    def __init__(self, vehicle_kind: VehicleKind, planners: Planners) -> None:
        self.vehicle_kind = vehicle_kind
        self.planners = planners
        self.table = ReservationTable()
        self.amended: list[Trajectory] = []  # other vehicles' legs postponed, not yet taken

    @property
    def store(self) -> ReservationTable:
        return self.table

    def park(self, vehicle: int, pose: Pose) -> None:
        written = self.table.park(vehicle, self.vehicle_kind.body_cells_at_rest(pose), 0.0)
        if not written.ok:
            raise ValueError(f"start pose {pose} of vehicle {vehicle} overlaps vehicle "
                             f"{written.conflict_vehicle}")

    def execute(self, task: Task) -> Trajectory | PlanFailure:
        result = self.planners.get(task.filled).plan(task.vehicle, task.start, task.t_i,
                                                     task.goals, self.table)
        if isinstance(result, PlanFailure):
            return result
        leg = self.planners.policy.commitment(result, self.table)
        if isinstance(leg, PlanFailure):
            return leg
        written = leg.write(self.table)
        if not written.ok:  # the policy settled against this very table
            raise AssertionError(f"planned trajectory conflicts: {written.reason}")
        self.amended += [a.trajectory for a in leg.amends]
        return leg.trajectory

    def take_amended(self) -> list[Trajectory]:
        taken, self.amended = self.amended, []
        return taken

    def reserve_goods(self, intervals: Sequence[Interval]) -> None:
        self.table.commit(GOODS, intervals)  # refused where a vehicle holds the cell

    def freeze(self, t: float, freezes: list[Freeze], goods: list[Cell], zone: frozenset[Cell],
               zone_until: float, moving: list[int], standing: list[int]) -> None:
        for owner, intervals, release_from, cells in freeze_changes(t, freezes, goods, zone,
                                                                    zone_until):
            written = self.table.commit(owner, intervals) if intervals else \
                self.table.release(owner, release_from, cells)
            if not written.ok:  # the cascade left nothing in the way
                raise AssertionError(f"freeze at t={t} conflicts: {written.reason}")

    def resume(self, vehicle: int, freeze: Freeze, t: float, loaded: bool,
               battery: float | None = None) -> None:
        pass  # the table already holds the forklift's cells to infinity


FreezeChange = tuple[int, list[Interval], float | None, list[Cell] | None]


def freeze_changes(t: float, freezes: list[Freeze], goods: list[Cell], zone: frozenset[Cell],
                   zone_until: float) -> list[FreezeChange]:
    """The table changes of a freeze, in an order each is valid in: first every release
    (the frozen forklifts' plans after t, the cancelled deliveries' goods reservations, whole:
    goods a fill would have placed, or the claim an empty mission would have ended), then the
    frozen cells to infinity, then the zone. (owner, intervals to add, release from, only
    these cells)."""
    out: list[FreezeChange] = [(f.vehicle, [], t, None) for f in freezes]
    if goods:
        out.append((GOODS, [], 0.0, sorted(goods)))
    out += [(f.vehicle, [Interval(c, t, math.inf) for c in sorted(f.cells)], None, None)
            for f in freezes]
    if zone:
        out.append((ZONE, [Interval(c, t, zone_until) for c in sorted(zone)], None, None))
    return out


class NoPacer:
    """The in-process reference: no clock to wait for."""

    def before_decision(self, t_next: float, t_free: dict[int, float]) -> dict[int, float]:
        return t_free

    def finish(self, t_end: float) -> None:
        pass

    def disruptions(self, t_next: float, down: frozenset[int]) -> list[Disruption]:
        return []

    def resumed(self, vehicle: int) -> None:
        pass

    def instant(self, t: float) -> float:
        return t
