"""A task and its answer on the wire: the dispatcher's TaskRequest to an agent and the agent's
TaskResult back (docs/protocol.md). `*_from_wire` validates what `decode` does not (pose syntax,
enum values, time order) and raises ProtocolError naming the field."""

from __future__ import annotations

from collections.abc import Sequence

from fleet.dispatching.decision import TaskKind
from fleet.mission.seam import Task
from fleet.planning.trajectory import FailureReason, PlanFailure, Trajectory
from fleet.wire.convert import (
    intervals_from_wire,
    intervals_to_wire,
    leg_to_wire,
    pose_from_wire,
    step_from_wire,
    step_to_wire,
)
from fleet.wire.protocol import ProtocolError, TaskRequest, TaskResult


def task_to_wire(task: Task, task_id: str, revision: int) -> TaskRequest:
    return TaskRequest(task_id, task.vehicle, task.kind.value, str(task.start), task.t_i,
                       [str(g) for g in task.goals], sorted(task.filled), task.loaded,
                       revision, task.after)


def task_from_wire(message: TaskRequest) -> Task:
    try:
        kind = TaskKind(message.kind)
    except ValueError:
        raise ProtocolError(f"dispatch.task.kind: unknown task kind {message.kind!r}") from None
    if not message.goals:
        raise ProtocolError("dispatch.task.goals: no goal pose")
    return Task(message.vehicle, kind, pose_from_wire(message.start, "dispatch.task.start"),
                message.t_i, tuple(pose_from_wire(g, "dispatch.task.goals") for g in message.goals),
                frozenset(message.filled), message.loaded, message.after)


def result_to_wire(task_id: str, vehicle: int, result: Trajectory | PlanFailure, revision: int,
                   rejections: list[str], amended: Sequence[Trajectory] = ()) -> TaskResult:
    if isinstance(result, PlanFailure):
        return TaskResult(task_id, vehicle, False, revision, failure=result.reason.value,
                          detail=result.detail, expansions=result.expansions,
                          rejections=rejections)
    return TaskResult(task_id, vehicle, True, revision, str(result.start), str(result.goal),
                      result.t_start, [step_to_wire(s) for s in result.steps],
                      intervals_to_wire(result.intervals), result.expansions,
                      rejections=rejections, amended=[leg_to_wire(leg) for leg in amended])


def result_from_wire(message: TaskResult) -> Trajectory | PlanFailure:
    where = "dispatch.task_result"
    if not message.ok:
        try:
            reason = FailureReason(message.failure)
        except ValueError:
            raise ProtocolError(f"{where}.failure: unknown reason {message.failure!r}") from None
        return PlanFailure(reason, message.detail, message.expansions)
    steps = [step_from_wire(step, f"{where}.steps[{i}]")
             for i, step in enumerate(message.steps)]
    try:
        intervals = intervals_from_wire(message.intervals)
    except ValueError as exc:
        raise ProtocolError(f"{where}.intervals: {exc}") from None
    return Trajectory(message.vehicle, pose_from_wire(message.start, f"{where}.start"),
                      pose_from_wire(message.goal, f"{where}.goal"), message.t_start, tuple(steps),
                      intervals, message.expansions)
