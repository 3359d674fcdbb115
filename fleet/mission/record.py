"""The mission record: what a mission did, as the engine keeps it while it runs (MissionRecord)
and as one frozen value (MissionSummary).

The engine's record gives it at the end of a run (`MissionSummary.of_record`); a recording
gives it back, also for a run that never ended (fleet.recording.mission_record.summary_of).
Its JSON form (`to_dict`) is the dispatcher's result (dispatch/done), and the digest of that
form proves two runs identical, bit for bit.
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import dataclass, field
from typing import Any

from fleet.dispatching.decision import TaskKind
from fleet.mission.spec import Mission
from fleet.params import LOOKAHEAD_S
from fleet.planning.geometry import Cell
from fleet.planning.trajectory import Pose, Trajectory
from fleet.wire.convert import intervals_to_wire
from fleet.wire.protocol import (
    DeadlockSeen,
    DecisionFailure,
    LegAmended,
    RecordStep,
    SubtaskEvent,
    WireInterval,
    body_of,
    build_message,
)


# -- as the engine keeps it ---------------------------------------------------------------------
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
    """One decision failure (docs/metrics.md): at t_i, the vehicle chosen or decided for."""

    t: float
    vehicle: int
    stage: str  # "score" (no target accepted), "dispatch" (the same, ending a dispatch), "plan"
    reason: str


@dataclass
class MissionRecord:
    mission: Mission
    layout: str
    vehicles: tuple[int, ...]
    starts: tuple[Pose, ...]
    subtasks: list[Subtask] = field(default_factory=list)
    failures: list[FailureEvent] = field(default_factory=list)  # each counted, each announced
    end_time: float = 0.0  # the last stack done
    all_parked_time: float = 0.0  # every vehicle at rest for good
    stacks_done: list[tuple[str, int, float]] = field(default_factory=list)
    busy_s: dict[int, float] = field(default_factory=dict)
    wait_s: dict[int, float] = field(default_factory=dict)
    halts: list[tuple[int, float, str]] = field(default_factory=list)  # vehicle, t, cause
    resumes: list[tuple[int, float]] = field(default_factory=list)
    cut_subtasks: list[int] = field(default_factory=list)  # indices of subtasks cut short
    deadlocks: list[DeadlockSeen] = field(default_factory=list)  # found, and how each broke

    @property
    def decision_failures(self) -> int:
        return len(self.failures)

    @property
    def total_wait_s(self) -> float:
        return sum(self.wait_s.values())


def record_steps(trajectory: Trajectory) -> list[RecordStep]:
    return [(st.manner.label, str(st.start), str(st.end), st.t0, st.t1, int(st.v0), int(st.v1))
            for st in trajectory.steps]


def subtask_event(s: Subtask) -> SubtaskEvent:
    """A subtask as the dispatcher announces it (and as mission records hold it)."""
    return SubtaskEvent(
        s.vehicle, s.kind.value, s.target, s.stack_index, s.t_i, s.t_end, s.t_done,
        s.postponed, record_steps(s.trajectory), intervals_to_wire(s.trajectory.intervals))


def amended_event(s: Subtask) -> LegAmended:
    """A subtask's leg postponed, as the dispatcher announces it."""
    return LegAmended(s.vehicle, s.t_i, s.t_end, s.t_done, record_steps(s.trajectory),
                      intervals_to_wire(s.trajectory.intervals))


# -- as one frozen value --------------------------------------------------------------------------
@dataclass(frozen=True)
class MissionHeader:
    """Which mission ran."""

    layout: str  # the layout's name
    kind: str  # "fill" or "empty"
    strategy: str
    vehicles: int
    seed: int
    lookahead: float = LOOKAHEAD_S  # Algorithm 1's (inf: none)

    def to_dict(self) -> dict[str, Any]:
        """As JSON-able data; the lookahead only when it is not the default, so that the
        records (and digests) of missions run with it are as they were before it could be
        set."""
        out = {"layout": self.layout, "kind": self.kind, "strategy": self.strategy,
               "vehicles": self.vehicles, "seed": self.seed}
        if self.lookahead != LOOKAHEAD_S:
            out["lookahead"] = _time(self.lookahead)
        return out


