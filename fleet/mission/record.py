"""Mission records as plain JSON-able data (the interim record format until the MCAP
recorder lands), and a digest that proves two runs identical."""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import dataclass, field
from typing import Any

from fleet.dispatching.decision import TaskKind
from fleet.mission.spec import Mission
from fleet.planning.geometry import Cell
from fleet.planning.trajectory import Pose, Trajectory
from fleet.wire.protocol import SubtaskEvent, body_of


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
    halts: list[tuple[int, float, str]] = field(default_factory=list)  # vehicle, t, cause
    resumes: list[tuple[int, float]] = field(default_factory=list)
    cut_subtasks: list[int] = field(default_factory=list)  # indices of subtasks cut short

    @property
    def total_wait_s(self) -> float:
        return sum(self.wait_s.values())


def subtask_event(s: Subtask) -> SubtaskEvent:
    """A subtask as the dispatcher announces it (and as mission records hold it)."""
    return SubtaskEvent(
        s.vehicle, s.kind.value, s.target, s.stack_index, s.t_i, s.t_end, s.t_done,
        s.postponed,
        [(st.manner.label, str(st.start), str(st.end), st.t0, st.t1, int(st.v0), int(st.v1))
         for st in s.trajectory.steps],
        [(iv.cell[0], iv.cell[1], iv.t0, iv.t1) for iv in s.trajectory.intervals])


def _time(t: float) -> float | str:
    return "inf" if t == math.inf else t


def record_to_dict(rec: MissionRecord) -> dict[str, Any]:
    return {
        "mission": {"layout": rec.mission.layout, "kind": rec.mission.kind.value,
                    "strategy": rec.mission.strategy.value, "vehicles": len(rec.vehicles),
                    "seed": rec.mission.seed},
        "starts": [str(p) for p in rec.starts],
        "end_time_s": rec.end_time,
        "all_parked_s": rec.all_parked_time,
        "decision_failures": rec.decision_failures,
        "wait_s": {str(k): v for k, v in rec.wait_s.items()},
        "busy_s": {str(k): v for k, v in rec.busy_s.items()},
        "stacks_done": [list(s) for s in rec.stacks_done],
        "failures": [{"t": f.t, "vehicle": f.vehicle, "stage": f.stage, "reason": f.reason}
                     for f in rec.failures],
        "subtasks": [subtask_dict(subtask_event(s)) for s in rec.subtasks],
        **_faults(rec),
    }


def _faults(rec: MissionRecord) -> dict[str, Any]:
    """What faults did to the mission (nothing at all in a run without faults, so its record
    and digest are those of a run before faults existed)."""
    if not (rec.halts or rec.resumes):
        return {}
    return {"halts": [list(h) for h in rec.halts], "resumes": [list(r) for r in rec.resumes],
            "cut_subtasks": list(rec.cut_subtasks)}


def subtask_dict(event: SubtaskEvent) -> dict[str, Any]:
    """A subtask as JSON-able data (an infinite end written "inf")."""
    body = body_of(event)
    body["steps"] = [list(st) for st in event.steps]
    body["intervals"] = [[c, r, t0, _time(t1)] for c, r, t0, t1 in event.intervals]
    return body


def digest(rec: MissionRecord) -> str:
    return digest_of(record_to_dict(rec))


def digest_of(record: dict[str, Any]) -> str:
    """SHA-256 of a record's canonical JSON: equal digests, equal missions bit for bit."""
    text = json.dumps(record, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()


def held_intervals(record: dict) -> list[tuple[int, tuple[int, int], float, float]]:
    """(vehicle, cell, t0, t1) as the table held them: a trajectory's parking to infinity
    ends where the same vehicle's next trajectory starts (it is released from there)."""
    held = []
    by_vehicle: dict[int, list[dict]] = {}
    for s in record["subtasks"]:
        by_vehicle.setdefault(s["vehicle"], []).append(s)
    for vehicle, subtasks in by_vehicle.items():
        for k, s in enumerate(subtasks):
            nxt = subtasks[k + 1] if k + 1 < len(subtasks) else None
            release = math.inf
            if nxt is not None:
                release = nxt["steps"][0][3] if nxt["steps"] else nxt["t_end"]
            for c, r, t0, t1 in s["intervals"]:
                t1 = math.inf if t1 == "inf" else t1
                if t0 < release:
                    held.append((vehicle, (c, r), t0, min(t1, release)))
    return held
