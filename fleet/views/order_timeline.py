"""What an order mission's record says happened when (seed 002; docs/agv-002.md, "Orders"):
each AGV's trips, which shelf stood where, which packing station was in use, when each order
was complete, where each AGV was, and how long AGVs spent on each cell.

Pure: the mission record (fleet.mission.record.MissionSummary, for a recording as
fleet.recording.mission_record.summary_of rebuilds it, amendments applied) and the layout in,
plain data out; the plots (fleet/views/order_plots.py) draw it.

When a shelf moves follows the order book and the AGVs' `loaded` flag: it leaves its slot on
the AGV when the AGV sets off for a packing station (the pack trip's t_i: an AGV waiting
under the slot for a free station still leaves it there), rides on it through the station's
dwell, and stands in the slot the stow trip ends at from the AGV's arrival there on. An
order is complete when its shelf is put down: the stow trip's arrival, after any amendment
that postponed it.
"""

from __future__ import annotations

import bisect
import math
from collections import defaultdict
from collections.abc import Iterable
from dataclasses import dataclass
from itertools import pairwise

from fleet.mission.record import MissionSummary
from fleet.planning.geometry import Cell
from fleet.planning.trajectory import Pose
from fleet.wire.protocol import VehicleState
from fleet.world.layout import Layout

FETCH, PACK, STOW, CHARGE = "fetch", "pack", "stow", "charge"
WAIT = "wait"  # the step label of a wait a collision rule put into a leg
EPS = 1e-9


@dataclass(frozen=True)
class Trip:
    """One subtask of an AGV: from t_i it drives from `start` to `goal` (standing where a
    collision rule made it wait), arrives at t_end, and is done at t_done (after the packing
    dwell, for a pack trip)."""

    index: int  # its place in the record's subtasks
    vehicle: int
    kind: str  # fetch, pack, stow, charge (or aside: out of another's way)
    target: str  # the shelf (fetch), station (pack), slot (stow) or pile (charge)
    t_i: float
    t_end: float
    t_done: float
    start: Cell
    goal: Cell
    waits: tuple[tuple[float, float], ...]  # [t0, t1) of each wait step
    shelf: str | None  # the shelf fetched or carried


@dataclass(frozen=True)
class ShelfMove:
    """A shelf carried from the slot it stood in to the slot it was put down in."""

    shelf: str
    vehicle: int
    slot: Cell  # where it was lifted from
    lifted: float  # the pack trip's t_i
    put: float  # the stow trip's arrival (inf: not put down within the record)
    to: Cell | None  # the slot it was put down in


@dataclass(frozen=True)
class Packing:
    """A packing station taken by an AGV: reserved from t_i (on its way), packing from t_end,
    free again at t_done."""

    station: str
    vehicle: int
    shelf: str | None
    t_i: float
    t_end: float
    t_done: float


@dataclass(frozen=True)
class Completion:
    """An order complete: its shelf put down at t."""

    order: int | None  # the order's id, as dispatch.stack announced it (None: not heard)
    shelf: str
    vehicle: int
    t: float


@dataclass(frozen=True)
class Stay:
    """An AGV standing from t0 to t1 (inf: to the end of the record) for a reason: loaded
    under its slot waiting for a free packing station, or on a pile after a charge trip."""

    vehicle: int
    where: str  # the shelf (waiting for a station) or the pile
    t0: float
    t1: float


@dataclass(frozen=True)
class Shelves:
    """Where the shelves are at one instant."""

    in_slot: dict[Cell, str]  # slot cell -> the shelf standing in it
    on_agv: dict[int, str]  # AGV -> the shelf it carries


