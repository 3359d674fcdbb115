"""The mission record (fleet.mission.record.MissionSummary) rebuilt from a recording's
dispatch events, so plots and summaries read recordings, including those of runs that never
ended.

A run recorded in segments has windows in which no recorder ran (docs/recording.md). What a
dispatcher announced then is in its final record (dispatch/done: every subtask, failure and
stack of that dispatcher), so it is taken from there. A dispatcher that died and was replaced
(docs/faults.md) left no record: what it announced while no recorder ran is known nowhere,
and the rebuilt record's `incomplete` says so (empty: the figures are whole).

A mission that did not finish says how far it got (dispatch/stopped): `recorded_standstill`.
"""

from __future__ import annotations

import bisect
import dataclasses
import math
from collections import defaultdict
from dataclasses import dataclass
from typing import Any

from fleet.mission.record import (
    MissionHeader,
    MissionSummary,
    StackRecord,
    SubtaskRecord,
    failure_from_dict,
)
from fleet.mission.standstill import Standstill
from fleet.recording.reader import Recorded, Recording, RecordingError
from fleet.wire.protocol import (
    DeadlockSeen,
    DecisionFailure,
    Halt,
    LegAmended,
    MissionDone,
    MissionInfo,
    MissionStopped,
    Progress,
    ProtocolError,
    Resume,
    StackDone,
    StackReopened,
    SubtaskEvent,
    ZoneClosed,
)

# A stream whose numbers fall this far below the highest seen is a restarted sender whose
# first messages were not recorded (a stream shared by threads may swap a few neighbours).
RESTART_DROP = 16
# What each dispatcher publishes, each key numbered from 1 by each dispatcher that runs.
EVENTS = (MissionInfo, Progress, SubtaskEvent, StackDone, DecisionFailure, DeadlockSeen, Halt,
          Resume, StackReopened, ZoneClosed)
# Those the numbers are made of: the first three are in the final record too; a halt's stand
# time and a stack reopened are in the recording only.
IN_RECORD = (SubtaskEvent, DecisionFailure, StackDone)
RECORDING_ONLY = (Halt, Resume, StackReopened)
NOUNS = {SubtaskEvent: ("subtask", "subtasks"),
         DecisionFailure: ("announced decision failure", "announced decision failures"),
         StackDone: ("stack done", "stacks done"), Halt: ("halt", "halts"),
         Resume: ("resume", "resumes"), StackReopened: ("stack reopened", "stacks reopened")}


@dataclass(frozen=True)
class Restart:
    """A new dispatcher took over (docs/faults.md): the first message of it recorded, and
    the last of the dispatchers' messages recorded before (receive times, Unix ns)."""

    at_ns: int
    last_before_ns: int
    unrecorded: bool  # no recorder ran for a while between: the old one's last words unknown


@dataclass(frozen=True)
class Account:
    """The dispatcher's own figures: busy and waiting seconds per forklift (waiting counts
    postponements too) and its count of decision failures."""

    busy_s: dict[int, float]
    wait_s: dict[int, float]
    decision_failures: int


@dataclass(frozen=True)
class Final:
    """The last dispatcher's record (its result, dispatch/done), checked: all it announced."""

    since_ns: int  # where that dispatcher's messages begin (receive time)
    subtasks: tuple[SubtaskRecord, ...]
    failures: tuple[DecisionFailure, ...]
    stacks: tuple[StackRecord, ...]
    account: Account | None  # None: not in the record in the expected shape


