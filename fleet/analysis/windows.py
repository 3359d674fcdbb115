"""A run recorded in segments (a recorder killed and restarted, docs/recording.md): the files
as read, the windows in which no recorder ran, and what the verdicts could not check because
of them or because a forklift said nothing from its fault until its freeze."""

from __future__ import annotations

import math
from dataclasses import dataclass

from fleet.analysis.streams import Hole
from fleet.recording.format import NS
from fleet.recording.reader import RecorderGap, Recording
from fleet.wire.protocol import Halt, MissionDone, StackDone, VehicleState, WireChange
from fleet.wire.topics import message_type

SILENT = "silent from its fault until the freeze"


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
class NotRecorded:
    """Messages of a stream sent while no recorder was running (between two segments)."""

    key: str
    sender: str
    missing: int
    first_missing: int  # sequence number
    wall_from_s: float  # the window without a recorder they fell in (Unix seconds)
    wall_to_s: float



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



def recorder_down(recording: Recording, gap: RecorderGap) -> RecorderDown:
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



def reservations_unknown(unverified: list[Unverified], vehicle: int, t0: float, t1: float) -> bool:
    """Whether the instant t0 = t1, or the span [t0, t1), meets a window in which the
    forklift's reservations are not known."""
    return any(u.check == "reservations" and u.vehicle == vehicle and t0 < u.sim_to_s
               and (u.sim_from_s < t1 or u.sim_from_s == t0 == t1) for u in unverified)



def states_unknown(unverified: list[Unverified], vehicle: int, t0: float, t1: float) -> str:
    """Why the forklift's states over [t0, t1) are not known, if they are not ("": known)."""
    return next((u.why for u in unverified if u.check == "states" and u.vehicle == vehicle
                 and u.sim_from_s < t1 and t0 < u.sim_to_s), "")



def stacks_not_recorded(done: list[MissionDone], unrecorded: list[Hole],
                        unseen: set[tuple[str, int]], tail_unrecorded: bool = False
                        ) -> set[tuple[str, int]]:
    """Stacks the dispatcher's final record lists as done whose dispatch/stack message was
    not recorded (all of them, if no more than the messages not recorded; else none).
    `tail_unrecorded`: a dispatcher with no record of its own may have announced its last
    stacks while no recorder ran, with no later number to count them by (it died then, or
    announced no stack after the window; its successor's record has every stack)."""
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