@dataclass(frozen=True)
class OrderTimeline:
    trips: tuple[Trip, ...]
    moves: tuple[ShelfMove, ...]
    packings: tuple[Packing, ...]
    completions: tuple[Completion, ...]  # in time order
    station_waits: tuple[Stay, ...]
    pile_stays: tuple[Stay, ...]
    home: dict[Cell, str]  # every slot's shelf at the start

    def shelves_at(self, t: float) -> Shelves:
        """Which shelf stands in which slot, and which rides on which AGV, at t."""
        in_slot = dict(self.home)
        on_agv: dict[int, str] = {}
        events = sorted([(m.lifted, 1, k) for k, m in enumerate(self.moves)]
                        + [(m.put, 0, k) for k, m in enumerate(self.moves)])
        for when, lift, k in events:  # at one instant, a shelf put down before one lifted
            if when > t:
                break
            m = self.moves[k]
            if lift:
                if in_slot.get(m.slot) == m.shelf:
                    del in_slot[m.slot]
                on_agv[m.vehicle] = m.shelf
            else:
                if on_agv.get(m.vehicle) == m.shelf:
                    del on_agv[m.vehicle]
                if m.to is not None:
                    in_slot[m.to] = m.shelf
        return Shelves(in_slot, on_agv)

    def stations_at(self, t: float) -> dict[str, str]:
        """Stations in use at t: station -> "packing" (an AGV dwells on it) or "reserved" (an
        AGV is on its way to it)."""
        used = {}
        for p in self.packings:
            if p.t_i <= t < p.t_done:
                used[p.station] = "packing" if t >= p.t_end else "reserved"
        return used

    def completed_by(self, t: float) -> int:
        return bisect.bisect_right([c.t for c in self.completions], t)

    @property
    def makespan(self) -> float:
        """When the last shelf was put down (0 with no order complete)."""
        return self.completions[-1].t if self.completions else 0.0


def _cell(pose: str, fallback: Cell) -> Cell:
    try:
        return Pose.parse(pose).cell
    except ValueError:  # a damaged recording: draw what can be drawn
        return fallback


def _start(record: MissionSummary, vehicle: int) -> Cell:
    if 1 <= vehicle <= len(record.starts):
        return _cell(record.starts[vehicle - 1], (0, 0))
    return (0, 0)


def timeline(layout: Layout, record: MissionSummary) -> OrderTimeline:
    """The order mission's story from its record: trips in the order decided, the shelves'
    moves, the stations' use and the orders completed."""
    slots = {s.name: s.cell for s in layout.slots}
    here: dict[int, Cell] = {}
    fetched: dict[int, tuple[str, Cell]] = {}  # AGV -> shelf under it and its slot
    carrying: dict[int, int] = {}  # AGV -> index into moves of the shelf it carries
    moves: list[ShelfMove] = []
    trips: list[Trip] = []
    packings: list[Packing] = []
    stows: list[tuple[str, int, float]] = []  # (shelf, vehicle, t)
    waits: list[Stay] = []
    piles: list[Stay] = []
    last: dict[int, Trip] = {}
    for k, s in enumerate(record.subtasks):
        v = s.vehicle
        start = here[v] if v in here else _start(record, v)
        goal = _cell(s.steps[-1][2], start) if s.steps else start
        here[v] = goal
        before = last.get(v)
        if before is not None and s.t_i > before.t_done + EPS:
            if before.kind == FETCH:
                waits.append(Stay(v, before.target, before.t_done, s.t_i))
            elif before.kind == CHARGE:
                piles.append(Stay(v, before.target, before.t_end, s.t_i))
        shelf = None
        if s.kind == FETCH:
            shelf = s.target
            fetched[v] = (s.target, goal)
        elif s.kind == PACK and v in fetched:
            shelf, slot = fetched.pop(v)
            carrying[v] = len(moves)
            moves.append(ShelfMove(shelf, v, slot, s.t_i, math.inf, None))
            packings.append(Packing(s.target, v, shelf, s.t_i, s.t_end, s.t_done))
        elif s.kind == PACK:
            packings.append(Packing(s.target, v, None, s.t_i, s.t_end, s.t_done))
        elif s.kind == STOW and v in carrying:
            j = carrying.pop(v)
            m = moves[j]
            shelf = m.shelf
            moves[j] = ShelfMove(m.shelf, v, m.slot, m.lifted, s.t_end, slots.get(s.target, goal))
            stows.append((m.shelf, v, s.t_end))
        elif v in carrying:
            shelf = moves[carrying[v]].shelf
        trip = Trip(k, v, s.kind, s.target, s.t_i, s.t_end, s.t_done, start, goal,
                    tuple((st[3], st[4]) for st in s.steps if st[0] == WAIT), shelf)
        trips.append(trip)
        last[v] = trip
    for v, trip in last.items():
        if trip.kind == CHARGE:
            piles.append(Stay(v, trip.target, trip.t_end, math.inf))
    return OrderTimeline(tuple(trips), tuple(moves), tuple(packings),
                         _completions(record, stows), tuple(waits), tuple(piles),
                         {cell: name for name, cell in slots.items()})


