"""`fleet analyze`: what a recording says about its run, and two verdicts.

Safety (fleet/analysis/safety.py, independent of the planner and the table): no two
forklifts on one cell at one instant or between two instants, no forklift outside its own
reservation, no cell held by two owners at once. Work: every stack of the layout filled (or
emptied) exactly once.
Messages: every stream's sequence numbers are complete (a gap is a lost message,
fleet/analysis/streams.py).

A run recorded in segments (a recorder killed and restarted) has windows in which no
recorder ran: what was sent then is reported as not recorded, apart from what was lost in
transit, and what the verdicts could not check there is listed as not verified
(fleet/analysis/windows.py). The Report and its text are in fleet/analysis/report.py; each
forklift's time in fleet/analysis/time_use.py.
"""

from __future__ import annotations

import bisect
import math
from collections import Counter
from collections.abc import Callable
from typing import TypeVar

from fleet.analysis.report import Report
from fleet.analysis.safety import (
    Body,
    Sample,
    double_bookings,
    outside_reservation,
    overlaps,
    replay,
)
from fleet.analysis.streams import (
    LOSS_NOTICED_WALL_S,
    Hole,
    sent_while_down,
    sequence_holes,
    stream_gaps,
)
from fleet.analysis.time_use import time_use
from fleet.analysis.windows import (
    SILENT,
    NotRecorded,
    SegmentRead,
    Unverified,
    recorder_down,
    reservations_unknown,
    silent_windows,
    stacks_not_recorded,
    unverified_windows,
)
from fleet.mission.driving import state_period
from fleet.mission.spec import ClockMode
from fleet.recording.format import NS
from fleet.recording.mission_record import dispatcher_restarts, summary_of
from fleet.recording.reader import Recording, RecordingError
from fleet.wire.protocol import (
    Halt,
    MissionDone,
    MissionInfo,
    Resume,
    StackDone,
    StackReopened,
    VehicleState,
    WireChange,
)
from fleet.wire.topics import message_type

Finding = TypeVar("Finding")
# A vehicle's states further apart than this many state periods leave a hole between them:
# nothing is interpolated across it, and a stack's handling over it is not seen.
STATE_GAP_PERIODS = 1.5


def analyze(recording: Recording) -> Report:
    info = recording.info
    if info is None:
        raise RecordingError(f"{recording.path}: no mission message from the dispatcher was "
                             f"recorded, so the run is unknown (was the recorder started "
                             f"after the mission?)")
    layout = recording.layout()
    record = summary_of(recording)
    kind = layout.vehicle_kind
    outline = kind.outline  # numbers only: the verifier has its own geometry
    body = Body(outline.front, outline.rear, outline.width, layout.cell_size, layout.origin)
    period = state_period(info.clock, info.speed)
    states = [(r.envelope.sim_time, m) for r, m in recording.of(VehicleState)]
    usable = [(t, m) for t, m in states
              if all(math.isfinite(v) for v in (t, m.x, m.y, m.theta))]
    samples = [Sample(m.vehicle, t, m.x, m.y, m.theta) for t, m in usable]
    samples += standing_samples(recording, sorted({s.t for s in samples}))
    held = replay(_unique_revisions(recording))
    done = [m for _, m in recording.of(MissionDone)]
    holes = sequence_holes(recording)
    down_halts = [m for _, m in recording.of(Halt) if not m.moving]
    # On the fast clock a forklift is stopped between two ticks: nothing of it is in flight.
    cut_off = [h for h in holes if not h.window and info.clock == ClockMode.REALTIME and
               sent_while_down(h, down_halts, LOSS_NOTICED_WALL_S * info.speed)]
    lost = [h for h in holes if not h.window and h not in cut_off]
    unrecorded = [h for h in holes if h.window]
    gaps = stream_gaps(lost)
    downs = {g: recorder_down(recording, g) for g in recording.gaps}
    unverified = unverified_windows(recording, unrecorded, downs) + \
        silent_windows(states, down_halts, period) + _cut_off_windows(cut_off)
    outside, outside_unknown = _judged(
        outside_reservation(samples, held, body),
        lambda o: reservations_unknown(unverified, o.vehicle, o.t, o.t))
    bookings, bookings_unknown = _judged(
        double_bookings(held),
        lambda d: any(reservations_unknown(unverified, v, d.t0, d.t1) for v in d.vehicles))
    stacks = Counter((m.cluster, m.index) for _, m in recording.of(StackDone))
    stacks -= Counter((m.cluster, m.index) for _, m in recording.of(StackReopened))
    expected = {(s.cluster, s.index) for s in layout.stacks}
    seen = set(stacks) & expected
    from_record = stacks_not_recorded(done, unrecorded, expected - seen, any(
        x.unrecorded for x in dispatcher_restarts(recording)))
    return Report(
        path=str(recording.path), complete=recording.complete, problem=recording.problem,
        recovered_span_s=recording.span_s, recovered_sim_s=recording.last_sim_time,
        mission=_mission(info),
        finished=bool(done) and done[-1].ok,
        mission_error=done[-1].error if done else "",
        end_time_s=record.end_time_s,
        all_parked_s=record.all_parked_s,
        stacks_expected=len(expected),
        stacks_done=len(seen | from_record),
        stacks_duplicated=sorted(f"{c}#{i}" for (c, i), n in stacks.items() if n > 1),
        stacks_lost=sorted(f"{c}#{i}" for c, i in expected - seen - from_record),
        subtasks=len(record.subtasks),
        decision_failures=record.decision_failures,
        plans_failed=sum(f.stage == "plan" for f in record.failures),
        undecided=sum(f.stage == "dispatch" for f in record.failures),
        commit_conflicts=len(done[-1].rejections) if done else 0,
        vehicles=time_use(record.subtasks, [m for _, m in recording.of(Halt)],
                          [m for _, m in recording.of(Resume)], info.vehicles,
                          max(record.end_time_s, record.all_parked_s), info.kind,
                          layout.vehicle_kind),
        messages=dict(Counter(r.envelope.message.TYPE for r in recording.messages
                              if r.genuine)),
        messages_lost=sum(g.missing for g in gaps), gaps=gaps,
        messages_cut_off=sum(h.missing for h in cut_off),
        malformed=sum(r.envelope is None for r in recording.messages)
        + len(states) - len(usable),
        foreign=len(recording.foreign),
        overlaps=overlaps(samples, body, kind.max_speed_mps, STATE_GAP_PERIODS * period),
        outside_reservation=outside,
        double_bookings=bookings,
        segments=[SegmentRead(str(s.path), s.messages, s.complete, s.problem,
                              None if s.first_log_ns is None else s.first_log_ns / NS,
                              None if s.last_log_ns is None else s.last_log_ns / NS,
                              s.duplicates) for s in recording.segments],
        recorder_gaps=list(downs.values()),
        not_recorded=[NotRecorded(h.key, h.sender, h.missing, h.first, h.window[0].start_ns / NS,
                                  h.window[-1].end_ns / NS) for h in unrecorded],
        messages_not_recorded=sum(h.missing for h in unrecorded),
        unverified=unverified,
        outside_reservation_unverified=outside_unknown,
        double_bookings_unverified=bookings_unknown,
        stacks_not_recorded=sorted(f"{c}#{i}" for c, i in from_record),
        incomplete=list(record.incomplete),
    )


