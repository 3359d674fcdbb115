"""The two seams the engine decides through: the mission's work (fill and empty of seed 000)
and the dispatch policy (any policy registered for a strategy runs a whole mission)."""

import sys
from pathlib import Path

import pytest

from fleet.dispatching.decision import (
    Decision,
    DispatchOutcome,
    FailedChoice,
    Strategy,
    TaskKind,
)
from fleet.dispatching.policy import POLICIES
from fleet.mission.engine import run_mission
from fleet.mission.spec import STACK_KINDS, Mission, MissionKind
from fleet.mission.vehicle_slot import VehicleSlot
from fleet.mission.work import EmptyWork, FillWork, stack_work
from fleet.params import DispatchParams
from fleet.planning.reservations import Interval, ReservationTable
from fleet.planning.trajectory import Trajectory
from fleet.world.layout_file import load_layout
from fleet.world.site import planners_for

sys.path.insert(0, str(Path(__file__).parent))
from mission_check import mission_problems

SMALL = load_layout("small")


def work_of(kind: MissionKind):
    return stack_work(kind, SMALL, DispatchParams(), ReservationTable(),
                        planners_for(SMALL))


def leg_ending(t_end: float) -> Trajectory:
    """A committed leg that arrives at t_end (all `serve` reads of it)."""
    pose = SMALL.vehicle_starts[0]
    return Trajectory(1, pose, pose, t_end, (), (), 0)


def deliver(work, view, cluster):
    target = next(t for t in work.targets(view, {view.vehicle: view.pose}) if t.name == cluster)
    return Decision(view.vehicle, view.t_free, TaskKind.DELIVER, target, False), target


@pytest.mark.parametrize("kind, cls, first, present, ready",
                         [(MissionKind.FILL, FillWork, 1, 0, 5.0),
                          (MissionKind.EMPTY, EmptyWork, 12, 24, 0.0)])
def test_each_kind_orders_its_stacks_and_says_which_way_the_goods_go(kind, cls, first,
                                                                     present, ready):
    work = work_of(kind)
    assert isinstance(work, cls) and work.ready_at == ready
    assert (len(work.filled), work.total, work.remaining()) == (present, 24, {"a": 12, "b": 12})
    assert work.loaded(TaskKind.DELIVER) is (kind is MissionKind.FILL)
    assert work.loaded(TaskKind.RETURN) is (kind is MissionKind.EMPTY)
    view = VehicleSlot(1, SMALL.vehicle_starts[0], ready, TaskKind.DELIVER).view()
    decision, target = deliver(work, view, "a")
    assert (target.stack_index, target.remaining) == (first, 12)
    served = work.serve(decision, leg_ending(40.0), 45.0)
    assert (served.cluster, served.index, served.t_done) == ("a", first, 45.0)
    assert served.goods.cell == target.stack_cell
    assert (target.stack_cell in work.filled) is (kind is MissionKind.FILL)
    assert work.remaining() == {"a": 11, "b": 12}
    returning = VehicleSlot(1, target.goals[0], 45.0, TaskKind.RETURN).view()
    assert [t.name for t in work.targets(returning, {})] == [st.name for st in SMALL.stations]
    assert work.reopen("a", first) == target.stack_cell  # a delivery cut short
    # the goods as before: a fill's never came, an empty's claim left them on their stack
    assert len(work.filled) == present and work.remaining() == {"a": 12, "b": 12}
    assert work.goods_stay_if_cancelled is (kind is MissionKind.EMPTY)
    assert deliver(work, view, "a")[1].stack_index == first


def test_a_fill_stack_another_forklift_will_cross_is_not_offered():
    work = work_of(MissionKind.FILL)
    view = VehicleSlot(1, SMALL.vehicle_starts[0], 5.0, TaskKind.DELIVER).view()
    _, target = deliver(work, view, "a")
    work.store.commit(2, [Interval(target.stack_cell, 50.0, 60.0)])
    assert [t.name for t in work.targets(view, {1: view.pose})] == ["b"]


class EarliestToFirstTarget:
    """A stand-in for another seed's policy: the earliest free forklift to the first target it
    is offered; if none is offered anything, the earliest waits 10 s."""

    def __init__(self) -> None:
        self.decisions = 0

    def decide(self, vehicles, failed, targets_for, remaining):
        for v in sorted(vehicles, key=lambda v: (v.t_free, v.vehicle)):
            targets = targets_for(v)
            if targets:
                self.decisions += 1
                return DispatchOutcome(Decision(v.vehicle, v.t_free, v.next_task, targets[0],
                                                False))
        first = min(vehicles, key=lambda v: (v.t_free, v.vehicle))
        return DispatchOutcome(None, [FailedChoice(first.vehicle, first.t_free, "none offered")],
                               {first.vehicle: first.t_free + 10.0})


@pytest.mark.parametrize("kind", STACK_KINDS)
def test_a_registered_policy_runs_a_whole_mission_without_the_engine_knowing_it(
        kind, monkeypatch):
    policy = EarliestToFirstTarget()
    monkeypatch.setitem(POLICIES, Strategy.GREEDY, lambda setup: policy)
    rec = run_mission(Mission(layout="small", kind=kind, strategy=Strategy.GREEDY,
                              vehicles=1), None, SMALL)
    assert mission_problems(rec, SMALL) == []
    assert len(rec.stacks_done) == 24
    plans_failed = sum(f.stage == "plan" for f in rec.failures)
    assert policy.decisions == len(rec.subtasks) + plans_failed  # it decided every one
