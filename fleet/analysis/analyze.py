"""`fleet analyze`: what a recording says about its run, and two verdicts.

Safety (fleet/analysis/safety.py, independent of the planner and the table): no two forklifts on one
cell at one instant, no forklift outside its own reservation, no cell held by two owners at
once. Work: every stack of the layout filled (or emptied) exactly once. Messages: every
stream's sequence numbers are complete (a gap is a lost message).

A run recorded in segments (a recorder killed and restarted) has windows in which no
recorder ran: what was sent then is reported as not recorded, apart from what was lost in
transit, and what the verdicts could not check there is listed as not verified.
"""

from __future__ import annotations

import bisect
import itertools
import math
import re
from collections import Counter, defaultdict
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from fleet.analysis.safety import (
    Body,
    Sample,
    double_bookings,
    outside_reservation,
    overlaps,
    replay,
)
from fleet.analysis.time_use import VehicleStats, time_use
from fleet.mission.driving import state_period
from fleet.mission.spec import ClockMode
from fleet.recording.mcapfile import (
    NS,
    Recorded,
    RecorderGap,
    Recording,
    RecordingError,
    message_type,
)
from fleet.recording.mission_record import RESTART_DROP, dispatcher_restarts, record_of
from fleet.wire.protocol import (
    Halt,
    MissionDone,
    Resume,
    StackDone,
    StackReopened,
    VehicleState,
    WireChange,
)

GOODS_OWNER = 0  # the reservation table's owner of stacks with goods (fleet.mission.seam.GOODS)


@dataclass(frozen=True)
class Gap:
    key: str
    sender: str
    missing: int  # messages lost
    first_missing: int  # sequence number


@dataclass(frozen=True)
class NotRecorded:
    """Messages of a stream sent while no recorder was running (between two segments)."""

    key: str
    sender: str
    missing: int
    first_missing: int  # sequence number
    wall_from_s: float  # the window without a recorder they fell in (Unix seconds)
    wall_to_s: float


@dataclass(frozen=True)
class SegmentRead:
    """One file of the recording, as read."""

    path: str
    messages: int
    complete: bool
    problem: str
    wall_from_s: float | None  # receive times of its first and last message (Unix seconds)
    wall_to_s: float | None
    duplicates: int  # messages an overlapping earlier segment already held


@dataclass(frozen=True)
class RecorderDown:
    """A window in which no recorder was running, in wall and (estimated) sim time."""

    after: str  # the segment that ended
    before: str  # the segment that began
    wall_from_s: float
    wall_to_s: float
    sim_from_s: float | None  # the latest state instant recorded before it
    sim_to_s: float | None  # the earliest recorded after it

    @property
    def duration_s(self) -> float:
        return self.wall_to_s - self.wall_from_s


@dataclass(frozen=True)
class Unverified:
    """What the safety verdict could not check, and over which sim-time window: "states"
    (a forklift's states were not recorded: it is in no check between the two instants) or
    "reservations" (table changes were not recorded: the forklift's reservations then are not
    known, so being outside them or double-booking is not judged)."""

    check: str
    vehicle: int  # the forklift (for reservations 0: the goods on the stacks)
    sim_from_s: float  # exclusive for states: the last recorded instant before
    sim_to_s: float  # inf: to the end of the recording
    why: str