def _completions(record: MissionSummary, stows: list[tuple[str, int, float]]
                 ) -> tuple[Completion, ...]:
    """Each stow as an order complete, named by the order dispatch.stack announced for its
    shelf (a shelf's orders are served in turn, so its k-th stow is its k-th announced)."""
    announced: dict[str, list[int]] = defaultdict(list)
    for stack in record.stacks_done:  # cluster: the shelf; index: the order
        announced[stack.cluster].append(stack.index)
    served: dict[str, int] = defaultdict(int)
    out = []
    for shelf, vehicle, t in stows:
        ids = announced.get(shelf, [])
        k = served[shelf]
        served[shelf] += 1
        out.append(Completion(ids[k] if k < len(ids) else None, shelf, vehicle, t))
    return tuple(sorted(out, key=lambda c: (c.t, c.vehicle)))


# ---------------------------------------------------------------------------- positions


@dataclass(frozen=True)
class Track:
    """Where one AGV is over time, in cell coordinates (column, row as floats): each step a
    straight segment, at one speed, from its start cell to its end cell."""

    start: Cell
    t0: tuple[float, ...]
    t1: tuple[float, ...]
    a: tuple[Cell, ...]
    b: tuple[Cell, ...]

    def at(self, t: float) -> tuple[float, float]:
        k = bisect.bisect_right(self.t0, t) - 1  # the last step started by t
        if k < 0:
            return float(self.start[0]), float(self.start[1])
        (c0, r0), (c1, r1) = self.a[k], self.b[k]
        if t >= self.t1[k]:
            return float(c1), float(r1)
        s = (t - self.t0[k]) / (self.t1[k] - self.t0[k])
        return c0 + s * (c1 - c0), r0 + s * (r1 - r0)


def tracks(record: MissionSummary) -> dict[int, Track]:
    """Every AGV's track, also those that never moved."""
    steps: dict[int, list[tuple[float, float, Cell, Cell]]] = defaultdict(list)
    for s in record.subtasks:
        for _, a, b, t0, t1, *_ in s.steps:
            if t1 > t0:
                start = _cell(a, (0, 0))
                steps[s.vehicle].append((t0, t1, start, _cell(b, start)))
    vehicles = set(range(1, len(record.starts) + 1)) | set(steps)
    out = {}
    for v in sorted(vehicles):
        rows = sorted(steps[v], key=lambda st: st[0])
        out[v] = Track(_start(record, v), tuple(r[0] for r in rows), tuple(r[1] for r in rows),
                       tuple(r[2] for r in rows), tuple(r[3] for r in rows))
    return out


# ---------------------------------------------------------------------------- time on cells

STATE_GAP_CAP_S = 2.0  # as fleet.views.plots: a state stands for 2 s at most


@dataclass(frozen=True)
class CellTime:
    """AGV-seconds on each cell from the recorded states: all of them (`total`), and those
    standing in a collision rule's wait (`waiting`: congestion)."""

    total: dict[Cell, float]
    waiting: dict[Cell, float]
    per_vehicle: dict[int, float]  # each AGV's seconds counted


def cell_seconds(layout: Layout, states: Iterable[tuple[float, VehicleState]],
                 cap_s: float = STATE_GAP_CAP_S) -> CellTime:
    """Each (sim time, state) counts for the time until the same AGV's next state, at most
    cap_s, on the one cell its centre is nearest to (a unit AGV is on one node at a time,
    as the seed's routes are); a last state counts for nothing. States with a non-finite time
    or position are skipped."""
    ox, oy = layout.origin
    size = layout.cell_size
    by_vehicle: dict[int, list[tuple[float, VehicleState]]] = defaultdict(list)
    for t, state in states:
        if all(math.isfinite(x) for x in (t, state.x, state.y)):
            by_vehicle[state.vehicle].append((t, state))
    total: dict[Cell, float] = defaultdict(float)
    waiting: dict[Cell, float] = defaultdict(float)
    per_vehicle: dict[int, float] = {}
    for v, rows in by_vehicle.items():
        rows.sort(key=lambda row: row[0])
        counted = 0.0
        for (t, state), (t_next, _) in pairwise(rows):
            dt = min(t_next - t, cap_s)
            if dt <= 0:
                continue
            cell = (round((state.x - ox) / size), round((state.y - oy) / size))
            total[cell] += dt
            if state.maneuver == WAIT:
                waiting[cell] += dt
            counted += dt
        per_vehicle[v] = counted
    return CellTime(dict(total), dict(waiting), per_vehicle)
