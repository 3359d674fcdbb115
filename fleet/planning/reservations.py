"""Space-time reservation table: per grid cell, sorted non-overlapping [t0, t1) intervals, each
owned by one vehicle.

This is the data structure the reservation service holds; planners read it through the
`ReservationView` protocol and participants change it through the `ReservationWriter` protocol
(rmf_traffic's Viewer and Writer), so an in-process table and the remote service
(reservation/client.py) are interchangeable.
Intervals of one vehicle that touch or overlap in a cell are merged, so a cell's intervals never
overlap at all; intervals of different vehicles may touch (one leaves at t, the other enters at
t) but never overlap. Every change bumps the revision and is kept as a `Change`, from which a
mirror can follow the table (`diff`, `apply`).
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Collection, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Protocol

from fleet.planning.geometry import Cell

INF = math.inf
# Arrival times are sums of move times and waits, so a postponed stay may come out a rounding
# error shorter than the stay it postpones: an amendment is judged to this much.
SUM_TOLERANCE_S = 1e-9


@dataclass(frozen=True, order=True)
class Interval:
    """One cell reserved over [t0, t1); t1 may be infinity (parked)."""

    cell: Cell
    t0: float
    t1: float

    def __post_init__(self) -> None:
        if not (self.t0 < self.t1) or math.isnan(self.t0) or math.isnan(self.t1):
            raise ValueError(f"interval on cell {self.cell} must have t0 < t1, got "
                             f"[{self.t0}, {self.t1})")


@dataclass(frozen=True)
class TimedRoute:
    """A vehicle's committed route in time as other vehicles read it: its nodes, when it
    arrives at each and how long it stands there (the last dwell may be infinite). Seed
    002's AGVs share these ("operational status", Section 5) to predict and settle
    collisions; the table keeps each vehicle's latest beside its reservations."""

    cells: tuple[Cell, ...]
    arrivals: tuple[float, ...]
    dwells: tuple[float, ...]

    def __post_init__(self) -> None:
        if not (len(self.cells) == len(self.arrivals) == len(self.dwells) >= 1):
            raise ValueError("a timed route has one arrival and one dwell per node, and a node")


def _on_at(route: TimedRoute, t: float) -> frozenset[Cell]:
    """The cells a route has its unit body on at t: the node it stands on (at a departure
    instant still), or both ends of the move it makes and the cells a diagonal sweeps."""
    cells, arrivals, dwells = route.cells, route.arrivals, route.dwells
    for m, cell in enumerate(cells):
        if arrivals[m] <= t <= arrivals[m] + dwells[m]:
            return frozenset({cell})
        if m + 1 < len(cells) and t < arrivals[m + 1]:
            (c0, r0), (c1, r1) = cell, cells[m + 1]
            return frozenset({cell, cells[m + 1], (c0, r1), (c1, r0)})
    return frozenset()


@dataclass(frozen=True)
class Conflict:
    """An interval that cannot be reserved because another vehicle holds the cell."""

    cell: Cell
    t0: float
    t1: float
    other: int

    @property
    def reason(self) -> str:
        return f"cell {self.cell} is held by vehicle {self.other} over [{self.t0}, {self.t1})"


@dataclass(frozen=True)
class Amendment:
    """Another vehicle's holdings from `release_from` on, replaced by `intervals`, which only
    postpone them: the same cells, each taken and left no earlier than before (a wait a
    collision rule put into a schedule already committed, seed 002)."""

    vehicle: int
    release_from: float
    intervals: tuple[Interval, ...]
    route: TimedRoute | None = None  # the postponed route the intervals come from


@dataclass(frozen=True)
class WriteResult:
    """A writer's answer to a commit or release: made (`ok`), the table at `revision`; or
    refused, the table unchanged at `revision`, with the reason."""

    ok: bool
    revision: int
    reason: str = ""
    # The vehicle holding a cell the commit wanted, and that cell. None on a refusal for
    # another reason (halted since, too late), which replanning cannot cure.
    conflict_vehicle: int | None = None
    conflict_cell: Cell | None = None


@dataclass(frozen=True)
class Reservation:
    vehicle: int
    cell: Cell
    t0: float
    t1: float


