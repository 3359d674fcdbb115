"""A lower bound on a stack mission's end time, and where a real mission's time went beyond it.

Seed 000's forklifts alternate trips: from a station to a stack (fill: goods claimed at the
station, unloaded on the stack; empty: claimed on the stack) and back to a station. Relax
every interaction between forklifts (an empty reservation table: no waiting, no detour) and
give each stack its shortest trips on the floor it has at its turn: `out` from the best
station dock to any of its unload poses, `back` from the best unload pose to the best dock,
each chosen apart (a forklift may return to another station than it came from), each the
fastest trip the planner finds alone on the floor. Forklift v serving stacks S_v is then busy
at least

    sum over S_v of (out + back + t_claim + t_unload) - back(last) - tail

before its last stack is done: its last return is not needed, and in an empty mission neither
is the unload after it (tail = t_unload; in a fill the first claim is the start's, counted).
The end time is at least the mean of that over the forklifts, and the sum is smallest when
the V forklifts' last stacks are those with the longest returns. A forklift that starts off a
station dock takes its first trip from its start: the bound credits it the most such a start
could save, by the relaxed arrival time (never more work than a dock start).

`gap` splits a real record's forklift-seconds up to the end time by the same costs, so the
distance from the bound reads as waiting, detours, idle forklifts and unshared work.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from fleet.dispatching.decision import TaskKind
from fleet.mission.record import MissionRecord
from fleet.mission.spec import MissionKind
from fleet.params import DispatchParams
from fleet.planning.geometry import Cell
from fleet.planning.planner import HybridAStar
from fleet.planning.reservations import ReservationTable
from fleet.planning.trajectory import Pose, Trajectory
from fleet.world.layout import Layout, LayoutError
from fleet.world.site import planners_for


@dataclass(frozen=True)
class StackTrips:
    """A stack's shortest trips on an empty floor, at its turn in the mission's order."""

    cell: Cell
    out: float  # best station dock -> any unload pose
    back: float  # best unload pose -> any station dock
    first: dict[Pose, float]  # from each start that is not a dock -> any unload pose


@dataclass(frozen=True)
class Bound:
    value: float  # the end time no schedule beats
    trips: dict[Cell, StackTrips]
    ready_at: float  # a fill's forklifts first claim goods where they start

    @classmethod
    def of(cls, trips: dict[Cell, StackTrips], kind: MissionKind, starts: Sequence[Pose],
           params: DispatchParams) -> Bound:
        """The bound for a fleet starting at `starts`, from trips found for those starts or
        more (module docstring)."""
        handling = params.t_claim + params.t_unload
        work = sum(t.out + t.back + handling for t in trips.values())
        tail = params.t_unload if kind is MissionKind.EMPTY else 0.0
        longest_backs = sorted((t.back for t in trips.values()), reverse=True)[:len(starts)]
        work -= sum(longest_backs) + tail * len(longest_backs)
        for start in starts:  # the most a start off the docks can save on its first trip
            if trips and start in next(iter(trips.values())).first:
                work += min(0.0, min(t.first[start] - t.out for t in trips.values()))
        return cls(work / len(starts), trips,
                   params.t_claim if kind is MissionKind.FILL else 0.0)


def _shortest(planner: HybridAStar, starts: list[Pose], ends: list[Pose],
              empty: ReservationTable) -> float:
    """The fastest trip the planner finds from any start to any end on an empty floor, one
    end at a time (a search towards several ends at whichever its weighted heuristic
    favours, not always the nearest). Pairs go in order of their relaxed arrival time
    (`earliest_arrivals`, never later than a real trip), and once that is no sooner than the
    best trip found, no later pair can beat it."""
    pairs = []
    for start in starts:
        relaxed = planner.earliest_arrivals(start)
        pairs += [(relaxed[key], i, start, end) for i, end in enumerate(ends)
                  if (key := (end.cell[0], end.cell[1], end.heading)) in relaxed]
    best = math.inf
    for at_least, _, start, end in sorted(pairs, key=lambda p: p[:2]):
        if at_least >= best:
            break
        out = planner.plan(1, start, 0.0, [end], empty)
        if isinstance(out, Trajectory):
            best = min(best, out.t_end)
    return best


def _relaxed(planner: HybridAStar, start: Pose, ends: list[Pose]) -> float:
    relaxed = planner.earliest_arrivals(start)
    return min((relaxed.get((e.cell[0], e.cell[1], e.heading), math.inf) for e in ends),
               default=math.inf)


def stack_trips(layout: Layout, kind: MissionKind, starts: Sequence[Pose],
                progress: Callable[[int, int], None] | None = None) -> dict[Cell, StackTrips]:
    """Every stack's shortest trips; `progress` hears (stacks done, stacks) after each, since
    a large floor takes minutes. A start off the docks gets the relaxed arrival (a first trip
    can only be longer)."""
    fill = kind is MissionKind.FILL
    present: set[Cell] = set() if fill else {s.cell for s in layout.stacks}
    order = sorted(layout.stacks, key=lambda s: (s.cluster, s.index if fill else -s.index))
    docks = [st.dock for st in layout.stations]
    off_dock = [p for p in dict.fromkeys(starts) if p not in docks]
    empty = ReservationTable()
    planners = planners_for(layout)
    trips: dict[Cell, StackTrips] = {}
    for done, stack in enumerate(order, 1):
        key = frozenset(present - {stack.cell})
        planner = planners.get(key)
        goals = layout.unload_poses(stack.cell, key)
        out = _shortest(planner, docks, goals, empty)
        back = _shortest(planner, goals, docks, empty)
        if math.inf in (out, back):
            raise LayoutError(f"layout {layout.name}: stack {stack.cluster}#{stack.index} cannot "
                              f"be served from any station, even on an empty floor (fleet "
                              f"layout check lists every such stack)")
        first = {p: _relaxed(planner, p, goals) for p in off_dock}
        trips[stack.cell] = StackTrips(stack.cell, out, back, first)
        if fill:
            present.add(stack.cell)
        else:
            present.discard(stack.cell)
        if progress:
            progress(done, len(order))
    return trips


def bound(layout: Layout, kind: MissionKind, starts: Sequence[Pose],
          params: DispatchParams | None = None,
          progress: Callable[[int, int], None] | None = None) -> Bound:
    return Bound.of(stack_trips(layout, kind, starts, progress), kind, starts,
                    params or DispatchParams())


def lower_bound(layout: Layout, kind: MissionKind, vehicles: int,
                params: DispatchParams | None = None,
                progress: Callable[[int, int], None] | None = None) -> float:
    """The bound for the layout's first `vehicles` start poses."""
    return bound(layout, kind, layout.vehicle_starts[:vehicles], params, progress).value