@dataclass
class Report:
    path: str
    complete: bool  # the file ended with its footer
    problem: str  # why reading stopped early
    recovered_span_s: float  # receive-time span of what could be read
    recovered_sim_s: float  # the latest sim time in it
    mission: dict[str, Any]
    finished: bool  # the dispatcher's result is in the recording
    mission_error: str
    end_time_s: float
    all_parked_s: float  # the last trajectory's end
    stacks_expected: int
    stacks_done: int
    stacks_duplicated: list[str]
    stacks_lost: list[str]
    subtasks: int
    # The dispatcher's count (docs/metrics.md): a chosen forklift given no goal it accepts, or
    # a decided trajectory that could not be planned. Only the latter and the dispatches that
    # ended with no decision at all are announced, one dispatch.failure message each.
    decision_failures: int
    plans_failed: int
    undecided: int  # dispatches without a decision (each iter_dispatch choices without a goal)
    commit_conflicts: int
    vehicles: list[VehicleStats]  # fleet.analysis.time_use: where each forklift's time went
    messages: dict[str, int]  # per message type
    messages_lost: int
    gaps: list[Gap]
    messages_cut_off: int  # sent by a forklift around the time it was down: never arrived
    malformed: int  # payloads that were no valid message (recorded as they came)
    foreign: int  # valid messages on a key not theirs, or from a sender not the key's
    overlaps: list = field(default_factory=list)
    outside_reservation: list = field(default_factory=list)
    double_bookings: list = field(default_factory=list)
    # A run recorded in segments (docs/recording.md): the files, the windows without a
    # recorder, what was sent then, and what the verdicts could not check because of it.
    segments: list[SegmentRead] = field(default_factory=list)
    recorder_gaps: list[RecorderDown] = field(default_factory=list)
    not_recorded: list[NotRecorded] = field(default_factory=list)
    messages_not_recorded: int = 0
    unverified: list[Unverified] = field(default_factory=list)
    # Findings set aside, not failed: inside a window whose reservations are not known.
    outside_reservation_unverified: list = field(default_factory=list)
    double_bookings_unverified: list = field(default_factory=list)
    # Stacks counted done from the dispatcher's final record: their dispatch/stack message
    # was sent while no recorder was running.
    stacks_not_recorded: list[str] = field(default_factory=list)
    # Why the numbers (subtasks, decision failures, end time, each forklift's time) leave
    # something out: what a dispatcher announced that neither a recorder nor its final record
    # kept (fleet.recording.mission_record). Empty: they are whole.
    incomplete: list[str] = field(default_factory=list)

    @property
    def safe(self) -> bool:
        return not (self.overlaps or self.outside_reservation or self.double_bookings)

    @property
    def work_done(self) -> bool:
        return (self.stacks_done == self.stacks_expected and not self.stacks_duplicated
                and not self.stacks_lost)

    @property
    def passed(self) -> bool:
        return self.safe and self.work_done and self.messages_lost == 0

    def to_json(self) -> dict[str, Any]:
        data = asdict(self)
        for name in ("overlaps", "outside_reservation", "double_bookings",
                     "outside_reservation_unverified", "double_bookings_unverified"):
            data[name] = len(getattr(self, name))
            data[f"{name}_first"] = [_jsonable(asdict(x)) for x in getattr(self, name)[:20]]
        data.update(safe=self.safe, work_done=self.work_done, passed=self.passed)
        return _jsonable(data)

    def verdict_lines(self) -> list[str]:
        def mark(ok: bool) -> str:
            return "pass" if ok else "FAIL"

        unchecked = ""
        if self.unverified:
            set_aside = (len(self.outside_reservation_unverified)
                         + len(self.double_bookings_unverified))
            silent = sum(u.why.startswith(SILENT) for u in self.unverified)
            why = ", ".join(part for part in (
                f"{len(self.unverified) - silent} with no recorder running"
                if len(self.unverified) > silent else "",
                f"{silent} of a forklift {SILENT}" if silent else "") if part)
            unchecked = (f"; {len(self.unverified)} windows not verified ({why})"
                         + (f", {set_aside} findings in them not judged" if set_aside else ""))
        return [
            f"safety             {mark(self.safe)}: {len(self.overlaps)} overlaps, "
            f"{len(self.outside_reservation)} moments outside a reservation, "
            f"{len(self.double_bookings)} double-booked cells{unchecked}",
            f"work               {mark(self.work_done)}: {self.stacks_done} of "
            f"{self.stacks_expected} stacks, {len(self.stacks_duplicated)} twice, "
            f"{len(self.stacks_lost)} lost"
            + (f" ({len(self.stacks_not_recorded)} known done from the dispatcher's record "
               f"only)" if self.stacks_not_recorded else ""),
            f"messages           {mark(self.messages_lost == 0)}: "
            f"{sum(self.messages.values())} recorded, {self.messages_lost} lost, "
            + (f"{self.messages_cut_off} sent while cut off, " if self.messages_cut_off
               else "")
            + (f"{self.messages_not_recorded} not recorded (no recorder running), "
               if self.recorder_gaps else "")
            + f"{self.malformed} malformed, {self.foreign} foreign",
        ]

    def numbers_lines(self) -> list[str]:
        """End time, subtasks, decision failures and waiting: as `fleet run` and `fleet analyze`
        print them (docs/metrics.md)."""
        no_goal = self.decision_failures - self.plans_failed
        stopped = sum(v.stopped_s for v in self.vehicles)
        postponed = sum(v.postponed_s for v in self.vehicles)
        return [
            f"  end time           {self.end_time_s:.2f} s (last stack done); every forklift "
            f"parked at {self.all_parked_s:.2f} s",
            f"  stacks             {self.stacks_done} of {self.stacks_expected}",
            f"  subtasks           {self.subtasks}",
            f"  decision failures  {self.decision_failures}: {self.plans_failed} plans failed, "
            f"{no_goal} choices without a goal"
            + (f" ({self.undecided} dispatches without a decision)" if self.undecided else ""),
            f"  waiting            {stopped + postponed:.2f} s in all: {stopped:.2f} s stopped, "
            f"{postponed:.2f} s postponed",
            *self.incomplete_lines(),
        ]

    def incomplete_lines(self) -> list[str]:
        """That the numbers are not whole, and why (nothing when they are)."""
        if not self.incomplete:
            return []
        return ["  incomplete         these figures miss what no recorder or record kept:",
                *(f"                     {why}" for why in self.incomplete)]

    def vehicle_lines(self, distance: bool = False) -> list[str]:
        """Each forklift's time (fleet.analysis.time_use), with its distance if asked; a down
        column only when some forklift was down."""
        down = any(v.down_s for v in self.vehicles)
        head = "  forklift" + (" distance m" if distance else "") + \
            " busy s stopped s postponed s handling s" + (" down s" if down else "") + \
            " idle s busy %"
        out = [head]
        for v in self.vehicles:
            out.append(f"  {v.vehicle:>8}" + (f" {v.distance_m:10.1f}" if distance else "")
                       + f" {v.busy_s:6.1f} {v.stopped_s:9.1f} {v.postponed_s:11.1f}"
                       f" {v.handling_s:10.1f}" + (f" {v.down_s:6.1f}" if down else "")
                       + f" {v.idle_s:6.1f} {v.utilisation:6.0%}")
        return out

    def lines(self) -> list[str]:
        m = self.mission
        out = [f"recording {self.path}"]
        if not self.complete:
            out.append(f"  truncated: {self.problem}; recovered {self.recovered_span_s:.1f} s "
                       f"of messages, up to sim time {self.recovered_sim_s:.1f} s")
        if len(self.segments) > 1:
            out.append(f"  segments           {len(self.segments)}: " + ", ".join(
                f"{Path(s.path).name} ({s.messages} messages"
                + ("" if s.complete else ", torn") + ")" for s in self.segments))
        for g in self.recorder_gaps:
            sim = "" if g.sim_from_s is None or g.sim_to_s is None else \
                f", sim time {g.sim_from_s:.2f} to {g.sim_to_s:.2f} s"
            out.append(f"  no recorder        {g.duration_s:.2f} s between {Path(g.after).name} "
                       f"and {Path(g.before).name}{sim}")
        out += [
            f"  mission            {m.get('kind')} on {m.get('layout')} with "
            f"{m.get('vehicles')} forklifts, strategy {m.get('strategy')}, clock "
            f"{m.get('clock')}, seed {m.get('seed')}",
            f"  finished           {'yes' if self.finished else 'no'}"
            + (f" ({self.mission_error})" if self.mission_error else ""),
            *self.numbers_lines(),
            f"  commit conflicts   {self.commit_conflicts}",
            *self.vehicle_lines(distance=True),
        ]
        out.append("  messages           " + ", ".join(
            f"{k} {n}" for k, n in sorted(self.messages.items())))
        for gap in self.gaps[:10]:
            out.append(f"  gap                {gap.missing} lost on {gap.key} from "
                       f"{gap.sender} at seq {gap.first_missing}")
        for n in self.not_recorded[:10]:
            out.append(f"  not recorded       {n.missing} on {n.key} from {n.sender} at seq "
                       f"{n.first_missing} (no recorder running)")
        if len(self.not_recorded) > 10:
            out.append(f"  not recorded       ... {len(self.not_recorded) - 10} streams more")
        out += [f"  {line}" for line in self.verdict_lines()]
        for u in self.unverified[:20]:
            owner = "the goods'" if u.vehicle == GOODS_OWNER else f"forklift {u.vehicle}"
            out.append(f"  not verified       {owner} {u.check} from sim time "
                       f"{u.sim_from_s:.2f} to {u.sim_to_s:.2f} s: {u.why}")
        if len(self.unverified) > 20:
            out.append(f"  not verified       ... {len(self.unverified) - 20} windows more")
        for o in self.outside_reservation_unverified[:10]:
            out.append(f"  not judged         t={o.t:.2f} s forklift {o.vehicle} on "
                       f"{list(o.cells)}: its reservations then are not known")
        for d in self.double_bookings_unverified[:10]:
            out.append(f"  not judged         cell {d.cell} by {d.vehicles} over "
                       f"[{d.t0:.2f}, {d.t1:.2f}): the reservations then are not known")
        for o in self.overlaps[:10]:
            out.append(f"  overlap            t={o.t:.2f} s forklifts {o.vehicles} on "
                       f"{list(o.cells)}")
        for o in self.outside_reservation[:10]:
            out.append(f"  outside            t={o.t:.2f} s forklift {o.vehicle} on "
                       f"{list(o.cells)}")
        for d in self.double_bookings[:10]:
            out.append(f"  double-booked      cell {d.cell} by {d.vehicles} over "
                       f"[{d.t0:.2f}, {d.t1:.2f})")
        for name in self.stacks_duplicated[:10]:
            out.append(f"  done twice         {name}")
        if self.stacks_not_recorded:
            out.append(f"  done, not recorded {', '.join(self.stacks_not_recorded[:20])}"
                       + (" ..." if len(self.stacks_not_recorded) > 20 else ""))
        if self.stacks_lost:
            out.append(f"  not done           {', '.join(self.stacks_lost[:20])}"
                       + (" ..." if len(self.stacks_lost) > 20 else ""))
        return out