@dataclass(frozen=True)
class SubtaskRecord:
    """A subtask the dispatcher decided and a forklift committed, as announced
    (dispatch/subtask): its whole trajectory, step by step, and the cells it reserved."""

    vehicle: int
    kind: str  # "deliver", "return" or "aside" (out of another's way)
    target: str  # cluster or station
    stack: int | None  # stack index in the cluster, for deliveries
    t_i: float
    t_end: float
    t_done: float  # after claiming / unloading
    postponed: bool
    steps: tuple[RecordStep, ...]
    intervals: tuple[WireInterval, ...]  # (col, row, t0, t1); t1 inf: parked for good

    @classmethod
    def of_event(cls, event: SubtaskEvent) -> SubtaskRecord:
        return cls(event.vehicle, event.kind, event.target, event.stack, event.t_i,
                   event.t_end, event.t_done, event.postponed,
                   tuple(tuple(st) for st in event.steps),
                   tuple(tuple(iv) for iv in event.intervals))

    @classmethod
    def from_dict(cls, data: dict) -> SubtaskRecord:
        """From its JSON form (`to_dict`), checked as its message is (ProtocolError)."""
        return cls.of_event(build_message(SubtaskEvent, _as_sent(data)))

    def to_dict(self) -> dict[str, Any]:
        """As JSON-able data (an infinite end written "inf")."""
        return {"vehicle": self.vehicle, "kind": self.kind, "target": self.target,
                "stack": self.stack, "t_i": self.t_i, "t_end": self.t_end,
                "t_done": self.t_done, "postponed": self.postponed,
                "steps": [list(st) for st in self.steps],
                "intervals": [[c, r, t0, _time(t1)] for c, r, t0, t1 in self.intervals]}

    @property
    def leaves_at(self) -> float:
        """When the forklift leaves where it stood before: its first maneuver's start."""
        return self.steps[0][3] if self.steps else self.t_end


def _time(t: float) -> float | str:
    return "inf" if t == math.inf else t


def _as_sent(subtask: dict) -> dict:
    """A record's subtask as its message carried it (an infinite end is "inf" in records)."""
    intervals = subtask.get("intervals")
    if not isinstance(intervals, list):
        return subtask
    return dict(subtask, intervals=[
        [*iv[:3], math.inf] if isinstance(iv, list) and len(iv) == 4 and iv[3] == "inf"
        else iv for iv in intervals])


def failure_from_dict(data: dict) -> DecisionFailure:
    """A decision failure of a record, from its JSON form (ProtocolError if it is none)."""
    return build_message(DecisionFailure, data)


@dataclass(frozen=True)
class StackRecord:
    """A stack filled (or emptied) at t."""

    cluster: str
    index: int
    t: float


@dataclass(frozen=True)
class HaltRecord:
    """A forklift frozen by a fault at t (docs/faults.md)."""

    vehicle: int
    t: float
    cause: str


@dataclass(frozen=True)
class ResumeRecord:
    vehicle: int
    t: float