def _mission(info: MissionInfo) -> dict:
    """Which run it was, as the recording's mission message says."""
    return {"layout": info.layout, "kind": info.kind, "strategy": info.strategy,
            "vehicles": info.vehicles, "seed": info.seed, "clock": info.clock,
            "speed": info.speed}


def _cut_off_windows(cut_off: list[Hole]) -> list[Unverified]:
    """The states a forklift sent while it was cut off never arrived: it is in no check
    between the instants around them."""
    return [Unverified("states", h.right.envelope.message.vehicle,
                       h.left.envelope.sim_time if h.left else 0.0, h.right.envelope.sim_time,
                       f"{SILENT} ({h.missing} states sent while cut off)")
            for h in cut_off if message_type(h.key) is VehicleState]


def _judged(findings: list[Finding], unknown: Callable[[Finding], bool]
            ) -> tuple[list[Finding], list[Finding]]:
    """The findings judged, and those set aside: inside a window whose reservations are not
    known (each list in the findings' order)."""
    flags = [unknown(f) for f in findings]
    return ([f for f, set_aside in zip(findings, flags, strict=True) if not set_aside],
            [f for f, set_aside in zip(findings, flags, strict=True) if set_aside])


def standing_samples(recording: Recording, instants: list[float]) -> list[Sample]:
    """Where a forklift that was down stood at each recorded instant until it moved again:
    it says nothing then, the dispatcher's halt says where (so the check covers it too)."""
    resumes = sorted((m.vehicle, m.t) for _, m in recording.of(Resume))
    # A forklift heard again was resumed, even if the resume was sent while no recorder ran.
    heard = sorted((m.vehicle, r.envelope.sim_time) for r, m in recording.of(VehicleState))
    out = []
    for _, halt in recording.of(Halt):
        if halt.moving:
            continue
        until = min([t for v, t in resumes if v == halt.vehicle and t >= halt.t]
                    + [t for v, t in heard if v == halt.vehicle and t > halt.t],
                    default=math.inf)
        first = bisect.bisect_left(instants, halt.t)
        last = bisect.bisect_left(instants, until)
        out += [Sample(halt.vehicle, t, halt.x, halt.y, halt.theta)
                for t in instants[first:last]]
    return out


def _unique_revisions(recording: Recording) -> list[tuple]:
    """The table's changes in revision order, each once (a retried publish may repeat)."""
    by_revision: dict[int, WireChange] = {}
    for _, m in recording.of(WireChange):
        by_revision.setdefault(m.revision, m)
    return [(m.op, m.vehicle, m.intervals, m.release_from, m.release_cells)
            for _, m in sorted(by_revision.items())]
