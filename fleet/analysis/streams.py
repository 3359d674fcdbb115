"""Loss accounting: every stream of genuine messages numbers them 1, 2, 3, ...; a number
missing from a stream is a message lost in transit, sent while no recorder ran, or sent by a
forklift while it was cut off (it never left it)."""

from __future__ import annotations

import itertools
from collections import defaultdict
from dataclasses import dataclass

from fleet.recording.mission_record import RESTART_DROP
from fleet.recording.reader import Recorded, RecorderGap, Recording
from fleet.wire.protocol import Halt
from fleet.wire.topics import vehicle_of

# Real time: a lost link is noticed within the zenoh lease (1 s) and frozen a margin (0.5 s)
# later; with room for the rest, a forklift's freeze comes at most this long after its loss.
LOSS_NOTICED_WALL_S = 2.0


@dataclass(frozen=True)
class Gap:
    """Messages of one stream lost in transit."""

    key: str
    sender: str
    missing: int  # messages lost
    first_missing: int  # sequence number



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
    return stream_gaps([h for h in sequence_holes(recording) if not h.window])


def stream_gaps(holes: list[Hole]) -> list[Gap]:
    """The holes of each stream, added up."""
    by_stream: dict[tuple[str, str], list[Hole]] = defaultdict(list)
    for h in holes:
        by_stream[h.key, h.sender].append(h)
    return [Gap(key, sender, sum(h.missing for h in found), found[0].first)
            for (key, sender), found in sorted(by_stream.items())]



def sent_while_down(hole: Hole, down_halts: list[Halt], late: float) -> bool:
    """Whether the messages missing from a forklift's own stream were sent about when it
    went down (cut off, stalled: they never left it), rather than lost on the way: the
    hole spans its halt, or on the real-time clock began at most `late` before it (a link
    cut shorter than that may be back before the forklift is frozen)."""
    vehicle = vehicle_of(hole.sender)
    if vehicle is None:
        return False
    t0 = hole.left.envelope.sim_time if hole.left is not None else 0.0
    return any(h.vehicle == vehicle and t0 <= h.t <= max(hole.right.envelope.sim_time,
                                                         t0 + late) for h in down_halts)