def _jsonable(value: Any) -> Any:
    if isinstance(value, float) and not math.isfinite(value):
        return str(value)
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_jsonable(v) for v in value]
    return value


def analyze(recording: Recording) -> Report:
    info = recording.info
    if info is None:
        raise RecordingError(f"{recording.path}: no mission message from the dispatcher was "
                             f"recorded, so the run is unknown (was the recorder started "
                             f"after the mission?)")
    layout = recording.layout()
    record = record_of(recording)
    dims = layout.vehicle.dims
    body = Body(dims.front, dims.rear, dims.width, layout.cell_size, layout.origin)
    states = [(r.envelope.sim_time, m) for r, m in recording.of(VehicleState)]
    usable = [(t, m) for t, m in states
              if all(math.isfinite(v) for v in (t, m.x, m.y, m.theta))]
    samples = [Sample(m.vehicle, t, m.x, m.y, m.theta) for t, m in usable]
    samples += standing_samples(recording, sorted({s.t for s in samples}))
    held = replay(_unique_revisions(recording))
    done = [m for _, m in recording.of(MissionDone)]
    stacks = Counter((m.cluster, m.index) for _, m in recording.of(StackDone))
    stacks -= Counter((m.cluster, m.index) for _, m in recording.of(StackReopened))
    expected = {(s.cluster, s.index) for s in layout.stacks}
    holes = sequence_holes(recording)
    down_halts = [m for _, m in recording.of(Halt) if not m.moving]
    # On the fast clock a forklift is stopped between two ticks: nothing of it is in flight.
    cut_off = [h for h in holes if not h.window and info.clock == ClockMode.REALTIME and
               _while_down(h, down_halts, LOSS_NOTICED_WALL_S * info.speed)]
    lost = [h for h in holes if not h.window and h not in cut_off]
    unrecorded = [h for h in holes if h.window]
    gaps = _stream_gaps(lost)
    downs = {g: _recorder_down(recording, g) for g in recording.gaps}
    unverified = unverified_windows(recording, unrecorded, downs) + \
        silent_windows(states, down_halts, state_period(info.clock, info.speed)) + \
        [Unverified("states", h.right.envelope.message.vehicle,
                    h.left.envelope.sim_time if h.left else 0.0, h.right.envelope.sim_time,
                    f"{SILENT} ({h.missing} states sent while cut off)")
         for h in cut_off if message_type(h.key) is VehicleState]
    outside = outside_reservation(samples, held, body)
    bookings = double_bookings(held)
    judged = [not _unknown(unverified, o.vehicle, o.t, o.t) for o in outside]
    booked = [not any(_unknown(unverified, v, d.t0, d.t1) for v in d.vehicles)
              for d in bookings]
    seen = set(stacks) & expected
    from_record = _stacks_not_recorded(done, unrecorded, expected - seen, any(
        x.unrecorded for x in dispatcher_restarts(recording)))
    return Report(
        path=str(recording.path), complete=recording.complete, problem=recording.problem,
        recovered_span_s=recording.span_s, recovered_sim_s=recording.last_sim_time,
        mission={"layout": info.layout, "kind": info.kind, "strategy": info.strategy,
                 "vehicles": info.vehicles, "seed": info.seed, "clock": info.clock,
                 "speed": info.speed},
        finished=bool(done) and done[-1].ok,
        mission_error=done[-1].error if done else "",
        end_time_s=record["end_time_s"],
        all_parked_s=record["all_parked_s"],
        stacks_expected=len(expected),
        stacks_done=len(seen | from_record),
        stacks_duplicated=sorted(f"{c}#{i}" for (c, i), n in stacks.items() if n > 1),
        stacks_lost=sorted(f"{c}#{i}" for c, i in expected - seen - from_record),
        subtasks=len(record["subtasks"]),
        decision_failures=record["decision_failures"],
        plans_failed=sum(f["stage"] == "plan" for f in record["failures"]),
        undecided=sum(f["stage"] == "dispatch" for f in record["failures"]),
        commit_conflicts=len(done[-1].rejections) if done else 0,
        vehicles=time_use(record["subtasks"], [m for _, m in recording.of(Halt)],
                          [m for _, m in recording.of(Resume)], info.vehicles,
                          max(record["end_time_s"], record["all_parked_s"]), info.kind,
                          layout.cell_size),
        messages=dict(Counter(r.envelope.message.TYPE for r in recording.messages
                              if r.genuine)),
        messages_lost=sum(g.missing for g in gaps), gaps=gaps,
        messages_cut_off=sum(h.missing for h in cut_off),
        malformed=sum(r.envelope is None for r in recording.messages)
        + len(states) - len(usable),
        foreign=len(recording.foreign),
        overlaps=overlaps(samples, body),
        outside_reservation=list(itertools.compress(outside, judged)),
        double_bookings=list(itertools.compress(bookings, booked)),
        segments=[SegmentRead(str(s.path), s.messages, s.complete, s.problem,
                              None if s.first_log_ns is None else s.first_log_ns / NS,
                              None if s.last_log_ns is None else s.last_log_ns / NS,
                              s.duplicates) for s in recording.segments],
        recorder_gaps=list(downs.values()),
        not_recorded=[NotRecorded(h.key, h.sender, h.missing, h.first, h.window[0].start_ns / NS,
                                  h.window[-1].end_ns / NS) for h in unrecorded],
        messages_not_recorded=sum(h.missing for h in unrecorded),
        unverified=unverified,
        outside_reservation_unverified=[o for o, ok in zip(outside, judged, strict=True)
                                        if not ok],
        double_bookings_unverified=[d for d, ok in zip(bookings, booked, strict=True)
                                    if not ok],
        stacks_not_recorded=sorted(f"{c}#{i}" for c, i in from_record),
        incomplete=record["incomplete"],
    )


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


