"""In-process reference engine: a deterministic discrete-event run of a whole mission.

Algorithm 4 of seed 000: while work is left, the dispatch policy (Algorithm 1) picks a vehicle,
an instant t_i and a goal; the vehicle's improved hybrid A* plans against the reservation
table; a found trajectory is committed (the vehicle's old parking is released from t_i on) and
the work advances; a failed one sets `fail` and the policy re-selects. Subtasks are decided in
order of the vehicles' free times, so this is the discrete-event order of the mission. No wall
clock and no randomness enter the record: the same mission gives the same record, bit for bit.
The distributed runtime must reproduce it.

The engine keeps the loop; what it decides with lives beside it: the mission's work
(fleet/mission/work.py), the dispatch policy (fleet/dispatching/policy.py), the answer to
faults (fleet/mission/fault_response.py), and the forklifts through the Executor and Pacer
seam (fleet/mission/seam.py).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Collection, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from fleet.dispatching.algorithm1 import MlpFn
from fleet.dispatching.decision import (
    Decision,
    DispatchOutcome,
    Strategy,
    Target,
    TaskKind,
    VehicleView,
)
from fleet.dispatching.policy import PolicySetup, dispatch_policy
from fleet.errors import UserError
from fleet.mission.deadlock import Wait, WaitKind, deadlocks
from fleet.mission.drive_log import AddLeg, AmendLeg, DriveLog
from fleet.mission.driving import states_until
from fleet.mission.fault_response import FaultResponse
from fleet.mission.freeze import Disruption, VehicleDown
from fleet.mission.mission_work import mission_work
from fleet.mission.order_log import WorkLog
from fleet.mission.order_work import order_fleet
from fleet.mission.pickup import Recovered
from fleet.mission.record import (
    FailureEvent,
    MissionRecord,
    Subtask,
    amended_event,
    subtask_event,
)
from fleet.mission.seam import Executor, LocalExecutor, NoPacer, Pacer, Task, VehicleLost
from fleet.mission.spec import Mission, MissionKind
from fleet.mission.standstill import Cause, Standstill, failure_text, standstill
from fleet.mission.step_aside import SIDINGS_OFFERED, SentAside, break_deadlock
from fleet.mission.vehicle_slot import VehicleSlot
from fleet.params import DispatchParams
from fleet.planning.blockage import Blockage, held_for_good
from fleet.planning.trajectory import PlanFailure, Pose, Trajectory
from fleet.vehicles.kind import Planner
from fleet.wire.protocol import DeadlockSeen, DecisionFailure, Message, StackDone
from fleet.world.layout import Layout
from fleet.world.layout_file import load_layout
from fleet.world.site import planners_for

# A vehicle whose plans failed this often since the last subtask, on a way nobody parked
# for good closes, waits for those on its shortest way (see Engine._wait).
REPLANS_BEFORE_SHORTEST = 2
# The same for every vehicle after this many failed decisions in a row, since the preliminary
# A* may fail every choice before a plan is tried (fault-free runs on `paper` reach 238 with
# comprehensive, which breaks no deadlock: a lower count would move vehicles there that the
# way of fewest moves only seems to need).
DECISIONS_BEFORE_SHORTEST = 100


def goals_of(targets: Sequence[Target]) -> tuple[Pose, ...]:
    """Every pose the targets' subtasks may end at, each once, in the targets' order."""
    return tuple(dict.fromkeys(goal for target in targets for goal in target.goals))


class MissionStuck(UserError):
    """No subtask could be planned for a long run of attempts (the layout or fleet leaves
    no way forward); the message says when and what failed last, `standstill` how far the
    mission got and where each forklift stood."""

    def __init__(self, standstill: Standstill) -> None:
        super().__init__(standstill.reason)
        self.standstill = standstill


@dataclass(frozen=True)
class Planned:
    """A decision and what planning it gave (None: no trajectory), with every vehicle and the
    work left as they were when it was decided: what a training observer learns from."""

    decision: Decision
    trajectory: Trajectory | None
    fleet: tuple[VehicleView, ...]
    remaining: dict[str, int]


@dataclass(frozen=True)
class EngineOptions:
    params: DispatchParams = field(default_factory=DispatchParams)
    mlp: MlpFn | None = None
    # Score every target of a decision, even those that cannot win: what training learns
    # from (the choice is the same either way).
    score_every_target: bool = False
    max_consecutive_failures: int = 400
    # After this many failures in a row the fleet may be stuck on a choice rather than on the
    # layout: a forklift then skips the targets it failed to reach since the last success.
    unstick_after: int = 300
    # Observers, each told as it happens. After each commit: stacks done, total, the sim time
    # the mission has reached, failures.
    progress: Callable[[int, int, float, int], None] | None = None
    # Each subtask, stack done and decision failure, with its sim time (the dispatcher
    # publishes them; the in-process run records them).
    events: Callable[[Message, float], None] | None = None
    # Each decision once planned (training collects its samples from these).
    planned: Callable[[Planned], None] | None = None
    # The dispatcher's journal, which a restarted dispatcher reads: what an order mission's
    # work is fed, and where each forklift that went down stopped.
    work_log: WorkLog | None = None


def engine_options(mission: Mission, layout: Layout, weights: Path | None,
                   progress=None) -> EngineOptions:
    """The engine's options for the mission: with --strategy ann, the scorer of --weights (or
    of the weights shipped for the layout), loaded here so that bad weights are refused
    before anything starts."""
    mlp = None
    if mission.strategy is Strategy.ANN:
        from fleet.dispatching.scorer import load_scorer

        mlp = load_scorer(layout, weights)
    return EngineOptions(mlp=mlp, progress=progress)


@dataclass
class FailureStreak:
    """The decisions that came to nothing since the last committed subtask."""

    failed: list[int] = field(default_factory=list)  # vehicles whose plan failed, in order
    count: int = 0
    tried: dict[int, set[str]] = field(default_factory=dict)  # targets each failed to reach
    plans_failed: dict[int, int] = field(default_factory=dict)  # per vehicle

    def succeeded(self) -> None:
        self.failed, self.count, self.tried, self.plans_failed = [], 0, {}, {}

    def undecided(self) -> None:
        self.count += 1

    def plan_failed(self, vehicle: int, target: str) -> None:
        self.tried.setdefault(vehicle, set()).add(target)
        self.plans_failed[vehicle] = self.plans_failed.get(vehicle, 0) + 1
        self.failed = [v for v in self.failed if v != vehicle] + [vehicle]
        self.count += 1

    def forget(self, vehicles: Collection[int]) -> None:
        """These vehicles are decided for at a new instant (postponed, or lost)."""
        self.failed = [v for v in self.failed if v not in vehicles]


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
        self.planners = planners_for(self.layout)
        self.executor = executor or LocalExecutor(self.vehicle_kind, self.planners)
        self.pacer = pacer or NoPacer()
        starts = list(mission.starts or self.layout.vehicle_starts)
        n = mission.vehicles if mission.vehicles is not None else len(starts)
        if mission.kind is MissionKind.ORDERS and not mission.starts:
            n = order_fleet(self.layout, mission.vehicles)
        self.work = recovered.work if recovered is not None and recovered.work is not None \
            else mission_work(mission, self.layout, self.options.params, self.executor.store,
                              self.planners, n, self.options.work_log)
        starts = starts or list(self.work.start_poses())  # order missions: on the piles
        if not 1 <= n <= len(starts):
            raise UserError(f"{n} vehicles requested but layout {self.layout.name} has "
                             f"{len(starts)} start poses")
        self.fleet = {i + 1: VehicleSlot(i + 1, pose, self.work.ready_at, TaskKind.DELIVER,
                                         t_still=self.work.ready_at)
                      for i, pose in enumerate(starts[:n])}
        self.record = MissionRecord(mission, self.layout.name, tuple(self.fleet),
                                    tuple(starts[:n]))
        # What each forklift's agent was told, in order: an in-process run drives its
        # states from it.
        self.drive_log: DriveLog = {v: [] for v in self.fleet}
        self.faults = FaultResponse(self.fleet, self.record.starts, self.executor, self.work,
                                    self.record, self.drive_log, self.layout, self._emit,
                                    self.pacer, self.options.work_log)
        self.streak = FailureStreak()
        self.waits: dict[int, Wait] = {}  # the wait-for graph, as of the table's revision
        self.waiting_since: dict[int, float] = {}  # priority: the longest waiting goes first
        self.failed_at: dict[int, float] = {}  # the instant each vehicle last failed at
        self.asides = 0  # vehicles sent aside since the last subtask of the work
        self.parked_held: set[int] = set()  # held back, and sent to park (or tried to)
        self.released: set[int] = set()  # let go though the work holds them back
        self.let_go_at: list[tuple[float, int]] = []  # (instant, vehicle) of each let go
        # The stack (order) each subtask served, by their indices in the record: a subtask
        # postponed later (seed 002) serves it that much later.
        self.served_by: dict[int, int] = {}
        self.said_walled: set[tuple[int, int]] = set()  # (vehicle, revision) reported
        self.now = 0.0  # the instant the clock was last moved to
        self.decisions_at_now = 0  # decisions taken since the clock last moved
        self.undelivered: tuple[tuple[str, int, float, int], ...] = ()
        if recovered is not None:  # a restarted dispatcher: where the forklifts really are
            self._pick_up(recovered)
        for v in self.fleet.values():
            self.executor.park(v.vehicle, v.pose)
        self.policy = dispatch_policy(PolicySetup(
            mission.strategy, self.layout, self.executor.store,
            lambda: self.layout.grid_map(self.work.filled), self.options.params,
            self.options.mlp, self.options.score_every_target, mission.lookahead))

    def active(self) -> list[VehicleSlot]:
        """Vehicles with something left to do (any return, or a delivery while work waits)
        that the work does not hold back."""
        busy, held = self._busy()
        return [v for v in busy if v.vehicle not in held]

    def _held_back(self) -> list[VehicleSlot]:
        busy, held = self._busy()
        return [v for v in busy if v.vehicle in held]

    def _held(self) -> frozenset[int]:
        return self._busy()[1]

    def _busy(self) -> tuple[list[VehicleSlot], frozenset[int]]:
        """The vehicles that are up and have something left to do, and those of them the
        work holds back (unless let go)."""
        up = [v for v in self.fleet.values() if v.vehicle not in self.faults.down]
        views = [v.view() for v in up]
        busy = [v for v, view in zip(up, views, strict=True) if self.work.busy(view)]
        return busy, self.work.held_back(views, len(self.fleet)) - self.released

    def targets_for(self, view: VehicleView) -> list[Target]:
        """Where the forklift may go next; once the fleet is stuck, not where it failed to
        go since the last success, while it has somewhere else to try (the preliminary A*
        sees cells, not turns, and may keep choosing a station the forklift cannot reach)."""
        targets = self.work.targets(view, {v.vehicle: v.pose for v in self.fleet.values()})
        stuck = self.streak.count >= self.options.unstick_after
        tried = self.streak.tried.get(view.vehicle, set()) if stuck else set()
        return [t for t in targets if t.name not in tried] or targets

    # -- the run -------------------------------------------------------------------------------
    def _pick_up(self, r: Recovered) -> None:
        """Start from what a restarted dispatcher found: where the forklifts are, the stacks
        done, the legs committed."""
        for v in self.fleet.values():
            v.pose, v.t_free = r.poses[v.vehicle], r.t_free[v.vehicle]
            v.t_still = v.t_free
            halted = r.down.get(v.vehicle)  # down: what it was to do next, as journaled
            v.next_task = halted.next_task if halted is not None else \
                TaskKind.DELIVER if r.delivers_next[v.vehicle] else TaskKind.RETURN
        t_unload = self.work.handling(TaskKind.DELIVER)
        for cluster, index, t_done in (*r.done, *((c, i, t + t_unload)
                                                  for c, i, t, _ in r.undelivered)):
            self.work.pick_up(cluster, index)
            self.record.stacks_done.append((cluster, index, t_done))
        self.record.end_time = max((d[2] for d in self.record.stacks_done), default=0.0)
        self.undelivered = r.undelivered
        self.faults.picked_up(r.poses, r.legs, r.down)
        self.now = r.t

    def run(self) -> MissionRecord:
        self._reserve_undelivered()
        while (active := self._next_active()) is not None:
            self._decide(active)
        if self.work.work_left():  # only vehicles down for good could still do it
            left = self.work.total - len(self.record.stacks_done)
            raise MissionStuck(self.standstill(Cause.STUCK, (
                f"the mission cannot finish: {left} of {self.work.total} not done by "
                f"t={self.now:.2f} s, with vehicles "
                f"{', '.join(map(str, sorted(self.faults.down)))} down for good")))
        rec = self.record
        rec.all_parked_time = max((s.t_end for s in rec.subtasks), default=0.0)
        self.pacer.finish(states_until(max(rec.end_time, rec.all_parked_time)))
        rec.busy_s = {v.vehicle: v.busy_s for v in self.fleet.values()}
        rec.wait_s = {v.vehicle: v.wait_s for v in self.fleet.values()}
        return rec

    def _reserve_undelivered(self) -> None:
        """Goods the last dispatcher did not get to reserve: the forklift handled them."""
        t_unload = self.work.handling(TaskKind.DELIVER)
        for cluster, index, t_end, vehicle in self.undelivered:
            cell = next(s.cell for s in self.layout.stacks
                        if s.cluster == cluster and s.index == index)
            self.executor.reserve_goods([self.work.goods_after(cell, t_end, t_end + t_unload)])
            self._emit(StackDone(cluster, index, vehicle, t_end + t_unload), t_end + t_unload)

    def _next_active(self) -> list[VehicleSlot] | None:
        """The vehicles to decide for next, once every disruption up to their instant is
        applied; None once the mission is over (or the forklifts left are down for good).
        What the work takes as happening by itself (an order mission's arrivals) comes in
        time order with the disruptions: one at the instant of a fault comes after it (a
        trip cut short never arrived)."""
        while True:
            active = self.active()
            t_next = min((v.t_free for v in active), default=math.inf)
            t_work = self.work.next_event()
            if not active and not self.faults.down and t_work == math.inf:
                return None
            disruptions = self.pacer.disruptions(min(t_next, t_work),
                                                 frozenset(self.faults.down))
            if disruptions:
                for disruption in disruptions:
                    self._disrupt(disruption)
                continue
            if t_work <= t_next and t_work < math.inf:
                self._advance_work(t_work)
                continue
            for v in self._held_back():  # waits on: once let go, it is decided for from now
                if v.t_free < t_next < math.inf:
                    v.wait_until(t_next)
            return active or None

    def _advance_work(self, t: float) -> None:
        """The work takes what happens by itself up to t; the vehicles it gives something
        to do are free for it from then on."""
        for vehicle, t_given in self.work.advance(t).items():
            self.fleet[vehicle].wait_until(max(t_given, self.fleet[vehicle].t_free))

    def _disrupt(self, disruption: Disruption) -> None:
        # What the work had still to take before it happened first (a real-time clock
        # notices a fault a margin ahead of now, and the work may be behind now).
        while (t_work := self.work.next_event()) < disruption.t:
            self._advance_work(t_work)
        self.streak.tried = {}  # the table changes: a target that failed may not fail now
        self.waits = {}  # and who can move, whatever the table's revision says
        self.parked_held = set()  # a park cut short may have stopped anywhere
        for v in self._held_back():  # let go by it, decided for from its instant on
            v.wait_until(max(v.t_free, disruption.t))
        self.faults.disrupt(disruption)

    def _decide(self, active: list[VehicleSlot]) -> None:
        """One decision at the earliest free time, planned and committed if it can be."""
        t_next = min(v.t_free for v in active)
        self.decisions_at_now = self.decisions_at_now + 1 if t_next == self.now else 0
        self.now = t_next
        paced = self.pacer.before_decision(t_next, {v.vehicle: v.t_free for v in active})
        for v in active:
            v.wait_until(paced[v.vehicle])
        self._park_held_back()
        active = [v for v in active if v.vehicle not in self.faults.down]  # lost parking one
        if not active:
            return
        remaining = self.work.remaining()
        outcome = self.policy.decide([v.view() for v in active], self.streak.failed,
                                     self.targets_for, remaining)
        self._choices_failed(outcome)
        for vehicle, t_free in outcome.postponements.items():
            self.fleet[vehicle].wait_until(t_free)
        self.streak.forget(outcome.postponements)
        for f in outcome.failures:
            self._failed_again(f.vehicle, f.t_i)
        if outcome.decision is None:
            self.streak.undecided()
            self._passed_over(active, outcome)
            self._break_deadlocks()
        else:
            self._carry_out(outcome.decision, remaining)
        # Stuck once every forklift stands still, or (the last resort against a hang) once
        # the clock stood at one instant for as many decisions.
        limit = self.options.max_consecutive_failures
        if self.streak.count > limit and (self._at_rest() or self.decisions_at_now > limit):
            raise MissionStuck(self.standstill(Cause.STUCK, (
                f"{self.streak.count} decisions in a row failed by t={self.now:.2f} s; the "
                f"last: {failure_text(self.record.failures[-1])}")))

    def _at_rest(self) -> bool:
        """Whether every forklift that is up stands still by now: while one still drives or
        handles goods, the ways it holds open up once it is decided for again."""
        return all(v.t_still <= self.now for v in self.fleet.values()
                   if v.vehicle not in self.faults.down)

    def standstill(self, cause: Cause, reason: str) -> Standstill:
        """How far the mission got, as it stops now (fleet/mission/standstill.py)."""
        return standstill(cause, reason, self.now, self.fleet.values(), self.faults.down,
                          self.record, self.streak, self.work.total)

    def _carry_out(self, decision: Decision, remaining: dict[str, int]) -> None:
        try:
            result = self._plan(decision)
        except VehicleLost as exc:  # gone without a scheduled fault: recover all the same
            self._disrupt(VehicleDown(exc.vehicle, self.pacer.instant(self.now),
                                      f"agent lost: {exc}"))
            self.streak.forget({exc.vehicle})
            return
        traj = result if isinstance(result, Trajectory) else None
        if self.options.planned is not None:
            self.options.planned(Planned(decision, traj, tuple(v.view() for v in
                                                               self.fleet.values()), remaining))
        if isinstance(result, Trajectory):
            self._apply(decision, result)
            self.streak.succeeded()
            self.asides = 0
            self.waiting_since.pop(decision.vehicle, None)
        else:
            self.streak.plan_failed(decision.vehicle, decision.target.name)
            self._failed(FailureEvent(decision.t_i, decision.vehicle, "plan",
                                      result.reason.value))
            self._failed_again(decision.vehicle, decision.t_i)
            self._break_deadlocks()

    # -- held back (fleet/mission/work.py, `held_back`) ----------------------------------------
    def _park_held_back(self) -> None:
        """A vehicle the work holds back, once it stands still, goes to the nearest free
        parking place, out of the way of the work, once for each time it is held back (if
        none can be reached, the deadlock breaker may still move it)."""
        held = {v.vehicle: v for v in self._held_back()}
        self.parked_held &= set(held)
        in_the_way = self.work.keep_clear()
        planner = self.planners.get(self.work.filled)
        for vehicle, v in held.items():
            if vehicle in self.parked_held or v.t_still > self.now:
                continue
            self.parked_held.add(vehicle)
            on_work = not in_the_way.isdisjoint(planner.rest_cells(v.pose))
            if v.pose in self.work.parking() and not on_work:
                continue
            places = self._parking_places(v)[:SIDINGS_OFFERED]
            trajectory = self._send_aside(vehicle, places) if places else None
            if trajectory is not None:
                self._sent_aside(SentAside(vehicle, trajectory, vehicle), "park",
                                 breaks_deadlock=False)
            elif on_work:
                self._let_go({vehicle})  # it cannot stay on a dock or a stack to do

    def _let_go(self, vehicles: set[int]) -> None:
        """Decided for though the work holds them back, until they have fetched goods."""
        for vehicle in sorted(vehicles - self.released):
            self.released.add(vehicle)
            self.let_go_at.append((self.now, vehicle))

    def _parking_places(self, v: VehicleSlot) -> tuple[Pose, ...]:
        """The work's parking places nobody holds for good, off the cells the work still
        needs and the ways the waiting vehicles wait on, nearest first."""
        store = self.executor.store
        planner = self.planners.get(self.work.filled)
        needed = set(self.work.keep_clear()).union(
            *(w.blockage.cells for w in self.waits.values() if w.blockage is not None))
        free = [p for p in self.work.parking()
                if p != v.pose and all(held_for_good(store, v.vehicle, c) is None
                                       and c not in needed for c in planner.rest_cells(p))]
        return tuple(sorted(free, key=lambda p: (abs(p.cell[0] - v.pose.cell[0])
                                                 + abs(p.cell[1] - v.pose.cell[1]),
                                                 p.cell, p.heading)))

    # -- deadlocks (fleet/mission/deadlock.py, fleet/mission/step_aside.py) -------------------
    def _break_deadlocks(self) -> None:
        """Once every vehicle with work had a chance to fail since the last subtask, find the
        ones stuck for good and send one vehicle aside to free the longest waiting."""
        active = self.active()
        if self.streak.count < len(active) or self.asides >= 3 * len(self.fleet):
            return  # not all tried yet; or sending aside goes round in circles: give up
        store = self.executor.store
        planner = self.planners.get(self.work.filled)
        poses = {v.vehicle: v.pose for v in self.fleet.values()}

        def movable(owner: int) -> bool:
            return owner in self.fleet and owner not in self.faults.down

        # Still driving or handling: it moves by itself, and is decided for again after.
        idle = {v.vehicle for v in self.fleet.values()
                if v.vehicle not in self.faults.down and v.t_still <= self.now}
        self.waits = {v: w for v, w in self.waits.items() if w.revision == store.revision}
        held = self._held()
        for v in active:
            if v.vehicle not in idle:
                continue
            offered = self.work.targets(v.view(), poses)
            if not offered:
                # Offered nothing to do now: it cannot move by itself. It waits for the
                # held-back vehicles in the way of its work, if any: they never move by
                # themselves (any other in its way will, once it is decided for again).
                way = self.work.in_the_way(v.view(), poses) if held else None
                blockers = way.blockers & held if way else None
                if blockers:
                    idle.discard(v.vehicle)
                    self.waits[v.vehicle] = Wait(v.vehicle, dataclasses.replace(
                        way, blockers=blockers), store.revision)
                    self.waiting_since.setdefault(v.vehicle, self.now)
                continue
            idle.discard(v.vehicle)
            known = self.waits.get(v.vehicle)
            if known is None or (not known.shortest and not known.blockers
                                 and self._replanned(v.vehicle)):
                self.waits[v.vehicle] = self._wait(v, goals_of(offered), planner, movable)
            self.waiting_since.setdefault(v.vehicle, self.now)
        # A held-back vehicle in the way that cannot step aside has the ones walling it in
        # sent aside first: its way to another parking place.
        held_ways = {v.vehicle: Wait(v.vehicle, planner.blockage(
            v.vehicle, v.pose, [p for p in self.work.parking() if p != v.pose], store,
            movable), store.revision)
            for v in self.fleet.values() if v.vehicle in held and v.vehicle in idle}
        found = deadlocks(self.waits, idle, self.waiting_since)
        for deadlock in found:
            if deadlock.kind is WaitKind.WALLED:
                if (deadlock.waiting, store.revision) not in self.said_walled:
                    self.said_walled.add((deadlock.waiting, store.revision))
                    self._seen(DeadlockSeen(self.now, deadlock.waiting, deadlock.kind.value,
                                            list(deadlock.chain), None, None, None))
                continue
            waiting = self.fleet[deadlock.waiting]
            sent = break_deadlock(deadlock, held_ways | self.waits, planner, store, poses,
                                  self.work.keep_clear(), self._move_aside,
                                  lambda w=waiting: self._ways(w, planner, movable, poses))
            if sent is not None:
                self._seen(DeadlockSeen(self.now, deadlock.waiting, deadlock.kind.value,
                                        list(deadlock.chain), sent.vehicle,
                                        str(sent.trajectory.goal), sent.for_vehicle))
                self._sent_aside(sent)
                return
        # None could be sent aside: the held-back vehicles in the way are let go for goods,
        # out by the way every forklift takes.
        for deadlock in found:
            if deadlock.kind is not WaitKind.WALLED:
                self._let_go((set(deadlock.chain) | self.waits[deadlock.waiting].blockers)
                             & held)

    def _wait(self, v: VehicleSlot, goals: tuple[Pose, ...], planner: Planner,
              movable: Callable[[int], bool]) -> Wait:
        """The vehicle's way to the goals the work offers it, as the wait-for graph sees it.
        Only what is offered: a way open to a stack the work holds back does not move it. A
        way that crosses nobody parked for good but that its plans kept failing to find (the
        search gives up on long detours) counts as blocked by whoever stands on its shortest
        way."""
        store = self.executor.store
        way = planner.blockage(v.vehicle, v.pose, goals, store, movable)
        if way is not None and not way.blockers and self._replanned(v.vehicle):
            way = planner.blockage(v.vehicle, v.pose, goals, store, movable, shortest=True)
            return Wait(v.vehicle, way, store.revision, shortest=True)
        return Wait(v.vehicle, way, store.revision)

    def _ways(self, v: VehicleSlot, planner: Planner, movable: Callable[[int], bool],
              poses: dict[int, Pose]) -> list[Blockage]:
        """The vehicle's way to each pose the work offers its next subtask, fewest blockers
        first: where the way past fewest vehicles cannot be opened, another may (24
        forklifts on 16 docks, docs/dispatching.md)."""
        store = self.executor.store
        ways = (planner.blockage(v.vehicle, v.pose, [goal], store, movable)
                for goal in goals_of(self.work.targets(v.view(), poses)))
        return sorted((w for w in ways if w is not None), key=lambda w: len(w.blockers))

    def _replanned(self, vehicle: int) -> bool:
        """Whether its plans, or every decision, kept failing since the last subtask (the
        preliminary A* may fail every choice without a plan being tried)."""
        return (self.streak.plans_failed.get(vehicle, 0) >= REPLANS_BEFORE_SHORTEST
                or self.streak.count >= DECISIONS_BEFORE_SHORTEST)

    def _seen(self, deadlock: DeadlockSeen) -> None:
        self.record.deadlocks.append(deadlock)
        self._emit(deadlock, deadlock.t)

    def _move_aside(self, vehicle: int, sidings: tuple[Pose, ...]) -> Trajectory | None:
        """Out of another's way: a held-back vehicle to a parking place out of every way if
        it can reach one, else (and any other vehicle) to the nearest siding."""
        v = self.fleet[vehicle]
        if vehicle in self._held():
            places = self._parking_places(v)[:SIDINGS_OFFERED]
            trajectory = self._send_aside(vehicle, places) if places else None
            if trajectory is not None:
                return trajectory
        return self._send_aside(vehicle, sidings)

    def _send_aside(self, vehicle: int, sidings: tuple[Pose, ...]) -> Trajectory | None:
        """Plan and commit the vehicle's move to the nearest siding it can reach."""
        v = self.fleet[vehicle]
        if v.t_still > self.now:
            return None  # driving or handling until later: it can go from then, not now
        t_i = self.pacer.before_decision(self.now, {vehicle: self.now})[vehicle]
        try:
            result = self.executor.execute(Task(vehicle, TaskKind.ASIDE, v.pose, t_i, sidings,
                                                self.work.filled,
                                                loaded=self.work.loaded(v.next_task)))
        except VehicleLost as exc:
            self._disrupt(VehicleDown(exc.vehicle, self.pacer.instant(self.now),
                                      f"agent lost: {exc}"))
            return None
        return result if isinstance(result, Trajectory) else None

    def _sent_aside(self, sent: SentAside, why: str = "",
                    breaks_deadlock: bool = True) -> None:
        v, traj = self.fleet[sent.vehicle], sent.trajectory
        self.faults.committed(dataclasses.replace(v), traj)
        waited = sum(s.t1 - s.t0 for s in traj.steps
                     if self.vehicle_kind.is_wait(s.manner.label))
        v.step_aside(traj, waited)
        self.drive_log[v.vehicle].append(AddLeg(traj, self.work.loaded(v.next_task)))
        subtask = Subtask(v.vehicle, TaskKind.ASIDE, why or f"aside for {sent.for_vehicle}",
                          None,
                          None, traj.t_start, traj.t_end, traj.t_end, traj, False)
        self.record.subtasks.append(subtask)
        self._emit(subtask_event(subtask), traj.t_start)
        if breaks_deadlock:  # what the breaker's give-up counts
            self.asides += 1
        self.streak.forget({v.vehicle})

    def _emit(self, message: Message, t: float) -> None:
        if self.options.events is not None:
            self.options.events(message, t)

    def _choices_failed(self, outcome: DispatchOutcome) -> None:
        """Each choice of the policy that came to nothing, a decision failure of its own; the
        last of a dispatch that ended without a decision says so (stage "dispatch")."""
        last = len(outcome.failures) - 1 if outcome.decision is None else -1
        for k, f in enumerate(outcome.failures):
            self._failed(FailureEvent(f.t_i, f.vehicle, "score", f.why) if k != last else
                         FailureEvent(f.t_i, f.vehicle, "dispatch", f"{f.why}; no solid decision "
                                      f"within iter_dispatch={self.options.params.iter_dispatch}"))

    def _failed_again(self, vehicle: int, t_i: float) -> None:
        """A vehicle that fails twice at the instant it is free from is tried again Δt later,
        as the backup state postpones: else one whose way stays closed while the others work
        pins the mission's clock (the earliest free time) and what is due later, a forklift
        coming back up, never comes."""
        v = self.fleet[vehicle]
        if t_i != v.t_free:
            return  # postponed already
        if self.failed_at.get(vehicle) == t_i:
            v.wait_until(t_i + self.options.params.dt_postpone)
            self.streak.forget({vehicle})
        else:
            self.failed_at[vehicle] = t_i

    def _passed_over(self, active: list[VehicleSlot], outcome: DispatchOutcome) -> None:
        """Vehicles due now that a dispatch without a decision never chose (their plan failed
        since the last success, so they wait for the others' choices) are tried again Δt
        later, as the backup state would have postponed them: with more vehicles than
        iter_dispatch choices it is never reached, and one passed over pinned the clock at
        its free instant for good (24 forklifts, docs/dispatching.md)."""
        tried = {f.vehicle for f in outcome.failures}
        for v in active:
            if v.t_free == self.now and v.vehicle not in tried:
                v.wait_until(self.now + self.options.params.dt_postpone)
                self.streak.forget({v.vehicle})

    def _failed(self, failure: FailureEvent) -> None:
        """A decision failure: counted, and announced (dispatch/failure)."""
        self.record.failures.append(failure)
        self._emit(DecisionFailure(failure.t, failure.vehicle, failure.stage, failure.reason),
                   failure.t)

    def _plan(self, decision: Decision) -> Trajectory | PlanFailure:
        """Plan and commit (the executor does both; a failure commits nothing)."""
        v = self.fleet[decision.vehicle]
        return self.executor.execute(Task(v.vehicle, decision.kind, v.pose, decision.t_i,
                                          decision.target.goals, self.work.filled,
                                          loaded=self.work.loaded(decision.kind),
                                          after=self.work.carried_after(decision.kind)))

    def _apply(self, decision: Decision, traj: Trajectory) -> None:
        v = self.fleet[decision.vehicle]
        target = decision.target
        t_done = traj.t_end + self.work.handling(decision.kind)
        served = self.work.serve(decision, traj, t_done)
        if served is not None:
            if served.goods is not None:
                self.executor.reserve_goods([served.goods])
            self.served_by[len(self.record.subtasks)] = len(self.record.stacks_done)
            self.record.stacks_done.append((served.cluster, served.index, t_done))
            # Announced as it is committed (the clock at `now`), as a dispatcher of processes
            # publishes it: a reopening then follows the announcement it takes back.
            self._emit(StackDone(served.cluster, served.index, v.vehicle, t_done), self.now)
            self.record.end_time = max(self.record.end_time, t_done)
        self.faults.committed(dataclasses.replace(v), traj)
        waited = sum(s.t1 - s.t0 for s in traj.steps
                     if self.vehicle_kind.is_wait(s.manner.label))
        v.drive(decision.kind, target.name, traj, t_done, waited,
                self.work.next_task(decision.kind))
        self.released.discard(v.vehicle)
        self.drive_log[v.vehicle].append(AddLeg(traj, self.work.loaded(decision.kind),
                                                self.work.carried_after(decision.kind)))
        subtask = Subtask(v.vehicle, decision.kind, target.name, target.stack_index,
                          target.stack_cell, decision.t_i, traj.t_end, t_done, traj,
                          decision.postponed)
        self.record.subtasks.append(subtask)
        self._emit(subtask_event(subtask), decision.t_i)
        for leg in self.executor.take_amended():
            self._amended(leg)
        if self.options.progress:  # at the instant the clock reached, not the planned arrival
            self.options.progress(len(self.record.stacks_done), self.work.total, self.now,
                                  self.record.decision_failures)


    def _amended(self, leg: Trajectory) -> None:
        """Another vehicle's committed leg was postponed by this commit (seed 002's collision
        rules): it arrives later, and is free that much later."""
        v = self.fleet[leg.vehicle]
        delay = leg.t_end - self.faults.amended(leg).t_end
        mine = [i for i, s in enumerate(self.record.subtasks) if s.vehicle == leg.vehicle]
        if mine and self.record.subtasks[mine[-1]].trajectory.t_start == leg.t_start:
            k = mine[-1]
            before = self.record.subtasks[k]
            after = dataclasses.replace(before, t_end=leg.t_end, trajectory=leg,
                                        t_done=leg.t_end + self.work.handling(before.kind))
            self.record.subtasks[k] = after
            if k in self.served_by:  # what it served is done later (its announcement said then)
                cluster, index, _ = self.record.stacks_done[self.served_by[k]]
                self.record.stacks_done[self.served_by[k]] = (cluster, index, after.t_done)
                self.record.end_time = max(self.record.end_time, after.t_done)
            v.amended(delay, after.t_done)
            self._emit(amended_event(after), self.now)
        else:  # committed before this dispatcher picked the mission up: not in its record
            v.amended(delay, v.t_free + delay)
        self.drive_log[v.vehicle].append(AmendLeg(leg))
        self.work.amended(leg)


def run_mission(mission: Mission, options: EngineOptions | None = None,
                layout: Layout | None = None) -> MissionRecord:
    return Engine(mission, options, layout).run()
