"""Seed 002's order missions as the engine's work: the order book (fleet/mission/orders.py)
decides every trip (the nearest idle AGV to each order's shelf, the nearest free packing
station, the nearest vacant slot, a pile when the battery says so), and this feeds it what
happened when.

An AGV's trip is offered to the engine as its one target; once committed, its arrival is an
event at the leg's end (later if a collision rule postpones the leg). The engine takes the
events in time order before each decision (`next_event`, `advance`), so the book hears of
arrivals, dwells ending and batteries full at the instants they happen, and each decision it
makes becomes a trip from that instant on. The paper's dispatching has nothing to choose
among, so the policy only carries the trips out (fleet/dispatching/order_book_policy.py).

A completed order is announced as its shelf being put down, at the commit of the trip that
puts it down (as a stack mission announces a stack): `StackServed` names the shelf and the
order.

Faults (docs/faults.md): a trip cut short never arrives; the AGV keeps the shelf it carries
and its station, slot or pile, and is offered the same trip again from where it stands once
it can move (a cut return's order is not complete after all). An AGV that is down gives the
order it was fetching back to the book (the shelf never left its slot) and takes no new
one; the book chooses no slot, station or pile where it stands, nor in a closed zone (the
routes keep off both: fleet/vehicles/agv.py). Back up with nothing to do where it stands
(a lane), an AGV takes an order or goes to a pile.
"""

from __future__ import annotations

import heapq
import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from fleet.dispatching.decision import Decision, Target, TaskKind, VehicleView
from fleet.errors import UserError
from fleet.mission.battery import Battery, BatteryParams, parse_battery, start_charges
from fleet.mission.order_log import (
    Advance,
    Amended,
    Cancelled,
    Closed,
    Down,
    Input,
    Served,
    Up,
    WorkLog,
    from_record,
    to_record,
)
from fleet.mission.orders import Order, OrderBook, StationTrip, release_orders
from fleet.mission.spec import Mission
from fleet.mission.work import Reopened, StackServed
from fleet.planning.blockage import Blockage
from fleet.planning.geometry import Cell
from fleet.planning.reservations import Interval
from fleet.planning.trajectory import Pose, Trajectory
from fleet.vehicles.agv import EAST
from fleet.world.lanes import places
from fleet.world.layout import Layout

DEFAULT_AGVS = 10  # seed 002's fleet in Figures 17 and 19
DEFAULT_ORDERS = 100

ARRIVE, LEAVE, FULL, OPEN = "arrive", "leave", "full", "open"  # OPEN: a zone's end


def order_fleet(layout: Layout, vehicles: int | None) -> int:
    """The fleet of an order mission: `vehicles` or the paper's ten, one per charging pile
    at most (each starts on one)."""
    n = DEFAULT_AGVS if vehicles is None else vehicles
    if not 1 <= n <= len(layout.piles):
        raise UserError(f"--vehicles {n}: the AGVs of layout {layout.name} start on its "
                        f"{len(layout.piles)} charging piles, one each")
    return n


def mission_orders(mission: Mission, layout: Layout) -> tuple[Order, ...]:
    """The orders the mission releases (drawn with its seed on its area's shelves), or a
    UserError naming what is wrong (the area, the count)."""
    if mission.shelves:
        unknown = [(i, s) for i, s in enumerate(mission.shelves, 1) if s not in layout.shelves]
        if unknown:
            i, shelf = unknown[0]
            more = f" (and {len(unknown) - 1} more)" if len(unknown) > 1 else ""
            raise UserError(f"--orders: order {i} is for shelf {shelf!r}, which layout "
                            f"{layout.name} does not have{more}")
        return tuple(Order(i, s) for i, s in enumerate(mission.shelves, 1))
    try:
        return release_orders(layout, mission.orders, mission.seed, mission.order_area or None)
    except ValueError as exc:  # it names the layout, the area or the count
        raise UserError(str(exc)) from None


def mission_battery(mission: Mission) -> tuple[tuple[float, float], BatteryParams]:
    """The start charge range and the battery's numbers of the mission, or a UserError
    naming what is wrong in its `--battery` text."""
    try:
        return parse_battery(mission.battery)
    except ValueError as exc:
        raise UserError(f"--battery {mission.battery}: {exc}") from None