@dataclass(frozen=True)
class Hole:
    """Messages missing from one incarnation of a stream: numbers first .. first+missing-1,
    between two recorded messages (`left` is None before the incarnation's first message
    when it is the stream's first incarnation; else the previous incarnation's last)."""

    key: str
    sender: str
    first: int
    missing: int
    left: Recorded | None
    right: Recorded
    window: tuple[RecorderGap, ...]  # the windows without a recorder it spans; () = lost


def sequence_holes(recording: Recording) -> list[Hole]:
    """Every run of missing numbers in the streams of genuine messages: a (key, sender)
    stream numbers its messages 1, 2, 3, ... (a reply to a question carries 0 and is no
    stream's). A sender that starts again at 1 (or far below its highest number: its first
    messages went unrecorded) is a restarted process, a new incarnation of the stream
    numbered on its own. Messages missing on both sides of a window without a recorder
    (between two segments) were not recorded rather than lost; which it was cannot be told
    apart there."""
    incarnations: dict[tuple[str, str], list[dict[int, Recorded]]] = defaultdict(list)
    highest: dict[tuple[str, str], int] = {}
    for r in recording.messages:
        if not (r.genuine and r.envelope.seq > 0):
            continue
        stream, seq = (r.key, r.envelope.sender), r.envelope.seq
        runs = incarnations[stream]
        if not runs or seq == 1 or seq + RESTART_DROP < highest[stream]:
            runs.append({})
            highest[stream] = 0
        runs[-1].setdefault(seq, r)
        highest[stream] = max(highest[stream], seq)
    gaps = recording.gaps
    holes = []
    for (key, sender), runs in sorted(incarnations.items()):
        before: Recorded | None = None  # the previous incarnation's last message
        for numbers in runs:
            ordered = sorted(numbers)
            for a, b in itertools.pairwise([0, *ordered]):
                if b == a + 1:
                    continue
                left = numbers[a] if a else before
                right = numbers[b]
                window = tuple(g for g in gaps if g.end_ns <= right.log_ns
                               and (left is None or left.log_ns <= g.start_ns))
                if left is None:
                    window = window[-1:]  # sent some time before: the last window before
                holes.append(Hole(key, sender, a + 1, b - a - 1, left, right, window))
            before = max(numbers.values(), key=lambda r: r.log_ns)
    return holes


