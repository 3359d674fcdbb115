"""How the engine answers a disruption of the schedule: who is frozen (the cascade of
fleet/mission/freeze.py), what is cancelled, and how a forklift that was down moves again
(docs/faults.md).

It keeps what that needs and nothing else does: what each forklift has committed (to find
where it is at any instant), its state before each subtask (to undo a subtask cut before it
arrived), and which forklifts are down, which it journals for a dispatcher to come
(fleet/mission/halt_log.py).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

from fleet.dispatching.decision import TaskKind
from fleet.mission.drive_log import CutAt, DriveLog, ResumeAt, StopAt
from fleet.mission.driving import replayed
from fleet.mission.freeze import (
    BREAKDOWN,
    Disruption,
    Freeze,
    Motion,
    VehicleDown,
    VehicleUp,
    cascade,
)
from fleet.mission.halt_log import Halted, Resumed
from fleet.mission.order_log import WorkLog
from fleet.mission.record import MissionRecord
from fleet.mission.seam import Executor, Pacer
from fleet.mission.vehicle_slot import VehicleSlot
from fleet.mission.work import MissionWork
from fleet.planning.geometry import Cell
from fleet.planning.trajectory import Pose, Trajectory
from fleet.wire.protocol import Halt, Message, Resume, StackReopened, ZoneClosed
from fleet.world.layout import Layout

Emit = Callable[[Message, float], None]


class FaultResponse:
    """Freeze, cancel, resume, on the engine's fleet, work and record."""

    def __init__(self, fleet: dict[int, VehicleSlot], starts: tuple[Pose, ...],
                 executor: Executor, work: MissionWork, record: MissionRecord,
                 drive_log: DriveLog, layout: Layout, emit: Emit, pacer: Pacer,
                 log: WorkLog | None = None) -> None:
        self.fleet = fleet
        self.starts = starts
        # Where each forklift stands before its first leg in `driven`: its start, or where a
        # restarted dispatcher found it.
        self.rest: dict[int, Pose] = {v: starts[v - 1] for v in fleet}
        self.executor = executor
        self.work = work
        self.record = record
        self.drive_log = drive_log
        self.layout = layout
        self.emit = emit
        self.pacer = pacer
        self.log = log  # the dispatcher's journal: who went down, where, and who came back
        self.down: dict[int, Halted] = {}  # forklifts that cannot move, and where they stopped
        self.before: list[VehicleSlot] = []  # each forklift's slot before each subtask
        self.driven: dict[int, list[Trajectory]] = {v: [] for v in fleet}
        self.since_start = True  # its drive log holds every leg since the mission began

    def committed(self, before: VehicleSlot, traj: Trajectory) -> None:
        """A subtask's trajectory was committed; `before` is its forklift's slot until then."""
        self.before.append(before)
        self.driven[before.vehicle].append(traj)

    def amended(self, leg: Trajectory) -> Trajectory:
        """A committed leg was postponed (seed 002's collision rules): it is driven so.
        Returns it as it was."""
        legs = self.driven[leg.vehicle]
        k = max(i for i, traj in enumerate(legs) if traj.t_start == leg.t_start)
        before, legs[k] = legs[k], leg
        return before

    def picked_up(self, poses: dict[int, Pose], legs: dict[int, Trajectory],
                  down: dict[int, Halted]) -> None:
        """A restarted dispatcher: where each forklift stands and its last committed leg, as
        its agent holds it; those that are down, as the dead dispatcher journaled them."""
        for vehicle, pose in poses.items():
            leg = legs.get(vehicle)
            self.driven[vehicle] = [leg] if leg is not None else []
            self.rest[vehicle] = leg.start if leg is not None else pose
        for vehicle, halted in down.items():
            self.down[vehicle], freeze = halted, halted.freeze
            self.rest[vehicle] = freeze.step.start if freeze.step is not None else freeze.pose
        self.since_start = False

    def _charge_at(self, vehicle: int, t: float) -> float | None:
        """The vehicle's battery at t, as everything it was told since the start drove it
        (a restarted agent learns it so); None: no battery, or this dispatcher did not see
        the start (the agent keeps its own)."""
        battery = self.work.battery(vehicle)
        if battery is None or not self.since_start:
            return None
        drive, _ = replayed(vehicle, self.starts[vehicle - 1], self.layout, battery,
                            self.drive_log[vehicle])
        return round(drive.soc_at(t), 6)

    def disrupt(self, disruption: Disruption) -> None:
        """Apply what the clock reports: a forklift down or back, a zone closed."""
        if isinstance(disruption, VehicleUp):
            self._resume(disruption)
            return
        if isinstance(disruption, VehicleDown):
            if disruption.vehicle in self.down:
                return
            first, zone, until = {disruption.vehicle}, frozenset(), disruption.t
            cause = disruption.cause
        else:  # no spill on goods: nobody could enter their cells anyway
            first, zone, until = set(), disruption.cells - self.work.goods_off_table, \
                disruption.until
            cause = "zone closed"
        # Never before what the work has taken as happened (real time takes an order
        # mission's arrivals a lead ahead): that stays as it was.
        t = max(disruption.t, self.work.taken_until)
        if zone and t >= until:
            return  # over before it could close
        at_rest = self.layout.vehicle_kind.body_cells_at_rest
        motions = {v: Motion(v, self.rest[v], tuple(self.driven[v]), at_rest)
                   for v in self.fleet if v not in self.down}
        pending = self._pending_deliveries(t)
        by_cell = {cell: vehicle for vehicle, cells in pending.items() for cell in cells}
        kept = pending if self.work.goods_stay_if_cancelled else {}
        result = cascade(self.executor.store, t, motions, first, by_cell.get, zone, until,
                         lambda vehicle: kept.get(vehicle, ()))
        goods: list[Cell] = []
        for vehicle, freeze in sorted(result.freezes.items()):
            down = vehicle in first
            goods += self._freeze(freeze, down)
            why = cause if down or zone else "its plan crossed a stopped forklift's cells"
            self.record.halts.append((vehicle, t, why))
            self.drive_log[vehicle].append(StopAt(t) if down else CutAt(t))
            if down:
                self.down[vehicle] = Halted(freeze, cause, self.fleet[vehicle].next_task,
                                            self._charge_at(vehicle, freeze.t))
            self.emit(halt_message(freeze, why, not down, self.layout), t)
        if zone:
            self.emit(ZoneClosed(sorted(result.zone), t, until), t)
        broken = isinstance(disruption, VehicleDown) and disruption.cause == BREAKDOWN
        self.executor.freeze(t, list(result.freezes.values()), goods, result.zone, until,
                             moving=[v for v in result.freezes if v not in self.down],
                             standing=sorted(first) if broken else [])
        for vehicle in sorted(first):
            if self.log is not None:  # the store and the agents have it: a successor's word
                self.log.append(self.down[vehicle].to_record())
            self._given(t, self.work.down(vehicle, t, self.down[vehicle].freeze.cells))
        if result.zone:
            self._given(t, self.work.closed(result.zone, t, until))

    def _given(self, t: float, given: dict[int, float]) -> None:
        """Vehicles the work gave something to do from an instant: free from then on."""
        for vehicle, at in given.items():
            v = self.fleet[vehicle]
            v.wait_until(max(at, t, v.t_free))

    def _pending_deliveries(self, t: float) -> dict[int, list[Cell]]:
        """The stack cells of each forklift's deliveries not yet arrived at t: the goods
        reserved on them go if the delivery is cancelled (and on an empty mission the goods
        to claim stay on them)."""
        cut = set(self.record.cut_subtasks)
        pending: dict[int, list[Cell]] = {}
        for i, s in enumerate(self.record.subtasks):
            if i not in cut and s.kind is TaskKind.DELIVER and s.t_end > t and \
                    s.stack_cell is not None:
                pending.setdefault(s.vehicle, []).append(s.stack_cell)
        return pending

    def _freeze(self, freeze: Freeze, down: bool) -> list[Cell]:
        """Cut the forklift's plan after the maneuver in progress at freeze.t (`down`: it
        stands where it is at t instead): its subtasks not yet arrived are cancelled (a
        delivery's stack goes back to the queue, its goods as before). Returns the stack
        cells whose goods reservations go with them."""
        t, vehicle = freeze.t, freeze.vehicle
        stands = t if down else freeze.t_stand
        v = self.fleet[vehicle]
        cut = set(self.record.cut_subtasks)
        undone = [i for i, s in enumerate(self.record.subtasks)
                  if s.vehicle == vehicle and i not in cut and s.t_end > t]
        goods = []
        if undone:
            before = self.before[undone[0]]
            v.next_task, v.linked_cluster, v.linked_kind = \
                before.next_task, before.linked_cluster, before.linked_kind
            v.busy_s, v.wait_s, v.postponed_s = before.busy_s, before.wait_s, before.postponed_s
            # Not before it was free for the first subtask undone: one decided ahead, not
            # started by t, waited for the handling before it to end.
            v.t_free = max(freeze.t_stand, before.t_free)
            v.t_still = max(freeze.t_stand, before.t_still)
        else:
            v.t_free = max(v.t_free, freeze.t_stand)
            v.t_still = freeze.t_stand
        for i in undone:
            self.record.cut_subtasks.append(i)
            s = self.record.subtasks[i]
            driven = sum(min(step.t1, stands) - step.t0 for step in s.trajectory.steps
                         if step.t0 < stands and not self.layout.vehicle_kind.is_wait(
                             step.manner.label))
            reopened = self.work.cancel(vehicle, s.kind, s.target, s.stack_index, driven)
            if reopened is not None:
                self._reopen(reopened.cluster, reopened.index, s.vehicle, t)
                if reopened.goods is not None:
                    goods.append(reopened.goods)
        v.pose = freeze.pose
        self.driven[vehicle] = [c for c in (_truncated(traj, freeze)
                                            for traj in self.driven[vehicle]) if c is not None]
        return goods

    def _reopen(self, cluster: str, index: int, vehicle: int, t: float) -> None:
        """Work counted as done when its subtask was committed is not done after all."""
        done = next(d for d in self.record.stacks_done if d[:2] == (cluster, index))
        self.record.stacks_done.remove(done)
        self.record.end_time = max((d[2] for d in self.record.stacks_done), default=0.0)
        self.emit(StackReopened(cluster, index, vehicle, t), t)

    def _resume(self, up: VehicleUp) -> None:
        halted = self.down.pop(up.vehicle, None)
        if halted is None:
            return
        freeze = halted.freeze
        v = self.fleet[up.vehicle]
        # Not before the freeze nor what the work has taken (in real time both may be later
        # than the instant it was noticed at).
        up = dataclasses.replace(up, t=max(up.t, freeze.t, self.work.taken_until))
        shift = up.t - freeze.t
        t_stand = up.t
        if freeze.step is not None:  # the rest of the maneuver, from where it stood
            step = dataclasses.replace(freeze.step, t0=freeze.step.t0 + shift,
                                       t1=freeze.step.t1 + shift)
            t_stand = step.t1
            self.driven[up.vehicle].append(Trajectory(up.vehicle, step.start, step.end,
                                                      step.t0, (step,), (), 0))
        v.t_free = max(v.t_free, t_stand)
        v.t_still = t_stand
        if self.log is not None:  # before it is told: a successor never resumes it twice
            self.log.append(Resumed(up.vehicle, up.t).to_record())
        self.executor.resume(up.vehicle, freeze, up.t, loaded=self.work.loaded(v.next_task),
                             battery=halted.battery)
        self.pacer.resumed(up.vehicle)
        self.record.resumes.append((up.vehicle, up.t))
        self.drive_log[up.vehicle].append(ResumeAt(up.t))
        self.emit(Resume(up.vehicle, up.t, t_stand), up.t)
        pose = freeze.step.end if freeze.step is not None else freeze.pose
        self._given(t_stand, self.work.up(up.vehicle, up.t, pose))


def halt_message(freeze: Freeze, cause: str, moving: bool, layout: Layout) -> Halt:
    """The dispatcher's word that a forklift stops, with where it stands in the world."""
    kind = layout.vehicle_kind
    at = kind.at_rest(freeze.pose) if freeze.step is None else kind.on_step(freeze.step,
                                                                             freeze.t)
    ox, oy = layout.origin
    return Halt(freeze.vehicle, freeze.t, cause, moving, str(freeze.pose), freeze.t_stand,
                sorted(freeze.cells), at.x + ox, at.y + oy, at.theta)


def _truncated(traj: Trajectory, freeze: Freeze) -> Trajectory | None:
    """The part of a trajectory driven up to the end of the maneuver in progress at the
    freeze (None if none of it is)."""
    kept = tuple(s for s in traj.steps if s.t0 < freeze.t)
    if not kept:
        return None
    if len(kept) == len(traj.steps):
        return traj
    return Trajectory(traj.vehicle, traj.start, kept[-1].end, traj.t_start, kept, (),
                      traj.expansions)
