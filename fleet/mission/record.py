"""Mission records as plain JSON-able data (the interim record format until the MCAP
recorder lands), and a digest that proves two runs identical."""

from __future__ import annotations

import hashlib
import json
import math
from typing import Any

from fleet.mission.engine import MissionRecord, subtask_event
from fleet.wire.protocol import SubtaskEvent, body_of


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