def summary_of(recording: Recording,
               known: tuple[list[Restart], Final | None] | None = None) -> MissionSummary:
    """The mission record of a recording (RecordingError if it holds no mission message);
    `known`: its dispatcher restarts and final record, when the caller has them already."""
    info = recording.info
    if info is None:
        raise RecordingError(f"{recording.path}: no mission message (dispatch/mission) was "
                             f"recorded, so the run is unknown")
    restarts, final = known if known is not None else \
        (restarts := dispatcher_restarts(recording), final_record(recording, restarts))
    incomplete = unknown(recording, restarts, final is not None)
    heard = recording.of(SubtaskEvent)
    subtasks, later = amended(heard, recording.of(LegAmended))
    # A stack (order) is done when the subtask that served it is, postponed or not.
    stacks = [StackRecord(m.cluster, m.index, later.get((m.vehicle, m.t), m.t))
              for _, m in recording.of(StackDone)]
    failures = [m for _, m in recording.of(DecisionFailure)]
    if final is not None:
        # Those of the dispatchers before it as recorded, then all it announced.
        own = set(final.subtasks)
        if any(r.log_ns >= final.since_ns and s not in own
               for (r, _), s in zip(heard, subtasks, strict=True)):
            incomplete.append("the dispatcher's record lacks subtasks it announced")
        subtasks = [s for s in subtasks if s not in own] + list(final.subtasks)
        announced = set(final.failures)
        failures = [f for f in failures if f not in announced] + list(final.failures)
        seen = {(s.cluster, s.index) for s in stacks}
        stacks += [s for s in final.stacks if (s.cluster, s.index) not in seen]
    busy: dict[int, float] = {v: 0.0 for v in range(1, info.vehicles + 1)}
    wait = dict(busy)
    for s in subtasks:
        for label, _, _, t0, t1, *_ in s.steps:
            (wait if label == "stop" else busy)[s.vehicle] += t1 - t0
    account = final.account if final is not None else None
    if account:  # the dispatcher's own, which also counts postponements as waiting
        busy, wait = account.busy_s, account.wait_s
    return MissionSummary(
        MissionHeader(info.layout, info.kind, info.strategy, info.vehicles, info.seed,
                      info.lookahead_s),
        tuple(info.starts),
        end_time_s=max((s.t for s in stacks), default=0.0),
        all_parked_s=max((s.t_end for s in subtasks), default=0.0),
        decision_failures=len(failures),  # each counted failure is announced
        wait_s=wait, busy_s=busy, stacks_done=tuple(stacks), failures=tuple(failures),
        subtasks=tuple(subtasks), deadlocks=tuple(m for _, m in recording.of(DeadlockSeen)),
        incomplete=tuple(incomplete))


def amended(heard: list[tuple[Recorded, SubtaskEvent]],
            amendments: list[tuple[Recorded, LegAmended]]
            ) -> tuple[list[SubtaskRecord], dict[tuple[int, float], float]]:
    """The subtasks as announced, each postponed by the amendments announced after it (seed
    002's collision rules): the vehicle's latest subtask decided at the amendment's t_i; and
    (vehicle, the done time announced) -> the done time after every postponement."""
    subtasks = [SubtaskRecord.of_event(m) for _, m in heard]
    at = [r.log_ns for r, _ in heard]
    announced = [(s.vehicle, s.t_done) for s in subtasks]
    for r, a in amendments:
        k = max((i for i, s in enumerate(subtasks)
                 if s.vehicle == a.vehicle and s.t_i == a.t_i and at[i] <= r.log_ns),
                default=None)
        if k is None:
            continue  # its subtask was not recorded
        subtasks[k] = dataclasses.replace(
            subtasks[k], t_end=a.t_end, t_done=a.t_done,
            steps=tuple(tuple(st) for st in a.steps),
            intervals=tuple(tuple(iv) for iv in a.intervals))
    later = {was: s.t_done for was, s in zip(announced, subtasks, strict=True)
             if was[1] != s.t_done}
    return subtasks, later