def mission_charges(mission: Mission, vehicles: int) -> tuple[float, ...]:
    """Each AGV's charge at the start of the mission (drawn with its seed)."""
    (low, high), _ = mission_battery(mission)
    return start_charges(low, high, vehicles, mission.seed)


@dataclass(order=True)
class _Event:
    t: float
    seq: int
    agv: int
    what: str
    kind: TaskKind | None = None  # the trip an arrival ends
    driven: float = 0.0  # seconds of driving on that trip
    live: bool = True  # False: superseded (the leg was postponed)


@dataclass(frozen=True)
class _Zone:
    cells: frozenset[Cell]
    until: float


def driving(leg: Trajectory) -> float:
    """Seconds of the leg the AGV moves (its waits drain no battery)."""
    return sum(s.t1 - s.t0 for s in leg.steps if s.manner.label != "wait")


class OrderWork:
    """Orders released at once, carried out trip by trip as the order book decides."""

    goods_stay_if_cancelled = True  # unused: a shelf travels with its AGV, not in the table

    def __init__(self, layout: Layout, mission: Mission, vehicles: int) -> None:
        if mission.orders < 1:
            raise UserError(f"an order mission needs at least one order, not {mission.orders}")
        dwells = {p.dwell for p in layout.packing}
        if len(dwells) > 1:
            raise UserError(f"layout {layout.name}: packing stations of different dwells "
                            f"({sorted(dwells)}) are not supported")
        _, params = mission_battery(mission)
        self.start_charges = mission_charges(mission, vehicles)
        try:
            self.book = OrderBook(layout, vehicles, mission_orders(mission, layout), params,
                                  self.start_charges)
        except ValueError as exc:  # it names the number that is wrong (n_op, the fleet)
            raise UserError(f"--battery: {exc}") from None
        self.layout = layout
        self.dwell = dwells.pop() if dwells else 0.0
        self.trips: dict[int, Target] = {}  # each AGV's next trip, decided, not yet committed
        self.events: list[_Event] = []
        self.pending: dict[int, _Event] = {}  # each AGV's arrival still to come
        self.seq = itertools.count()
        self.given: dict[int, float] = {}  # AGVs given a trip by the last advance, and when
        self.committed: dict[int, Target] = {}  # each AGV's trip committed, not yet arrived
        self.cut_driven: dict[int, float] = {}  # seconds driven on its trip's cut legs
        self.stopped: dict[int, frozenset[Cell]] = {}  # AGVs down, and the cells they hold
        self.zones: list[_Zone] = []  # closed now
        self.access = {place.cell: place.access for _, place in places(layout)}
        self.legs: dict[int, tuple[float, float]] = {}  # each AGV's last committed leg
        self.since: dict[int, float] = {}  # when each AGV's trip was decided
        self.log: WorkLog | None = None  # where the inputs go (a dispatcher's journal)
        self._assign(0.0)

    def start_poses(self) -> tuple[Pose, ...]:
        """Where the AGVs stand at the start (the book puts them on piles)."""
        return tuple(Pose(a.cell, EAST) for a in self.book.agvs.values())

    # -- what the engine asks ----------------------------------------------------------------
    @property
    def ready_at(self) -> float:
        return 0.0

    @property
    def total(self) -> int:
        return self.book.total

    @property
    def filled(self) -> frozenset[Cell]:
        return frozenset()  # a shelf in its slot closes no lane

    @property
    def closed_cells(self) -> frozenset[Cell]:
        """Where no AGV can go now: where AGVs that are down stand, and closed zones."""
        return frozenset().union(*self.stopped.values(), *(z.cells for z in self.zones))

    @property
    def goods_off_table(self) -> frozenset[Cell]:
        return frozenset()

    def work_left(self) -> bool:
        return self.book.work_left()

    def remaining(self) -> dict[str, int]:
        return {"orders": len(self.book.pending())}

    def busy(self, view: VehicleView) -> bool:
        return view.vehicle in self.trips and self.work_left()

    def next_task(self, kind: TaskKind) -> TaskKind:
        """What usually follows (the book decides at the arrival)."""
        return {TaskKind.FETCH: TaskKind.PACK, TaskKind.PACK: TaskKind.STOW}.get(
            kind, TaskKind.FETCH)

    def targets(self, view: VehicleView, poses: dict[int, Pose]) -> list[Target]:
        trip = self.trips.get(view.vehicle)
        return [] if trip is None else [trip]

    def held_back(self, fleet: Sequence[VehicleView], size: int) -> frozenset[int]:
        return frozenset()  # the order book hands out trips as the work arrives

    def in_the_way(self, view: VehicleView, poses: dict[int, Pose]) -> Blockage | None:
        return None

    def parking(self) -> tuple[Pose, ...]:
        return ()

    def loaded(self, kind: TaskKind) -> bool:
        return kind in (TaskKind.PACK, TaskKind.STOW)

    def battery(self, vehicle: int) -> Battery:
        return Battery(self.book.battery, self.start_charges[vehicle - 1],
                       frozenset(p.cell for p in self.layout.piles))

    def carried_after(self, kind: TaskKind) -> bool:
        """An AGV lifts the shelf as it arrives under it, and puts it down as it arrives in
        the slot (note A.3: no lift or drop time)."""
        return kind in (TaskKind.FETCH, TaskKind.PACK)

    def handling(self, kind: TaskKind) -> float:
        """The packing dwell at a station; lifting and putting down take no time (note A.3)."""
        return self.dwell if kind is TaskKind.PACK else 0.0

    def keep_clear(self) -> frozenset[Cell]:
        return frozenset()

    def serve(self, decision: Decision, trajectory: Trajectory, t_done: float
              ) -> StackServed | None:
        """The trip is committed: its arrival is due at the leg's end."""
        return self._input(Served(decision.vehicle, trajectory.t_start, trajectory.t_end,
                                  driving(trajectory)))

    def amended(self, trajectory: Trajectory) -> None:
        self._input(Amended(trajectory.vehicle, trajectory.t_start, trajectory.t_end,
                            driving(trajectory)))

    def next_event(self) -> float:
        while self.events and not self.events[0].live:
            heapq.heappop(self.events)
        return self.events[0].t if self.events else math.inf

    def advance(self, t: float) -> dict[int, float]:
        return self._input(Advance(t))

    # -- faults (docs/faults.md) -----------------------------------------------------------
    @property
    def taken_until(self) -> float:
        return self.book.clock

    def cancel(self, vehicle: int, kind: TaskKind, target: str, index: int | None,
               driven: float) -> Reopened | None:
        """The AGV's committed trip was cut before it arrived: its arrival will not come and
        the trip is offered again, from where the AGV stands (with the shelf it carries). A
        cut return puts no shelf down: its order is not complete after all."""
        if self.committed.get(vehicle) is None or kind is not self.committed[vehicle].kind:
            return None  # not a trip of the book's (sent aside)
        return self._input(Cancelled(vehicle, kind, driven))

    def down(self, vehicle: int, t: float, cells: frozenset[Cell]) -> dict[int, float]:
        return self._input(Down(vehicle, t, cells))

    def up(self, vehicle: int, t: float, pose: Pose) -> dict[int, float]:
        return self._input(Up(vehicle, t, pose.cell))

    def closed(self, cells: frozenset[Cell], t: float, until: float) -> dict[int, float]:
        return self._input(Closed(cells, t, until))

    # -- a restarted dispatcher (docs/faults.md) ---------------------------------------------
    @classmethod
    def replayed(cls, layout: Layout, mission: Mission, vehicles: int,
                 records: Sequence[object], log: WorkLog | None = None) -> OrderWork:
        """The work as a dead dispatcher left it: its journal's inputs taken again in order
        (UserError naming the record that cannot be); new inputs go to `log`."""
        work = cls(layout, mission, vehicles)
        for k, raw in enumerate(records, 1):
            try:
                work._take(from_record(raw))
            except (ValueError, AssertionError, KeyError) as exc:  # EventError, InvariantError
                raise UserError(f"the order book's journal, record {k}: {exc}") from None
        work.log = log
        return work

    def last_leg(self, vehicle: int) -> tuple[float, float] | None:
        """The vehicle's last leg the work heard committed (start, end), if any."""
        return self.legs.get(vehicle)

    def trip_since(self, vehicle: int) -> float | None:
        """From when the vehicle's next trip is decided (None: it has none)."""
        return self.since.get(vehicle) if vehicle in self.trips else None

    def done(self) -> list[tuple[str, int, float]]:
        """Every order done as it is announced (shelf, order, when its shelf is put down):
        complete, or on a return already committed."""
        done = [(self.book.orders[i].shelf, i, t) for i, t in self.book.completed.items()]
        for agv, trip in self.committed.items():
            order = self.book.agvs[agv].order
            if trip.kind is TaskKind.STOW and order is not None:
                done.append((order.shelf, order.id, self.pending[agv].t))
        return sorted(done, key=lambda d: (d[2], d[1]))

    def done_at(self, goods: Interval) -> float | None:
        return None  # a shelf is never in the table: the journal says what is done

    def pick_up(self, cluster: str, index: int) -> None:
        pass  # the journal replayed has it done

    # -- inputs ------------------------------------------------------------------------------
    def _input(self, i: Input) -> Any:
        """Take an input, journaled first (fleet/mission/order_log.py)."""
        if self.log is not None:
            self.log.append(to_record(i))
        return self._take(i)

    def _take(self, i: Input) -> Any:
        match i:
            case Advance(t):
                return self._advance(t)
            case Served(vehicle, t_start, t_end, driven):
                return self._served(vehicle, t_start, t_end, driven)
            case Amended(vehicle, t_start, t_end, driven):
                before = self.pending[vehicle]
                before.live = False
                self.legs[vehicle] = (t_start, t_end)
                self._arrival(vehicle, before.kind, t_end, driven)
                return None
            case Cancelled(vehicle, kind, driven):
                return self._cancelled(vehicle, kind, driven)
            case Down(vehicle, t, cells):
                return self._down(vehicle, self._now(t), cells)
            case Up(vehicle, t, cell):
                return self._up(vehicle, self._now(t), cell)
            case Closed(cells, t, until):
                self.zones.append(_Zone(cells, until))
                self._later(until, 0, OPEN)
                return self._changed(self._now(t))
        raise TypeError(f"not an order work input: {i!r}")

    def _advance(self, t: float) -> dict[int, float]:
        self.given = {}
        while self.next_event() <= t:
            event = heapq.heappop(self.events)
            self._happen(event)
            if self.next_event() > event.t:  # every event of the instant taken: assign
                self._assign(event.t)
        return self.given

    def _served(self, vehicle: int, t_start: float, t_end: float, driven: float
                ) -> StackServed | None:
        trip = self.committed[vehicle] = self.trips.pop(vehicle)
        self.legs[vehicle] = (t_start, t_end)
        self._arrival(vehicle, trip.kind, t_end, driven)
        if trip.kind is not TaskKind.STOW:
            return None
        order = self.book.agvs[vehicle].order
        assert order is not None
        return StackServed(order.shelf, order.id, t_end + self.handling(trip.kind), None)

    def _cancelled(self, vehicle: int, kind: TaskKind, driven: float) -> Reopened | None:
        self.pending.pop(vehicle).live = False
        self.trips[vehicle] = self.committed.pop(vehicle)
        self.cut_driven[vehicle] = self.cut_driven.get(vehicle, 0.0) + driven
        if kind is not TaskKind.STOW:
            return None
        order = self.book.agvs[vehicle].order
        assert order is not None
        return Reopened(order.shelf, order.id, None)

    def _down(self, vehicle: int, now: float, cells: frozenset[Cell]) -> dict[int, float]:
        self.stopped[vehicle] = cells
        self.book.down(vehicle, now)
        trip = self.trips.get(vehicle)
        if trip is not None and trip.kind is TaskKind.FETCH:  # not on its way (or cut)
            del self.trips[vehicle]
            self.book.give_back(vehicle, now, self.cut_driven.pop(vehicle, 0.0))
        return self._changed(now)

    def _up(self, vehicle: int, now: float, cell: Cell) -> dict[int, float]:
        del self.stopped[vehicle]
        self.book.up(vehicle, now, cell)
        self._changed(now)
        if vehicle not in self.trips and vehicle not in self.pending:  # nothing to do where
            park = self.book.park(vehicle, now)  # it stands: it does not stay on a lane
            if park is not None:
                self._trip(vehicle, TaskKind.CHARGE, park.pile.name, park.pile.cell, now)
        return self.given

    def _now(self, t: float) -> float:
        return max(t, self.book.clock)

    def _changed(self, now: float) -> dict[int, float]:
        """What the book does once the cells closed to the AGVs change: trips into places
        closed now re-decided, queues served, orders assigned."""
        self.given = {}
        self._block(now)
        for agv, trip in sorted(self.trips.items()):
            if trip.goals[0].cell not in self.book.blocked:
                continue
            if trip.kind is TaskKind.FETCH:  # its shelf cannot be fetched now
                del self.trips[agv]
                self.book.give_back(agv, now, self.cut_driven.pop(agv, 0.0))
            elif (place := self.book.retarget(agv, now)) is not None:
                self._trip(agv, trip.kind, place.name, place.cell, now)
        self._assign(now)
        return self.given

    def _block(self, now: float) -> None:
        """The book's blocked cells: those closed now, and places no AGV can enter through
        any of their access cells."""
        closed = self.closed_cells
        shut = {cell for cell, access in self.access.items()
                if access and all(a in closed for a in access)}
        for trip in self.book.block(closed | shut, now):
            if isinstance(trip, StationTrip):
                self._trip(trip.agv, TaskKind.PACK, trip.station.name, trip.station.cell, now)
            else:
                self._trip(trip.agv, TaskKind.CHARGE, trip.pile.name, trip.pile.cell, now)

    # -- the book's events -------------------------------------------------------------------
    def _arrival(self, agv: int, kind: TaskKind | None, t_end: float, driven: float) -> None:
        event = _Event(t_end, next(self.seq), agv, ARRIVE, kind, driven)
        self.pending[agv] = event
        heapq.heappush(self.events, event)

    def _later(self, t: float, agv: int, what: str) -> None:
        heapq.heappush(self.events, _Event(t, next(self.seq), agv, what))

    def _trip(self, agv: int, kind: TaskKind, name: str, cell: Cell, t: float) -> None:
        self.trips[agv] = Target(name, (Pose(cell, EAST),), kind=kind)
        self.given[agv] = self.since[agv] = t

    def _happen(self, e: _Event) -> None:
        book = self.book
        if e.what == ARRIVE:
            del self.pending[e.agv]
            del self.committed[e.agv]
            driven = e.driven + self.cut_driven.pop(e.agv, 0.0)
            if e.kind is TaskKind.FETCH:
                trip = book.at_shelf(e.agv, e.t, driven)
                if trip is not None:  # else it waits loaded under the slot for a station
                    self._trip(e.agv, TaskKind.PACK, trip.station.name, trip.station.cell, e.t)
            elif e.kind is TaskKind.PACK:
                self._later(book.at_station(e.agv, e.t, driven), e.agv, LEAVE)
            elif e.kind is TaskKind.STOW:
                done = book.returned(e.agv, e.t, driven)
                if done.charge is not None:
                    pile = done.charge.pile
                    self._trip(e.agv, TaskKind.CHARGE, pile.name, pile.cell, e.t)
            elif e.kind is TaskKind.CHARGE:
                self._later(book.at_pile(e.agv, e.t, driven), e.agv, FULL)
        elif e.what == LEAVE:
            back = book.left_station(e.agv, e.t)
            self._trip(e.agv, TaskKind.STOW, back.slot.name, back.slot.cell, e.t)
            if back.served is not None:
                st = back.served.station
                self._trip(back.served.agv, TaskKind.PACK, st.name, st.cell, e.t)
        elif e.what == FULL:
            book.charged(e.agv, e.t)
        elif e.what == OPEN:  # a zone's end: its cells are open again
            self.zones = [z for z in self.zones if z.until > e.t]
            self._block(e.t)

    def _assign(self, t: float) -> None:
        for a in self.book.assign(t):
            self._trip(a.agv, TaskKind.FETCH, a.order.shelf, a.slot.cell, t)
            if a.charge is not None:  # the pile it left went to one waiting for a pile
                pile = a.charge.pile
                self._trip(a.charge.agv, TaskKind.CHARGE, pile.name, pile.cell, t)
