"""In-process reference engine: a deterministic discrete-event run of a whole mission.

Algorithm 4 of seed 000: while work is left, the dispatcher (Algorithm 1) picks a vehicle, an
instant t_i and a goal; the vehicle's improved hybrid A* plans against the reservation table;
a found trajectory is committed (the vehicle's old parking is released from t_i on) and the
fill state advances; a failed one sets `fail` and the dispatcher re-selects. Subtasks are
decided in order of the vehicles' free times, so this is the discrete-event order of the
mission. No wall clock and no randomness enter the record: the same mission gives the same
record, bit for bit. The distributed runtime must reproduce it.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

from fleet.dispatching.algorithm1 import Decision, Dispatcher, Target, TaskKind, VehicleView
from fleet.errors import UserError
from fleet.mission.freeze import (
    BREAKDOWN,
    Disruption,
    Freeze,
    Motion,
    Recovered,
    VehicleDown,
    VehicleUp,
    cascade,
)
from fleet.mission.seam import Executor, LocalExecutor, NoPacer, Pacer, Task, VehicleLost
from fleet.mission.spec import Mission, MissionKind
from fleet.params import DispatchParams
from fleet.planning.geometry import Cell
from fleet.planning.reservations import Interval, ReservationTable
from fleet.planning.trajectory import PlanFailure, Pose, Trajectory
from fleet.vehicles.kind import Planner
from fleet.wire.convert import intervals_to_wire
from fleet.wire.protocol import (
    DecisionFailure,
    Halt,
    Message,
    Resume,
    StackDone,
    StackReopened,
    SubtaskEvent,
    ZoneClosed,
)
from fleet.world.layout import Layout, LayoutError
from fleet.world.layout_file import load_layout


class MissionStuck(UserError):
    """No subtask could be planned for a long run of attempts (the layout or fleet leaves
    no way forward); the message says when and what failed last."""


@dataclass
class VehicleState:
    vehicle: int
    pose: Pose
    t_free: float
    next_task: TaskKind
    linked_cluster: str | None = None
    linked_kind: TaskKind | None = None
    busy_s: float = 0.0  # driving (maneuvers other than stop)
    wait_s: float = 0.0  # stop maneuvers and postponements

    def view(self) -> VehicleView:
        return VehicleView(self.vehicle, self.pose, self.t_free, self.next_task,
                           self.linked_cluster, self.linked_kind)


@dataclass(frozen=True)
class Subtask:
    vehicle: int
    kind: TaskKind
    target: str  # cluster or station
    stack_index: int | None
    stack_cell: Cell | None
    t_i: float
    t_end: float
    t_done: float  # after claiming / unloading
    trajectory: Trajectory
    postponed: bool


def subtask_event(s: Subtask) -> SubtaskEvent:
    """A subtask as the dispatcher announces it (and as mission records hold it)."""
    return SubtaskEvent(
        s.vehicle, s.kind.value, s.target, s.stack_index, s.t_i, s.t_end, s.t_done,
        s.postponed,
        [(st.manner.label, str(st.start), str(st.end), st.t0, st.t1, int(st.v0), int(st.v1))
         for st in s.trajectory.steps],
        intervals_to_wire(s.trajectory.intervals))


@dataclass(frozen=True)
class FailureEvent:
    t: float
    vehicle: int | None
    stage: str  # "dispatch" or "plan"
    reason: str


@dataclass
class MissionRecord:
    mission: Mission
    layout: str
    vehicles: tuple[int, ...]
    starts: tuple[Pose, ...]
    subtasks: list[Subtask] = field(default_factory=list)
    failures: list[FailureEvent] = field(default_factory=list)
    decision_failures: int = 0
    end_time: float = 0.0  # the last stack done
    all_parked_time: float = 0.0  # every vehicle at rest for good
    stacks_done: list[tuple[str, int, float]] = field(default_factory=list)
    busy_s: dict[int, float] = field(default_factory=dict)
    wait_s: dict[int, float] = field(default_factory=dict)
    training_samples: list[tuple[tuple[float, ...], int, float]] = field(default_factory=list)
    halts: list[tuple[int, float, str]] = field(default_factory=list)  # vehicle, t, cause
    resumes: list[tuple[int, float]] = field(default_factory=list)
    cut_subtasks: list[int] = field(default_factory=list)  # indices of subtasks cut short

    @property
    def total_wait_s(self) -> float:
        return sum(self.wait_s.values())


@dataclass
class EngineOptions:
    params: DispatchParams = field(default_factory=DispatchParams)
    mlp: Callable[[list[float]], list[float]] | None = None
    collect_training: bool = False
    max_consecutive_failures: int = 400
    # After this many failures in a row the fleet may be stuck on a choice rather than on the
    # layout: a forklift then skips the targets it failed to reach since the last success.
    unstick_after: int = 300
    # After each commit: stacks done, total, the sim time the mission has reached, failures.
    progress: Callable[[int, int, float, int], None] | None = None
    # Each subtask, stack done and decision failure as it happens, with its sim time (the
    # dispatcher publishes them; the in-process run records them).
    events: Callable[[Message, float], None] | None = None


def _far_clusters(layout: Layout) -> set[str]:
    """Clusters whose route to the stations is longest (s1 and s2 on the paper layout): the
    third with the largest mean distance from their stacks to the nearest station dock."""
    dist = {}
    for cluster in layout.clusters:
        cells = [s.cell for s in layout.stacks if s.cluster == cluster.name]
        dist[cluster.name] = sum(min(abs(c[0] - st.dock.cell[0]) + abs(c[1] - st.dock.cell[1])
                                     for st in layout.stations) for c in cells) / len(cells)
    ranked = sorted(dist, key=lambda n: (-dist[n], n))
    return set(ranked[: max(1, len(ranked) // 3)])


class Engine:
    """Runs one mission: in one process by default, or with the forklifts elsewhere when given
    an executor and a pacer for them (fleet/mission/seam.py)."""

    def __init__(self, mission: Mission, options: EngineOptions | None = None,
                 layout: Layout | None = None, executor: Executor | None = None,
                 pacer: Pacer | None = None, recovered: Recovered | None = None) -> None:
        self.mission = mission
        self.options = options or EngineOptions()
        self.layout = layout or load_layout(mission.layout)
        self.vehicle_kind = self.layout.vehicle_kind
        self.planners = self.vehicle_kind.planners(self.layout.grid_map)
        self.executor = executor or LocalExecutor(self.vehicle_kind, self.planners)
        self.pacer = pacer or NoPacer()
        starts = list(mission.starts or self.layout.vehicle_starts)
        n = mission.vehicles if mission.vehicles is not None else len(starts)
        if not 1 <= n <= len(starts):
            raise UserError(f"{n} vehicles requested but layout {self.layout.name} has "
                             f"{len(starts)} start poses")
        self.starts = starts[:n]
        fill = mission.kind is MissionKind.FILL
        first = TaskKind.DELIVER
        handling = self.options.params.t_claim if fill else 0.0
        self.vehicles = {i + 1: VehicleState(i + 1, pose, handling, first)
                         for i, pose in enumerate(self.starts)}
        if recovered is not None:  # a restarted dispatcher: where the forklifts really are
            for v in self.vehicles.values():
                v.pose, v.t_free = recovered.poses[v.vehicle], recovered.t_free[v.vehicle]
                v.next_task = TaskKind.DELIVER if recovered.delivers_next[v.vehicle] == fill \
                    else TaskKind.RETURN
        for v in self.vehicles.values():
            self.executor.park(v.vehicle, v.pose)
        by_cluster: dict[str, list] = {}
        for s in self.layout.stacks:
            by_cluster.setdefault(s.cluster, []).append(s)
        for stacks in by_cluster.values():
            stacks.sort(key=lambda s: s.index if fill else -s.index)
        self.queue = by_cluster  # stacks not yet assigned, in the order they are done
        self.present: set[Cell] = set() if fill else {s.cell for s in self.layout.stacks}
        self.total = len(self.layout.stacks)
        self.far = _far_clusters(self.layout)
        self.record = MissionRecord(mission, self.layout.name, tuple(self.vehicles),
                                    tuple(self.starts))
        self.trip_times: list[float] = []
        self.down: dict[int, Freeze] = {}  # forklifts that cannot move, and where they stopped
        self.before: list[VehicleState] = []  # the forklift's state before each subtask
        self.driven: dict[int, list[Trajectory]] = {v: [] for v in self.vehicles}
        self.now = 0.0  # the instant the clock was last moved to
        self.tried: dict[int, set[str]] = {}  # targets each forklift failed since a success
        self.stuck = False  # failures in a row reached unstick_after
        # What each forklift's agent was told, in order: ("add", trajectory, loaded),
        # ("cut", t), ("stop", t), ("resume", t): an in-process run drives its states from it.
        self.drive_log: dict[int, list[tuple]] = {v: [] for v in self.vehicles}
        self.undelivered: tuple[tuple[str, int, float, int], ...] = ()
        if recovered is not None:
            self._pick_up(recovered)
        self.dispatcher = Dispatcher(
            grid_for=lambda: self.layout.grid_map(self.present),
            store=self.executor.store, strategy=mission.strategy, params=self.options.params,
            cluster_names=tuple(c.name for c in self.layout.clusters), mlp=self.options.mlp)
        self.planning_wall_s = 0.0

    # -- helpers -------------------------------------------------------------------------------
    def planner(self, filled: set[Cell] | None = None) -> Planner:
        """The planner for a fill state (default: the current one)."""
        return self.planners.get(frozenset(self.present if filled is None else filled))

    def poses_with_a_way_out(self, poses: list[Pose], after: set[Cell],
                             others: list[Pose]) -> list[Pose]:
        """Unload poses from which a station dock is still reachable once the stack is filled
        (a pose beside the stack may be reachable only by sweeping the stack's own cell); none
        if filling the stack would wall in another forklift where it stands."""
        planner = self.planner(after)
        docks = {planner.component(st.dock) for st in self.layout.stations}
        now = self.planner()
        docks_now = {now.component(st.dock) for st in self.layout.stations}
        if any(planner.component(p) not in docks and now.component(p) in docks_now
               for p in others):
            return []
        return [p for p in poses if planner.component(p) in docks]

    def remaining(self) -> dict[str, int]:
        return {name: len(q) for name, q in self.queue.items()}

    def targets_for(self, view: VehicleView) -> list[Target]:
        """Where the forklift may go next; once the fleet is stuck, not where it failed to
        go since the last success, while it has somewhere else to try (the preliminary A*
        sees cells, not turns, and may keep choosing a station the forklift cannot reach)."""
        targets = self._targets(view)
        tried = self.tried.get(view.vehicle, set()) if self.stuck else set()
        return [t for t in targets if t.name not in tried] or targets

    def _targets(self, view: VehicleView) -> list[Target]:
        if view.next_task is TaskKind.RETURN:
            return [Target(st.name, (st.dock,)) for st in self.layout.stations]
        targets = []
        for cluster in self.layout.clusters:
            queue = self.queue.get(cluster.name, [])
            if not queue:
                continue
            stack = queue[0]
            if self.mission.kind is MissionKind.FILL and self.executor.store.conflict(
                    view.vehicle, stack.cell, view.t_free, math.inf) is not None:
                continue  # another forklift stands on or will cross the stack's cell
            poses = self.layout.unload_poses(stack.cell, self.present - {stack.cell})
            if self.mission.kind is MissionKind.FILL:
                others = [v.pose for v in self.vehicles.values() if v.vehicle != view.vehicle]
                poses = self.poses_with_a_way_out(poses, self.present | {stack.cell}, others)
            if poses:
                targets.append(Target(cluster.name, tuple(poses), stack.cell, stack.index,
                                      len(queue), cluster.name in self.far))
        return targets

    def active(self) -> list[VehicleState]:
        """Vehicles with something left to do: any return, or a delivery while stacks wait."""
        work_left = any(self.queue.values())
        return [v for v in self.vehicles.values() if v.vehicle not in self.down and
                (v.next_task is TaskKind.RETURN or work_left)]

    # -- the run -------------------------------------------------------------------------------
    def _pick_up(self, r: Recovered) -> None:
        """Start from what a restarted dispatcher found: stacks done, legs committed."""
        for cluster, index, t_done in (*r.done, *((c, i, t + self.options.params.t_unload)
                                                  for c, i, t, _ in r.undelivered)):
            stack = next(s for s in self.queue[cluster] if s.index == index)
            self.queue[cluster].remove(stack)
            self.present.add(stack.cell)
            self.record.stacks_done.append((cluster, index, t_done))
        self.record.end_time = max((d[2] for d in self.record.stacks_done), default=0.0)
        self.undelivered = r.undelivered
        for vehicle, leg in r.legs.items():
            self.driven[vehicle] = [leg]
        self.now = r.t

    def run(self) -> MissionRecord:
        failed: list[int] = []  # vehicles whose plan failed since the last success, in order
        streak = 0
        fill = self.mission.kind is MissionKind.FILL
        p = self.options.params
        for cluster, index, t_end, vehicle in self.undelivered:  # goods the last dispatcher
            cell = next(s.cell for s in self.layout.stacks  # did not get to reserve
                        if s.cluster == cluster and s.index == index)
            self.executor.reserve_goods([Interval(cell, t_end, math.inf)])
            self._emit(StackDone(cluster, index, vehicle, t_end + p.t_unload),
                       t_end + p.t_unload)
        while True:
            active = self.active()
            if not active and not self.down:
                break
            t_next = min((v.t_free for v in active), default=math.inf)
            disruptions = self.pacer.disruptions(t_next, frozenset(self.down))
            if disruptions:
                for disruption in disruptions:
                    self.disrupt(disruption)
                continue
            if not active:
                break  # the forklifts left are down for good
            self.now = t_next
            paced = self.pacer.before_decision(t_next, {v.vehicle: v.t_free for v in active})
            for v in active:
                v.wait_s += paced[v.vehicle] - v.t_free
                v.t_free = paced[v.vehicle]
            views = [v.view() for v in active]
            remaining = self.remaining()
            outcome = self.dispatcher.decide(views, failed, self.targets_for, remaining)
            self.record.decision_failures += outcome.failures
            for vid, t_free in outcome.postponements.items():
                v = self.vehicles[vid]
                v.wait_s += t_free - v.t_free
                v.t_free = t_free
            failed = [v for v in failed if v not in outcome.postponements]  # a new instant
            decision = outcome.decision
            if decision is None:
                self._failed(FailureEvent(
                    min(v.t_free for v in active), None, "dispatch",
                    f"no solid decision within iter_dispatch={p.iter_dispatch}"))
                streak += 1
            else:
                try:
                    result = self._plan(decision)
                except VehicleLost as exc:  # gone without a scheduled fault: recover all the same
                    self.disrupt(VehicleDown(exc.vehicle, self.pacer.instant(self.now),
                                             f"agent lost: {exc}"))
                    failed = [v for v in failed if v != exc.vehicle]
                    continue
                if isinstance(result, Trajectory):
                    self._apply(decision, result, fill, remaining)
                    failed, streak = [], 0
                    self.tried = {}
                else:
                    self.tried.setdefault(decision.vehicle, set()).add(decision.target.name)
                    self.record.decision_failures += 1
                    self._failed(FailureEvent(decision.t_i, decision.vehicle, "plan",
                                              result.reason.value))
                    if self.options.collect_training and decision.kind is TaskKind.DELIVER:
                        self._collect(decision, None, remaining)
                    failed = [v for v in failed if v != decision.vehicle] + [decision.vehicle]
                    streak += 1
            self.stuck = streak >= self.options.unstick_after
            if streak > self.options.max_consecutive_failures:
                raise MissionStuck(f"{streak} decisions in a row failed at t="
                                   f"{min(v.t_free for v in active):.2f} s; last: "
                                   f"{self.record.failures[-1]}")
        rec = self.record
        rec.all_parked_time = max((s.t_end for s in rec.subtasks), default=0.0)
        self.pacer.finish(max(rec.end_time, rec.all_parked_time))
        rec.busy_s = {v.vehicle: v.busy_s for v in self.vehicles.values()}
        rec.wait_s = {v.vehicle: v.wait_s for v in self.vehicles.values()}
        return rec

    def _emit(self, message: Message, t: float) -> None:
        if self.options.events is not None:
            self.options.events(message, t)

    def _failed(self, failure: FailureEvent) -> None:
        self.record.failures.append(failure)
        self._emit(DecisionFailure(failure.t, failure.vehicle, failure.stage, failure.reason),
                   failure.t)

    def _plan(self, decision: Decision) -> Trajectory | PlanFailure:
        """Plan and commit (the executor does both; a failure commits nothing)."""
        v = self.vehicles[decision.vehicle]
        fill = self.mission.kind is MissionKind.FILL
        deliver = decision.kind is TaskKind.DELIVER
        task = Task(v.vehicle, decision.kind, v.pose, decision.t_i, decision.target.goals,
                    frozenset(self.present), loaded=deliver == fill)
        t0 = time.perf_counter()
        result = self.executor.execute(task)
        self.planning_wall_s += time.perf_counter() - t0
        return result

    def _apply(self, decision: Decision, traj: Trajectory, fill: bool,
               remaining: dict[str, int]) -> None:
        p = self.options.params
        v = self.vehicles[decision.vehicle]
        target = decision.target
        deliver = decision.kind is TaskKind.DELIVER
        handling = (p.t_unload if deliver else p.t_claim) if fill else \
            (p.t_claim if deliver else p.t_unload)
        t_done = traj.t_end + handling
        if deliver:
            stack = self.queue[target.name].pop(0)
            if fill:
                self.present.add(stack.cell)
                self.executor.reserve_goods([Interval(stack.cell, traj.t_end, math.inf)])
            else:
                self.present.discard(stack.cell)
                self.executor.reserve_goods([Interval(stack.cell, 0.0, t_done)])
            self.record.stacks_done.append((target.name, stack.index, t_done))
            self._emit(StackDone(target.name, stack.index, v.vehicle, t_done), t_done)
            self.record.end_time = max(self.record.end_time, t_done)
            if self.options.collect_training:
                self._collect(decision, traj, remaining)
        self.before.append(dataclasses.replace(v))
        stops = sum(s.t1 - s.t0 for s in traj.steps
                    if self.vehicle_kind.is_wait(s.manner.label))
        v.busy_s += traj.t_end - traj.t_start - stops
        v.wait_s += stops
        v.pose = traj.goal
        v.t_free = t_done
        v.next_task = TaskKind.RETURN if deliver else TaskKind.DELIVER
        if deliver:
            v.linked_cluster, v.linked_kind = target.name, TaskKind.DELIVER
        else:
            v.linked_kind = TaskKind.RETURN if v.linked_cluster else None
        self.trip_times.append(traj.t_end - decision.t_i)
        self.driven[v.vehicle].append(traj)
        self.drive_log[v.vehicle].append(("add", traj, deliver == fill))
        subtask = Subtask(v.vehicle, decision.kind, target.name, target.stack_index,
                          target.stack_cell, decision.t_i, traj.t_end, t_done, traj,
                          decision.postponed)
        self.record.subtasks.append(subtask)
        self._emit(subtask_event(subtask), decision.t_i)
        if self.options.progress:  # at the instant the clock reached, not the planned arrival
            self.options.progress(len(self.record.stacks_done), self.total, self.now,
                                  self.record.decision_failures)

    # -- faults: freeze, cancel, resume (fleet/mission/freeze.py, docs/faults.md) ------------------
    def disrupt(self, disruption: Disruption) -> None:
        """Apply what the clock reports: a forklift down or back, a zone closed."""
        self.tried = {}  # the table changes: a target that failed may not fail now
        if isinstance(disruption, VehicleUp):
            self._resume(disruption)
            return
        if isinstance(disruption, VehicleDown):
            if disruption.vehicle in self.down:
                return
            first, zone, until = {disruption.vehicle}, frozenset(), disruption.t
            cause = disruption.cause
        else:
            first, zone, until = set(), disruption.cells, disruption.until
            cause = "zone closed"
        t = disruption.t
        motions = {v: Motion(v, self.starts[v - 1], tuple(self.driven[v]))
                   for v in self.vehicles if v not in self.down}
        result = cascade(self.executor.store, t, motions, first, self._goods_pending(t), zone,
                         until)
        goods: list[Cell] = []
        for vehicle, freeze in sorted(result.freezes.items()):
            goods += self._freeze(freeze)
            down = vehicle in first
            if down:
                self.down[vehicle] = freeze
            why = cause if down or zone else "its plan crossed a stopped forklift's cells"
            self.record.halts.append((vehicle, t, why))
            self.drive_log[vehicle].append(("stop" if down else "cut", t))
            self._emit(self._halt_event(freeze, why, moving=not down), t)
        if zone:
            self._emit(ZoneClosed(sorted(result.zone), t, until), t)
        broken = isinstance(disruption, VehicleDown) and disruption.cause == BREAKDOWN
        self.executor.freeze(t, list(result.freezes.values()), goods, result.zone, until,
                             moving=[v for v in result.freezes if v not in self.down],
                             standing=sorted(first) if broken else [])

    def _goods_pending(self, t: float) -> Callable[[Cell], int | None]:
        """Which forklift's delivery, not yet arrived at t, reserved goods on a cell."""
        cut = set(self.record.cut_subtasks)
        pending = {s.stack_cell: s.vehicle for i, s in enumerate(self.record.subtasks)
                   if i not in cut and s.kind is TaskKind.DELIVER and s.t_end > t and
                   s.stack_cell is not None}
        return pending.get

    def _freeze(self, freeze: Freeze) -> list[Cell]:
        """Cut the forklift's plan after the maneuver in progress at freeze.t: its subtasks
        not yet arrived are cancelled (a delivery's stack goes back to the queue). Returns
        the stack cells whose goods reservations go with them."""
        t, vehicle = freeze.t, freeze.vehicle
        v = self.vehicles[vehicle]
        cut = set(self.record.cut_subtasks)
        undone = [i for i, s in enumerate(self.record.subtasks)
                  if s.vehicle == vehicle and i not in cut and s.t_end > t]
        goods = []
        if undone:
            before = self.before[undone[0]]
            v.next_task, v.linked_cluster, v.linked_kind = \
                before.next_task, before.linked_cluster, before.linked_kind
            v.busy_s, v.wait_s = before.busy_s, before.wait_s
            v.t_free = freeze.t_stand
        else:
            v.t_free = max(v.t_free, freeze.t_stand)
        for i in undone:
            self.record.cut_subtasks.append(i)
            s = self.record.subtasks[i]
            if s.kind is TaskKind.DELIVER and s.stack_index is not None:
                goods.append(self._reopen(s, t))
        v.pose = freeze.pose
        self.driven[vehicle] = [c for c in (_truncated(traj, freeze)
                                            for traj in self.driven[vehicle]) if c is not None]
        return goods

    def _reopen(self, s: Subtask, t: float) -> Cell:
        stack = next(st for st in self.layout.stacks
                     if st.cluster == s.target and st.index == s.stack_index)
        fill = self.mission.kind is MissionKind.FILL
        queue = self.queue[s.target]
        queue.append(stack)
        queue.sort(key=lambda st: st.index if fill else -st.index)
        self.present.discard(stack.cell)
        self.record.stacks_done.remove((s.target, stack.index, s.t_done))
        self.record.end_time = max((d[2] for d in self.record.stacks_done), default=0.0)
        self._emit(StackReopened(s.target, stack.index, s.vehicle, t), t)
        return stack.cell

    def _resume(self, up: VehicleUp) -> None:
        freeze = self.down.pop(up.vehicle, None)
        if freeze is None:
            return
        v = self.vehicles[up.vehicle]
        shift = up.t - freeze.t
        t_stand = up.t
        if freeze.step is not None:  # the rest of the maneuver, from where it stood
            step = dataclasses.replace(freeze.step, t0=freeze.step.t0 + shift,
                                       t1=freeze.step.t1 + shift)
            t_stand = step.t1
            self.driven[up.vehicle].append(Trajectory(up.vehicle, step.start, step.end,
                                                      step.t0, (step,), (), 0))
        v.t_free = max(v.t_free, t_stand)
        fill = self.mission.kind is MissionKind.FILL
        self.executor.resume(up.vehicle, freeze, up.t,
                             loaded=(v.next_task is TaskKind.DELIVER) == fill)
        self.record.resumes.append((up.vehicle, up.t))
        self.drive_log[up.vehicle].append(("resume", up.t))
        self._emit(Resume(up.vehicle, up.t, t_stand), up.t)

    def _halt_event(self, freeze: Freeze, cause: str, moving: bool) -> Halt:
        at = self.vehicle_kind.at_rest(freeze.pose) if freeze.step is None else \
            self.vehicle_kind.on_step(freeze.step, freeze.t)
        ox, oy = self.layout.origin
        return Halt(freeze.vehicle, freeze.t, cause, moving, str(freeze.pose), freeze.t_stand,
                    sorted(freeze.cells), at.x + ox, at.y + oy, at.theta)

    def _collect(self, decision: Decision, traj: Trajectory | None,
                 remaining: dict[str, int]) -> None:
        """Training targets of Equations (6)/(10) for every scored cluster."""
        p = self.options.params
        names = self.dispatcher.cluster_names
        u = tuple(self.dispatcher.mlp_inputs([v.view() for v in self.vehicles.values()],
                                             remaining))
        mean_trip = sum(self.trip_times) / len(self.trip_times) if self.trip_times else 0.0
        for score in decision.scores:
            base = score.value - p.C1 * score.target.remaining if \
                self.mission.strategy.value == "ann" else score.J0
            if score.target.name == decision.target.name:
                if traj is None:
                    target = p.C5
                else:
                    norm = p.C7 if score.target.far else p.C8
                    target = base - p.C6 * (traj.t_end - decision.t_i - mean_trip + norm)
            else:
                target = base
            self.record.training_samples.append((u, names.index(score.target.name), target))


def run_mission(mission: Mission, options: EngineOptions | None = None,
                layout: Layout | None = None) -> MissionRecord:
    return Engine(mission, options, layout).run()


def lower_bound(layout: Layout, kind: MissionKind, vehicles: int,
                params: DispatchParams | None = None) -> float:
    """A lower bound on the mission end time: every subtask at its unobstructed shortest time
    (an empty reservation table, the best station for each stack), shared ideally among the
    vehicles: sum over stacks of (trip from the station + handling + trip back + handling),
    divided by the number of vehicles."""
    p = params or DispatchParams()
    fill = kind is MissionKind.FILL
    total = 0.0
    present: set[Cell] = set() if fill else {s.cell for s in layout.stacks}
    order = sorted(layout.stacks, key=lambda s: (s.cluster, s.index if fill else -s.index))
    empty = ReservationTable()
    planners = layout.vehicle_kind.planners(layout.grid_map)
    for stack in order:
        key = frozenset(present - {stack.cell})
        planner = planners.get(key)
        goals = layout.unload_poses(stack.cell, key)
        best = math.inf
        for st in layout.stations:
            out = planner.plan(1, st.dock, 0.0, goals, empty)
            if isinstance(out, Trajectory):
                back = planner.plan(1, out.goal, 0.0, [st.dock], empty)
                if isinstance(back, Trajectory):
                    best = min(best, out.t_end + back.t_end)
        if best == math.inf:
            raise LayoutError(f"layout {layout.name}: stack {stack.cluster}#{stack.index} cannot "
                              f"be served from any station, even on an empty floor (fleet "
                              f"layout check lists every such stack)")
        total += best + p.t_claim + p.t_unload
        if fill:
            present.add(stack.cell)
        else:
            present.discard(stack.cell)
    return total / vehicles


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
