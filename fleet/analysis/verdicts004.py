"""A seed-004 run judged from its events by the verifiers that know nothing of the tracker or
the planner (fleet/analysis/cells004.py, traffic004.py): the events are only read, as a
recording would be."""

from __future__ import annotations

import bisect
import itertools
from collections import defaultdict
from collections.abc import Iterable, Mapping
from dataclasses import dataclass

from fleet.analysis.cells004 import BadMove, Clash, Move, clashes, held
from fleet.analysis.traffic004 import (
    Breach,
    Drive,
    Floor,
    breaches,
    loaded_at,
    yielding_breaches,
)
from fleet.mission.tracking004 import (
    STEPPED_ASIDE,
    Conflict,
    Event,
    LegDone,
    Met,
    Moved,
    Paused,
    Replanned,
    Turned,
)
from fleet.planning.rules004 import XY, Kind
from fleet.world.floor004 import Floor004

N_RELAX = 3  # failed plans in a row before an empty AGV may drive without the rules (B.4.1)


@dataclass(frozen=True)
class Verdict004:
    clashes: list[Clash]
    bad_moves: list[BadMove]
    rule_breaches: list[Breach]  # moves against the rules, and relaxed moves not earned
    yield_breaches: list[Breach]

    @property
    def passed(self) -> bool:
        return not (self.clashes or self.bad_moves or self.rule_breaches
                    or self.yield_breaches)


def rules_floor(floor: Floor004) -> Floor:
    lanes = frozenset(xy for xy, kind in floor.kinds.items() if kind is Kind.LANE)
    drivable = frozenset(xy for xy, kind in floor.kinds.items()
                         if kind in (Kind.FLOOR, Kind.SLOT, Kind.LANE))
    steps = frozenset(step for s in floor.stations for step in itertools.pairwise(s.route))
    return Floor(floor.width, floor.grid.aisle_columns, floor.grid.aisle_rows,
                 frozenset(s.xy for s in floor.slots), lanes, drivable, steps)


def judge(floor: Floor004, events: Iterable[Event], starts: Mapping[int, XY],
          carrying: Mapping[int, XY] | None = None, n_relax: int = N_RELAX) -> Verdict004:
    """`starts`: where each AGV stood at t = 0; `carrying`: the shelf's home of those that
    started loaded; `n_relax`: the failed plans in a row that earn a relaxed episode."""
    events = list(events)
    moves = [e for e in events if isinstance(e, Moved)]
    spans, bad = held([Move(m.vehicle, m.t0, m.t1, m.origin, m.to) for m in moves], starts)
    loads: dict[int, list[tuple[float, bool]]] = defaultdict(list)
    lifted_at: dict[int, list[tuple[float, XY]]] = defaultdict(list)
    for v, cell in (carrying or {}).items():
        loads[v].append((0.0, True))
        lifted_at[v].append((0.0, cell))
    for e in events:
        if isinstance(e, Paused) and e.label in ("lift", "drop"):
            loads[e.vehicle].append((e.t1, e.label == "lift"))
            if e.label == "lift":
                lifted_at[e.vehicle].append((e.t1, e.at))

    def home(v: int, t: float) -> XY | None:
        found = None
        for since, cell in lifted_at[v]:
            if since > t:
                break
            found = cell
        return found

    # Loaded or not is what its lifts and drops say, not what the move says of itself.
    drives = [Drive(m.vehicle, m.t0, m.origin, m.to, m.task.value,
                    loaded := loaded_at(loads, m.vehicle, m.t0), m.relaxed,
                    home(m.vehicle, m.t0) if loaded else None) for m in moves]
    head_ons = [(e.t, e.vehicle, e.other) for e in events
                if isinstance(e, Met) and e.kind is Conflict.HEAD_ON]
    replans = [(e.t, e.vehicle) for e in events
               if isinstance(e, Replanned) and e.why.startswith("head-on")]
    return Verdict004(clashes(spans), bad + _driving_while_still(moves, events),
                      breaches(rules_floor(floor), drives) + unearned(events, n_relax),
                      yielding_breaches(head_ons, replans, loads))


def unearned(events: list[Event], n_relax: int) -> list[Breach]:
    """Relaxed moves outside an earned episode: an AGV may drive without the rules only once
    `n_relax` of its plans in a row found no path (since its leg began or a plan last found
    one), and only until its next head-on conflict or the end of its leg (B.4.1)."""
    fails: dict[int, int] = defaultdict(int)
    earned: set[int] = set()
    out = []
    for e in events:
        if isinstance(e, Replanned) and e.why != STEPPED_ASIDE:  # (a step aside plans nothing)
            fails[e.vehicle] = 0 if e.found else fails[e.vehicle] + 1
            if fails[e.vehicle] >= n_relax:
                earned.add(e.vehicle)
        elif isinstance(e, LegDone):
            fails[e.vehicle] = 0
            earned.discard(e.vehicle)
        elif isinstance(e, Met) and e.kind is Conflict.HEAD_ON:
            earned.discard(e.vehicle)
        elif isinstance(e, Moved) and e.relaxed and e.vehicle not in earned:
            out.append(Breach(e.vehicle, e.t0, f"drives {e.origin} -> {e.to} without the "
                              f"rules, but no {n_relax} plans in a row had failed since its "
                              f"leg began or its last head-on conflict"))
    return out


def _driving_while_still(moves: list[Moved], events: list[Event]) -> list[BadMove]:
    """Moves begun while the AGV was lifting, dropping, picking, charging or turning."""
    still: dict[int, list[tuple[float, float, str]]] = defaultdict(list)
    for e in events:
        if isinstance(e, Paused):
            still[e.vehicle].append((e.t0, e.t1, e.label))
        elif isinstance(e, Turned):
            still[e.vehicle].append((e.t0, e.t1, "turning"))
    for spans in still.values():
        spans.sort()
    longest = {v: max(t1 - t0 for t0, t1, _ in spans) for v, spans in still.items()}
    starts = {v: [t0 for t0, _, _ in spans] for v, spans in still.items()}
    out = []
    for m in moves:
        if m.vehicle not in still:
            continue
        first = bisect.bisect_left(starts[m.vehicle], m.t0 - longest[m.vehicle])
        last = bisect.bisect_left(starts[m.vehicle], m.t1)
        for t0, t1, doing in still[m.vehicle][first:last]:  # the spans that may overlap it
            if t0 <= m.t0 < t1 or m.t0 < t0 < m.t1:
                out.append(BadMove(Move(m.vehicle, m.t0, m.t1, m.origin, m.to),
                                   f"drives while {doing} from t={t0} to t={t1}"))
    return out
