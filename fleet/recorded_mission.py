"""The mission record (the dict of fleet.record_io) rebuilt from a recording's dispatch
events, so plots and summaries read recordings, including those of runs that never ended."""

from __future__ import annotations

from typing import Any

from fleet.protocol import DecisionFailure, MissionDone, Progress, StackDone, SubtaskEvent
from fleet.record_io import subtask_dict
from fleet.recording import Recording, RecordingError


def record_of(recording: Recording) -> dict[str, Any]:
    info = recording.info
    if info is None:
        raise RecordingError(f"{recording.path}: no mission message (dispatch/mission) was "
                             f"recorded, so the run is unknown")
    subtasks = [subtask_dict(m) for _, m in recording.of(SubtaskEvent)]
    stacks = [[m.cluster, m.index, m.t] for _, m in recording.of(StackDone)]
    failures = [{"t": m.t, "vehicle": m.vehicle, "stage": m.stage, "reason": m.reason}
                for _, m in recording.of(DecisionFailure)]
    busy: dict[str, float] = {str(v): 0.0 for v in range(1, info.vehicles + 1)}
    wait = dict(busy)
    for s in subtasks:
        for label, _, _, t0, t1, *_ in s["steps"]:
            (wait if label == "stop" else busy)[str(s["vehicle"])] += t1 - t0
    done = [m for _, m in recording.of(MissionDone) if m.ok and m.record]
    account = _dispatcher_account(done[-1].record) if done else None
    if account:  # the dispatcher's own, which also counts postponements as waiting
        busy, wait, _ = account
    failure_count = decision_failures(recording, account[2] if account else None)
    return {
        "mission": {"layout": info.layout, "kind": info.kind, "strategy": info.strategy,
                    "vehicles": info.vehicles, "seed": info.seed},
        "starts": list(info.starts),
        "end_time_s": max((t for _, _, t in stacks), default=0.0),
        "all_parked_s": max((s["t_end"] for s in subtasks), default=0.0),
        "decision_failures": failure_count,
        "wait_s": wait,
        "busy_s": busy,
        "stacks_done": stacks,
        "failures": failures,
        "subtasks": subtasks,
    }


def decision_failures(recording: Recording, final: int | None) -> int:
    """The dispatcher's count of decision failures (docs/metrics.md). Failures inside a
    decision are counted, not announced one by one: each progress report has the count so
    far, the dispatcher's result (`final`) the last one. A restarted dispatcher counts from 0
    again (its reports are numbered from 1 again): the counts of each are added."""
    counts: list[int] = []
    for r, m in recording.of(Progress):
        if not counts or r.envelope.seq == 1:
            counts.append(0)
        counts[-1] = max(counts[-1], m.failures)
    if final is not None:
        counts[-1:] = [max([final, *counts[-1:]])]
    plans = sum(m.stage == "plan" for _, m in recording.of(DecisionFailure))
    return max(sum(counts), plans)


def _dispatcher_account(record: dict) -> tuple[dict, dict, int] | None:
    """Busy and waiting seconds per forklift and the decision failures from the dispatcher's
    final record, or None if they are not there in the expected shape (a damaged file)."""
    busy, wait, failures = (record.get(k) for k in ("busy_s", "wait_s", "decision_failures"))

    def seconds(value: Any) -> bool:
        return isinstance(value, dict) and all(
            isinstance(k, str) and k.isdigit() and isinstance(v, int | float)
            and not isinstance(v, bool)
            for k, v in value.items())

    if seconds(busy) and seconds(wait) and isinstance(failures, int) \
            and not isinstance(failures, bool):
        return busy, wait, failures
    return None