@dataclass(frozen=True)
class Change:
    """One accepted change: a commit (release from `release_from`, then add `intervals`) or a
    release (no intervals)."""

    revision: int
    vehicle: int
    release_from: float | None
    intervals: tuple[Interval, ...] = ()
    release_cells: frozenset[Cell] | None = None  # release only these cells (None: all)
    # "commit": adds intervals (or, as a first step of `amended`, only releases); "release":
    # only gives up (the dispatcher's freeze, which the store takes for a halt)
    op: str = "commit"
    # The route in time the intervals come from: a commit that adds intervals sets the
    # vehicle's route to it (None: the vehicle has none); a release drops it.
    route: TimedRoute | None = None


@dataclass(frozen=True)
class Snapshot:
    revision: int
    reservations: tuple[Reservation, ...]
    routes: tuple[tuple[int, TimedRoute], ...] = ()  # (vehicle, its route), where it has one


class ReservationView(Protocol):
    """What a planner needs from a store."""

    def conflict(self, vehicle: int, cell: Cell, t0: float, t1: float) -> int | None: ...

    def parked_from(self, vehicle: int, cell: Cell) -> float:
        """When another vehicle takes `cell` for good (infinity if none does)."""
        ...

    def busy(self, vehicle: int, cell: Cell, after: float = -INF
             ) -> list[tuple[float, float]]:
        """The times other vehicles hold `cell`, [start, end) in order, those that end after
        `after` only."""
        ...


class ReservationWriter(Protocol):
    """How a participant changes a store: the table itself in one process, the reservation
    service's client (reservation/client.py) across processes."""

    def commit(self, vehicle: int, intervals: Sequence[Interval],
               release_from: float | None = None,
               amends: Sequence[Amendment] = (), route: TimedRoute | None = None
               ) -> WriteResult:
        """All or nothing: if no interval conflicts with another vehicle, release this
        vehicle's reservations from `release_from` on (when given) and add the intervals;
        otherwise change nothing and name the first conflict. `amends` postpone other
        vehicles' holdings in the same step (seed 002's collision rules); `route` is the
        route in time the intervals come from, for other vehicles to read."""
        ...

    def release(self, vehicle: int, from_t: float = -INF,
                cells: Collection[Cell] | None = None) -> WriteResult:
        """Drop what the vehicle holds from `from_t` on (intervals straddling it are cut), on
        `cells` only when given (ValueError for an empty collection)."""
        ...


@dataclass
class _CellLine:
    starts: list[float] = field(default_factory=list)
    ends: list[float] = field(default_factory=list)
    owners: list[int] = field(default_factory=list)


