"""Seed 004's path tracking (Section 2; seed pack note B.4.3): lifting AGVs drive their global
paths cell by cell. Before it enters the next cell an AGV takes it from the reservation store,
which is the race-free form of the seed's "enter when the next cell's value is 0, 3 or 7":
the take is one commit of [now, forever) on that cell, refused while anyone else holds it.
While moving the AGV holds the cell it leaves and the one it enters; on arrival it lets the
one behind go. When the take is refused the holder decides what happens:

- a head-on conflict (the holder wants our cell): the empty AGV replans around the blocked
  cell and the loaded one waits (GIVEN); two empty ones: the relaxed one, else the larger id,
  replans; two loaded ones (only at slot mouths): the larger id waits the stagnation time,
  then replans (CHOICEs);
- a stagnant holder (stood longer than T_stag outside a station): an empty AGV replans, since
  the filter of Equation (3) does not expand such a cell; a loaded one waits (DERIVED);
- anything else (a crossing or rear-end conflict): wait until the cell is let go (GIVEN).

A waiting AGV outside a station turns stagnant after T_stag, and an empty one then replans
(CHOICE). A plan that fails is retried every second; after N_relax failures in a row an empty
AGV plans without the traffic rules until its next head-on conflict or the end of its leg.

Time is discrete events in (time, vehicle) order, so a run is deterministic. The grid values
the planner reads are derived, never stored: a cell's static kind, and whether the AGV that
holds it in the store moves or is stagnant (`grid_values`).

What each AGV does for itself, taking and letting go of cells and planning its path, goes
through one seam (`Vehicles`): `LocalVehicles` in this process against a `ReservationTable`,
or each AGV's agent process against the reservation service (dispatcher/remote004.py), which
orders the requests about each cell as the events do, so a run of processes is the
in-process run.
"""

from __future__ import annotations

import dataclasses
import heapq
import itertools
import math
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from enum import Enum
from typing import Protocol

from fleet.mission.freeze import BREAKDOWN
from fleet.planning.astar004 import Costs, heading_of, plan
from fleet.planning.reservations import INF, Interval, ReservationTable, ReservationView
from fleet.planning.rules004 import (
    STEP,
    WALL_VALUE,
    XY,
    Direction,
    Kind,
    Occupancy,
    Task,
    allowed,
    perpendicular,
    value,
)
from fleet.wire.protocol import ZONE
from fleet.world.floor004 import Floor004, Station


@dataclass(frozen=True)
class TrackingParams:
    """The seed's timing (Table 4 is missing; the note's CHOICEs, B.3) and the tracker's."""

    t_cell: float = 1.0  # one cell at constant speed
    t_turn: float = 1.0  # a quarter turn on the spot; driving backwards needs none
    t_lift: float = 2.0
    t_drop: float = 2.0
    t_pick: float = 10.0  # at a station's work cell
    t_stag: float = 3.0  # standing this long outside a station: stagnant
    retry_s: float = 1.0  # a failed plan is tried again this much later
    n_relax: int = 3  # failed plans in a row before an empty AGV plans without the rules
    t_evict: float = 10.0  # waited this long for an idle AGV: it is sent out of the way
    watchdog_s: float = 300.0  # an AGV that stood this long waiting or failing: stuck
    costs: Costs = field(default_factory=Costs)
    heap: bool = True


@dataclass(frozen=True)
class Leg:
    """One task: to `goal` (M1: the shelf's slot, then lift; M2: a station's entrance, then
    its route through the work cell to the exit point; M3: the shelf's home slot, then drop;
    M4: a pile)."""

    task: Task
    goal: XY
    home: XY | None = None  # a loaded AGV's own slot (entered and left in any direction)
    station: Station | None = None  # M2: the station whose route follows the entrance
    make_way: bool = False  # M1 rules, nothing lifted: an idle AGV sent out of the way
    charge_s: float = 0.0  # M4: how long it charges at the pile

    def __post_init__(self) -> None:
        if (self.task is Task.DELIVER) != (self.station is not None):
            raise ValueError("a delivery, and only a delivery, names its station")
        if self.make_way and self.task is not Task.FETCH:
            raise ValueError("only an empty AGV is sent out of the way (an M1 leg)")
        if self.station is not None and self.goal != self.station.entrance:
            raise ValueError(f"a delivery to {self.station.name} ends at its entrance "
                             f"{self.station.entrance}, not {self.goal}")


@dataclass(frozen=True)
class RouteQuery:
    """What an AGV's planner is asked: its leg's path from where it stands, on the grid as it
    is at `t` (the store's holders, and which of them move or are stagnant)."""

    vehicle: int
    t: float
    task: Task
    start: XY
    goal: XY
    heading: Direction
    home: XY | None = None
    relaxed: bool = False
    blocked: frozenset[XY] = frozenset()  # avoided in this plan only (read as walls)
    moving: frozenset[int] = frozenset()  # AGVs between two cells now
    stagnant: frozenset[int] = frozenset()  # AGVs standing longer than T_stag outside a lane


