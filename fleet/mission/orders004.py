"""Seed 004's work above its tracker (Section 1.1, simplification 2; Section 2, shelf recall and
Equation 5; seed pack note B.4.6, B.4.8, B.4.9): orders by popularity handed to the stations
in turn; a station with fewer than Q_max orders in flight takes its next and asks for the
nearest shelf holding the goods; the shelf's place picks the nearest idle AGV, which fetches
it, brings it to the station and, once picked from, takes it home and rests under it.

- Distances are Manhattan distances, obstacles ignored (GIVEN). A shelf being taken home can
  be recalled (GIVEN): its distance is Equation (5), d = |x_J - x_W| + |y_J - y_W| - z, with J
  the cell of the AGV carrying it, W the station's entrance and z the distance from J to the
  shelf's home, the return it saves (CHOICE). The carrier then delivers it instead.
- An order is one goods line; classes are drawn 6:5:4:3:2:1 from red to black and a class's
  goods alike (of those the floor holds); all orders exist at t = 0 and go to the stations
  round-robin (CHOICEs).
- An order whose goods has no shelf free waits and lets later ones by; orders that have a
  shelf take idle AGVs first come, first served (CHOICE).
- Battery (B.4.9): consumption is running time (moving, turning, lifting); an AGV that turns
  idle below the threshold goes to the nearest free pile and charges for rho times what it
  consumed, then rests there, idle, holding the pile until it leaves. It never drops a shelf
  to charge. The state of charge is seed 002's `BatteryParams` with seed 004's numbers.

Every tie is broken by a stated key, so a mission is a function of its inputs, as the
tracker below it is.
"""

from __future__ import annotations

import random
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field

from fleet.errors import UserError
from fleet.mission.battery import FULL, BatteryParams
from fleet.mission.faults import Fault
from fleet.mission.faults004 import apply_faults, check_faults004
from fleet.mission.orders import manhattan
from fleet.mission.tracking004 import (
    Event,
    Leg,
    LegDone,
    Milestone,
    Picked,
    Repaired,
    Tracker,
    TrackingParams,
    Vehicles,
)
from fleet.planning.rules004 import XY, Direction, Task
from fleet.world.floor004 import CLASSES, Floor004

CLASS_WEIGHTS = (6, 5, 4, 3, 2, 1)  # red to black (CHOICE, note B.4.8)
E_MAX_S = 1800.0  # running seconds a full battery lasts (CHOICE, note B.3)
RHO = 0.5  # charging time per second consumed (CHOICE)
# Seed 004's battery in seed 002's terms: drains per running second, charges 1/rho as fast.
BATTERY_004 = BatteryParams(drain_per_s=FULL / E_MAX_S, charge_per_s=FULL / (RHO * E_MAX_S))


DEFAULT_AGVS_004 = 10  # `fleet run`'s fleet when none is given (the seed runs 10 to 60)


def fleet004(floor: Floor004, vehicles: int | None) -> int:
    """The fleet of a mission on `floor`: `vehicles`, or DEFAULT_AGVS_004, one per parking
    place at most (each starts on one)."""
    n = min(DEFAULT_AGVS_004, len(floor.parking)) if vehicles is None else vehicles
    if not 1 <= n <= len(floor.parking):
        raise UserError(f"--vehicles {n}: the AGVs of {floor.name} start on its "
                        f"{len(floor.parking)} parking places, one each")
    return n


@dataclass(frozen=True)
class Order004:
    id: int
    goods: str  # e.g. "red-2"
    station: str  # handed to it in turn


