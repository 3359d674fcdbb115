"""The mission-kind seam: the work a mission is made of, owned by one object the engine asks.

A mission kind says what is left and in which order it is done, where a vehicle may go next,
whether it carries goods there, how long handling takes at the end, what an arrival changes
and when the mission is done. The engine decides through it and never asks which kind it
runs. Fill and empty (seed 000) are the first two kinds: both work through the stacks of each
cluster in a fixed order, one goods-carrying trip and one empty trip per stack. Seed 002's
order missions (orders -> shelf -> station -> slot, fleet/mission/order_work.py) are the
third: their order book decides every trip at the instants things happen, which the engine
feeds it (`next_event`, `advance`).
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Sequence
from dataclasses import dataclass
from typing import ClassVar, Protocol

from fleet.dispatching.decision import Decision, Target, TaskKind, VehicleView
from fleet.mission.battery import Battery
from fleet.mission.spec import MissionKind
from fleet.params import DispatchParams
from fleet.planning.blockage import Blockage, held_for_good
from fleet.planning.geometry import Cell
from fleet.planning.reservations import Interval, ReservationView
from fleet.planning.trajectory import Pose, Trajectory
from fleet.vehicles.kind import Planner, Planners
from fleet.world.layout import Layout, Stack


@dataclass(frozen=True)
class StackServed:
    """A delivery arrived: its stack is done at t_done, and the goods hold its cell over
    `goods` (owner GOODS in the table)."""

    cluster: str  # order missions: the shelf
    index: int  # order missions: the order
    t_done: float
    goods: Interval | None  # None: nothing for the table (a shelf travels with its AGV)


@dataclass(frozen=True)
class Reopened:
    """Work a subtask cut short had counted as done, to do again: its unit (a stack, or an
    order: cluster and index as `StackServed` names them) and the cell whose goods
    reservation goes with it (None: nothing in the table)."""

    cluster: str
    index: int
    goods: Cell | None


class MissionWork(Protocol):
    @property
    def ready_at(self) -> float:
        """When every vehicle is free for its first subtask."""

    @property
    def total(self) -> int:
        """Units of work in the whole mission (what progress counts up to)."""

    @property
    def filled(self) -> frozenset[Cell]:
        """The cells goods stand on now: what a planner and the dispatcher's map see."""

    def work_left(self) -> bool:
        """Whether anything is still to be assigned (False: the mission is done once every
        vehicle is home)."""

    def busy(self, view: VehicleView) -> bool:
        """Whether the vehicle has something to do now or next (the engine decides for the
        busy ones only)."""

    def next_task(self, kind: TaskKind) -> TaskKind:
        """What a vehicle does after a subtask of this kind."""

    def next_event(self) -> float:
        """When the work next changes by itself, as time passes (infinity: never)."""

    def advance(self, t: float) -> dict[int, float]:
        """Take what happens up to t; returns the vehicles it gave something to do, and from
        when."""

    def amended(self, trajectory: Trajectory) -> None:
        """A committed leg was postponed (seed 002's collision rules): it arrives later."""

    def remaining(self) -> dict[str, int]:
        """Work still to be assigned, per group of targets (per cluster)."""

    def targets(self, view: VehicleView, poses: dict[int, Pose]) -> list[Target]:
        """Where the vehicle may go for its next subtask, in the order they are offered;
        `poses` are where every vehicle of the fleet stands (or will once it arrives)."""

    def held_back(self, fleet: Sequence[VehicleView], size: int) -> frozenset[int]:
        """The vehicles, of those that are up (`fleet`), that are to wait where they stand
        rather than start their next subtask: none is decided for until that changes.
        `size`: the whole fleet's, those down included (they come back)."""

    def parking(self) -> tuple[Pose, ...]:
        """Where a vehicle the work holds back waits (the nearest free place)."""

    def in_the_way(self, view: VehicleView, poses: dict[int, Pose]) -> Blockage | None:
        """When the vehicle is offered nothing to do: the vehicles standing for good where
        they keep its work from being offered, and the cells that work needs (None: no
        vehicle does; the wait-for graph then takes it as idle)."""

    @abstractmethod
    def loaded(self, kind: TaskKind) -> bool:
        """Whether a vehicle carries goods on a subtask of this kind."""

    def carried_after(self, kind: TaskKind) -> bool | None:
        """Whether it carries goods once it arrives, when that changes at the arrival (None:
        as on the subtask, until its next; `Task.after`)."""

    def battery(self, vehicle: int) -> Battery | None:
        """The vehicle's battery as the mission gives it (None: none is modelled)."""

    @abstractmethod
    def handling(self, kind: TaskKind) -> float:
        """Seconds from arrival to being free again (claiming or unloading)."""

    def serve(self, decision: Decision, trajectory: Trajectory, t_done: float
              ) -> StackServed | None:
        """A decided subtask was committed: the work it does is no longer left."""

    @property
    def goods_off_table(self) -> frozenset[Cell]:
        """Cells whose goods only the planners' static map holds, not the reservation table
        (a zone never closes them: nobody could enter them anyway)."""

    @property
    def goods_stay_if_cancelled(self) -> bool:
        """What a delivery cancelled before it arrived leaves on its stack: True if the goods
        it was to take stay there (their cell is an obstacle again from the cancel on); False
        if the goods it was to place never come (their reservation goes)."""

    def keep_clear(self) -> frozenset[Cell]:
        """Cells a vehicle sent aside should not stop on (where the work still goes)."""

    @property
    def taken_until(self) -> float:
        """The latest instant the work has taken what happened up to (`advance`): a freeze
        never comes before it, for what the work took as done stays done."""

    def cancel(self, vehicle: int, kind: TaskKind, target: str, index: int | None,
               driven: float) -> Reopened | None:
        """A committed subtask was cut short before it arrived (`driven`: the seconds of it
        driven): what it would have done is to do again (None: nothing counted as done)."""

    def down(self, vehicle: int, t: float, cells: frozenset[Cell]) -> dict[int, float]:
        """The vehicle stands for good on `cells` from t until it is `up`; returns the
        vehicles given something to do, and from when, as `advance` does."""

    def up(self, vehicle: int, t: float, pose: Pose) -> dict[int, float]:
        """The vehicle that was down moves again from t, from `pose` (as `advance`)."""

    def closed(self, cells: frozenset[Cell], t: float, until: float) -> dict[int, float]:
        """A zone closes `cells` over [t, until) (as `advance`)."""

    def done_at(self, goods: Interval) -> float | None:
        """When the stack under a goods reservation of the table was done, as a restarted
        dispatcher reads it (None: the goods say it is not)."""

    def pick_up(self, cluster: str, index: int) -> None:
        """A restarted dispatcher found the stack done."""


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