def grid_values(floor: Floor004, view: ReservationView, query: RouteQuery
                ) -> Callable[[XY], int]:
    """The multi-valued grid as the asking AGV reads it at the query's instant: the cell's
    static kind and its holder's motion, derived from the store, never stored."""
    t, blocked, me = query.t, query.blocked, query.vehicle
    after = math.nextafter(t, INF)

    def occupancy(xy: XY) -> Occupancy:
        holder = view.conflict(me, floor.cell(xy), t, after)
        if holder is None:
            return Occupancy.FREE
        if holder in query.moving:
            return Occupancy.MOVING
        return Occupancy.STAGNANT if holder in query.stagnant else Occupancy.FREE

    def values(xy: XY) -> int:
        if xy in blocked:
            return WALL_VALUE
        return value(floor.kind(xy), occupancy(xy))
    return values


def route(floor: Floor004, view: ReservationView, query: RouteQuery, costs: Costs,
          heap: bool = True) -> tuple[XY, ...] | None:
    """The improved A*'s path for the query (start first); None: none now."""
    found = plan(floor.grid, query.task, query.start, query.goal, query.heading, costs,
                 grid_values(floor, view, query), heap, relaxed=query.relaxed, home=query.home)
    return None if found is None else found.cells


@dataclass(frozen=True)
class Routed:
    cells: tuple[XY, ...] | None  # start first; None: no path now
    planning_s: float  # wall time the planner took (measured; it decides nothing)


class Vehicles(Protocol):
    """What each AGV does for itself: take a cell from the store before it enters (one
    commit of [t, forever), refused while another holds it), let the cell behind go, and
    plan. `view` is the store as the tracker reads it, holding every change made so far."""

    @property
    def view(self) -> ReservationView: ...

    def take(self, vehicle: int, xy: XY, t: float) -> bool: ...

    def release(self, vehicle: int, xy: XY, t: float) -> None: ...

    def route(self, query: RouteQuery) -> Routed: ...

    def close(self, xys: list[XY], t0: float, t1: float) -> None:
        """Close cells (a fault): held by ZONE over [t0, t1); none of them is held then."""
        ...

    def down(self, vehicle: int, t: float, cause: str) -> None:
        """A fault stops the AGV at t (`cause`: BREAKDOWN, or what befell its agent); until
        `up` nobody asks it anything but to let go of the cell its last move left."""
        ...

    def up(self, vehicle: int, t: float) -> None:
        """The AGV goes on from t (repaired, or its agent back)."""
        ...

    def service_fault(self, t: float) -> None:
        """The reservation service is killed at t: it changes nothing the tracker decides,
        only when the fault injector acts."""
        ...


class LocalVehicles:
    """Every AGV in this process, against one `ReservationTable`."""

    def __init__(self, floor: Floor004, params: TrackingParams,
                 table: ReservationTable | None = None) -> None:
        self.floor, self.params = floor, params
        self.table = table if table is not None else ReservationTable()

    @property
    def view(self) -> ReservationView:
        return self.table

    def take(self, vehicle: int, xy: XY, t: float) -> bool:
        return self.table.commit(vehicle, [Interval(self.floor.cell(xy), t, INF)]).ok

    def release(self, vehicle: int, xy: XY, t: float) -> None:
        self.table.release(vehicle, t, [self.floor.cell(xy)])

    def close(self, xys: list[XY], t0: float, t1: float) -> None:
        written = self.table.commit(ZONE, [Interval(self.floor.cell(xy), t0, t1) for xy in xys])
        assert written.ok, written.reason

    def route(self, query: RouteQuery) -> Routed:
        started = time.perf_counter()
        cells = route(self.floor, self.table, query, self.params.costs, self.params.heap)
        return Routed(cells, time.perf_counter() - started)

    def down(self, vehicle: int, t: float, cause: str) -> None:
        pass  # in this process every AGV is the tracker's own: a fault is its down_until

    def up(self, vehicle: int, t: float) -> None:
        pass

    def service_fault(self, t: float) -> None:
        pass  # no services here


class StageKind(Enum):
    PLANNED = "planned"  # the leg's global path, replanned as tracking needs
    ROUTE = "route"  # a station's fixed route
    PAUSE = "pause"  # standing: lift, drop, pick


@dataclass(frozen=True)
class Stage:
    kind: StageKind
    cells: tuple[XY, ...] = ()  # ROUTE: the cells to enter
    seconds: float = 0.0  # PAUSE
    label: str = ""  # PAUSE: "lift", "drop" or "pick"