def generate_orders(floor: Floor004, count: int, seed: int) -> tuple[Order004, ...]:
    """`count` orders by popularity from `random.Random(seed)`, round-robin to stations."""
    if isinstance(count, bool) or not isinstance(count, int) or count < 0:
        raise UserError(f"the number of orders must be a whole number, 0 or more, not "
                        f"{count!r}")
    rng = random.Random(seed)
    stations = [s.name for s in floor.stations]
    held = {colour: sorted(g for g in floor.goods if g.split("-")[0] == colour)
            for colour in CLASSES}  # a small floor may lack some goods: never ordered
    classes = [(c, w) for c, w in zip(CLASSES, CLASS_WEIGHTS, strict=True) if held[c]]
    out = []
    for i in range(count):
        colour = rng.choices([c for c, _ in classes], weights=[w for _, w in classes])[0]
        out.append(Order004(i + 1, rng.choice(held[colour]), stations[i % len(stations)]))
    return tuple(out)


@dataclass(frozen=True)
class WorkParams:
    q_max: int = 4  # orders in flight per station: its three waiting cells and the work cell
    recall: bool = True
    battery: BatteryParams = BATTERY_004

    def __post_init__(self) -> None:
        if self.q_max < 1:
            raise UserError(f"a station must take at least 1 order at a time, not {self.q_max}")


@dataclass
class _Shelf:
    home: XY
    goods: str
    carrier: int | None = None  # the AGV under it (lifting, carrying or dropping it)
    order: int | None = None  # the order it is fetched or delivered for
    returning: bool = False


@dataclass
class _Agv:
    soc: float = FULL  # at `ran_at` seconds of running
    ran_at: float = 0.0
    shelf: XY | None = None  # the home of the shelf it fetches, carries or returns
    needs_pile: bool = False  # idle below the threshold, no pile free yet


@dataclass(frozen=True)
class PickedOrder:
    order: int
    goods: str
    station: str
    shelf: XY  # the shelf's home
    vehicle: int
    recalled: bool
    t: float


@dataclass(frozen=True)
class Result004:
    completion_s: float  # the last order picked
    shelves_home_s: float  # every shelf home again
    picked: tuple[PickedOrder, ...]
    charges: int
    lowest_soc: float
    events: tuple[Event, ...]
    counts: dict[str, int]