def sequence_gaps(recording: Recording) -> list[Gap]:
    """Messages lost in transit from each stream of genuine messages (see sequence_holes;
    not counting those sent while no recorder was running)."""
    return _stream_gaps([h for h in sequence_holes(recording) if not h.window])


def _stream_gaps(holes: list[Hole]) -> list[Gap]:
    by_stream: dict[tuple[str, str], list[Hole]] = defaultdict(list)
    for h in holes:
        by_stream[h.key, h.sender].append(h)
    return [Gap(key, sender, sum(h.missing for h in found), found[0].first)
            for (key, sender), found in sorted(by_stream.items())]


def _recorder_down(recording: Recording, gap: RecorderGap) -> RecorderDown:
    """A window without a recorder, with the sim times of the state instants around it."""
    times = [(r.log_ns, r.envelope.sim_time) for r, _ in recording.of(VehicleState)
             if math.isfinite(r.envelope.sim_time)]
    return RecorderDown(str(gap.after), str(gap.before), gap.start_ns / NS, gap.end_ns / NS,
                        max((t for log, t in times if log <= gap.start_ns), default=None),
                        min((t for log, t in times if log >= gap.end_ns), default=None))


def unverified_windows(recording: Recording, unrecorded: list[Hole],
                       downs: dict[RecorderGap, RecorderDown]) -> list[Unverified]:
    """What the safety checks cannot see for messages that were not recorded: a forklift's
    missing states (between the recorded instants around them), and after table changes that
    were not recorded, each forklift's reservations until its next recorded change that
    releases all it holds from some instant (a commit of a new trajectory does)."""
    found = []
    table_holes = []
    for h in unrecorded:
        cls = message_type(h.key)
        around = [downs[g].sim_from_s for g in h.window if downs[g].sim_from_s is not None]
        start = h.left.envelope.sim_time if h.left is not None else min(around, default=0.0)
        if cls is VehicleState:
            found.append(Unverified("states", h.right.envelope.message.vehicle, start,
                                    h.right.envelope.sim_time,
                                    f"{h.missing} states not recorded"))
        elif cls is WireChange:
            table_holes.append((h, min([start, *around])))
    if table_holes:
        changes = recording.of(WireChange)
        info = recording.info
        owners = sorted({m.vehicle for _, m in changes}
                        | set(range(1, (info.vehicles if info else 0) + 1)))
        for h, start in table_holes:
            for vehicle in owners:
                until = next((m.release_from for r, m in changes if m.vehicle == vehicle
                              and r.log_ns >= h.right.log_ns and m.release_from is not None
                              and m.release_cells is None), math.inf)
                if until > start:
                    found.append(Unverified("reservations", vehicle, start, until,
                                            f"{h.missing} table changes not recorded"))
    return found


