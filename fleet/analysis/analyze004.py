"""What a seed-004 recording says, from the recording alone: its tracking events read back,
judged by the verifiers that know nothing of the tracker or planner (verdicts004.py: cells,
traffic rules, giving way), and the work checked from lifts, drops and picks: every order
picked once, every shelf lifted at its slot put down there again, by the AGV that lifted it,
before the mission ended."""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

from fleet.analysis.traffic004 import Breach
from fleet.analysis.verdicts004 import Verdict004, judge
from fleet.errors import UserError
from fleet.mission.record004 import NotAnEvent, event_from_wire
from fleet.mission.tracking004 import (
    BrokeDown,
    Event,
    Met,
    Moved,
    Paused,
    Picked,
    Replanned,
    Turned,
    ZoneClosed,
)
from fleet.planning.trajectory import Pose
from fleet.recording.reader import Recording
from fleet.wire.protocol import AgvEvent, MissionDone, MissionInfo, MissionStopped
from fleet.world.floor004 import Floor004


@dataclass(frozen=True)
class ShelfSlip:
    """A lift or drop that breaks shelf conservation."""

    t: float
    vehicle: int
    at: tuple[int, int]
    why: str


def fault_breaches(events: list[Event]) -> list[Breach]:
    """From the recorded faults and moves alone: a broken-down AGV begins nothing (a move,
    turn or pause) until it is repaired; no move enters a closed cell while it is closed."""
    down = [e for e in events if isinstance(e, BrokeDown)]
    zones = [e for e in events if isinstance(e, ZoneClosed)]
    out = []
    for e in events:
        if isinstance(e, Moved | Turned | Paused):
            for b in down:
                if b.vehicle == e.vehicle and b.t <= e.t0 < b.until:
                    out.append(Breach(e.vehicle, e.t0, f"{type(e).__name__.lower()} at "
                                           f"t={e.t0} while broken down from t={b.t} to "
                                           f"t={b.until}"))
        if isinstance(e, Moved):
            for z in zones:
                if e.to in z.cells and e.t0 < z.t1 and z.t0 < e.t1:
                    out.append(Breach(e.vehicle, e.t0, f"entered {e.to} at t={e.t0}, "
                                           f"closed from t={z.t0} to t={z.t1}"))
    return out


@dataclass
class Report004:
    path: str
    layout: str
    clock: str
    vehicles: int
    seed: int
    orders_expected: int
    orders_picked: int
    completion_s: float  # the last order picked
    end_time_s: float  # the last event's end
    counts: dict[str, int]
    verdict: Verdict004
    shelf_slips: list[ShelfSlip]
    unreadable: list[str] = field(default_factory=list)  # AgvEvents naming no event
    finished: bool = False  # the dispatcher's result is recorded and says done
    heat_w: float = 0.0  # the heat cost's weight the AGVs planned with (0: off)
    faults: int = 0  # breakdowns and zones closed
    fault_breaches: list[Breach] = field(default_factory=list)
    # The dispatcher's events (numbered 1, 2, ...) that no segment holds, as (first, last)
    # runs: what no recorder wrote and no restarted one caught up on.
    events_missing: list[tuple[int, int]] = field(default_factory=list)
    segments: list[str] = field(default_factory=list)  # of a recording in several, each
    # Each dispatcher after the first (killed, picked up): the sim time of its first event
    # recorded (None: none).
    restarts: list[float | None] = field(default_factory=list)

    # What `fleet runs` keeps of a judged run (fleet/commands/runs.py, summary_of), as seed
    # 000's report has it.
    @property
    def mission(self) -> dict[str, object]:
        return {"kind": "orders", "layout": self.layout, "strategy": "nearest",
                "clock": self.clock, "vehicles": self.vehicles, "seed": self.seed}

    @property
    def safe(self) -> bool:
        v = self.verdict
        return not (v.clashes or v.bad_moves or v.rule_breaches or v.yield_breaches
                    or self.fault_breaches)

    @property
    def messages_whole(self) -> bool:
        return not self.unreadable and not self.events_missing

    incomplete: tuple[str, ...] = ()

    @property
    def work_done(self) -> bool:
        return self.finished and self.orders_picked == self.orders_expected and \
            not self.shelf_slips

    @property
    def passed(self) -> bool:
        return self.verdict.passed and self.work_done and self.messages_whole and \
            not self.fault_breaches