class StackWork(ABC):
    """Seed 000's work: the stacks of each cluster one after another in a fixed order, each
    served by a delivery (to the cluster) and then a return (to a station). The subclasses
    say which way the goods go."""

    def __init__(self, layout: Layout, params: DispatchParams, store: ReservationView,
                 planners: Planners) -> None:
        self.layout = layout
        self.params = params
        self.store = store
        self.planners = planners
        self.queue: dict[str, list[Stack]] = {}  # stacks not yet assigned, in their order
        for s in layout.stacks:
            self.queue.setdefault(s.cluster, []).append(s)
        for stacks in self.queue.values():
            stacks.sort(key=self.order)
        self.present = self.initially_present()  # stack cells with goods on them
        self.far = _far_clusters(layout)

    # what a kind says
    goods_stay_if_cancelled: ClassVar[bool]

    @property
    @abstractmethod
    def ready_at(self) -> float: ...

    @property
    @abstractmethod
    def goods_off_table(self) -> frozenset[Cell]: ...

    @abstractmethod
    def order(self, stack: Stack) -> int:
        """Sorts a cluster's stacks in the order they are done."""

    @abstractmethod
    def initially_present(self) -> set[Cell]: ...

    @abstractmethod
    def loaded(self, kind: TaskKind) -> bool: ...

    def carried_after(self, kind: TaskKind) -> bool | None:
        return None  # a forklift unloads (claims) over a handling time, then drives on

    def battery(self, vehicle: int) -> Battery | None:
        return None  # seed 000 models no battery

    @abstractmethod
    def handling(self, kind: TaskKind) -> float: ...

    @abstractmethod
    def goods_after(self, cell: Cell, t_end: float, t_done: float) -> Interval:
        """The goods' hold on a served stack's cell."""

    @abstractmethod
    def done_at(self, goods: Interval) -> float | None: ...

    @abstractmethod
    def _served(self, cell: Cell) -> None:
        """The goods on a served stack's cell as they are once it is served."""

    @abstractmethod
    def _unserved(self, cell: Cell) -> None:
        """The goods on a reopened stack's cell as they were before it was served."""

    def _candidate(self, view: VehicleView, stack: Stack, poses: dict[int, Pose]
                   ) -> list[Pose]:
        """The poses a vehicle may serve the stack from (none: not now)."""
        return self.layout.unload_poses(stack.cell, self.present - {stack.cell})

    # what the engine asks
    @property
    def total(self) -> int:
        return len(self.layout.stacks)

    @property
    def filled(self) -> frozenset[Cell]:
        return frozenset(self.present)

    def work_left(self) -> bool:
        return any(self.queue.values())

    def remaining(self) -> dict[str, int]:
        return {name: len(q) for name, q in self.queue.items()}

    def busy(self, view: VehicleView) -> bool:
        return view.next_task is TaskKind.RETURN or self.work_left()

    def next_task(self, kind: TaskKind) -> TaskKind:
        return TaskKind.RETURN if kind is TaskKind.DELIVER else TaskKind.DELIVER

    def next_event(self) -> float:
        return math.inf  # the stacks change only when subtasks are committed

    def advance(self, t: float) -> dict[int, float]:
        return {}

    def amended(self, trajectory: Trajectory) -> None:
        raise AssertionError("a forklift's leg is never amended")

    def targets(self, view: VehicleView, poses: dict[int, Pose]) -> list[Target]:
        if view.next_task is TaskKind.RETURN:
            return [Target(st.name, (st.dock,)) for st in self.layout.stations]
        targets = []
        for cluster in self.layout.clusters:
            queue = self.queue.get(cluster.name, [])
            if not queue:
                continue
            stack = queue[0]
            goals = self._candidate(view, stack, poses)
            if goals:
                targets.append(Target(cluster.name, tuple(goals), stack.cell, stack.index,
                                      len(queue), cluster.name in self.far))
        return targets

    def held_back(self, fleet: Sequence[VehicleView], size: int) -> frozenset[int]:
        return frozenset()

    def parking(self) -> tuple[Pose, ...]:
        return self.layout.vehicle_starts

    def in_the_way(self, view: VehicleView, poses: dict[int, Pose]) -> Blockage | None:
        return None

    def keep_clear(self) -> frozenset[Cell]:
        return frozenset({st.dock.cell for st in self.layout.stations}
                         | {s.cell for queue in self.queue.values() for s in queue})

    def serve(self, decision: Decision, trajectory: Trajectory, t_done: float
              ) -> StackServed | None:
        if decision.kind is not TaskKind.DELIVER:
            return None
        stack = self.queue[decision.target.name].pop(0)
        self._served(stack.cell)
        return StackServed(decision.target.name, stack.index, t_done,
                           self.goods_after(stack.cell, trajectory.t_end, t_done))

    @property
    def taken_until(self) -> float:
        return -math.inf  # the stacks change only when subtasks are committed

    def cancel(self, vehicle: int, kind: TaskKind, target: str, index: int | None,
               driven: float) -> Reopened | None:
        if kind is not TaskKind.DELIVER or index is None:
            return None  # a return only takes the forklift back
        return Reopened(target, index, self.reopen(target, index))

    def down(self, vehicle: int, t: float, cells: frozenset[Cell]) -> dict[int, float]:
        return {}  # a frozen forklift is a wall the planners see in the table

    def up(self, vehicle: int, t: float, pose: Pose) -> dict[int, float]:
        return {}

    def closed(self, cells: frozenset[Cell], t: float, until: float) -> dict[int, float]:
        return {}

    def reopen(self, cluster: str, index: int) -> Cell:
        """A delivery was cut short before it arrived: its stack is to do again, its goods as
        they were before the delivery was decided. Returns the stack's cell."""
        stack = next(st for st in self.layout.stacks
                     if st.cluster == cluster and st.index == index)
        queue = self.queue[cluster]
        queue.append(stack)
        queue.sort(key=self.order)
        self._unserved(stack.cell)
        return stack.cell

    def pick_up(self, cluster: str, index: int) -> None:
        stack = next(s for s in self.queue[cluster] if s.index == index)
        self.queue[cluster].remove(stack)
        self._served(stack.cell)


