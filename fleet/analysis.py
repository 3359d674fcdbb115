"""`fleet analyze`: what a recording says about its run, and two verdicts.

Safety (fleet/safety.py, independent of the planner and the table): no two forklifts on one
cell at one instant, no forklift outside its own reservation, no cell held by two owners at
once. Work: every stack of the layout filled (or emptied) exactly once. Messages: every
stream's sequence numbers are complete (a gap is a lost message).
"""

from __future__ import annotations

import functools
import itertools
import math
from collections import Counter, defaultdict
from dataclasses import asdict, dataclass, field
from typing import Any

from fleet.maneuvers import Manner, local_pose
from fleet.protocol import Change, MissionDone, StackDone, VehicleState
from fleet.recorded_mission import record_of
from fleet.recording import Recording, RecordingError
from fleet.safety import (
    Body,
    Sample,
    double_bookings,
    outside_reservation,
    overlaps,
    replay,
)

IDLE, WAITING, BUSY = "idle", "waiting", "busy"


@dataclass
class VehicleStats:
    vehicle: int
    distance_m: float = 0.0
    busy_s: float = 0.0  # driving a maneuver
    waiting_s: float = 0.0  # a stop maneuver inside a trajectory
    idle_s: float = 0.0  # the rest of the mission: at rest, claiming, unloading
    subtasks: int = 0


@dataclass(frozen=True)
class Gap:
    key: str
    sender: str
    missing: int  # messages lost
    first_missing: int  # sequence number


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
    stacks_expected: int
    stacks_done: int
    stacks_duplicated: list[str]
    stacks_lost: list[str]
    subtasks: int
    decision_failures: int
    commit_conflicts: int
    vehicles: list[VehicleStats]
    messages: dict[str, int]  # per message type
    messages_lost: int
    gaps: list[Gap]
    malformed: int  # payloads that were no valid message (recorded as they came)
    foreign: int  # valid messages on a key not theirs, or from a sender not the key's
    overlaps: list = field(default_factory=list)
    outside_reservation: list = field(default_factory=list)
    double_bookings: list = field(default_factory=list)

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
        for name in ("overlaps", "outside_reservation", "double_bookings"):
            data[name] = len(getattr(self, name))
            data[f"{name}_first"] = [_jsonable(asdict(x)) for x in getattr(self, name)[:20]]
        data.update(safe=self.safe, work_done=self.work_done, passed=self.passed)
        return _jsonable(data)

    def verdict_lines(self) -> list[str]:
        def mark(ok: bool) -> str:
            return "pass" if ok else "FAIL"

        return [
            f"safety             {mark(self.safe)}: {len(self.overlaps)} overlaps, "
            f"{len(self.outside_reservation)} moments outside a reservation, "
            f"{len(self.double_bookings)} double-booked cells",
            f"work               {mark(self.work_done)}: {self.stacks_done} of "
            f"{self.stacks_expected} stacks, {len(self.stacks_duplicated)} twice, "
            f"{len(self.stacks_lost)} lost",
            f"messages           {mark(self.messages_lost == 0)}: "
            f"{sum(self.messages.values())} recorded, {self.messages_lost} lost, "
            f"{self.malformed} malformed, {self.foreign} foreign",
        ]

    def lines(self) -> list[str]:
        m = self.mission
        out = [f"recording {self.path}"]
        if not self.complete:
            out.append(f"  truncated: {self.problem}; recovered {self.recovered_span_s:.1f} s "
                       f"of messages, up to sim time {self.recovered_sim_s:.1f} s")
        out += [
            f"  mission            {m.get('kind')} on {m.get('layout')} with "
            f"{m.get('vehicles')} forklifts, strategy {m.get('strategy')}, clock "
            f"{m.get('clock')}, seed {m.get('seed')}",
            f"  finished           {'yes' if self.finished else 'no'}"
            + (f" ({self.mission_error})" if self.mission_error else ""),
            f"  end time           {self.end_time_s:.2f} s",
            f"  subtasks           {self.subtasks}",
            f"  decision failures  {self.decision_failures}",
            f"  commit conflicts   {self.commit_conflicts}",
            "  forklift  distance m   busy s   wait s   idle s  subtasks",
        ]
        for v in self.vehicles:
            out.append(f"  {v.vehicle:>8} {v.distance_m:11.1f} {v.busy_s:8.1f} "
                       f"{v.waiting_s:8.1f} {v.idle_s:8.1f} {v.subtasks:9d}")
        out.append("  messages           " + ", ".join(
            f"{k} {n}" for k, n in sorted(self.messages.items())))
        for gap in self.gaps[:10]:
            out.append(f"  gap                {gap.missing} lost on {gap.key} from "
                       f"{gap.sender} at seq {gap.first_missing}")
        out += [f"  {line}" for line in self.verdict_lines()]
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
    held = replay(_unique_revisions(recording))
    done = [m for _, m in recording.of(MissionDone)]
    stacks = Counter((m.cluster, m.index) for _, m in recording.of(StackDone))
    expected = {(s.cluster, s.index) for s in layout.stacks}
    gaps = sequence_gaps(recording)
    return Report(
        path=str(recording.path), complete=recording.complete, problem=recording.problem,
        recovered_span_s=recording.span_s, recovered_sim_s=recording.last_sim_time,
        mission={"layout": info.layout, "kind": info.kind, "strategy": info.strategy,
                 "vehicles": info.vehicles, "seed": info.seed, "clock": info.clock,
                 "speed": info.speed},
        finished=bool(done) and done[-1].ok,
        mission_error=done[-1].error if done else "",
        end_time_s=record["end_time_s"],
        stacks_expected=len(expected),
        stacks_done=len(set(stacks) & expected),
        stacks_duplicated=sorted(f"{c}#{i}" for (c, i), n in stacks.items() if n > 1),
        stacks_lost=sorted(f"{c}#{i}" for c, i in expected - set(stacks)),
        subtasks=len(record["subtasks"]),
        decision_failures=record["decision_failures"],
        commit_conflicts=len(done[-1].rejections) if done else 0,
        vehicles=vehicle_stats(record, layout.cell_size),
        messages=dict(Counter(r.envelope.message.TYPE for r in recording.messages
                              if r.genuine)),
        messages_lost=sum(g.missing for g in gaps), gaps=gaps,
        malformed=sum(r.envelope is None for r in recording.messages)
        + len(states) - len(usable),
        foreign=len(recording.foreign),
        overlaps=overlaps(samples, body),
        outside_reservation=outside_reservation(samples, held, body),
        double_bookings=double_bookings(held),
    )