SILENT = "silent from its fault until the freeze"
# Real time: a lost link is noticed within the zenoh lease (1 s) and frozen a margin (0.5 s)
# later; with room for the rest, a forklift's freeze comes at most this long after its loss.
LOSS_NOTICED_WALL_S = 2.0


def silent_windows(states: list[tuple[float, VehicleState]], down_halts: list[Halt],
                   period: float) -> list[Unverified]:
    """A forklift that died, stalled or was cut off says nothing from its fault on. On the
    real-time clock it is frozen only once that is noticed, a margin ahead (docs/faults.md),
    and is taken to follow its committed plan until then: no check sees it meanwhile."""
    found = []
    for halt in down_halts:
        before = [t for t, m in states if m.vehicle == halt.vehicle and t < halt.t]
        last = max(before, default=0.0)
        if halt.t - last > 1.5 * period:
            found.append(Unverified("states", halt.vehicle, last, halt.t,
                                    f"{SILENT} ({halt.cause})"))
    return found


def _while_down(hole: Hole, down_halts: list[Halt], late: float) -> bool:
    """Whether the messages missing from a forklift's own stream were sent about when it
    went down (cut off, stalled: they never left it), rather than lost on the way: the
    hole spans its halt, or on the real-time clock began at most `late` before it (a link
    cut shorter than that may be back before the forklift is frozen)."""
    match = re.fullmatch(r"vehicle-(\d+)", hole.sender)
    if match is None:
        return False
    vehicle = int(match.group(1))
    t0 = hole.left.envelope.sim_time if hole.left is not None else 0.0
    return any(h.vehicle == vehicle and t0 <= h.t <= max(hole.right.envelope.sim_time,
                                                         t0 + late) for h in down_halts)