class FillWork(StackWork):
    """Goods claimed at a station go to the stacks in each cluster's fill order."""

    goods_stay_if_cancelled = False  # the goods a cancelled delivery carried never arrive

    @property
    def ready_at(self) -> float:
        return self.params.t_claim  # each forklift first claims goods at its station

    def order(self, stack: Stack) -> int:
        return stack.index

    def initially_present(self) -> set[Cell]:
        return set()

    def loaded(self, kind: TaskKind) -> bool:
        return kind is TaskKind.DELIVER

    def handling(self, kind: TaskKind) -> float:
        return self.params.t_unload if kind is TaskKind.DELIVER else self.params.t_claim

    def goods_after(self, cell: Cell, t_end: float, t_done: float) -> Interval:
        return Interval(cell, t_end, math.inf)  # placed on arrival, for good

    def done_at(self, goods: Interval) -> float | None:
        return goods.t0 + self.params.t_unload if goods.t1 == math.inf else None

    @property
    def goods_off_table(self) -> frozenset[Cell]:
        return frozenset()  # every placed goods' cell is reserved from its delivery on

    def _served(self, cell: Cell) -> None:
        self.present.add(cell)

    def _unserved(self, cell: Cell) -> None:
        self.present.discard(cell)

    def held_back(self, fleet: Sequence[VehicleView], size: int) -> frozenset[int]:
        """An empty forklift waits, parked, rather than fetch goods while as many carry or
        fetch them as the clusters can take (one delivery each at a time), and never so
        many that they could take every dock. Goods beyond what the clusters take wait at
        the docks; once every dock is taken, the empty forklifts can come back to none and
        stand, with nowhere to go, in front of the very stacks the loaded ones wait for (64
        forklifts on 24 docks, docs/benchmarks.md). Once every stack is assigned, an empty
        one has no goods to fetch and stays parked: the docks could not hold the whole
        fleet. A fleet no larger than the docks never takes them all while one of its
        forklifts is empty: it is never held back, and every forklift ends at a dock. The
        whole fleet counts, those down too: a forklift down comes back, and the rules do
        not change with a fault. (Every dock counts: a layout that passes `fleet layout
        check` reaches every stack from every dock.)"""
        if size <= len(self.layout.stations):
            return frozenset()
        empty = frozenset(v.vehicle for v in fleet if v.next_task is TaskKind.RETURN)
        if not self.work_left():
            return empty
        in_flight = len(fleet) - len(empty)
        return empty if in_flight >= self.in_flight_limit() else frozenset()

    def in_flight_limit(self) -> int:
        """The most forklifts that may carry or fetch goods at once, when more forklifts
        than docks."""
        clusters = sum(1 for queue in self.queue.values() if queue)
        return max(1, min(clusters, len(self.layout.stations) - 1))

    def in_the_way(self, view: VehicleView, poses: dict[int, Pose]) -> Blockage | None:
        """A loaded forklift offered no stack waits for the forklifts parked where they keep
        every cluster's next stack from being offered: on the stack's cell, walled in by
        filling it, or across every way out of its unload poses. Without these waits the
        wait-for graph saw it as idle, and the forklifts in its way, with nothing to do
        either, were never sent aside."""
        if view.next_task is not TaskKind.DELIVER:
            return None
        planner = self.planners.get(self.filled)
        blockers: set[int] = set()
        cells: set[Cell] = set()
        goal = None
        for queue in self.queue.values():
            if not queue:
                continue
            offer = self._offer(view, queue[0], poses)
            if offer.poses:
                return None  # offered after all
            if offer.in_the_way:
                blockers |= offer.in_the_way
                unload = self.layout.unload_poses(queue[0].cell, self.present - {queue[0].cell})
                cells |= {queue[0].cell, *(c for p in unload for c in planner.rest_cells(p)),
                          *(c for p in unload for c in planner.exit_cells(p))}
                goal = goal or (unload[0] if unload else None)
        if not blockers or goal is None:
            return None
        return Blockage(goal, frozenset(blockers), frozenset(cells))

    def _candidate(self, view: VehicleView, stack: Stack, poses: dict[int, Pose]
                   ) -> list[Pose]:
        return list(self._offer(view, stack, poses).poses)

    def _offer(self, view: VehicleView, stack: Stack, fleet: dict[int, Pose]) -> Offer:
        """The unload poses a forklift may serve the stack from: none while another forklift
        stands on or will cross the stack's cell, or if filling the stack would wall in
        another where it stands; else those from which a station dock is still reachable once
        the stack is filled (a pose beside the stack may be reachable only by sweeping the
        stack's own cell), and that do not trap the forklift with another parked in its way.
        With them, the forklifts parked for good that keep the others from being offered."""
        vehicle = view.vehicle
        if self.store.conflict(vehicle, stack.cell, view.t_free, math.inf) is not None:
            owner = held_for_good(self.store, vehicle, stack.cell)  # a forklift, not goods
            return Offer((), frozenset({owner}) if owner in fleet else frozenset())
        planner = self.planners.get(frozenset(self.present | {stack.cell}))
        docks = {planner.component(st.dock) for st in self.layout.stations}
        now = self.planners.get(frozenset(self.present))
        docks_now = {now.component(st.dock) for st in self.layout.stations}
        walled = frozenset(v for v, p in fleet.items() if v != vehicle
                           and planner.component(p) not in docks
                           and now.component(p) in docks_now)
        if walled:
            return Offer((), walled)
        poses, in_the_way = [], set()
        for p in self.layout.unload_poses(stack.cell, self.present - {stack.cell}):
            if planner.component(p) not in docks:
                continue
            trapping = self._trapping(vehicle, p, planner, fleet)
            if trapping:
                in_the_way |= trapping
            else:
                poses.append(p)
        return Offer(tuple(poses), frozenset(in_the_way))

    def _trapping(self, vehicle: int, pose: Pose, planner: Planner,
                  fleet: dict[int, Pose]) -> frozenset[int]:
        """The forklifts parked for good across every move out of `pose` once the stack is
        filled, if one of them could not leave either with this one there: neither could ever
        move (a deadlock that no forklift sent aside can break). Empty: not trapped."""
        blockers = planner.exit_blockers(vehicle, pose, self.store)
        if not blockers:
            return frozenset()
        mine = planner.rest_cells(pose)
        if any(planner.exit_blockers(b, fleet[b], self.store, mine) != frozenset()
               for b in blockers if b in fleet):
            return blockers
        return frozenset()