def shelf_slips(floor: Floor004, events: list[Event]) -> list[ShelfSlip]:
    """Shelves conserved: an AGV lifts only at a slot, only when empty, and drops only what
    it carries, where it lifted it (its home); nobody lifts a shelf that is away; at the
    end every shelf is home."""
    slots = {s.xy for s in floor.slots}
    carrying: dict[int, tuple[int, int]] = {}  # AGV -> the slot of the shelf it carries
    away: set[tuple[int, int]] = set()
    out = []
    for e in sorted((e for e in events if isinstance(e, Paused)), key=lambda e: (e.t1, e.vehicle)):
        if e.label == "lift":
            why = "not at a slot" if e.at not in slots else \
                "it carries a shelf already" if e.vehicle in carrying else \
                "that shelf is away" if e.at in away else ""
            if why:
                out.append(ShelfSlip(e.t1, e.vehicle, e.at, f"lifted {why}"))
                continue
            carrying[e.vehicle] = e.at
            away.add(e.at)
        elif e.label == "drop":
            home = carrying.pop(e.vehicle, None)
            if home != e.at:
                out.append(ShelfSlip(e.t1, e.vehicle, e.at, "dropped nothing" if home is None
                                     else f"dropped the shelf of {home} elsewhere"))
            away.discard(home)
    out.extend(ShelfSlip(float("inf"), v, at, "never brought home")
               for v, at in sorted(carrying.items()))
    return out


def recorded_events(recording: Recording, floor: Floor004) -> tuple[list[Event], list[str]]:
    """The tracking events the recording holds, in the order the dispatcher numbered them
    (a restarted recorder writes those its predecessor lost after the live ones it heard
    first), each once, and why any recorded one names no event."""
    events, unreadable = [], []
    numbered = {r.envelope.seq: m for r, m in reversed(recording.of(AgvEvent))}  # the first
    for _, m in sorted(numbered.items()):
        try:
            events.append(event_from_wire(m, floor))
        except NotAnEvent as exc:
            unreadable.append(str(exc))
    return events, unreadable


def analyze004(recording: Recording) -> Report004:
    info = recording.info
    if info is None:
        raise UserError(f"{recording.path}: no mission description was recorded")
    floor = recording.layout().floor
    if floor is None:
        raise UserError(f"{recording.path}: layout {info.layout} is no seed-004 floor")
    events, unreadable = recorded_events(recording, floor)
    verdict = judge(floor, events, recorded_starts(recording, floor))
    picked = [e for e in events if isinstance(e, Picked)]
    counts: Counter[str] = Counter(e.kind.value for e in events if isinstance(e, Met))
    counts["replans"] = sum(isinstance(e, Replanned) for e in events)
    counts["turns"] = sum(isinstance(e, Turned) for e in events)
    counts["cells"] = sum(isinstance(e, Moved) for e in events)
    return Report004(str(recording.path), info.layout, info.clock, info.vehicles, info.seed,
                     info.orders, len(picked), max((e.t for e in picked), default=0.0),
                     end_time_s(events), dict(sorted(counts.items())), verdict,
                     shelf_slips(floor, events), unreadable, mission_finished(recording),
                     info.heat_w,
                     sum(isinstance(e, BrokeDown | ZoneClosed) for e in events),
                     fault_breaches(events),
                     missing_runs([r.envelope.seq for r, _ in recording.of(AgvEvent)],
                                  events_published(recording)),
                     [f"{Path(s.path).name}" + ("" if s.complete else " (torn)")
                      for s in recording.segments] if len(recording.segments) > 1 else [],
                     dispatcher_restarts(recording))


def dispatcher_restarts(recording: Recording) -> list[float | None]:
    """A dispatcher publishes what the run is first (message 1 of its stream, where an
    answer to a recorder's question is numbered 0); for each after the first, the sim time
    of its first event: the lowest numbered of the events recorded after that which number
    above every event recorded before (an old event caught up on later, to fill a hole,
    numbers below; None: none)."""
    starts = [r.log_ns for r, _ in recording.of(MissionInfo) if r.envelope.seq == 1]
    events = [(r.log_ns, r.envelope.seq, m.t0) for r, m in recording.of(AgvEvent)]
    out: list[float | None] = []
    for start in starts[1:]:
        before = max((n for at, n, _ in events if at < start), default=0)
        after = [(n, t0) for at, n, t0 in events if at > start and n > before]
        out.append(min(after)[1] if after else None)
    return out


def events_published(recording: Recording) -> int:
    """How many events the dispatcher published, as its recorded result says (0: unknown)."""
    done = [m for _, m in recording.of(MissionDone)]
    count = done[-1].record.get("events") if done else None
    return count if isinstance(count, int) and not isinstance(count, bool) else 0


def missing_runs(numbers: list[int], published: int = 0) -> list[tuple[int, int]]:
    """The numbers from 1 to `published` (or to the highest of `numbers`) that are not
    among `numbers`, as (first, last) runs."""
    runs, expected = [], 1
    for n in sorted(set(numbers)):
        if n > expected:
            runs.append((expected, n - 1))
        expected = n + 1
    if published >= expected:
        runs.append((expected, published))
    return runs


def recorded_starts(recording: Recording, floor: Floor004) -> dict[int, tuple[int, int]]:
    """Each AGV's start cell, as the recording's mission description says."""
    starts = recording.info.starts if recording.info is not None else []
    return {v: _xy(floor, Pose.parse(p)) for v, p in enumerate(starts, 1)}


