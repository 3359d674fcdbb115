"""A lower bound on a stack mission's end time, and where a real mission's time went beyond it.

Seed 000's forklifts alternate trips: from a station to a stack (fill: goods claimed at the
station, unloaded on the stack; empty: claimed on the stack) and back to a station. Relax
every interaction between forklifts (an empty reservation table: no waiting, no detour) and
give each stack its shortest trips on the least obstructed floor it can have at its turn
(only the stacks of its own cluster that come before it in the cluster's order hold goods):
`out` from the best station dock to any of its unload poses, `back` from the best unload pose
to the best dock, each chosen apart (a forklift may return to another station than it came
from), each the fastest trip the planner finds alone on that floor. Forklift v serving stacks
S_v is then busy at least

    sum over S_v of (out + back + t_claim + t_unload) - back(last) - tail

before its last stack is done: its last return is not needed, and in an empty mission neither
is the unload after it (tail = t_unload; in a fill the first claim is the start's, counted).
The end time is at least the mean of that over the forklifts, and the sum is smallest when
the V forklifts' last stacks are those with the longest returns. A forklift that starts off a
station dock takes its first trip from its start: the bound credits it the most such a start
could save, by the relaxed arrival time (`earliest_arrivals`: never later than a real trip).

The bound is relative to the planner: the improved hybrid A* weighs turns, lane changes and
reversals beside time and its heuristic (C11 = 3), so it is not time-optimal, and a trip it
plans among other forklifts may be faster than the one it finds alone. No mission has ended
before the bound (tests/test_lower_bound.py tries seeded random ones); `Gap.faster_s` says how
much of a record's driving beat the bound's trips. `relaxed_bound` is the one that proves
itself, every trip at its relaxed arrival time, and is far looser.

`gap` splits a real record's forklift-seconds up to the end time by the bound's costs, so the
distance from the bound reads as driving beyond the shortest trips, handling, idle forklifts
and unshared work.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from fleet.dispatching.decision import TaskKind
from fleet.mission.record import MissionRecord, Subtask
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

    out: float  # best station dock -> any unload pose
    back: float  # best unload pose -> any station dock
    first: dict[Pose, float]  # relaxed, from each start that is not a dock -> any unload pose


@dataclass(frozen=True)
class Trips:
    """Every stack's trips (by its cell), and the station docks they start and end at."""

    stacks: dict[Cell, StackTrips]
    docks: frozenset[Pose]

    def first_saving(self, start: Pose) -> float:
        """The most a forklift starting at `start` can save on its first trip (<= 0)."""
        if start in self.docks or not self.stacks:
            return 0.0  # a trip from a dock is no shorter than the best dock's
        if start not in next(iter(self.stacks.values())).first:
            raise ValueError(f"no trips were found from start {start}")
        return min(0.0, min(t.first[start] - t.out for t in self.stacks.values()))


@dataclass(frozen=True)
class Bound:
    value: float  # the end time no schedule beats (module docstring: planner-relative)
    trips: Trips
    ready_at: float  # a fill's forklifts first claim goods where they start

    @classmethod
    def of(cls, trips: Trips, kind: MissionKind, starts: Sequence[Pose],
           params: DispatchParams) -> Bound:
        """The bound for a fleet starting at `starts`, from trips found for those starts or
        more (module docstring)."""
        stacks = trips.stacks.values()
        handling = params.t_claim + params.t_unload
        work = sum(t.out + t.back + handling for t in stacks)
        tail = params.t_unload if kind is MissionKind.EMPTY else 0.0
        longest_backs = sorted((t.back for t in stacks), reverse=True)[:len(starts)]
        work -= sum(longest_backs) + tail * len(longest_backs)
        work += sum(trips.first_saving(start) for start in starts)
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


def _turn_floors(layout: Layout) -> dict[Cell, frozenset[Cell]]:
    """Each stack's least obstructed floor at its turn, in a fill or an empty: goods only on
    the stacks of its cluster that come before it in the cluster's fill order (filled before
    it, or emptied after it); other clusters may be empty then."""
    return {s.cell: frozenset(o.cell for o in layout.cluster_stacks(s.cluster)
                              if o.index < s.index) for s in layout.stacks}


def stack_trips(layout: Layout, starts: Sequence[Pose],
                progress: Callable[[int, int], None] | None = None) -> Trips:
    """Every stack's shortest trips; `progress` hears (stacks done, stacks) after each, since
    a large floor takes minutes. The same for a fill and an empty (`_turn_floors`)."""
    docks = [st.dock for st in layout.stations]
    off_dock = [p for p in dict.fromkeys(starts) if p not in docks]
    empty = ReservationTable()
    planners = planners_for(layout)
    floors = _turn_floors(layout)
    order = sorted(layout.stacks, key=lambda s: (s.cluster, s.index))  # planners reused
    stacks: dict[Cell, StackTrips] = {}
    for done, stack in enumerate(order, 1):
        floor = floors[stack.cell]
        planner = planners.get(floor)
        goals = layout.unload_poses(stack.cell, floor)
        out = _shortest(planner, docks, goals, empty)
        back = _shortest(planner, goals, docks, empty)
        if math.inf in (out, back):
            raise LayoutError(f"layout {layout.name}: stack {stack.cluster}#{stack.index} cannot "
                              f"be served from any station, even on an empty floor (fleet "
                              f"layout check lists every such stack)")
        first = {p: _relaxed(planner, p, goals) for p in off_dock}
        stacks[stack.cell] = StackTrips(out, back, first)
        if progress:
            progress(done, len(order))
    return Trips(stacks, frozenset(docks))