def stages(leg: Leg, params: TrackingParams) -> list[Stage]:
    """What an AGV does for a leg, in order."""
    planned = Stage(StageKind.PLANNED)
    if leg.task is Task.FETCH and not leg.make_way:
        return [planned, Stage(StageKind.PAUSE, seconds=params.t_lift, label="lift")]
    if leg.task is Task.RETURN:
        return [planned, Stage(StageKind.PAUSE, seconds=params.t_drop, label="drop")]
    if leg.task is Task.CHARGE and leg.charge_s > 0:
        return [planned, Stage(StageKind.PAUSE, seconds=leg.charge_s, label="charge")]
    if leg.task is Task.DELIVER:
        assert leg.station is not None
        s = leg.station
        return [planned, Stage(StageKind.ROUTE, (*s.waiting, s.work)),
                Stage(StageKind.PAUSE, seconds=params.t_pick, label="pick"),
                Stage(StageKind.ROUTE, (*s.exits, s.exit_point))]
    return [planned]


class Conflict(Enum):
    HEAD_ON = "head-on"
    CROSSING = "crossing"
    REAR_END = "rear-end"


@dataclass(frozen=True)
class Moved:
    vehicle: int
    t0: float  # leaves `origin` (it holds both cells from here)
    t1: float  # in `to` (lets `origin` go)
    origin: XY
    to: XY
    task: Task  # the leg's
    loaded: bool
    relaxed: bool


@dataclass(frozen=True)
class Turned:
    vehicle: int
    t0: float
    t1: float
    at: XY
    heading: Direction  # after the turn


@dataclass(frozen=True)
class Paused:
    vehicle: int
    t0: float
    t1: float
    at: XY
    label: str  # lift, drop, pick


@dataclass(frozen=True)
class Met:
    """One conflict episode: `vehicle`, at `at`, could not take `cell`, held by `other`."""

    t: float
    vehicle: int
    other: int
    at: XY
    cell: XY
    kind: Conflict


@dataclass(frozen=True)
class Stagnant:
    """A waiting AGV has stood longer than T_stag at `at` (its cell's value is 5 or 6)."""

    t: float
    vehicle: int
    at: XY


@dataclass(frozen=True)
class Replanned:
    t: float
    vehicle: int
    why: str
    relaxed: bool  # the plan made, if any, lifts the traffic rules
    found: bool


@dataclass(frozen=True)
class MadeWay:
    """An idle AGV sent from `at` to `to`, out of the way of `vehicle` (CHOICE: eviction)."""

    t: float
    vehicle: int
    idle: int
    at: XY
    to: XY


@dataclass(frozen=True)
class Picked:
    """The worker has picked from the shelf the AGV brought to `station`."""

    t: float
    vehicle: int
    station: str


@dataclass(frozen=True)
class LegDone:
    t: float
    vehicle: int
    leg: Leg


@dataclass(frozen=True)
class BrokeDown:
    """A fault: the AGV stops where it stands, or where the move it is in ends, until
    `until` (infinity: it is not repaired); it holds its cell, which reads stagnant."""

    t: float
    vehicle: int
    at: XY
    until: float
    cause: str = BREAKDOWN  # or the process fault: "agent killed", "agent stalled", "link lost"


@dataclass(frozen=True)
class Repaired:
    t: float
    vehicle: int
    at: XY


@dataclass(frozen=True)
class ZoneClosed:
    """A fault: `cells` are closed (a spill) over [t0, t1): held in the store by ZONE.
    Cells an AGV held at t0 stay open; they are not listed."""

    t0: float
    t1: float
    cells: tuple[XY, ...]


Milestone = Picked | LegDone | Repaired  # what the work above the tracker acts on
Fault = BrokeDown | Repaired | ZoneClosed
Event = Moved | Turned | Paused | Met | Stagnant | Replanned | MadeWay | Fault | Milestone


@dataclass
class Agv:
    vehicle: int
    cell: XY  # where it stands, or the cell it leaves while moving
    heading: Direction
    loaded: bool = False
    leg: Leg | None = None
    stages: list[Stage] = field(default_factory=list)  # the leg's, the current one first
    path: list[XY] = field(default_factory=list)  # the cells still to enter in this stage
    moving_to: XY | None = None
    planned: bool = False  # the leg's first plan is made
    busy_until: float = 0.0  # turning or pausing until then
    standing_since: float = 0.0  # since it last arrived (or was placed): stagnant after T_stag
    waiting_on: XY | None = None
    trouble_since: float | None = None  # waiting or without a path since, until it moves
    met: tuple[int, XY] | None = None  # the conflict episode in progress
    stagnant_said: bool = False  # Stagnant logged for this standing
    failures: int = 0  # failed plans in a row
    relaxed: bool = False
    blocked: frozenset[XY] = frozenset()  # cells the next plan avoids
    running_s: float = 0.0  # moving, turning and lifting: the seed's consumption
    down_until: float = 0.0  # broken down until then (a fault; infinity: for good)