def end_time_s(events: list[Event]) -> float:
    """The last event's end (the last move, lift or drop, as a rule)."""
    return max((getattr(e, "t1", getattr(e, "t", 0.0)) for e in events), default=0.0)


def mission_finished(recording: Recording) -> bool:
    """The dispatcher's result is recorded and says done (and nobody stopped the mission)."""
    done = [m for _, m in recording.of(MissionDone)]
    return bool(done) and done[-1].ok and not recording.of(MissionStopped)


def _xy(floor: Floor004, pose: Pose) -> tuple[int, int]:
    """The floor's (x, y) of a recorded start pose's cell (row 0 at the bottom)."""
    col, row = pose.cell
    return (col, floor.height - 1 - row)


def _verdict(ok: bool, text: str) -> str:
    return f"{'pass' if ok else 'FAIL'}: {text}"


def report_lines(r: Report004) -> list[str]:
    """The numbers, as `fleet analyze` prints them (labels as seed 000's)."""
    c = r.counts
    lines = [
        f"mission orders on {r.layout} with {r.vehicles} lifting AGVs, seed {r.seed}, "
        f"{r.clock} clock" + (f", heat cost {r.heat_w:g}" if r.heat_w else ""),
        f"  {'orders':<19}{r.orders_picked} of {r.orders_expected} picked, the last at "
        f"t={r.completion_s:.1f} s",
        f"  {'end time':<19}{r.end_time_s:.1f} s (the last move, lift or drop)",
        f"  {'driving':<19}{c.get('cells', 0)} cells, {c.get('turns', 0)} turns, "
        f"{c.get('replans', 0)} replans",
        f"  {'conflicts':<19}{c.get('head-on', 0)} head-on, {c.get('crossing', 0)} crossing, "
        f"{c.get('rear-end', 0)} rear-end",
    ]
    if r.segments:
        lines.append(f"  {'segments':<19}{len(r.segments)}: {', '.join(r.segments)}")
    if r.restarts:
        firsts = ", ".join("none" if t is None else f"t={t:.1f}" for t in r.restarts)
        times = "once" if len(r.restarts) == 1 else f"{len(r.restarts)} times"
        lines.append(f"  {'dispatcher':<19}restarted {times}, the mission picked up (the "
                     f"first event after: {firsts})")
    return lines


def verdict_lines(r: Report004) -> list[str]:
    v = r.verdict
    lines = [
        f"  {'cells':<19}" + _verdict(not (v.clashes or v.bad_moves),
                                       f"{len(v.clashes)} shared, {len(v.bad_moves)} bad moves"),
        f"  {'traffic rules':<19}" + _verdict(not v.rule_breaches,
                                               f"{len(v.rule_breaches)} moves against them"),
        f"  {'giving way':<19}" + _verdict(not v.yield_breaches,
                                            f"{len(v.yield_breaches)} head-on conflicts not "
                                            f"given way by the empty AGV"),
        f"  {'work':<19}" + _verdict(r.work_done, f"{r.orders_picked} of {r.orders_expected} "
                                     f"orders, {len(r.shelf_slips)} shelf slips"
                                     + ("" if r.finished else ", no result recorded")),
    ]
    for problem in [*v.clashes, *v.bad_moves, *v.rule_breaches, *v.yield_breaches,
                    *r.shelf_slips][:5]:
        lines.append(f"  {'':<19}{problem}")
    if r.faults:
        lines.append(f"  {'faults':<19}" + _verdict(not r.fault_breaches, (
            f"{r.faults} struck, {len(r.fault_breaches)} moves against them")))
        lines += [f"  {'':<19}{b}" for b in r.fault_breaches[:5]]
    if r.unreadable:
        lines.append(f"  {'events':<19}FAIL: {len(r.unreadable)} name no event of the floor: "
                     f"{r.unreadable[0]}")
    if r.events_missing:
        missing = sum(b - a + 1 for a, b in r.events_missing)
        lines.append(f"  {'events':<19}FAIL: {missing} of the dispatcher's not recorded (" +
                     ", ".join(f"{a}" if a == b else f"{a} to {b}"
                               for a, b in r.events_missing[:3]) + ")")
    return lines


def report_json(r: Report004) -> dict:
    v = r.verdict
    return {"mission": {"kind": "orders", "layout": r.layout, "vehicles": r.vehicles,
                        "seed": r.seed, "clock": r.clock, "heat": r.heat_w},
            "orders": r.orders_expected, "picked": r.orders_picked,
            "completion_s": r.completion_s, "end_time_s": r.end_time_s, "counts": r.counts,
            "recording": r.path,
            "verdicts": {"cells": not (v.clashes or v.bad_moves),
                         "rules": not v.rule_breaches, "giving_way": not v.yield_breaches,
                         "work": r.work_done, "events": r.messages_whole,
                         "faults": not r.fault_breaches, "passed": r.passed},
            "faults": r.faults, "dispatcher_restarts": r.restarts}
