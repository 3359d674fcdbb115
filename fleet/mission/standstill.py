"""How far a mission that did not finish got: why it stopped, the sim time it reached, the
stacks done of the total, and where each forklift stood and what it was stuck on. Built from
the engine's state the moment the mission stops (`standstill`), published and recorded as a
`MissionStopped` (fleet/wire/protocol.py), and read back from the recording to say so
(`Standstill.lines`), so a wedge can be looked at after the run."""

from __future__ import annotations

import math
from collections.abc import Collection, Iterable, Mapping
from dataclasses import dataclass
from enum import Enum
from typing import Protocol

from fleet.dispatching.decision import TaskKind
from fleet.mission.record import FailureEvent, MissionRecord
from fleet.mission.vehicle_slot import VehicleSlot
from fleet.planning.trajectory import Pose
from fleet.wire.protocol import MissionStopped, ProtocolError


class Cause(Enum):
    STUCK = "stuck"  # too many decisions in a row failed (MissionStuck)
    STOPPED = "stopped"  # a signal: Ctrl-C, SIGTERM
    LOST = "lost"  # a forklift's agent or the reservation service gone
    FAILED = "failed"  # any other error that ended the mission


@dataclass(frozen=True)
class VehicleStanding:
    vehicle: int
    pose: Pose  # where it stands once its committed legs are driven
    t_free: float  # from when
    next_task: TaskKind
    down: bool  # frozen by a fault
    unreached: tuple[str, ...]  # the targets it failed to reach since its last subtask
    failure: str  # its last failure since its last subtask, in words ("" none)

    def line(self) -> str:
        """Where it stands and what it was at, in one line."""
        parts = [f"forklift {self.vehicle} at {self.pose} from t={self.t_free:.2f} s"
                 + (", down" if self.down else ""), f"next {self.next_task.value}"]
        if self.unreached:
            parts.append(f"could not reach {', '.join(self.unreached)}")
        if self.failure:
            parts.append(f"last failure {self.failure}")
        return "; ".join(parts)


@dataclass(frozen=True)
class Standstill:
    cause: Cause
    reason: str  # the error that ended the mission, in words
    t: float  # the sim time the mission reached (the clock's last decision instant)
    stacks_done: int  # done by t
    stacks_total: int
    failures_in_a_row: int  # decisions that came to nothing since the last committed subtask
    decision_failures: int  # in all: the dispatcher's count (each announced)
    vehicles: tuple[VehicleStanding, ...]

    def headline(self) -> str:
        """How far it got, in one line."""
        return (f"{self.cause.value} at t={self.t:.2f} s with {self.stacks_done} of "
                f"{self.stacks_total} stacks done"
                + (f", {self.failures_in_a_row} "
                   f"decision{'s' if self.failures_in_a_row > 1 else ''} in a row failed"
                   if self.failures_in_a_row else ""))

    def lines(self) -> list[str]:
        """The headline, then each forklift's line."""
        return [self.headline(), *(v.line() for v in self.vehicles)]

    def message(self) -> MissionStopped:
        return MissionStopped(self.cause.value, self.reason, self.t, self.stacks_done,
                              self.stacks_total, self.failures_in_a_row,
                              self.decision_failures,
                              [(v.vehicle, str(v.pose), v.t_free, v.next_task.value, v.down,
                                list(v.unreached), v.failure) for v in self.vehicles])

    @classmethod
    def of_message(cls, m: MissionStopped) -> Standstill:
        """Back from the wire (ProtocolError for a cause or task no run publishes)."""
        try:
            cause = Cause(m.cause)
            vehicles = tuple(VehicleStanding(v, Pose.parse(pose), t_free, TaskKind(task), down,
                                             tuple(unreached), failure)
                             for v, pose, t_free, task, down, unreached, failure in m.vehicles)
        except ValueError as exc:
            raise ProtocolError(f"{MissionStopped.TYPE}: {exc}") from None
        return cls(cause, m.reason, m.t, m.stacks_done, m.stacks_total, m.failures_in_a_row,
                   m.decision_failures, vehicles)

    def to_dict(self) -> dict:
        """As JSON has it (the run's summary.json, `fleet run --json`)."""
        return {"cause": self.cause.value, "reason": self.reason, "t": self.t,
                "stacks_done": self.stacks_done, "stacks_total": self.stacks_total,
                "failures_in_a_row": self.failures_in_a_row,
                "decision_failures": self.decision_failures,
                "vehicles": [{"vehicle": v.vehicle, "pose": str(v.pose), "t_free": v.t_free,
                              "next_task": v.next_task.value, "down": v.down,
                              "unreached": list(v.unreached), "failure": v.failure}
                             for v in self.vehicles]}


class Streak(Protocol):
    """The engine's failures since the last committed subtask (engine.FailureStreak)."""

    count: int
    tried: Mapping[int, Collection[str]]  # the targets each forklift failed to reach


def standstill(cause: Cause, reason: str, t: float, fleet: Iterable[VehicleSlot],
               down: Collection[int], record: MissionRecord, streak: Streak,
               total: int) -> Standstill:
    """Where the mission stands at sim time t: each forklift's slot, whether it is down, the
    targets it failed to reach and its last failure since its last subtask."""
    since = {s.vehicle: s.t_done for s in record.subtasks}  # each one's last subtask
    last: dict[int, FailureEvent] = {}
    for f in record.failures:
        if f.t >= since.get(f.vehicle, -math.inf):
            last[f.vehicle] = f
    vehicles = tuple(VehicleStanding(
        v.vehicle, v.pose, v.t_free, v.next_task, v.vehicle in down,
        tuple(sorted(streak.tried.get(v.vehicle, ()))),
        failure_text(last[v.vehicle], named=False) if v.vehicle in last else "")
        for v in fleet)
    return Standstill(cause, reason, t, sum(t_done <= t for *_, t_done in record.stacks_done),
                      total, streak.count, record.decision_failures, vehicles)


def failure_text(f: FailureEvent, named: bool = True) -> str:
    """A decision failure in words: "plan of forklift 2 for t=12.00 s: no path" (`named`:
    with the forklift; t is the instant the decision was for)."""
    who = f" of forklift {f.vehicle}" if named else ""
    return f"{f.stage}{who} for t={f.t:.2f} s: {f.reason}"