def _unknown(unverified: list[Unverified], vehicle: int, t0: float, t1: float) -> bool:
    """Whether the instant t0 = t1, or the span [t0, t1), meets a window in which the
    forklift's reservations are not known."""
    return any(u.check == "reservations" and u.vehicle == vehicle and t0 < u.sim_to_s
               and (u.sim_from_s < t1 or u.sim_from_s == t0 == t1) for u in unverified)


def _stacks_not_recorded(done: list[MissionDone], unrecorded: list[Hole],
                         unseen: set[tuple[str, int]], tail_unrecorded: bool = False
                         ) -> set[tuple[str, int]]:
    """Stacks the dispatcher's final record lists as done whose dispatch/stack message was
    not recorded (all of them, if no more than the messages not recorded; else none).
    `tail_unrecorded`: a dispatcher died while no recorder ran, so the last messages it sent
    are missing without a number to count them by (its successor's record has every stack)."""
    missing = math.inf if tail_unrecorded else \
        sum(h.missing for h in unrecorded if message_type(h.key) is StackDone)
    if not (missing and unseen and done and isinstance(done[-1].record, dict)):
        return set()
    entries = done[-1].record.get("stacks_done", [])
    claimed = {(e[0], e[1]) for e in entries if isinstance(e, list | tuple) and len(e) >= 2
               and isinstance(e[0], str) and isinstance(e[1], int)} \
        if isinstance(entries, list) else set()
    explained = claimed & unseen
    return explained if len(explained) <= missing else set()