def _unique_revisions(recording: Recording) -> list[tuple[str, int, list, float | None]]:
    """The table's changes in revision order, each once (a retried publish may repeat)."""
    by_revision: dict[int, Change] = {}
    for _, m in recording.of(Change):
        by_revision.setdefault(m.revision, m)
    return [(m.op, m.vehicle, m.intervals, m.release_from)
            for _, m in sorted(by_revision.items())]


def sequence_gaps(recording: Recording) -> list[Gap]:
    """Messages missing from each stream of genuine messages: a (key, sender) stream numbers
    its messages 1, 2, 3, ... (a reply to a question carries 0 and is no stream's)."""
    seen: dict[tuple[str, str], set[int]] = defaultdict(set)
    for r in recording.messages:
        if r.genuine and r.envelope.seq > 0:
            seen[r.key, r.envelope.sender].add(r.envelope.seq)
    gaps = []
    for (key, sender), numbers in sorted(seen.items()):
        ordered = sorted(numbers)
        missing = ordered[0] - 1 + sum(b - a - 1 for a, b in itertools.pairwise(ordered))
        if missing:
            first = 1 if ordered[0] > 1 else next(
                a + 1 for a, b in itertools.pairwise(ordered) if b > a + 1)
            gaps.append(Gap(key, sender, missing, first))
    return gaps


def vehicle_stats(record: dict[str, Any], cell_size: float) -> list[VehicleStats]:
    """Distance and time per activity from the maneuvers each forklift committed: busy
    driving, waiting in a stop maneuver, idle the rest of the mission."""
    stats = {int(v): VehicleStats(int(v)) for v in record["busy_s"]}
    for s in record["subtasks"]:
        st = stats.setdefault(s["vehicle"], VehicleStats(s["vehicle"]))
        st.subtasks += 1
        for label, _, _, t0, t1, *_ in s["steps"]:
            if label == "stop":
                st.waiting_s += t1 - t0
            else:
                st.busy_s += t1 - t0
                st.distance_m += maneuver_length(label) * cell_size
    end = max(record["end_time_s"], record["all_parked_s"])
    for st in stats.values():
        st.idle_s = max(0.0, end - st.busy_s - st.waiting_s)
    return [stats[v] for v in sorted(stats)]


@functools.cache
def maneuver_length(label: str) -> float:
    """Path length of a maneuver in cells (its rear-axle point's arc, finely sampled)."""
    manner = Manner.from_label(label)
    points = [local_pose(manner, k / 200)[:2] for k in range(201)]
    return sum(math.dist(a, b) for a, b in itertools.pairwise(points))