@dataclass(frozen=True)
class Gap:
    """A record's forklift-seconds up to its end time, by what they were spent on."""

    shortest_s: float  # driving, at the bound's shortest trip for each stack served
    beyond_shortest_s: float  # the rest of the driving: waits, detours, another station
    handling_s: float  # claiming and unloading
    between_s: float  # at rest between subtasks (a decision failed, or came later)
    after_last_s: float  # at rest after its last subtask, before the end
    aside_s: float  # driving out of another's way (a deadlock broken)

    @property
    def total_s(self) -> float:
        return (self.shortest_s + self.beyond_shortest_s + self.handling_s + self.between_s
                + self.after_last_s + self.aside_s)

    def as_dict(self) -> dict[str, float]:
        return {k: round(v, 2) for k, v in vars(self).items()}


def gap(record: MissionRecord, bound: Bound) -> Gap:
    """Split each forklift's time from 0 to the record's end time (module docstring)."""
    end, trips, ready_at = record.end_time, bound.trips, bound.ready_at
    parts = dict.fromkeys(("shortest", "beyond", "handling", "between", "after", "aside"), 0.0)
    for v in record.vehicles:
        t = ready_at
        parts["handling"] += min(ready_at, end)
        last_stack: Cell | None = None
        for s in sorted((s for s in record.subtasks if s.vehicle == v), key=lambda s: s.t_i):
            if s.t_i >= end:
                break
            parts["between"] += s.t_i - t
            drive = min(s.t_end, end) - s.t_i
            if s.kind is TaskKind.ASIDE:
                parts["aside"] += drive
            else:
                cell = s.stack_cell if s.kind is TaskKind.DELIVER else last_stack
                best = 0.0 if cell is None else (
                    trips[cell].out if s.kind is TaskKind.DELIVER else trips[cell].back)
                parts["shortest"] += min(best, drive)
                parts["beyond"] += drive - min(best, drive)
            if s.kind is TaskKind.DELIVER:
                last_stack = s.stack_cell
            parts["handling"] += max(0.0, min(s.t_done, end) - s.t_end)
            t = min(s.t_done, end)
        parts["after"] += end - t
    return Gap(parts["shortest"], parts["beyond"], parts["handling"], parts["between"],
               parts["after"], parts["aside"])