@dataclass(frozen=True)
class MissionSummary:
    """What a mission did (docs/metrics.md has each number's definition)."""

    mission: MissionHeader
    starts: tuple[str, ...]  # start pose of forklift 1..N
    end_time_s: float  # the last stack done
    all_parked_s: float  # every forklift at rest for good
    decision_failures: int  # the dispatcher's count: its failures, each announced
    wait_s: dict[int, float]  # per forklift: stop maneuvers and postponements
    busy_s: dict[int, float]  # per forklift: driving
    stacks_done: tuple[StackRecord, ...]  # in the order done
    failures: tuple[DecisionFailure, ...]  # as announced (dispatch/failure)
    subtasks: tuple[SubtaskRecord, ...]  # in the order decided
    # What faults did (nothing at all in a run without faults, so its record and digest are
    # those of a run before faults existed).
    halts: tuple[HaltRecord, ...] = ()
    resumes: tuple[ResumeRecord, ...] = ()
    cut_subtasks: tuple[int, ...] = ()  # indices into `subtasks` of those cut short
    # Deadlocks found and how each was broken (none in most runs: their digests stay).
    deadlocks: tuple[DeadlockSeen, ...] = ()
    # Rebuilt from a recording: what its figures miss (fleet.recording.mission_record);
    # empty when they are whole (always, in a dispatcher's own record).
    incomplete: tuple[str, ...] = ()

    @classmethod
    def of_record(cls, rec: MissionRecord) -> MissionSummary:
        """The engine's record of a finished mission."""
        m = rec.mission
        return cls(
            MissionHeader(m.layout, m.kind.value, m.strategy.value, len(rec.vehicles), m.seed,
                          m.lookahead),
            tuple(str(p) for p in rec.starts), rec.end_time, rec.all_parked_time,
            rec.decision_failures, dict(rec.wait_s), dict(rec.busy_s),
            tuple(StackRecord(*s) for s in rec.stacks_done),
            tuple(DecisionFailure(f.t, f.vehicle, f.stage, f.reason) for f in rec.failures),
            tuple(SubtaskRecord.of_event(subtask_event(s)) for s in rec.subtasks),
            tuple(HaltRecord(*h) for h in rec.halts),
            tuple(ResumeRecord(*r) for r in rec.resumes), tuple(rec.cut_subtasks),
            tuple(rec.deadlocks))

    def to_dict(self) -> dict[str, Any]:
        """As JSON-able data: the dispatcher's result, which the digest is taken over."""
        out = {
            "mission": self.mission.to_dict(),
            "starts": list(self.starts),
            "end_time_s": self.end_time_s,
            "all_parked_s": self.all_parked_s,
            "decision_failures": self.decision_failures,
            "wait_s": {str(k): v for k, v in self.wait_s.items()},
            "busy_s": {str(k): v for k, v in self.busy_s.items()},
            "stacks_done": [[s.cluster, s.index, s.t] for s in self.stacks_done],
            "failures": [body_of(f) for f in self.failures],
            "subtasks": [s.to_dict() for s in self.subtasks],
        }
        if self.halts or self.resumes:
            out |= {"halts": [[h.vehicle, h.t, h.cause] for h in self.halts],
                    "resumes": [[r.vehicle, r.t] for r in self.resumes],
                    "cut_subtasks": list(self.cut_subtasks)}
        if self.deadlocks:
            out["deadlocks"] = [body_of(d) for d in self.deadlocks]
        if self.incomplete:
            out["incomplete"] = list(self.incomplete)
        return out


def digest(rec: MissionRecord) -> str:
    """The digest of the engine's record of a mission."""
    return digest_of(MissionSummary.of_record(rec).to_dict())


def digest_of(record: dict[str, Any]) -> str:
    """SHA-256 of a record's canonical JSON: equal digests, equal missions bit for bit."""
    text = json.dumps(record, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()


def held_intervals(summary: MissionSummary) -> list[tuple[int, tuple[int, int], float, float]]:
    """(vehicle, cell, t0, t1) as the table held them: a trajectory's parking to infinity
    ends where the same vehicle's next trajectory starts (it is released from there)."""
    held = []
    by_vehicle: dict[int, list[SubtaskRecord]] = {}
    for s in summary.subtasks:
        by_vehicle.setdefault(s.vehicle, []).append(s)
    for vehicle, subtasks in by_vehicle.items():
        for k, s in enumerate(subtasks):
            release = subtasks[k + 1].leaves_at if k + 1 < len(subtasks) else math.inf
            for c, r, t0, t1 in s.intervals:
                if t0 < release:
                    held.append((vehicle, (c, r), t0, min(t1, release)))
    return held