class ReservationTable:
    """The table itself, a `ReservationView` and a `ReservationWriter`. Not thread-safe; the
    service serialises access."""

    def __init__(self) -> None:
        self._cells: dict[Cell, _CellLine] = {}
        # Each vehicle's cells, with the latest end of what it holds there: a release from t
        # passes over the cells of its past (their holds all end by t) without reading them.
        self._cells_of: dict[int, dict[Cell, float]] = {}
        self._routes: dict[int, TimedRoute] = {}
        self.revision = 0
        self.changes: list[Change] = []

    # -- queries -------------------------------------------------------------------------------
    def conflict(self, vehicle: int, cell: Cell, t0: float, t1: float) -> int | None:
        """The other vehicle holding `cell` somewhere in [t0, t1), or None."""
        line = self._cells.get(cell)
        if line is None:
            return None
        i = bisect.bisect_left(line.starts, t1) - 1
        while i >= 0 and line.ends[i] > t0:
            if line.owners[i] != vehicle:
                return line.owners[i]
            i -= 1
        return None

    def parked_from(self, vehicle: int, cell: Cell) -> float:
        """When another vehicle takes `cell` for good (infinity if none does). Intervals do not
        overlap, so only a cell's last interval can run to infinity."""
        line = self._cells.get(cell)
        if line is None or line.ends[-1] != INF or line.owners[-1] == vehicle:
            return INF
        return line.starts[-1]

    def busy(self, vehicle: int, cell: Cell, after: float = -INF
             ) -> list[tuple[float, float]]:
        """The times other vehicles hold `cell`, [start, end) in order, those that end after
        `after` only (intervals do not overlap, so their ends are in order too: a search late
        in a long mission does not read the cell's past)."""
        line = self._cells.get(cell)
        if line is None:
            return []
        i = bisect.bisect_right(line.ends, after)
        return [(t0, t1) for t0, t1, owner in zip(line.starts[i:], line.ends[i:],
                                                  line.owners[i:], strict=True)
                if owner != vehicle]

    def first_conflict(self, vehicle: int, intervals: Iterable[Interval]) -> Conflict | None:
        for iv in intervals:
            other = self.conflict(vehicle, iv.cell, iv.t0, iv.t1)
            if other is not None:
                return Conflict(iv.cell, iv.t0, iv.t1, other)
        return None

    def reservations(self, vehicle: int | None = None) -> list[Reservation]:
        """All reservations (of one vehicle, or of all), sorted by cell then time."""
        out = []
        cells = self._cells_of.get(vehicle, {}) if vehicle is not None else self._cells
        for cell in sorted(cells):
            line = self._cells[cell]
            for t0, t1, owner in zip(line.starts, line.ends, line.owners, strict=True):
                if vehicle is None or owner == vehicle:
                    out.append(Reservation(owner, cell, t0, t1))
        return out

    def reservations_after(self, t: float) -> list[Reservation]:
        """The reservations that hold after `t` (end later), sorted by cell then time: the
        table as a plan made at `t` reads it, without the past."""
        out = []
        for vehicle, cells in self._cells_of.items():
            for cell, last_end in cells.items():
                if last_end <= t:
                    continue  # the vehicle's holds on this cell are all past
                line = self._cells[cell]
                out += [Reservation(owner, cell, t0, t1) for t0, t1, owner
                        in zip(line.starts, line.ends, line.owners, strict=True)
                        if owner == vehicle and t1 > t]
        return sorted(out, key=lambda r: (r.cell, r.t0))

    def vehicles(self) -> list[int]:
        return sorted(v for v, cells in self._cells_of.items() if cells)

    def route(self, vehicle: int) -> TimedRoute | None:
        """The route in time the vehicle's latest commit came from (None: it gave none, or
        released since)."""
        return self._routes.get(vehicle)

    # -- changes -------------------------------------------------------------------------------
    def commit(self, vehicle: int, intervals: Iterable[Interval],
               release_from: float | None = None,
               amends: Sequence[Amendment] = (), route: TimedRoute | None = None
               ) -> WriteResult:
        """All or nothing: if no interval conflicts with another vehicle, release this
        vehicle's reservations from `release_from` on (when given) and add the intervals;
        otherwise change nothing and name the first conflict. With `amends`, the other
        vehicles' holdings are postponed in the same step (`amended`). `route`: the route in
        time the intervals come from, for others to read (`route`)."""
        intervals = tuple(intervals)
        if amends:
            planned = self.amended(vehicle, intervals, release_from, amends, route)
            if isinstance(planned, str):
                return WriteResult(False, self.revision, planned)
            if isinstance(planned, Conflict):
                return WriteResult(False, self.revision, planned.reason, planned.other,
                                   planned.cell)
            for change in planned:
                self._apply(change)
            return WriteResult(True, self.revision)
        conflict = self.first_conflict(vehicle, intervals)
        if conflict is not None:
            return WriteResult(False, self.revision, conflict.reason, conflict.other,
                               conflict.cell)
        self._apply(Change(self.revision + 1, vehicle, release_from, intervals, op="commit",
                           route=route))
        return WriteResult(True, self.revision)

    def amended(self, vehicle: int, intervals: tuple[Interval, ...],
                release_from: float | None, amends: Sequence[Amendment],
                route: TimedRoute | None = None) -> list[Change] | Conflict | str:
        """A commit that also postpones other vehicles' holdings, checked whole against the
        table it would leave, as the changes that make it: every release first (the
        committing vehicle's, then each amended one's), then each amended vehicle's new
        intervals, then the committing vehicle's (always a last change, which carries the
        request). Each revision between holds a part of what the last one holds, so none
        holds two overlapping reservations. A Conflict, or why the amendments are refused
        (one names the committing vehicle, one vehicle twice or no vehicle, reaches back
        before the commit's own release, or does more than postpone)."""
        names = [a.vehicle for a in amends]
        if vehicle in names or len(set(names)) != len(names):
            return "an amendment names the committing vehicle or one vehicle twice"
        for a in amends:
            if a.vehicle < 1:
                return f"owner {a.vehicle} is no vehicle: only vehicles' holdings are amended"
            if release_from is not None and a.release_from < release_from:
                return (f"the amendment of vehicle {a.vehicle} releases from {a.release_from}, "
                        f"before the commit's own release from {release_from}")
            why = self._not_postponed(a)
            if why:
                return f"the amendment of vehicle {a.vehicle} does not only postpone: {why}"
        released = {a.vehicle: a.release_from for a in amends}
        if release_from is not None:
            released[vehicle] = release_from
        parts = [(vehicle, intervals), *((a.vehicle, a.intervals) for a in amends)]
        new_by_cell: dict[Cell, list[tuple[float, float, int]]] = {}
        for owner, ivs in parts:
            for iv in ivs:
                other = self._held_after(owner, iv, released)
                if other is None:  # then against the other parts' new intervals
                    other = next((o for t0, t1, o in new_by_cell.get(iv.cell, ())
                                  if o != owner and max(t0, iv.t0) < min(t1, iv.t1)), None)
                if other is not None:
                    return Conflict(iv.cell, iv.t0, iv.t1, other)
                new_by_cell.setdefault(iv.cell, []).append((iv.t0, iv.t1, owner))
        steps: list[tuple[int, float | None, tuple[Interval, ...], TimedRoute | None]] = []
        if release_from is not None:
            steps.append((vehicle, release_from, (), None))
        steps += [(a.vehicle, a.release_from, (), None) for a in amends]
        steps += [(a.vehicle, None, a.intervals, a.route) for a in amends if a.intervals]
        steps.append((vehicle, None, intervals, route))
        return [Change(self.revision + k, v, t, ivs, op="commit", route=r)
                for k, (v, t, ivs, r) in enumerate(steps, 1)]

    def _held_after(self, vehicle: int, iv: Interval, released: Mapping[int, float]
                    ) -> int | None:
        """Who else holds the interval's cell over it once `released` vehicles have given
        up their holdings from their instants on."""
        line = self._cells.get(iv.cell)
        if line is None:
            return None
        i = bisect.bisect_left(line.starts, iv.t1) - 1
        while i >= 0 and line.ends[i] > iv.t0:
            owner = line.owners[i]
            end = min(line.ends[i], released.get(owner, INF))
            if owner != vehicle and line.starts[i] < end and end > iv.t0:
                return owner
            i -= 1
        return None

    def _not_postponed(self, a: Amendment) -> str:
        """Why the amendment is not a postponement of what the vehicle holds from its
        release on ("" if it is): the same cells, each taken no earlier and held no shorter
        (waits only lengthen a stay and push what follows later), and a cell it holds across
        the release instant held on without a gap. With a route, only the cells the route
        has the vehicle on at that instant count as held across: a cell it left just then
        (held on by its next move, merged into one interval) may be taken again later."""
        on = None if a.route is None else _on_at(a.route, a.release_from)
        before: dict[Cell, list[tuple[float, float, bool]]] = {}  # (t0, t1, held across)
        for cell, last_end in self._cells_of.get(a.vehicle, {}).items():
            if last_end <= a.release_from:
                continue  # a cell of its past
            line = self._cells[cell]
            for t0, t1, owner in zip(line.starts, line.ends, line.owners, strict=True):
                if owner == a.vehicle and t1 > a.release_from:
                    across = t0 < a.release_from and (on is None or cell in on)
                    before.setdefault(cell, []).append((max(t0, a.release_from), t1, across))
        after: dict[Cell, list[tuple[float, float]]] = {}
        for iv in sorted(a.intervals):  # from the release on, merged as the table would
            if iv.t1 <= a.release_from:
                continue
            t0 = max(iv.t0, a.release_from)
            spans = after.setdefault(iv.cell, [])
            if spans and t0 <= spans[-1][1]:
                spans[-1] = (spans[-1][0], max(spans[-1][1], iv.t1))
            else:
                spans.append((t0, iv.t1))
        if set(before) != set(after):
            return f"it holds cells {sorted(before)} from then on, not {sorted(after)}"
        for cell, spans in before.items():
            new = after[cell]
            old = sorted(spans)
            if len(new) != len(old) or any(
                    n0 < o0 - SUM_TOLERANCE_S or n1 - n0 < o1 - o0 - SUM_TOLERANCE_S
                    or (across and abs(n0 - o0) > SUM_TOLERANCE_S)
                    for (o0, o1, across), (n0, n1) in zip(old, new, strict=True)):
                return (f"cell {cell} would be taken earlier, held shorter or left for a "
                        f"while: {new} against {[(o0, o1) for o0, o1, _ in old]}")
        return ""

    def release(self, vehicle: int, from_t: float = -INF,
                cells: Iterable[Cell] | None = None) -> WriteResult:
        """Drop what the vehicle holds from `from_t` on (intervals straddling it are cut), on
        `cells` only when given (never none: on the wire, no cells means all)."""
        only = None if cells is None else frozenset(cells)
        if only is not None and not only:
            raise ValueError("a release of no cells releases nothing; give None for all")
        self._apply(Change(self.revision + 1, vehicle, from_t, (), only, op="release"))
        return WriteResult(True, self.revision)

    def park(self, vehicle: int, cells: Iterable[Cell], t0: float) -> WriteResult:
        """Reserve cells from t0 to infinity."""
        return self.commit(vehicle, [Interval(c, t0, INF) for c in cells])

    def apply(self, change: Change) -> None:
        """Replay a change made elsewhere (a mirror following the authoritative table)."""
        if change.revision != self.revision + 1:
            raise ValueError(f"change revision {change.revision} does not follow table "
                             f"revision {self.revision}")
        self._apply(change)

    def _apply(self, change: Change) -> None:
        if change.release_from is not None:
            self._release(change.vehicle, change.release_from, change.release_cells)
        for iv in change.intervals:
            self._insert(change.vehicle, iv)
        if change.op == "release":
            self._routes.pop(change.vehicle, None)
        elif change.intervals or change.route is not None:
            if change.route is None:
                self._routes.pop(change.vehicle, None)
            else:
                self._routes[change.vehicle] = change.route
        self.revision = change.revision
        self.changes.append(change)

    def _release(self, vehicle: int, from_t: float, only: frozenset[Cell] | None) -> None:
        cells = self._cells_of.get(vehicle, {})
        for cell, last_end in list(cells.items()):
            if (only is not None and cell not in only) or last_end <= from_t:
                continue  # not asked, or all it holds here ends by then: unchanged
            line = self._cells[cell]
            keep = [(s, e, o) for s, e, o in zip(line.starts, line.ends, line.owners, strict=True)
                    if o != vehicle or s < from_t]
            keep = [(s, min(e, from_t) if o == vehicle else e, o) for s, e, o in keep]
            self._set_line(cell, keep)
            ends = [e for _, e, o in keep if o == vehicle]
            if ends:
                cells[cell] = max(ends)
            else:
                del cells[cell]

    def _insert(self, vehicle: int, iv: Interval) -> None:
        line = self._cells.get(iv.cell)
        if line is None:
            line = self._cells[iv.cell] = _CellLine()
        t0, t1 = iv.t0, iv.t1
        # Only the entries that touch or overlap [t0, t1] can change: they lie side by side,
        # since a line's intervals do not overlap (a long mission's past is not rewritten).
        i = bisect.bisect_left(line.ends, t0)
        j = bisect.bisect_right(line.starts, t1)
        kept = []
        for s, e, o in zip(line.starts[i:j], line.ends[i:j], line.owners[i:j], strict=True):
            if o == vehicle:  # touching or overlapping: merge
                t0, t1 = min(t0, s), max(t1, e)
            else:
                kept.append((s, e, o))
        kept.append((t0, t1, vehicle))
        kept.sort()
        line.starts[i:j] = [s for s, _, _ in kept]
        line.ends[i:j] = [e for _, e, _ in kept]
        line.owners[i:j] = [o for _, _, o in kept]
        cells = self._cells_of.setdefault(vehicle, {})
        cells[iv.cell] = max(cells.get(iv.cell, t1), t1)

    def _set_line(self, cell: Cell, entries: list[tuple[float, float, int]]) -> None:
        if not entries:
            self._cells.pop(cell, None)
            return
        self._cells[cell] = _CellLine([s for s, _, _ in entries], [e for _, e, _ in entries],
                                      [o for _, _, o in entries])

    # -- wire forms ----------------------------------------------------------------------------
    def snapshot(self) -> Snapshot:
        return Snapshot(self.revision, tuple(self.reservations()),
                        tuple(sorted(self._routes.items())))

    @classmethod
    def from_snapshot(cls, snap: Snapshot) -> ReservationTable:
        table = cls()
        table.load(snap)
        return table

    def load(self, snap: Snapshot) -> None:
        """Become the table of the snapshot (in place, so holders of this object see it)."""
        self._cells, self._cells_of, self.changes, self._routes = {}, {}, [], {}
        by_vehicle: dict[int, list[Interval]] = {}
        for r in snap.reservations:
            by_vehicle.setdefault(r.vehicle, []).append(Interval(r.cell, r.t0, r.t1))
        for vehicle, intervals in sorted(by_vehicle.items()):
            for iv in intervals:
                self._insert(vehicle, iv)
        self._routes = dict(snap.routes)
        self.revision = snap.revision

    def diff(self, since: int) -> list[Change]:
        """Changes after revision `since` (all of them kept in memory)."""
        return [c for c in self.changes if c.revision > since]
