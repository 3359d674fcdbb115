"""Core objects through the wire and back: tasks and planning results, exactly."""

import math

import pytest

from fleet.dispatching.algorithm1 import TaskKind
from fleet.mission.seam import Task
from fleet.planning.planner import HybridAStar
from fleet.planning.reservations import ReservationTable
from fleet.planning.trajectory import FailureReason, PlanFailure, Pose, Trajectory
from fleet.wire.convert import result_from_wire, result_to_wire, task_from_wire, task_to_wire
from fleet.wire.protocol import ProtocolError, TaskRequest, decode, encode
from fleet.world.layout_file import load_layout


def through_the_wire(message):
    return decode(encode(message, "test", 1, 0.0)).message


def test_a_task_survives_the_wire():
    task = Task(3, TaskKind.DELIVER, Pose((4, 6), 3), 12.25, (Pose((1, 4), 2), Pose((1, 3), 2)),
                frozenset({(0, 7), (0, 6)}), True)
    message = through_the_wire(task_to_wire(task, "d:1", 17))
    assert message.revision == 17 and message.task_id == "d:1"
    assert task_from_wire(message) == task


def test_a_planned_trajectory_survives_the_wire_bit_for_bit():
    layout = load_layout("small")
    planner = HybridAStar(layout.grid_map(), layout.vehicle.dims)
    traj = planner.plan(1, layout.vehicle_starts[0], 3.1, [Pose((1, 4), 2)], ReservationTable())
    assert isinstance(traj, Trajectory)
    assert any(iv.t1 == math.inf for iv in traj.intervals)
    back = result_from_wire(through_the_wire(result_to_wire("d:2", 1, traj, 5, ["refused"])))
    assert back == traj


def test_a_failure_survives_the_wire():
    failure = PlanFailure(FailureReason.GOAL_BLOCKED, "every goal is taken", 12)
    message = through_the_wire(result_to_wire("d:3", 2, failure, 9, []))
    assert not message.ok and result_from_wire(message) == failure


@pytest.mark.parametrize("field,value,complaint", [
    ("kind", "fly", "unknown task kind 'fly'"),
    ("start", "4,6", "dispatch.task.start"),
    ("goals", ["1,4,X"], "dispatch.task.goals"),
    ("goals", [], "no goal pose"),
])
def test_a_bad_task_is_refused_naming_the_field(field, value, complaint):
    body = dict(task_id="d:4", vehicle=1, kind="deliver", start="4,6,S", t_i=0.0,
                goals=["1,4,W"], filled=[], loaded=False, revision=0)
    body[field] = value
    with pytest.raises(ProtocolError, match=complaint):
        task_from_wire(TaskRequest(**body))


def test_an_unknown_maneuver_in_a_result_is_refused():
    layout = load_layout("small")
    planner = HybridAStar(layout.grid_map(), layout.vehicle.dims)
    traj = planner.plan(1, layout.vehicle_starts[0], 0.0, [Pose((1, 4), 2)], ReservationTable())
    message = result_to_wire("d:5", 1, traj, 1, [])
    steps = [("moonwalk", *message.steps[0][1:]), *message.steps[1:]]
    with pytest.raises(ProtocolError, match=r"steps\[0\].*moonwalk"):
        result_from_wire(type(message)(**{**message.__dict__, "steps": steps}))