@dataclass(frozen=True)
class Offer:
    """The unload poses a stack is offered from, and the forklifts parked for good that keep
    it from being offered from the others (or at all)."""

    poses: tuple[Pose, ...]
    in_the_way: frozenset[int]


class EmptyWork(StackWork):
    """Goods taken from the stacks in reverse fill order go to a station."""

    goods_stay_if_cancelled = True  # a cancelled claim leaves the goods on their stack

    @property
    def ready_at(self) -> float:
        return 0.0

    def order(self, stack: Stack) -> int:
        return -stack.index

    def initially_present(self) -> set[Cell]:
        return {s.cell for s in self.layout.stacks}

    def loaded(self, kind: TaskKind) -> bool:
        return kind is TaskKind.RETURN

    def handling(self, kind: TaskKind) -> float:
        return self.params.t_claim if kind is TaskKind.DELIVER else self.params.t_unload

    def goods_after(self, cell: Cell, t_end: float, t_done: float) -> Interval:
        return Interval(cell, 0.0, t_done)  # there until claimed

    def done_at(self, goods: Interval) -> float | None:
        return goods.t1 if goods.t1 < math.inf else None  # claimed when the hold ends

    @property
    def goods_off_table(self) -> frozenset[Cell]:
        return frozenset(self.present)  # goods not yet claimed: the static map has them

    def _served(self, cell: Cell) -> None:
        self.present.discard(cell)

    def _unserved(self, cell: Cell) -> None:
        self.present.add(cell)


STACK_WORK: dict[MissionKind, type[StackWork]] = {MissionKind.FILL: FillWork,
                                                 MissionKind.EMPTY: EmptyWork}


def stack_work(kind: MissionKind, layout: Layout, params: DispatchParams,
               store: ReservationView, planners: Planners) -> StackWork:
    return STACK_WORK[kind](layout, params, store, planners)