def bound(layout: Layout, kind: MissionKind, starts: Sequence[Pose],
          params: DispatchParams | None = None,
          progress: Callable[[int, int], None] | None = None) -> Bound:
    return Bound.of(stack_trips(layout, starts, progress), kind, starts,
                    params or DispatchParams())


def lower_bound(layout: Layout, kind: MissionKind, vehicles: int,
                params: DispatchParams | None = None,
                progress: Callable[[int, int], None] | None = None) -> float:
    """The bound for the layout's first `vehicles` start poses."""
    return bound(layout, kind, layout.vehicle_starts[:vehicles], params, progress).value


def relaxed_trips(layout: Layout, starts: Sequence[Pose]) -> Trips:
    """Every stack's trips at their relaxed arrival times (`earliest_arrivals`): with them
    `Bound.of` gives a bound by proof, on any planner, and far below any real schedule."""
    docks = [st.dock for st in layout.stations]
    planners = planners_for(layout)
    floors = _turn_floors(layout)
    stacks = {}
    for stack in sorted(layout.stacks, key=lambda s: (s.cluster, s.index)):
        floor = floors[stack.cell]
        planner = planners.get(floor)
        goals = layout.unload_poses(stack.cell, floor)
        stacks[stack.cell] = StackTrips(
            min(_relaxed(planner, d, goals) for d in docks),
            min(_relaxed(planner, g, docks) for g in goals),
            {p: _relaxed(planner, p, goals) for p in starts if p not in docks})
    return Trips(stacks, frozenset(docks))


def relaxed_bound(layout: Layout, kind: MissionKind, starts: Sequence[Pose],
                  params: DispatchParams | None = None) -> float:
    return Bound.of(relaxed_trips(layout, starts), kind, starts,
                    params or DispatchParams()).value


@dataclass(frozen=True)
class Gap:
    """A record's forklift-seconds up to its end time, by what they were spent on."""

    shortest_s: float  # driving, up to the bound's shortest trip for each trip driven
    beyond_shortest_s: float  # the rest of the driving: waits, detours, another station
    handling_s: float  # claiming and unloading
    between_s: float  # at rest between subtasks (a decision failed, or came later)
    after_last_s: float  # at rest after its last subtask, before the end
    aside_s: float  # driving out of another's way (a deadlock broken)
    # Not a part of the time: how much sooner than the bound's trips some trips were (the
    # planner is not time-optimal; module docstring).
    faster_s: float = 0.0

    @property
    def total_s(self) -> float:
        return (self.shortest_s + self.beyond_shortest_s + self.handling_s + self.between_s
                + self.after_last_s + self.aside_s)

    def as_dict(self) -> dict[str, float]:
        return {k: round(v, 2) for k, v in vars(self).items()}


def gap(record: MissionRecord, reference: Bound) -> Gap:
    """Split each forklift's time from 0 to the record's end time (module docstring)."""
    end, trips = record.end_time, reference.trips
    shortest = beyond = handling = between = after = aside = faster = 0.0
    for v, start in zip(record.vehicles, record.starts, strict=True):
        t = min(reference.ready_at, end)
        handling += t
        last_stack: Cell | None = None
        first = True
        for s in sorted((s for s in record.subtasks if s.vehicle == v), key=lambda s: s.t_i):
            if s.t_i >= end:
                break
            between += s.t_i - t
            drive = min(s.t_end, end) - s.t_i
            if s.kind is TaskKind.ASIDE:
                aside += drive
            else:
                best = _best_trip(trips, s, last_stack, start if first else None)
                shortest += min(best, drive)
                beyond += max(0.0, drive - best)
                faster += max(0.0, best - drive) if s.t_end <= end else 0.0
                first = False
            if s.kind is TaskKind.DELIVER:
                last_stack = s.stack_cell
            handling += max(0.0, min(s.t_done, end) - s.t_end)
            t = min(s.t_done, end)
        after += end - t
    return Gap(shortest_s=shortest, beyond_shortest_s=beyond, handling_s=handling,
               between_s=between, after_last_s=after, aside_s=aside, faster_s=faster)


def _best_trip(trips: Trips, subtask: Subtask, last_stack: Cell | None,
               start: Pose | None) -> float:
    """The bound's trip for a subtask: `out` to its stack (from an off-dock start, the
    relaxed first trip if shorter), `back` from the stack served before it."""
    if subtask.kind is TaskKind.DELIVER and subtask.stack_cell is not None:
        stack = trips.stacks[subtask.stack_cell]
        return min(stack.out, stack.first.get(start, math.inf)) if start else stack.out
    if last_stack is not None:
        return trips.stacks[last_stack].back
    return 0.0
