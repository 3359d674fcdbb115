"""Where each vehicle's time went, from a recording's dispatch events alone.

Every instant of the mission span [0, T] (T: the later of the last stack done and the last
vehicle parked) is counted once per vehicle, in one of these (docs/metrics.md):

- busy: driving a step of a committed trajectory (any but a wait, which the vehicle kind
  names: seed 000's forklift's stop maneuver);
- stopped: a wait inside a committed trajectory (standing where it was planned to, to let
  another vehicle pass);
- postponed: free (its last subtask done, or the mission begun) while its next subtask starts
  later: the dispatcher postponed it, or the real-time clock held it;
- handling: claiming goods at a station or unloading them at a stack (a fill begins with
  every vehicle claiming its first goods);
- down: halted by a fault, from the halt until it is resumed;
- idle: the rest, with nothing to do (after its last subtask).

waiting = stopped + postponed: what the dispatcher's record keeps as `wait_s`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from fleet.mission.record import SubtaskRecord
from fleet.params import DispatchParams
from fleet.vehicles.kind import VehicleKind
from fleet.wire.protocol import Halt, Resume

BUSY, STOPPED, POSTPONED, HANDLING, DOWN = "busy", "stopped", "postponed", "handling", "down"


@dataclass(frozen=True)
class VehicleStats:
    vehicle: int
    subtasks: int
    distance_m: float  # each driven step's path
    busy_s: float
    stopped_s: float
    postponed_s: float
    waiting_s: float  # stopped + postponed
    handling_s: float
    down_s: float
    idle_s: float
    utilisation: float  # busy over the mission span


@dataclass
class _Span:
    t0: float
    t1: float
    what: str
    label: str = ""  # the step, for busy and stopped spans
    full_s: float = 0.0  # the whole step's duration (a span may be part of it)


@dataclass
class _Timeline:
    """One vehicle's spans as the dispatch events come, in sim-time order."""

    kind: VehicleKind
    free: float  # when it may start its next subtask
    spans: list[_Span]
    live: list[tuple[float, list[_Span]]]  # uncut subtasks: their t_end and their spans
    down_from: float | None = None
    in_progress: _Span | None = None  # the step a vehicle that went down stood in

    def subtask(self, s: SubtaskRecord) -> None:
        own = [_Span(self.free, s.t_i, POSTPONED)] if s.t_i > self.free else []
        for label, _, _, t0, t1, *_ in s.steps:
            what = STOPPED if self.kind.is_wait(label) else BUSY
            own.append(_Span(t0, t1, what, label, t1 - t0))
        own.append(_Span(s.t_end, s.t_done, HANDLING))
        self.spans += own
        self.live.append((s.t_end, own))
        self.free = s.t_done

    def halt(self, h: Halt) -> None:
        """The plan is cut (fleet.mission.engine: Engine._freeze): a subtask not yet arrived at h.t
        ends with the step in progress (at h.t_stand), or at h.t if the vehicle is down,
        which then stands until resumed."""
        if self.down_from is not None:
            return  # already down
        cut = [spans for t_end, spans in self.live if t_end > h.t]
        self.live = []
        stop = h.t_stand if h.moving else h.t
        self.free = h.t_stand if cut else max(self.free, h.t_stand)
        if not h.moving:
            self.in_progress = next((sp for spans in cut for sp in spans
                                     if sp.what in (BUSY, STOPPED) and sp.t0 <= h.t < sp.t1),
                                    None)
            cut = [self.spans]  # nothing goes on while it is down, not even unloading
            self.down_from = h.t
        for spans in cut:
            for sp in spans:
                sp.t1 = min(sp.t1, max(sp.t0, stop))

    def resume(self, r: Resume) -> None:
        if self.down_from is None:
            return
        self.spans.append(_Span(self.down_from, r.t, DOWN))
        if self.in_progress is not None:  # the rest of that step, from where it stood
            sp = self.in_progress
            self.spans.append(_Span(r.t, r.t_stand, sp.what, sp.label, sp.full_s))
        self.free = max(self.free, r.t_stand)
        self.down_from, self.in_progress = None, None


def time_use(subtasks: Sequence[SubtaskRecord], halts: list[Halt], resumes: list[Resume],
             vehicles: int, span_s: float, kind: str,
             vehicle_kind: VehicleKind) -> list[VehicleStats]:
    """Each vehicle's time over [0, span_s], from the subtasks (as announced) and the halts
    and resumes of a recording. A subtask decided before a halt (its
    t_i earlier) is cut by it; the engine applies a fault before any decision at its instant."""
    claim = DispatchParams().t_claim if kind == "fill" else 0.0
    events: list[tuple[float, int, Any]] = [(s.t_i, 2, s) for s in subtasks]
    events += [(h.t, 0, h) for h in halts] + [(r.t, 1, r) for r in resumes]
    out = []
    for v in sorted(set(range(1, vehicles + 1)) | {s.vehicle for s in subtasks}):
        line = _Timeline(vehicle_kind, claim, [_Span(0.0, claim, HANDLING)] if claim else [],
                         [])
        for _, _, e in sorted((e for e in events if e[2].vehicle == v),
                              key=lambda e: (e[0], e[1])):
            if isinstance(e, Halt):
                line.halt(e)
            elif isinstance(e, Resume):
                line.resume(e)
            else:
                line.subtask(e)
        if line.down_from is not None:
            line.spans.append(_Span(line.down_from, span_s, DOWN))
        out.append(_stats(v, sum(s.vehicle == v for s in subtasks), line.spans, span_s,
                          vehicle_kind))
    return out


def _stats(vehicle: int, subtasks: int, spans: list[_Span], span_s: float,
           vehicle_kind: VehicleKind) -> VehicleStats:
    seconds = dict.fromkeys((BUSY, STOPPED, POSTPONED, HANDLING, DOWN), 0.0)
    distance = 0.0
    for sp in spans:
        d = min(sp.t1, span_s) - max(sp.t0, 0.0)
        if d <= 0:
            continue
        seconds[sp.what] += d
        if sp.what == BUSY and sp.full_s > 0:
            distance += vehicle_kind.path_length_m(sp.label) * min(1.0, d / sp.full_s)
    return VehicleStats(
        vehicle, subtasks, distance, seconds[BUSY], seconds[STOPPED], seconds[POSTPONED],
        seconds[STOPPED] + seconds[POSTPONED], seconds[HANDLING], seconds[DOWN],
        max(0.0, span_s - sum(seconds.values())),
        seconds[BUSY] / span_s if span_s > 0 else 0.0)