@dataclass
class Mission004:
    """One order mission on one floor: `run` drives it to the end. The AGVs act in this
    process, or through `fleet` (their agent processes: dispatcher/remote004.py)."""

    floor: Floor004
    vehicles: int
    orders: tuple[Order004, ...]
    tracking: TrackingParams = field(default_factory=TrackingParams)
    work: WorkParams = field(default_factory=WorkParams)
    fleet: Vehicles | None = None  # None: every AGV in this process
    on_event: Callable[[Event], None] | None = None  # each tracking event as it happens
    pace: Callable[[float], None] | None = None  # holds each instant until it comes
    faults: tuple[Fault, ...] = ()  # breakdowns and closed zones (fleet/mission/faults004.py)

    def __post_init__(self) -> None:
        if not 1 <= self.vehicles <= len(self.floor.parking):
            raise UserError(f"{self.floor.name} parks 1 to {len(self.floor.parking)} AGVs, "
                            f"not {self.vehicles}")
        names = {s.name for s in self.floor.stations}
        goods = set(self.floor.goods)
        for o in self.orders:
            if o.station not in names:
                raise UserError(f"order {o.id} is for station {o.station!r}, which "
                                f"{self.floor.name} does not have")
            if o.goods not in goods:
                raise UserError(f"order {o.id} is for goods {o.goods!r}, which no shelf on "
                                f"{self.floor.name} holds")
        self.tracker = Tracker(self.floor, self.tracking, self.fleet, self.on_event, self.pace)
        for v in range(1, self.vehicles + 1):
            self.tracker.place(v, self.floor.parking[v - 1], Direction.DOWN)
        check_faults004(self.faults, self.floor, self.vehicles, "of the mission")
        apply_faults(self.tracker, self.faults)
        self._agvs = {v: _Agv() for v in range(1, self.vehicles + 1)}
        self._shelves = {s.xy: _Shelf(s.xy, s.goods) for s in self.floor.slots}
        self._stations = {s.name: s for s in self.floor.stations}
        self._queued = {name: deque(o for o in self.orders if o.station == name)
                        for name in self._stations}
        self._in_flight = dict.fromkeys(self._stations, 0)
        self._waiting: list[Order004] = []  # taken by their station, no shelf yet
        self._fetching: dict[int, Order004] = {}  # by AGV: the order its shelf is for
        self._recalled: set[int] = set()  # orders served by a recalled shelf
        self._picked: list[PickedOrder] = []
        self._charges = 0
        self._lowest = FULL

    # -- the loop ------------------------------------------------------------------------------
    def run(self) -> Result004:
        self._dispatch()
        shelves_home = 0.0
        while (m := self.tracker.advance()) is not None:
            self._on(m)
            if isinstance(m, LegDone) and m.leg.task is Task.RETURN:
                shelves_home = m.t
            self._dispatch()
            if len(self._picked) == len(self.orders) and all(
                    a.leg is None for a in self.tracker.agvs.values()):
                break  # the work is done: a fault still to come strikes nothing
        left = len(self.orders) - len(self._picked)
        if left:
            stranded = sorted(v for v, a in self._agvs.items() if a.needs_pile)
            raise UserError(f"{left} orders were never picked: " + (
                f"AGVs {stranded} wait for a free pile" if stranded else
                "no shelf or AGV was left to serve them"))
        return Result004(
            max((p.t for p in self._picked), default=0.0), shelves_home, tuple(self._picked),
            self._charges, self._lowest, tuple(self.tracker.events),
            dict(self.tracker.counts()))

    def soc(self, vehicle: int) -> float:
        a = self._agvs[vehicle]
        ran = self.tracker.agvs[vehicle].running_s - a.ran_at
        return self.work.battery.after_driving(a.soc, ran)

    # -- what happened -------------------------------------------------------------------------
    def _on(self, m: Milestone) -> None:
        if isinstance(m, Picked):
            self._picked_at(m)
            return
        if isinstance(m, Repaired):
            return  # available again: the dispatch that follows sees it
        v, leg = m.vehicle, m.leg
        a = self._agvs[v]
        self._lowest = min(self._lowest, self.soc(v))
        if leg.make_way:
            self._idle(v)
        elif leg.task is Task.FETCH:
            order = self._fetching[v]
            station = self._stations[order.station]
            self.tracker.assign(v, Leg(Task.DELIVER, station.entrance, home=a.shelf,
                                       station=station))
        elif leg.task is Task.DELIVER:
            assert a.shelf is not None
            shelf = self._shelves[a.shelf]
            shelf.order, shelf.returning = None, True
            self.tracker.assign(v, Leg(Task.RETURN, a.shelf, home=a.shelf))
        elif leg.task is Task.RETURN:
            assert a.shelf is not None
            shelf = self._shelves[a.shelf]
            shelf.carrier, shelf.returning, a.shelf = None, False, None
            self._idle(v)
        elif leg.task is Task.CHARGE and leg.charge_s == 0.0:  # at the pile: charge
            soc = self.soc(v)
            self.tracker.assign(v, Leg(Task.CHARGE, leg.goal, charge_s=(
                FULL - soc) / self.work.battery.charge_per_s))
            self._charges += 1
        else:  # charged: full, and idle on its pile until it leaves
            a.soc, a.ran_at = FULL, self.tracker.agvs[v].running_s

    def _picked_at(self, m: Picked) -> None:
        v = m.vehicle
        order = self._fetching.pop(v)
        shelf = self._agvs[v].shelf
        assert shelf is not None
        self._picked.append(PickedOrder(order.id, order.goods, order.station, shelf, v,
                                        order.id in self._recalled, m.t))
        self._in_flight[order.station] -= 1

    def _idle(self, v: int) -> None:
        """Idle again: below the threshold it goes to charge (B.4.9)."""
        a = self._agvs[v]
        if self.soc(v) < self.work.battery.threshold:
            a.needs_pile = True

    # -- decisions -----------------------------------------------------------------------------
    def _dispatch(self) -> None:
        for name, queue in self._queued.items():
            while queue and self._in_flight[name] < self.work.q_max:
                self._waiting.append(queue.popleft())
                self._in_flight[name] += 1
        self._send_to_piles()
        served = []
        for order in self._waiting:
            found = self._nearest_shelf(order)
            if found is None:
                continue  # no shelf of its goods is free: later orders may go by
            shelf, carrier = found
            if carrier is not None:
                self._recall(order, shelf, carrier)
            else:
                v = self._nearest_idle(shelf.home)
                if v is None:
                    break  # AGVs go first come, first served
                self._fetch(order, shelf, v)
            served.append(order)
        for order in served:
            self._waiting.remove(order)

    def _nearest_shelf(self, order: Order004) -> tuple[_Shelf, int | None] | None:
        """The available shelf nearest the order's station: at home and not wanted, or (with
        recall) on its way home, by Equation (5). Ties: the home cell."""
        entrance = self._stations[order.station].entrance
        best: tuple[float, XY] | None = None
        found: tuple[_Shelf, int | None] | None = None
        for slot in self.floor.goods[order.goods]:
            shelf = self._shelves[slot.xy]
            if shelf.order is not None:
                continue
            if shelf.carrier is None:
                d = float(manhattan(shelf.home, entrance))
            elif self.work.recall and shelf.returning and \
                    self.tracker.recallable(shelf.carrier):
                at = self._carrier_cell(shelf.carrier)
                d = float(manhattan(at, entrance) - manhattan(at, shelf.home))
            else:
                continue
            if best is None or (d, shelf.home) < best:
                best, found = (d, shelf.home), (shelf, shelf.carrier)
        return found

    def _carrier_cell(self, v: int) -> XY:
        agv = self.tracker.agvs[v]
        return agv.moving_to if agv.moving_to is not None else agv.cell

    def _nearest_idle(self, at: XY) -> int | None:
        idle = [v for v, a in self._agvs.items()
                if self.tracker.agvs[v].leg is None and a.shelf is None and not a.needs_pile
                and not self.tracker.is_down(v)]
        if not idle:
            return None
        return min(idle, key=lambda v: (manhattan(self.tracker.agvs[v].cell, at), v))

    def _fetch(self, order: Order004, shelf: _Shelf, v: int) -> None:
        shelf.carrier, shelf.order = v, order.id
        self._agvs[v].shelf = shelf.home
        self._fetching[v] = order
        self.tracker.assign(v, Leg(Task.FETCH, shelf.home))

    def _recall(self, order: Order004, shelf: _Shelf, v: int) -> None:
        station = self._stations[order.station]
        shelf.order, shelf.returning = order.id, False
        self._fetching[v] = order
        self._recalled.add(order.id)
        self.tracker.recall(v, Leg(Task.DELIVER, station.entrance, home=shelf.home,
                                   station=station))

    def _send_to_piles(self) -> None:
        """AGVs that need charging, by id, to the nearest free pile (ties: the pile's cell):
        free when nobody stands on it or is on the way to it."""
        agvs = self.tracker.agvs.values()
        taken = {a.cell for a in agvs} | {a.leg.goal for a in agvs if a.leg is not None
                                          and a.leg.task is Task.CHARGE}
        for v, a in sorted(self._agvs.items()):
            if not a.needs_pile or self.tracker.agvs[v].leg is not None or \
                    self.tracker.is_down(v):
                continue  # (one sent out of the way meanwhile goes when it is there)
            free = [p for p in self.floor.piles if p not in taken]
            if not free:
                return
            at = self.tracker.agvs[v].cell
            pile = min(free, key=lambda p: (manhattan(at, p), p))
            a.needs_pile = False
            taken.add(pile)
            self.tracker.assign(v, Leg(Task.CHARGE, pile))