def dispatcher_restarts(recording: Recording) -> list[Restart]:
    """Where a new dispatcher's messages begin. Every dispatcher numbers each key from 1, and
    its count of decision failures starts at 0: a key whose numbers start again, fall far
    below the highest, repeat, or whose count falls, shows a restart between two of its
    messages. A key quiet through a restart, or whose first new numbers went unrecorded, is
    told by the others: a restart is placed at the first message any key shows it at."""
    found: list[tuple[int, int]] = []  # (the key's last message before, the first after)
    last: dict[str, Recorded] = {}
    numbers: dict[str, set[int]] = defaultdict(set)
    highest: dict[str, int] = {}  # max(numbers[key]), kept as it grows (a run has many)
    failures: dict[str, int] = {}
    for r, m in _events(recording):
        key, seq = r.key, r.envelope.seq
        before = last.get(key)
        fewer = isinstance(m, Progress) and m.failures < failures.get(key, 0)
        if before is not None and (seq == 1 or seq in numbers[key] or fewer
                                   or seq + RESTART_DROP < highest[key]):
            found.append((before.log_ns, r.log_ns))
            numbers[key] = set()
            highest[key] = seq
        last[key] = r
        numbers[key].add(seq)
        highest[key] = max(highest.get(key, seq), seq)
        if isinstance(m, Progress):
            failures[key] = m.failures
    starts: list[int] = []
    for before, at in sorted(found, key=lambda pair: pair[1]):
        if not starts or before >= starts[-1]:  # else the same restart, seen on another key
            starts.append(at)
    times = sorted(r.log_ns for r, _ in _events(recording))
    out = []
    for at in starts:
        index = bisect.bisect_left(times, at)
        previous = times[index - 1] if index else at
        out.append(Restart(at, previous, any(previous <= g.start_ns and g.end_ns <= at
                                             for g in recording.gaps)))
    return out


def unknown(recording: Recording, restarts: list[Restart], final: bool) -> list[str]:
    """What the figures miss: numbers missing from a dispatcher's keys (announced while no
    recorder ran, or lost), unless its final record has them, and what a dispatcher with no
    record sent while no recorder ran with no later number to count it by (its last words,
    if it died then). `final`: the last dispatcher's record is in the recording."""
    lives = len(restarts) + 1
    numbers: dict[tuple[int, type, str], set[int]] = defaultdict(set)
    starts = [x.at_ns for x in restarts]
    for r, m in _events(recording):
        numbers[bisect.bisect_right(starts, r.log_ns), type(m), r.key].add(r.envelope.seq)
    missing: dict[tuple[int, type], int] = defaultdict(int)
    for (life, cls, _), seen in numbers.items():
        missing[life, cls] += max(seen) - len(seen)
    tails = uncounted_tails(recording, restarts, final)
    out = []
    for life in range(lives):
        kept = RECORDING_ONLY if final and life == lives - 1 else IN_RECORD + RECORDING_ONLY
        whose = f" (dispatcher {life + 1} of {lives})" if lives > 1 else ""
        out += [f"{_counted(missing[life, cls], NOUNS[cls])} not recorded{whose}"
                for cls in kept if missing[life, cls]]
        if life < lives - 1 and restarts[life].unrecorded:
            out.append(f"dispatcher {life + 1} of {lives} died while no recorder ran")
        elif tail := [NOUNS[cls][1] for cls in IN_RECORD if (life, cls) in tails]:
            out.append(f"any {' and '.join(tail)} sent after the last recorded, while no "
                       f"recorder ran, are not counted{whose}")
    return out


def uncounted_tails(recording: Recording, restarts: list[Restart], final: bool
                    ) -> set[tuple[int, type]]:
    """(dispatcher, kind of event) pairs, each dispatcher by its index among those that ran,
    of the events the figures are made of (IN_RECORD) whose last may have been sent while no
    recorder ran: a window without a recorder began in that dispatcher's life and no event
    of the kind was recorded from it after the window. Numbers count only what falls between
    two recorded messages, so those are not counted. The last dispatcher's, when its final
    record is in the recording (`final`), are in it, and are left out."""
    starts = [x.at_ns for x in restarts]
    last: dict[tuple[int, type], int] = {}
    for r, m in _events(recording):
        life = bisect.bisect_right(starts, r.log_ns)
        last[life, type(m)] = max(last.get((life, type(m)), r.log_ns), r.log_ns)
    out = set()
    for gap in recording.gaps:
        life = bisect.bisect_right(starts, gap.start_ns)
        if final and life == len(restarts):
            continue
        out |= {(life, cls) for cls in IN_RECORD
                if last.get((life, cls), gap.start_ns) <= gap.start_ns}
    return out