class Stuck(RuntimeError):
    """Nothing can happen any more, yet legs are unfinished."""


# Due events: arrivals before decisions at one instant, so every cell let go at t is free to
# be taken at t; then by vehicle, then in the order they were made.
_FAULT, _ARRIVE, _ACT = -1, 0, 1  # a fault strikes before anything else at its instant
# An AGV deciding this often at one instant is going round in circles: a defect, named.
MAX_ACTS_AT_ONCE = 1000
FIRST_PLAN = "first plan"  # the Replanned of a leg's first plan that found no path
STEPPED_ASIDE = "head-on: stepped aside"  # the Replanned of one giving way where it cannot
# plan around (the cell it wants is its goal; or the other could not give way at all)


class Tracker:
    """Every AGV of one floor, driven event by event against one reservation table (in the
    project's cells: row 0 at the bottom)."""

    def __init__(self, floor: Floor004, params: TrackingParams = TrackingParams(),
                 vehicles: Vehicles | None = None,
                 on_event: Callable[[Event], None] | None = None,
                 pace: Callable[[float], None] | None = None) -> None:
        self.floor = floor
        self.params = params
        self.vehicles = vehicles if vehicles is not None else LocalVehicles(floor, params)
        self.on_event = on_event  # told of each event as it happens (a run's publisher)
        self.pace = pace  # holds each instant until its time comes (a real-time clock)
        self.agvs: dict[int, Agv] = {}
        self.events: list[Event] = []
        self.t = 0.0
        self._due: list[tuple[float, int, int, int]] = []  # (t, rank, vehicle, order)
        self._order = itertools.count()
        self._waiters: dict[XY, set[int]] = {}
        self._faults: dict[int, Callable[[], Repaired | None]] = {}  # by order: a fault
        self._acts: Counter[int] = Counter()  # decisions by AGV at the current instant
        self.replans = 0  # planner calls while tracking, each leg's first plan not counted
        self.planning_s = 0.0  # wall time in the planner (measured; it decides nothing)

    # -- the fleet -----------------------------------------------------------------------------
    def place(self, vehicle: int, xy: XY, heading: Direction = Direction.DOWN,
              t: float = 0.0, loaded: bool = False) -> None:
        """An AGV standing at xy from t (it holds the cell from then on), carrying a shelf
        when `loaded`."""
        if vehicle in self.agvs:
            raise ValueError(f"AGV {vehicle} is placed already")
        if self.floor.kind(xy) in (Kind.WALL, Kind.STRUCTURE):
            raise ValueError(f"AGV {vehicle}: {xy} is not a cell an AGV can stand on")
        if not self.vehicles.take(vehicle, xy, t):
            raise ValueError(f"AGV {vehicle}: {xy} is taken by AGV {self._holder(vehicle, xy)}")
        self.agvs[vehicle] = Agv(vehicle, xy, heading, loaded, standing_since=t)

    def assign(self, vehicle: int, leg: Leg, t: float | None = None) -> None:
        """Start `leg` (the AGV must be idle and loaded as its task needs) from t (now)."""
        agv = self.agvs[vehicle]
        if agv.leg is not None:
            raise ValueError(f"AGV {vehicle} is on a leg already")
        if leg.task.loaded != agv.loaded:
            raise ValueError(f"AGV {vehicle} is {'loaded' if agv.loaded else 'empty'}: it "
                             f"cannot take a {leg.task.name.lower()} leg ({leg.task.value})")
        self._start(agv, leg)
        self._wake(vehicle, self.t if t is None else max(t, self.t))

    def recallable(self, vehicle: int) -> bool:
        """Whether the AGV carries its shelf home and has not begun to drop it."""
        agv = self.agvs[vehicle]
        return agv.leg is not None and agv.leg.task is Task.RETURN and agv.loaded and \
            agv.stages[0].kind is StageKind.PLANNED and agv.down_until <= self.t

    def recall(self, vehicle: int, leg: Leg) -> None:
        """The shelf it returns is wanted at a station (Equation 5): deliver it there
        instead, planned from the cell it stands on or is entering."""
        if not self.recallable(vehicle):
            raise ValueError(f"AGV {vehicle} returns no shelf that can be recalled")
        if leg.task is not Task.DELIVER:
            raise ValueError(f"a recalled shelf is delivered, not given a {leg.task.value} leg")
        agv = self.agvs[vehicle]
        self._start(agv, leg)
        if agv.moving_to is None:
            self._wake(vehicle, self.t)  # (moving: its arrival acts)

    # -- faults --------------------------------------------------------------------------------
    def break_down(self, vehicle: int, t: float, until: float = INF,
                   cause: str = BREAKDOWN) -> None:
        """At t the AGV stops: the move, turn or lift it is in ends, then it stands, holding
        its cell, until `until`. A killed agent's AGV does the same (`cause`): the tracker
        decides alike, and its seam keeps away from the agent until it is back."""
        def strike() -> None:
            agv = self.agvs[vehicle]
            agv.down_until = until
            self.vehicles.down(vehicle, t, cause)
            self._log(BrokeDown(t, vehicle, agv.moving_to or agv.cell, until, cause))
            if until < INF:
                self._at(until, repair)

        def repair() -> Repaired:
            self.vehicles.up(vehicle, until)
            agv = self.agvs[vehicle]
            agv.down_until = 0.0
            agv.standing_since = until  # it stood for a reason: stagnant only from now on
            agv.trouble_since = None  # nor was it in trouble
            self._fault_over()
            repaired = Repaired(until, vehicle, agv.moving_to or agv.cell)
            self._log(repaired)
            self._wake(vehicle, until)
            return repaired
        self._at(t, strike)

    def service_fault(self, t: float) -> None:
        """At t the reservation service is killed: the seam lets the fault injector act
        then (nothing is logged: the events are those of a run without it)."""
        self._at(t, lambda: self.vehicles.service_fault(t))

    def close_zone(self, xys: list[XY], t0: float, t1: float) -> None:
        """From t0 to t1 the cells nobody holds at t0 are closed: nobody enters them."""
        def close() -> None:
            free = [xy for xy in xys
                    if self.vehicles.view.conflict(ZONE, self.floor.cell(xy), t0, t1) is None]
            if free:
                self.vehicles.close(free, t0, t1)
            self._log(ZoneClosed(t0, t1, tuple(free)))
            self._at(t1, lambda: self._reopen(free))
        self._at(t0, close)

    def _held_by_fault(self, vehicle: int, xy: XY | None) -> bool:
        """Whether `xy` is held by a closed zone or a broken-down AGV that will be repaired,
        or by an AGV waiting, in a chain, for one: that is waiting out a fault, which the
        watchdog does not count."""
        seen = {vehicle}
        while xy is not None:
            holder = self._holder(vehicle, xy)
            if holder == ZONE:
                return True
            if holder is None or holder in seen or holder not in self.agvs:
                return False  # free, a loop, or someone outside the mission: no fault
            other = self.agvs[holder]
            if self.t < other.down_until < INF:
                return True
            seen.add(holder)
            vehicle, xy = holder, other.waiting_on
        return False

    def is_down(self, vehicle: int) -> bool:
        return self.agvs[vehicle].down_until > self.t

    def _fault_over(self) -> None:
        """A fault ended: who was waiting (maybe for it, in a chain) has the watchdog's
        whole time again from now."""
        for agv in self.agvs.values():
            if agv.trouble_since is not None:
                agv.trouble_since = self.t

    def _reopen(self, xys: list[XY]) -> None:
        self._fault_over()
        for xy in xys:
            for v in sorted(self._waiters.pop(xy, ())):
                self._wake(v, self.t)

    def _at(self, t: float, action: Callable[[], Repaired | None]) -> None:
        order = next(self._order)
        self._faults[order] = action
        heapq.heappush(self._due, (t, _FAULT, 0, order))

    def _start(self, agv: Agv, leg: Leg) -> None:
        """Take up `leg`, planned now if the AGV stands (so others see where it heads),
        else on arrival."""
        agv.leg, agv.stages, agv.path, agv.planned = leg, stages(leg, self.params), [], False
        agv.failures, agv.relaxed, agv.blocked = 0, False, frozenset()
        agv.waiting_on, agv.met, agv.trouble_since = None, None, None
        if agv.moving_to is None and agv.cell != leg.goal:
            agv.planned = self._plan(agv, first=True)
            agv.failures = 0  # a failure here is met again, and counted, when it acts

    # -- running -------------------------------------------------------------------------------
    def advance(self, until: float = INF) -> Milestone | None:
        """Run events up to `until`, stopping after the first pick or leg end (None: none by
        then). Raises Stuck when no event is left but a leg is unfinished."""
        while self._due:
            t, rank, vehicle, order = self._due[0]
            if t > until:
                return None
            heapq.heappop(self._due)
            if t != self.t:
                self._acts.clear()
                if self.pace is not None:
                    self.pace(t)
            if rank == _FAULT:
                self.t = t
                if (repaired := self._faults.pop(order)()) is not None:
                    return repaired  # an AGV to dispatch again
                continue
            self._acts[vehicle] += 1
            if self._acts[vehicle] > MAX_ACTS_AT_ONCE:
                raise Stuck(f"at t={t:.2f} AGV {vehicle} decided {MAX_ACTS_AT_ONCE} times "
                            f"without time passing (last: {self.events[-1]})")
            self.t = t
            agv = self.agvs[vehicle]
            if rank == _ARRIVE:
                self._arrive(agv)
            elif (done := self._act(agv)) is not None:
                return done
        busy = sorted(v for v, a in self.agvs.items() if a.leg is not None)
        if busy:
            raise Stuck(f"at t={self.t:.2f} nothing moves any more: " + "; ".join(
                f"AGV {v} at {self.agvs[v].cell} " + (
                    "is broken down" if self.agvs[v].down_until > self.t else
                    f"waits for {self.agvs[v].waiting_on}") for v in busy))
        return None

    def run(self) -> list[Milestone]:
        """Every assigned leg to its end."""
        done = []
        while (d := self.advance()) is not None:
            done.append(d)
        return done

    def counts(self) -> Counter[str]:
        """Conflicts by kind, replans, turns and cells driven, as Table 5 counts them."""
        out: Counter[str] = Counter(e.kind.value for e in self.events if isinstance(e, Met))
        out["replans"] = self.replans
        out["stepped_aside"] = sum(isinstance(e, Replanned) and e.why == STEPPED_ASIDE
                                   for e in self.events)
        out["turns"] = sum(isinstance(e, Turned) for e in self.events)
        out["cells"] = sum(isinstance(e, Moved) for e in self.events)
        return out

    # -- one AGV -------------------------------------------------------------------------------
    def _log(self, event: Event) -> None:
        self.events.append(event)
        if self.on_event is not None:
            self.on_event(event)

    def _wake(self, vehicle: int, t: float, rank: int = _ACT) -> None:
        heapq.heappush(self._due, (t, rank, vehicle, next(self._order)))

    def _arrive(self, agv: Agv) -> None:
        """In the next cell: let the one behind go, and wake whoever waits for it."""
        assert agv.moving_to is not None
        origin, agv.cell, agv.moving_to = agv.cell, agv.moving_to, None
        agv.standing_since = self.t
        self.vehicles.release(agv.vehicle, origin, self.t)
        for v in sorted(self._waiters.pop(origin, ())):
            self._wake(v, self.t)
        self._wake(agv.vehicle, self.t)

    def _act(self, agv: Agv) -> Milestone | None:
        t, p = self.t, self.params
        if agv.moving_to is not None or t < agv.busy_until or agv.leg is None:
            return None  # driving, turning or pausing: that ends with its own event
        if agv.down_until > t:
            return None  # broken down: its repair wakes it
        if agv.trouble_since is not None and t - agv.trouble_since > p.watchdog_s and \
                not self._held_by_fault(agv.vehicle, agv.waiting_on):
            raise Stuck(f"at t={t:.2f} AGV {agv.vehicle} at {agv.cell} has stood "
                        f"{t - agv.trouble_since:.0f} s " + (
                            f"waiting for {agv.waiting_on}, held by AGV "
                            f"{self._holder(agv.vehicle, agv.waiting_on)}"
                            if agv.waiting_on is not None else
                            f"without a path to {agv.leg.goal} ({agv.leg.task.value})"))
        while not agv.path:
            if not agv.stages:
                return self._leg_done(agv)
            stage = agv.stages[0]
            if stage.kind is StageKind.PLANNED:
                if agv.cell == agv.leg.goal:
                    agv.stages.pop(0)
                elif agv.planned:
                    self._replan(agv, "no path yet")
                    return None
                else:
                    agv.planned = True
                    if not self._plan(agv, first=True):  # logged: it counts to N_relax
                        self._log(Replanned(t, agv.vehicle, FIRST_PLAN, agv.relaxed, False))
                        self._wake(agv.vehicle, t + p.retry_s)
                        return None
                continue
            if stage.kind is StageKind.ROUTE:
                agv.path = list(agv.stages.pop(0).cells)
                continue
            return self._pause(agv, stage)
        nxt = agv.path[0]
        need = heading_of(agv.cell, nxt)
        if perpendicular(agv.heading, need):
            agv.heading, agv.busy_until = need, t + p.t_turn
            agv.running_s += p.t_turn
            self._log(Turned(agv.vehicle, t, agv.busy_until, agv.cell, need))
            self._wake(agv.vehicle, agv.busy_until)
            return None
        if self.vehicles.take(agv.vehicle, nxt, t):
            self._drive(agv, nxt)
            return None
        holder = self._holder(agv.vehicle, nxt)
        assert holder is not None, f"the store refused {nxt} and names no holder"
        if holder == ZONE or holder not in self.agvs:
            # closed, or held by someone outside the mission (a store others write to too):
            # an empty AGV goes round, a loaded one waits
            if not agv.loaded and self._can_go_around(agv, nxt):
                agv.blocked = frozenset({nxt})
                self._replan(agv, "closed zone ahead")
            else:
                self._wait(agv, nxt)
            return None
        self._blocked(agv, nxt, self.agvs[holder])
        return None

    def _holder(self, vehicle: int, xy: XY) -> int | None:
        """Who else holds xy from now on."""
        return self.vehicles.view.conflict(vehicle, self.floor.cell(xy), self.t, INF)

    def _drive(self, agv: Agv, nxt: XY) -> None:
        t, p = self.t, self.params
        agv.path.pop(0)
        agv.moving_to, agv.waiting_on, agv.met, agv.stagnant_said = nxt, None, None, False
        agv.trouble_since = None
        agv.running_s += p.t_cell
        assert agv.leg is not None
        self._log(Moved(agv.vehicle, t, t + p.t_cell, agv.cell, nxt, agv.leg.task,
                                 agv.loaded, agv.relaxed))
        self._wake(agv.vehicle, t + p.t_cell, _ARRIVE)

    def _pause(self, agv: Agv, stage: Stage) -> Picked | None:
        """Lift, drop, pick or charge: stand for the stage's time, then its effect."""
        t = self.t
        if stage.seconds > 0:  # not begun
            agv.busy_until = t + stage.seconds
            if stage.label in ("lift", "drop"):  # the AGV's work; picking and charging not
                agv.running_s += stage.seconds
            self._log(Paused(agv.vehicle, t, agv.busy_until, agv.cell, stage.label))
            agv.stages[0] = dataclasses.replace(stage, seconds=0.0)  # under way
            self._wake(agv.vehicle, agv.busy_until)
            return None
        agv.stages.pop(0)
        self._wake(agv.vehicle, t)
        if stage.label == "lift":
            agv.loaded = True
        elif stage.label == "drop":
            agv.loaded = False
        elif stage.label == "pick":
            assert agv.leg is not None and agv.leg.station is not None
            picked = Picked(t, agv.vehicle, agv.leg.station.name)
            self._log(picked)
            return picked
        return None

    def _leg_done(self, agv: Agv) -> LegDone:
        leg = agv.leg
        assert leg is not None
        agv.leg, agv.relaxed, agv.blocked, agv.failures = None, False, frozenset(), 0
        done = LegDone(self.t, agv.vehicle, leg)
        self._log(done)
        return done

    def _blocked(self, agv: Agv, nxt: XY, other: Agv) -> None:
        t = self.t
        head_on = other.moving_to is None and other.path[:1] == [agv.cell] and \
            other.down_until <= t  # a broken-down AGV is an obstacle: stagnant
        if head_on:
            kind = Conflict.HEAD_ON
        elif other.moving_to is not None and perpendicular(other.heading, agv.heading):
            kind = Conflict.CROSSING
        else:
            kind = Conflict.REAR_END
        if agv.met != (other.vehicle, nxt):
            agv.met = (other.vehicle, nxt)
            self._log(Met(t, agv.vehicle, other.vehicle, agv.cell, nxt, kind))
        if not agv.stagnant_said and self._stagnant(agv, t):
            agv.stagnant_said = True
            self._log(Stagnant(t, agv.vehicle, agv.cell))
        around = self._can_go_around(agv, nxt)
        if head_on:
            yields = _yields(agv, other)
            agv.relaxed = False  # relaxed mode ends at the first head-on conflict
            if not yields:
                self._wait(agv, nxt)
                self._wake(other.vehicle, t)  # the other gives way: it must act to see it
                return
            if agv.loaded and agv.waiting_on != nxt:  # two loaded: wait a while, then around
                self._wait(agv, nxt)
                return
            if around:
                agv.blocked = frozenset({nxt})
                if self._replan(agv, Conflict.HEAD_ON.value):
                    return
            if not self._step_aside(agv, other) and not (
                    other.busy_until <= t and (agv.loaded or not other.loaded)
                    and self._step_aside(other, agv)):
                self._wait(agv, nxt)  # neither can give way: wait (the watchdog names it)
            return
        if self._stagnant(other, t) and not agv.loaded and around:
            agv.blocked = frozenset({nxt})
            self._replan(agv, "stagnant AGV ahead")
            return
        if other.leg is None and not other.loaded and other.down_until <= t and \
                agv.waiting_on == nxt and \
                t - self._in_trouble(agv) >= self.params.t_evict:
            self._make_way(agv, other)
        elif self._stagnant(agv, t) and not agv.loaded and agv.waiting_on == nxt and around:
            agv.blocked = frozenset({nxt})  # waited too long: try around (CHOICE)
            self._replan(agv, "waited too long")
            return
        self._wait(agv, nxt)

    def _can_go_around(self, agv: Agv, cell: XY) -> bool:
        """Whether a new plan can avoid `cell`: on the leg's planned part, not its goal."""
        return agv.leg is not None and agv.leg.goal != cell and bool(agv.stages) and \
            agv.stages[0].kind is StageKind.PLANNED

    def _step_aside(self, agv: Agv, other: Agv) -> bool:
        """Give way where going around cannot (the cell wanted is the goal): move to a free
        neighbour off the other's way, the rules kept, then plan the leg again from there."""
        if agv.leg is None or not agv.stages or agv.stages[0].kind is not StageKind.PLANNED:
            return False  # on a station's fixed route, or pausing: it cannot leave its way
        rules = allowed(self.floor.grid, agv.leg.task, agv.cell, agv.leg.home)
        for d in sorted(rules):
            dx, dy = STEP[d]
            n = (agv.cell[0] + dx, agv.cell[1] + dy)
            kind = self.floor.kind(n)
            if n == other.cell or n in other.path[:2] or self._holder(agv.vehicle, n) is not None \
                    or kind not in ((Kind.FLOOR,) if agv.loaded else (Kind.FLOOR, Kind.SLOT)):
                continue
            self._log(Replanned(self.t, agv.vehicle, STEPPED_ASIDE, agv.relaxed, True))
            self.replans += 1
            agv.path, agv.waiting_on = [n], None
            self._wake(agv.vehicle, self.t)
            return True
        return False

    def _make_way(self, agv: Agv, idle: Agv) -> None:
        """Send an idle AGV to the nearest slot or parking place that is free for good and
        off the waiting AGV's way."""
        keep = {agv.cell, *agv.path}
        if agv.leg is not None:
            keep.add(agv.leg.goal)
        places = [s.xy for s in self.floor.slots] + list(self.floor.parking)
        free = [xy for xy in places if xy not in keep and self._holder(idle.vehicle, xy) is None]
        if not free:
            return
        to = min(free, key=lambda xy: (abs(xy[0] - idle.cell[0]) + abs(xy[1] - idle.cell[1]),
                                       xy))
        self._log(MadeWay(self.t, agv.vehicle, idle.vehicle, idle.cell, to))
        self.assign(idle.vehicle, Leg(Task.FETCH, to, make_way=True))

    def _in_trouble(self, agv: Agv) -> float:
        """Since when the AGV has been waiting or without a path (from now, if it was not)."""
        if agv.trouble_since is None:
            agv.trouble_since = self.t
        return agv.trouble_since

    def _wait(self, agv: Agv, cell: XY) -> None:
        """Stand until `cell` is let go, or until it turns stagnant."""
        self._in_trouble(agv)
        agv.waiting_on = cell
        self._waiters.setdefault(cell, set()).add(agv.vehicle)
        stagnant_at = agv.standing_since + self.params.t_stag
        self._wake(agv.vehicle, math.nextafter(stagnant_at, INF) if stagnant_at >= self.t
                   else self.t + self.params.retry_s)

    # -- planning ------------------------------------------------------------------------------
    def _plan(self, agv: Agv, first: bool = False) -> bool:
        """Plan the leg's path from where the AGV stands; False: no path now."""
        leg = agv.leg
        assert leg is not None
        if not first:
            self.replans += 1
        t = self.t
        routed = self.vehicles.route(RouteQuery(
            agv.vehicle, t, leg.task, agv.cell, leg.goal, agv.heading, leg.home, agv.relaxed,
            agv.blocked, frozenset(v for v, a in self.agvs.items() if a.moving_to is not None),
            frozenset(v for v, a in self.agvs.items() if self._stagnant(a, t)) | {ZONE}))
        self.planning_s += routed.planning_s
        found = routed.cells
        agv.blocked = frozenset()  # avoided in this plan only: the next one sees the grid anew
        if found is None:
            self._in_trouble(agv)
            agv.failures += 1
            if agv.failures >= self.params.n_relax and not agv.loaded:
                agv.relaxed = True  # deadlock 4: the rules are what walls it in
            agv.path = []
            return False
        agv.failures = 0
        agv.path = list(found[1:])
        return True

    def _replan(self, agv: Agv, why: str) -> bool:
        """Plan again now; False: no path (it tries again in `retry_s`)."""
        found = self._plan(agv)
        self._log(Replanned(self.t, agv.vehicle, why, agv.relaxed, found))
        if found:
            agv.waiting_on = None
        self._wake(agv.vehicle, self.t if found else self.t + self.params.retry_s)
        return found

    def _stagnant(self, agv: Agv, t: float) -> bool:
        """Standing longer than T_stag, but in a station's lane (its queue)."""
        if agv.moving_to is None and agv.down_until > t:
            return True  # broken down: an obstacle at once, in a station's lane too
        return agv.moving_to is None and self.floor.kind(agv.cell) is not Kind.LANE and \
            t - agv.standing_since > self.params.t_stag


def _yields(agv: Agv, other: Agv) -> bool:
    """Whether `agv` gives way in a head-on conflict with `other`: the empty one; of two
    empty ones the relaxed one, else the larger id; of two loaded ones the larger id."""
    if agv.loaded != other.loaded:
        return not agv.loaded
    if agv.relaxed != other.relaxed:
        return agv.relaxed
    return agv.vehicle > other.vehicle
