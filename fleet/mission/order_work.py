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
"""

from __future__ import annotations

import heapq
import itertools
import math
from dataclasses import dataclass

from fleet.dispatching.decision import Decision, Target, TaskKind, VehicleView
from fleet.errors import UserError
from fleet.mission.battery import BatteryParams, parse_battery, start_charges
from fleet.mission.orders import Order, OrderBook, release_orders
from fleet.mission.spec import Mission
from fleet.mission.work import StackServed
from fleet.planning.geometry import Cell
from fleet.planning.reservations import Interval
from fleet.planning.trajectory import Pose, Trajectory
from fleet.vehicles.agv import EAST
from fleet.world.layout import Layout

DEFAULT_AGVS = 10  # seed 002's fleet in Figures 17 and 19
DEFAULT_ORDERS = 100

ARRIVE, LEAVE, FULL = "arrive", "leave", "full"


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


class OrderWork:
    """Orders released at once, carried out trip by trip as the order book decides."""

    goods_stay_if_cancelled = True  # unused: order missions take no faults

    def __init__(self, layout: Layout, mission: Mission, vehicles: int) -> None:
        if mission.orders < 1:
            raise UserError(f"an order mission needs at least one order, not {mission.orders}")
        dwells = {p.dwell for p in layout.packing}
        if len(dwells) > 1:
            raise UserError(f"layout {layout.name}: packing stations of different dwells "
                            f"({sorted(dwells)}) are not supported")
        _, params = mission_battery(mission)
        try:
            self.book = OrderBook(layout, vehicles, mission_orders(mission, layout), params,
                                  mission_charges(mission, vehicles))
        except ValueError as exc:  # it names the number that is wrong (n_op, the fleet)
            raise UserError(f"--battery: {exc}") from None
        self.layout = layout
        self.dwell = dwells.pop() if dwells else 0.0
        self.trips: dict[int, Target] = {}  # each AGV's next trip, decided, not yet committed
        self.events: list[_Event] = []
        self.pending: dict[int, _Event] = {}  # each AGV's arrival still to come
        self.seq = itertools.count()
        self.given: dict[int, float] = {}  # AGVs given a trip by the last advance, and when
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

    def loaded(self, kind: TaskKind) -> bool:
        return kind in (TaskKind.PACK, TaskKind.STOW)

    def carried_after(self, kind: TaskKind) -> bool:
        """An AGV lifts the shelf as it arrives under it, and puts it down as it arrives in
        the slot (note A.3: no lift or drop time)."""
        return kind in (TaskKind.FETCH, TaskKind.PACK)

    def handling(self, kind: TaskKind) -> float:
        """The packing dwell at a station; lifting and putting down take no time (note A.3)."""
        return self.dwell if kind is TaskKind.PACK else 0.0

    def wanted(self, view: VehicleView) -> tuple[Pose, ...]:
        trip = self.trips.get(view.vehicle)
        return () if trip is None else trip.goals

    def keep_clear(self) -> frozenset[Cell]:
        return frozenset()

    def serve(self, decision: Decision, trajectory: Trajectory, t_done: float
              ) -> StackServed | None:
        """The trip is committed: its arrival is due at the leg's end."""
        trip = self.trips.pop(decision.vehicle)
        self._arrival(decision.vehicle, trip.kind, trajectory)
        if trip.kind is not TaskKind.STOW:
            return None
        order = self.book.agvs[decision.vehicle].order
        assert order is not None
        return StackServed(order.shelf, order.id, t_done, None)

    def amended(self, trajectory: Trajectory) -> None:
        before = self.pending[trajectory.vehicle]
        before.live = False
        self._arrival(trajectory.vehicle, before.kind, trajectory)

    def next_event(self) -> float:
        while self.events and not self.events[0].live:
            heapq.heappop(self.events)
        return self.events[0].t if self.events else math.inf

    def advance(self, t: float) -> dict[int, float]:
        self.given = {}
        while self.next_event() <= t:
            event = heapq.heappop(self.events)
            self._happen(event)
            if self.next_event() > event.t:  # every event of the instant taken: assign
                self._assign(event.t)
        return self.given

    # -- faults and restarts: not for order missions yet -------------------------------------
    def reopen(self, cluster: str, index: int) -> Cell:
        raise UserError("order missions take no faults yet")

    def done_at(self, goods: Interval) -> float | None:
        raise UserError("a restarted dispatcher cannot pick up an order mission yet")

    def pick_up(self, cluster: str, index: int) -> None:
        raise UserError("a restarted dispatcher cannot pick up an order mission yet")

    # -- the book's events -------------------------------------------------------------------
    def _arrival(self, agv: int, kind: TaskKind | None, leg: Trajectory) -> None:
        driven = sum(s.t1 - s.t0 for s in leg.steps if s.manner.label != "wait")
        event = _Event(leg.t_end, next(self.seq), agv, ARRIVE, kind, driven)
        self.pending[agv] = event
        heapq.heappush(self.events, event)

    def _later(self, t: float, agv: int, what: str) -> None:
        heapq.heappush(self.events, _Event(t, next(self.seq), agv, what))

    def _trip(self, agv: int, kind: TaskKind, name: str, cell: Cell, t: float) -> None:
        self.trips[agv] = Target(name, (Pose(cell, EAST),), kind=kind)
        self.given[agv] = t

    def _happen(self, e: _Event) -> None:
        book = self.book
        if e.what == ARRIVE:
            del self.pending[e.agv]
            if e.kind is TaskKind.FETCH:
                trip = book.at_shelf(e.agv, e.t, e.driven)
                if trip is not None:  # else it waits loaded under the slot for a station
                    self._trip(e.agv, TaskKind.PACK, trip.station.name, trip.station.cell, e.t)
            elif e.kind is TaskKind.PACK:
                self._later(book.at_station(e.agv, e.t, e.driven), e.agv, LEAVE)
            elif e.kind is TaskKind.STOW:
                done = book.returned(e.agv, e.t, e.driven)
                if done.charge is not None:
                    pile = done.charge.pile
                    self._trip(e.agv, TaskKind.CHARGE, pile.name, pile.cell, e.t)
            elif e.kind is TaskKind.CHARGE:
                self._later(book.at_pile(e.agv, e.t, e.driven), e.agv, FULL)
        elif e.what == LEAVE:
            back = book.left_station(e.agv, e.t)
            self._trip(e.agv, TaskKind.STOW, back.slot.name, back.slot.cell, e.t)
            if back.served is not None:
                st = back.served.station
                self._trip(back.served.agv, TaskKind.PACK, st.name, st.cell, e.t)
        elif e.what == FULL:
            book.charged(e.agv, e.t)

    def _assign(self, t: float) -> None:
        for a in self.book.assign(t):
            self._trip(a.agv, TaskKind.FETCH, a.order.shelf, a.slot.cell, t)
            if a.charge is not None:  # the pile it left went to one waiting for a pile
                pile = a.charge.pile
                self._trip(a.charge.agv, TaskKind.CHARGE, pile.name, pile.cell, t)