def _counted(n: int, noun: tuple[str, str]) -> str:
    """"1 stack done", "2 stacks done"."""
    return f"{n} {noun[0] if n == 1 else noun[1]}"


def _events(recording: Recording) -> list[tuple[Recorded, Any]]:
    """The dispatchers' numbered events, in the order they were received."""
    return [(r, r.envelope.message) for r in recording.messages
            if r.genuine and r.envelope.seq > 0 and isinstance(r.envelope.message, EVENTS)]


def final_record(recording: Recording, restarts: list[Restart]) -> Final | None:
    """The last dispatcher's record, if its result is in the recording and the record has
    the shape MissionSummary.to_dict gives it (else None: the recording alone says what
    happened)."""
    done = [(r, m) for r, m in recording.of(MissionDone)
            if m.ok and isinstance(m.record, dict) and m.record]
    since = restarts[-1].at_ns if restarts else 0
    if not done or done[-1][0].log_ns < since:
        return None
    record = done[-1][1].record
    try:
        subtasks = tuple(SubtaskRecord.from_dict(e) for e in _entries(record, "subtasks"))
        failures = tuple(failure_from_dict(e) for e in _entries(record, "failures"))
    except ProtocolError:
        return None
    return Final(since, subtasks, failures, _record_stacks(record), _dispatcher_account(record))


def _entries(record: dict, name: str) -> list[dict]:
    entries = record.get(name)
    if not (isinstance(entries, list) and all(isinstance(e, dict) for e in entries)):
        raise ProtocolError(f"dispatch.done.record.{name}: must be a list of maps")
    return entries


def _record_stacks(record: dict) -> tuple[StackRecord, ...]:
    """The record's stacks done that are in shape (a damaged entry is left out)."""
    entries = record.get("stacks_done")
    return tuple(StackRecord(e[0], e[1], float(e[2])) for e in entries
                 if isinstance(e, list) and len(e) == 3
                 and isinstance(e[0], str) and isinstance(e[1], int) and not isinstance(e[1], bool)
                 and isinstance(e[2], int | float) and not isinstance(e[2], bool)
                 and math.isfinite(e[2])) if isinstance(entries, list) else ()


def _dispatcher_account(record: dict) -> Account | None:
    """Busy and waiting seconds per forklift and the decision failures from the dispatcher's
    final record, or None if they are not there in the expected shape (a damaged file)."""
    busy, wait, failures = (record.get(k) for k in ("busy_s", "wait_s", "decision_failures"))

    def seconds(value: Any) -> bool:
        return isinstance(value, dict) and all(
            isinstance(k, str) and k.isdecimal() and isinstance(v, int | float)
            and not isinstance(v, bool)
            for k, v in value.items())

    if seconds(busy) and seconds(wait) and isinstance(failures, int) \
            and not isinstance(failures, bool):
        return Account({int(k): v for k, v in busy.items()},
                       {int(k): v for k, v in wait.items()}, failures)
    return None


def recorded_standstill(recording: Recording) -> Standstill | None:
    """How far a mission that did not finish got, as its dispatcher said when it stopped
    (fleet/mission/standstill.py); None when the mission finished, or when no account of it
    was recorded (a dispatcher killed outright says nothing) or it is damaged."""
    done = recording.of(MissionDone)
    stopped = recording.of(MissionStopped)
    if (done and done[-1][1].ok) or not stopped:
        return None
    try:
        return Standstill.of_message(stopped[-1][1])
    except ProtocolError:
        return None
