"""Seed 002's order missions as pure logic: orders -> shelf -> packing station -> slot, with
the battery's charging rules (seed pack note A.4.1, A.4.7; docs/agv-002.md, "Orders").

Nothing here drives, plans or waits: the caller (a test loop now, the engine later through
the mission-kind seam, fleet/mission/work.py) says what happened and when, and each method
returns what the central control system decided, as data. All distances are Manhattan
distances between cells (CHOICE, note A.6 #8); every tie is broken by a stated key, so a run
is a function of its inputs.

The life of an order, GIVEN in Sections 2.2 and 6 (1), with the notes' CHOICES marked:

1. `release_orders`: a batch at t = 0, shelves drawn uniformly with replacement by a seeded
   `random.Random` (CHOICE). A shelf "handling one order at a time" queues the next one FIFO.
2. `OrderBook.assign`: the nearest idle AGV takes the order; repeated as a greedy global
   nearest pair over the orders whose shelf stands in a slot and the available AGVs (CHOICE),
   ties by order id, then AGV id. The AGV becomes unavailable.
3. `at_shelf`: the AGV under the shelf is sent to the nearest available packing station from
   the slot, which becomes unavailable. With none available it waits loaded under the slot,
   FIFO with the others waiting (CHOICE), and is served when a station frees. The slot is
   vacant from the moment the AGV leaves it with the shelf.
4. `at_station` and `left_station`: the AGV dwells (10 s on the paper layouts); leaving, it
   frees the station and is sent to the nearest vacant slot from the station, reserved at
   once so two AGVs never head for one slot (CHOICE; the seed marks it unavailable only "once
   the AGV delivers the shelf").
5. `returned`: the shelf stands in that slot (not necessarily its home: shelf identity is kept
   apart from slots), the order is complete, the AGV is available under the shelf, and then
   the charging decision (fleet.mission.battery): below 20 %, or not among the N_op highest,
   it goes to the nearest free pile; with every pile taken it waits where it is.
6. `at_pile` and `charged`: it charges to 100 % and rejoins. It keeps its pile until an
   assignment takes it away, so the pile stays exclusive while it stands there.

Where the seed reads differently from the notes, the seed is followed: Section 2.2 has the
shelf's slot become available "once the AGV departs", so an AGV waiting loaded under its slot
(3.) still holds it and its shelf is still in it; the shelf is on the AGV from departure on
and at the station from arrival until the dwell ends. Section 6 (1) says the AGV picks the
station "nearest to itself", which is the slot, as it stands under the shelf.
"""

from __future__ import annotations

import random
from collections import deque
from collections.abc import Collection, Iterable, Sequence
from dataclasses import dataclass
from enum import Enum
from typing import Protocol, TypeVar

from fleet.mission.battery import FULL, BatteryParams, goes_to_charge, start_piles
from fleet.planning.geometry import Cell
from fleet.world.layout import Layout, PackingStation, Pile, Slot

EPS = 1e-9
LOWER_LEFT = "lower-left"  # Figure 19's "shelf area in the lower left corner"


class InvariantError(AssertionError):
    """The order book's state broke a rule (a shelf in two places, a slot reserved twice...)."""


class EventError(ValueError):
    """An event that cannot happen in the AGV's current phase, or out of time order."""


class _Placed(Protocol):
    @property
    def cell(self) -> Cell: ...


P = TypeVar("P", bound=_Placed)


def manhattan(a: Cell, b: Cell) -> int:
    return abs(a[0] - b[0]) + abs(a[1] - b[1])


def _cell_key(cell: Cell) -> tuple[int, int]:
    return (cell[1], cell[0])  # ties between equally near places: lower row, then column


# -- orders ------------------------------------------------------------------------------

@dataclass(frozen=True)
class Order:
    id: int
    shelf: str  # a shelf id (layout.shelves): an order targets a shelf, never a slot


def lower_left_shelves(layout: Layout) -> tuple[str, ...]:
    """Figure 19's area (CHOICE, note A.5 E002-3): the lowest-left 2 x L shelf block, the slots
    of the lowest two adjacent slot rows in the leftmost unbroken run of slot columns. On
    `paper002` that is rows 2-3, columns 3-11: 18 slots. (The notes also call them "sub-areas
    (1,1) and (2,1)"; sub-area (2,1) also holds row 6, which is not in the corner, so the
    cells are what is followed.)"""
    rows = sorted({s.cell[1] for s in layout.slots})
    if not rows:
        raise ValueError(f"layout {layout.name} has no shelf slots")
    band = {rows[0], rows[0] + 1} & set(rows)
    cols = sorted({s.cell[0] for s in layout.slots if s.cell[1] in band})
    run = [cols[0]]
    for col in cols[1:]:
        if col != run[-1] + 1:
            break
        run.append(col)
    return tuple(s.name for s in layout.slots if s.cell[1] in band and s.cell[0] in run)


def area_shelves(layout: Layout, area: str | Collection[str] | None) -> tuple[str, ...]:
    """The shelves orders may be drawn from, in the layout's order: all (None), Figure 19's
    corner (`LOWER_LEFT`), a shelf area of the layout by name ("a-1-1"), or given shelf ids."""
    if area is None:
        return tuple(s.name for s in layout.slots)
    if isinstance(area, str):
        if area == LOWER_LEFT:
            return lower_left_shelves(layout)
        found = tuple(s.name for s in layout.slots if s.area == area)
        if not found:
            names = ", ".join(a.name for a in layout.shelf_areas)
            raise ValueError(f"layout {layout.name} has no shelf area {area!r} (it has "
                             f"{LOWER_LEFT!r} and {names})")
        return found
    wanted = set(area)
    unknown = sorted(wanted - set(layout.shelves))
    if unknown:
        raise ValueError(f"layout {layout.name} has no shelf {unknown[0]!r}")
    if not wanted:
        raise ValueError("an order area needs at least one shelf")
    return tuple(s.name for s in layout.slots if s.name in wanted)


def release_orders(layout: Layout, count: int, seed: int,
                   area: str | Collection[str] | None = None) -> tuple[Order, ...]:
    """`count` orders with ids 1..count, released together (GIVEN: "The system simultaneously
    dispatches ... orders, which are randomly distributed across the shelves"); each shelf
    drawn uniformly with replacement from `area` (CHOICE) by `random.Random(seed)`."""
    if isinstance(count, bool) or not isinstance(count, int) or count < 0:
        raise ValueError(f"the number of orders must be a whole number, 0 or more, not "
                         f"{count!r}")
    shelves = area_shelves(layout, area)
    rng = random.Random(seed)
    return tuple(Order(i, rng.choice(shelves)) for i in range(1, count + 1))


# -- decisions ---------------------------------------------------------------------------

@dataclass(frozen=True)
class ChargeTrip:
    """An AGV sent to a pile; `reason`: "threshold" (below 20 %) or "staggered" (N_op)."""

    agv: int
    pile: Pile
    distance: int  # from where the AGV stands to the pile
    reason: str


@dataclass(frozen=True)
class Assignment:
    order: Order
    agv: int
    slot: Slot  # where the shelf stands now
    distance: int  # from the AGV's cell to the slot
    charge: ChargeTrip | None = None  # the pile the AGV left went to an AGV waiting for one


@dataclass(frozen=True)
class StationTrip:
    agv: int
    order: Order
    station: PackingStation
    distance: int  # from the slot to the station
    waited: float  # seconds the AGV waited loaded under the slot for a station


@dataclass(frozen=True)
class ReturnTrip:
    agv: int
    order: Order
    slot: Slot  # reserved for this AGV
    distance: int  # from the station to the slot
    served: StationTrip | None = None  # the freed station went to an AGV waiting for one


@dataclass(frozen=True)
class Completion:
    agv: int
    order: Order
    slot: Slot
    t: float
    charge: ChargeTrip | None  # the charging decision: sent to a pile now
    charge_wait: str | None = None  # the reason it must charge, waiting for a free pile


# -- state -------------------------------------------------------------------------------

class Phase(Enum):
    IDLE = "idle"  # available: under a shelf in a slot, or on a pile
    TO_SHELF = "to shelf"
    WAIT_STATION = "waiting for a station"  # loaded, under the slot
    TO_STATION = "to station"
    AT_STATION = "at station"
    TO_SLOT = "to slot"
    TO_PILE = "to pile"
    WAIT_PILE = "waiting for a pile"
    CHARGING = "charging"


AVAILABLE, BUSY, CHARGING = "available", "busy", "charging"
_CHARGE_PHASES = {Phase.TO_PILE, Phase.WAIT_PILE, Phase.CHARGING}
_CARRYING = {Phase.TO_STATION, Phase.AT_STATION, Phase.TO_SLOT}


class SlotState(Enum):
    OCCUPIED = "occupied"
    VACANT = "vacant"
    RESERVED = "reserved"


@dataclass(frozen=True)
class Place:
    """Where a shelf is: kind "slot", "agv" or "station", and which one."""

    kind: str
    at: str | int

    def __str__(self) -> str:
        return f"{self.kind} {self.at}"


@dataclass
class Agv:
    id: int
    cell: Cell
    soc: float  # as of the AGV's last event
    phase: Phase = Phase.IDLE
    order: Order | None = None
    slot: Slot | None = None  # the shelf's slot (to, under, or returning to)
    station: PackingStation | None = None
    pile: Pile | None = None  # heading to, charging on, or standing on
    leg_start: float = 0.0  # when its current trip was decided
    since: float = 0.0  # when it began waiting, arrived at a station or began charging
    charge_reason: str | None = None
    down: bool = False  # cannot move (a fault): given no order until it is up again

    @property
    def status(self) -> str:
        if self.phase is Phase.IDLE:
            return AVAILABLE
        return CHARGING if self.phase in _CHARGE_PHASES else BUSY


class OrderBook:
    """The central control system's state and rules for seed 002's orders and charging.

    AGVs are numbered 1..n (the paper's r_1..r_n). They start on piles (`start_piles`) unless
    `starts` gives their cells (slot or pile cells, the notes' alternative "under random
    shelves"); with given starts the fleet may outnumber the piles, and AGVs then queue for
    piles. `initial_soc` is one SOC for all or one per AGV.
    """

    def __init__(self, layout: Layout, n_agvs: int, orders: Iterable[Order] = (),
                 battery: BatteryParams | None = None,
                 initial_soc: float | Sequence[float] = FULL,
                 starts: Sequence[Cell] | None = None) -> None:
        if not layout.slots:
            raise ValueError(f"layout {layout.name} has no shelf slots")
        if not layout.packing:
            raise ValueError(f"layout {layout.name} has no packing stations")
        if not layout.piles:
            raise ValueError(f"layout {layout.name} has no charging piles")
        if isinstance(n_agvs, bool) or not isinstance(n_agvs, int) or n_agvs < 1:
            raise ValueError(f"the fleet needs a whole number of AGVs, at least 1, not "
                             f"{n_agvs!r}")
        self.layout = layout
        self.battery = battery or BatteryParams()
        self.n_op = self.battery.operational(n_agvs)
        socs = ([initial_soc] * n_agvs if isinstance(initial_soc, (int, float))
                else list(initial_soc))
        if len(socs) != n_agvs:
            raise ValueError(f"initial_soc gives {len(socs)} values for {n_agvs} AGVs")
        for i, soc in enumerate(socs, 1):
            if isinstance(soc, bool) or not isinstance(soc, (int, float)):
                raise ValueError(f"initial SOC of AGV {i} must be a number, not {soc!r}")
            if not 0.0 <= soc <= FULL:
                raise ValueError(f"initial SOC of AGV {i} must be between 0 and 100 %, not "
                                 f"{soc!r}")
        self.slots = {s.name: s for s in layout.slots}
        self.slot_at = {s.cell: s for s in layout.slots}
        self.stations = {p.name: p for p in layout.packing}
        self.piles = {c.name: c for c in layout.piles}
        pile_at = {c.cell: c for c in layout.piles}
        # shelves and slots: every slot holds its own shelf at the start
        self.where: dict[str, Place] = {s.name: Place("slot", s.name) for s in layout.slots}
        self.slot_state = {s.name: SlotState.OCCUPIED for s in layout.slots}
        self.slot_shelf: dict[str, str | None] = {s.name: s.name for s in layout.slots}
        self.reserved_by: dict[str, int] = {}
        self.station_agv: dict[str, int | None] = {p.name: None for p in layout.packing}
        self.station_shelf: dict[str, str | None] = {p.name: None for p in layout.packing}
        self.pile_agv: dict[str, int | None] = {c.name: None for c in layout.piles}
        # AGVs
        if starts is None:
            cells = [p.cell for p in start_piles(layout, n_agvs)]
        else:
            cells = [(int(c[0]), int(c[1])) for c in starts]
            if len(cells) != n_agvs:
                raise ValueError(f"starts gives {len(cells)} cells for {n_agvs} AGVs")
            if len(set(cells)) != len(cells):
                raise ValueError("two AGVs cannot start on one cell")
            for i, cell in enumerate(cells, 1):
                if cell not in self.slot_at and cell not in pile_at:
                    raise ValueError(f"AGV {i} starts at {cell}, which is neither a shelf "
                                     f"slot nor a charging pile of layout {layout.name}")
        self.agvs: dict[int, Agv] = {}
        for i, (cell, soc) in enumerate(zip(cells, socs, strict=True), 1):
            agv = Agv(i, cell, float(soc))
            if cell in pile_at:
                agv.pile = pile_at[cell]
                self.pile_agv[agv.pile.name] = i
            self.agvs[i] = agv
        # orders
        self.orders: dict[int, Order] = {}
        self.queues: dict[str, deque[Order]] = {}  # per shelf, FIFO
        self.active: dict[str, int] = {}  # shelf -> the AGV handling its order
        self.completed: dict[int, float] = {}  # order id -> when its shelf was put down
        self.station_queue: deque[int] = deque()  # AGVs waiting loaded for a station
        self.pile_queue: deque[int] = deque()  # AGVs waiting for a pile
        self.ran_flat: list[tuple[int, float]] = []  # (AGV, time) where a battery hit 0 %
        # Cells no AGV can use now (a stopped AGV stands there, a zone is closed): no slot,
        # station or pile there is chosen, no shelf there is fetched.
        self.blocked: frozenset[Cell] = frozenset()
        self.clock = 0.0
        self.release(orders)

    # -- questions -------------------------------------------------------------------

    @property
    def total(self) -> int:
        return len(self.orders)

    def work_left(self) -> bool:
        """Whether any order is not yet complete."""
        return len(self.completed) < len(self.orders)

    def pending(self) -> list[Order]:
        """Orders not yet assigned, by id."""
        return sorted((o for q in self.queues.values() for o in q), key=lambda o: o.id)

    def status(self, agv: int) -> str:
        return self._agv(agv).status

    def soc(self, agv: int, now: float | None = None) -> float:
        """The AGV's SOC as of its last event, or while it charges as of `now`."""
        a = self._agv(agv)
        if a.phase is Phase.CHARGING and now is not None:
            return self.battery.after_charging(a.soc, max(0.0, now - a.since))
        return a.soc

    def station_available(self, name: str) -> bool:
        return self.station_agv[name] is None

    def vacant_slots(self, blocked: bool = False) -> list[Slot]:
        """Vacant slots an AGV can use now (`blocked`: those it cannot, too)."""
        return [self.slots[n] for n, st in self.slot_state.items()
                if st is SlotState.VACANT and (blocked or self.slots[n].cell not in self.blocked)]

    def free_piles(self) -> list[Pile]:
        return [self.piles[n] for n, a in self.pile_agv.items()
                if a is None and self.piles[n].cell not in self.blocked]

    # -- events ----------------------------------------------------------------------

    def release(self, orders: Iterable[Order]) -> None:
        """Orders join their shelves' FIFO queues (in the given order)."""
        for order in orders:
            if order.shelf not in self.where:
                raise ValueError(f"order {order.id} is for shelf {order.shelf!r}, which "
                                 f"layout {self.layout.name} does not have")
            if order.id in self.orders:
                raise ValueError(f"order id {order.id} is given twice")
            self.orders[order.id] = order
            self.queues.setdefault(order.shelf, deque()).append(order)

    def assign(self, now: float) -> list[Assignment]:
        """Pairs pending orders with available AGVs, greedy global nearest pair: among the
        first pending order of each shelf that stands in a slot with no order in progress,
        and the available AGVs, the pair with the smallest Manhattan distance from the AGV's
        cell to the shelf's slot, ties by order id, then AGV id; repeated until either runs
        out."""
        self._tick(now)
        orders = [q[0] for shelf, q in self.queues.items()
                  if q and shelf not in self.active and self.where[shelf].kind == "slot"
                  and self._slot_of(shelf).cell not in self.blocked]
        agvs = [a for a in self.agvs.values() if a.phase is Phase.IDLE and not a.down]
        made = []
        while orders and agvs:
            best = min(((manhattan(a.cell, self._slot_of(o.shelf).cell), o.id, a.id, o, a)
                        for o in orders for a in agvs), key=lambda t: t[:3])
            distance, _, _, order, agv = best
            orders.remove(order)
            agvs.remove(agv)
            self.queues[order.shelf].popleft()
            self.active[order.shelf] = agv.id
            agv.phase, agv.order = Phase.TO_SHELF, order
            agv.slot = self._slot_of(order.shelf)
            agv.leg_start = now
            charge = None
            if agv.pile is not None:  # it leaves its pile, charged while it stood there
                agv.soc = self.battery.after_charging(agv.soc, max(0.0, now - agv.since))
                self.pile_agv[agv.pile.name] = None
                agv.pile = None
                charge = self._serve_pile_queue(now)
            made.append(Assignment(order, agv.id, agv.slot, distance, charge))
        return made

    def at_shelf(self, agv: int, now: float, driven: float | None = None) -> StationTrip | None:
        """The AGV reached its order's shelf (`driven`: seconds of driving since it was
        assigned; None: all of them). Returns the nearest available packing station from
        the slot, now unavailable; or None: it waits loaded under the slot for one."""
        a = self._event(agv, now, Phase.TO_SHELF, "reach a shelf")
        self._drive(a, now, driven)
        assert a.slot is not None
        a.cell = a.slot.cell
        station = self._nearest(self._free_stations(), a.cell)
        if station is None:
            a.phase, a.since = Phase.WAIT_STATION, now
            self.station_queue.append(a.id)
            return None
        return self._to_station(a, station, now)

    def at_station(self, agv: int, now: float, driven: float | None = None) -> float:
        """The AGV reached its packing station with the shelf. Returns when its dwell ends."""
        a = self._event(agv, now, Phase.TO_STATION, "reach a packing station")
        self._drive(a, now, driven)
        assert a.station is not None and a.order is not None
        a.cell, a.phase, a.since = a.station.cell, Phase.AT_STATION, now
        self.where[a.order.shelf] = Place("station", a.station.name)
        self.station_shelf[a.station.name] = a.order.shelf
        return now + a.station.dwell

    def left_station(self, agv: int, now: float) -> ReturnTrip:
        """The dwell is over: the station is available again and the AGV is sent to the
        nearest vacant slot from the station (ties: lower row, then column), reserved for it.
        An AGV waiting loaded for a station is then served (`served`)."""
        a = self._event(agv, now, Phase.AT_STATION, "leave a packing station")
        assert a.station is not None and a.order is not None
        if now < a.since + a.station.dwell - EPS:
            raise EventError(f"AGV {agv} cannot leave station {a.station.name} at {now}: its "
                             f"{a.station.dwell} s dwell from {a.since} is not over")
        station = a.station
        self.station_agv[station.name] = None
        self.station_shelf[station.name] = None
        self.where[a.order.shelf] = Place("agv", a.id)
        # A vacant slot blocked now (in a closed zone) only if no other is vacant: the AGV
        # then waits for it to open.
        slot = self._nearest(self.vacant_slots(), station.cell) or \
            self._nearest(self.vacant_slots(blocked=True), station.cell)
        if slot is None:
            raise InvariantError(f"no vacant slot for shelf {a.order.shelf} leaving station "
                                 f"{station.name}")
        self.slot_state[slot.name] = SlotState.RESERVED
        self.reserved_by[slot.name] = a.id
        a.phase, a.slot, a.station, a.leg_start = Phase.TO_SLOT, slot, None, now
        served = self._serve_station_queue(now)
        return ReturnTrip(a.id, a.order, slot, manhattan(station.cell, slot.cell), served)

    def returned(self, agv: int, now: float, driven: float | None = None) -> Completion:
        """The AGV put the shelf down in its reserved slot: the order is complete and the AGV
        available under the shelf, unless the charging decision sends it to a pile (or to
        wait for one where it stands)."""
        a = self._event(agv, now, Phase.TO_SLOT, "return a shelf")
        self._drive(a, now, driven)
        assert a.slot is not None and a.order is not None
        order, slot = a.order, a.slot
        if order.id in self.completed:
            raise InvariantError(f"order {order.id} completed twice")
        self.slot_state[slot.name] = SlotState.OCCUPIED
        self.slot_shelf[slot.name] = order.shelf
        del self.reserved_by[slot.name]
        self.where[order.shelf] = Place("slot", slot.name)
        del self.active[order.shelf]
        self.completed[order.id] = now
        a.cell, a.phase, a.order = slot.cell, Phase.IDLE, None
        operational = [(b.id, b.soc) for b in self.agvs.values() if b.status != CHARGING]
        reason = goes_to_charge(self.battery, a.id, a.soc, operational, len(self.agvs))
        if reason is None:
            return Completion(a.id, order, slot, now, None)
        a.charge_reason = reason
        pile = self._nearest(self.free_piles(), a.cell)
        if pile is None:
            a.phase, a.since = Phase.WAIT_PILE, now
            self.pile_queue.append(a.id)
            return Completion(a.id, order, slot, now, None, reason)
        return Completion(a.id, order, slot, now, self._to_pile(a, pile, now))

    def at_pile(self, agv: int, now: float, driven: float | None = None) -> float:
        """The AGV reached its pile and charges. Returns when it is full."""
        a = self._event(agv, now, Phase.TO_PILE, "reach a pile")
        self._drive(a, now, driven)
        assert a.pile is not None
        a.cell, a.phase, a.since = a.pile.cell, Phase.CHARGING, now
        return now + self.battery.time_to_full(a.soc)

    def charged(self, agv: int, now: float) -> None:
        """The AGV is full and rejoins, available, still standing on (and holding) its pile."""
        a = self._event(agv, now, Phase.CHARGING, "finish charging")
        full_at = a.since + self.battery.time_to_full(a.soc)
        if now < full_at - EPS:
            raise EventError(f"AGV {agv} is not full at {now}: it charges until {full_at}")
        a.soc, a.phase, a.charge_reason = FULL, Phase.IDLE, None

    # -- faults: an AGV that cannot move, places that cannot be used --------------------

    def down(self, agv: int, now: float) -> None:
        """The AGV cannot move from now on: it is given no order until it is `up`. A shelf
        it carries stays on it, and its station, slot or pile stay its own."""
        self._tick(now)
        self._agv(agv).down = True

    def give_back(self, agv: int, now: float, driven: float = 0.0) -> Order:
        """The AGV will not fetch its order's shelf (it is down on the way, having driven
        `driven` seconds of it): the order goes back to the front of its shelf's queue, for
        whichever AGV is nearest; the shelf never left its slot."""
        a = self._event(agv, now, Phase.TO_SHELF, "give its order back")
        self._drive(a, now, driven)
        assert a.order is not None
        order = a.order
        self.queues[order.shelf].appendleft(order)
        del self.active[order.shelf]
        a.phase, a.order, a.slot = Phase.IDLE, None, None
        return order

    def up(self, agv: int, now: float, cell: Cell) -> None:
        """The AGV moves again from `cell` (where its trip was cut, if it was on one)."""
        a = self._agv(agv)
        self._tick(now)
        a.down, a.cell = False, cell

    def park(self, agv: int, now: float) -> ChargeTrip | None:
        """An AGV available where it cannot stay (on a lane, its order given to another
        while it was down) goes to the nearest free pile, as if to charge (None: it
        already stands in a slot or on its pile, or no pile is free)."""
        a = self._agv(agv)
        self._tick(now)
        if a.phase is not Phase.IDLE or a.down or a.pile is not None or a.cell in self.slot_at:
            return None
        pile = self._nearest(self.free_piles(), a.cell)
        if pile is None:
            return None
        a.charge_reason = "park"
        return self._to_pile(a, pile, now)

    def retarget(self, agv: int, now: float) -> PackingStation | Slot | Pile | None:
        """The station, slot or pile the AGV heads for is blocked: it heads for the nearest
        free one from where it stands instead, which it now holds (None: none is free, it
        keeps its own and waits for it)."""
        a = self._agv(agv)
        self._tick(now)
        if a.phase is Phase.TO_STATION and a.station is not None:
            station = self._nearest(self._free_stations(), a.cell)
            if station is not None:
                self.station_agv[a.station.name] = None
                self.station_agv[station.name], a.station = a.id, station
            return station
        if a.phase is Phase.TO_SLOT and a.slot is not None:
            slot = self._nearest(self.vacant_slots(), a.cell)
            if slot is not None:
                self.slot_state[a.slot.name] = SlotState.VACANT
                del self.reserved_by[a.slot.name]
                self.slot_state[slot.name], self.reserved_by[slot.name] = SlotState.RESERVED, a.id
                a.slot = slot
            return slot
        if a.phase is Phase.TO_PILE and a.pile is not None:
            pile = self._nearest(self.free_piles(), a.cell)
            if pile is not None:
                self.pile_agv[a.pile.name] = None
                self.pile_agv[pile.name], a.pile = a.id, pile
            return pile
        return None

    def block(self, cells: frozenset[Cell], now: float) -> list[StationTrip | ChargeTrip]:
        """The cells no AGV can use from now on; an AGV waiting for a station or a pile
        that one freed from the block now serves goes there."""
        self._tick(now)
        self.blocked = frozenset(cells)
        served: list[StationTrip | ChargeTrip] = []
        while (trip := self._serve_station_queue(now)) is not None:
            served.append(trip)
        while (pile := self._serve_pile_queue(now)) is not None:
            served.append(pile)
        return served

    # -- the invariant ---------------------------------------------------------------

    def check(self) -> None:
        """Raises InvariantError naming what broke: each shelf in exactly one place (a slot,
        an AGV or a station) and every table agreeing with it; slots, stations and piles held
        by at most one AGV each; every order pending, in progress or complete, once."""
        def fail(msg: str) -> None:
            raise InvariantError(msg)

        seen: dict[str, list[Place]] = {shelf: [] for shelf in self.layout.shelves}
        for name, shelf in self.slot_shelf.items():
            state = self.slot_state[name]
            if (shelf is None) != (state is not SlotState.OCCUPIED):
                fail(f"slot {name} is {state.value} but holds shelf {shelf}")
            if shelf is not None:
                seen.setdefault(shelf, []).append(Place("slot", name))
        for a in self.agvs.values():
            if a.phase in {Phase.TO_STATION, Phase.TO_SLOT}:
                assert a.order is not None
                seen.setdefault(a.order.shelf, []).append(Place("agv", a.id))
        for name, shelf in self.station_shelf.items():
            if shelf is not None:
                seen.setdefault(shelf, []).append(Place("station", name))
        for shelf, places in seen.items():
            if shelf not in self.layout.shelves:
                fail(f"shelf {shelf} is not a shelf of layout {self.layout.name}")
            if len(places) != 1:
                fail(f"shelf {shelf} is in {len(places)} places: "
                     f"{', '.join(str(p) for p in places) or 'none'}")
            if self.where[shelf] != places[0]:
                fail(f"shelf {shelf} is recorded at {self.where[shelf]} but found at "
                     f"{places[0]}")
        reserved = {n for n, st in self.slot_state.items() if st is SlotState.RESERVED}
        heading = {a.slot.name: a.id for a in self.agvs.values()
                   if a.phase is Phase.TO_SLOT and a.slot is not None}
        if reserved != set(heading) or len(heading) != sum(
                a.phase is Phase.TO_SLOT for a in self.agvs.values()):
            fail(f"reserved slots {sorted(reserved)} are not those AGVs head for "
                 f"{sorted(heading)}")
        if self.reserved_by != heading:
            fail(f"slot reservations {self.reserved_by} disagree with the AGVs {heading}")
        holding = {a.station.name: a.id for a in self.agvs.values()
                   if a.phase in {Phase.TO_STATION, Phase.AT_STATION} and a.station}
        if len(holding) != sum(a.phase in {Phase.TO_STATION, Phase.AT_STATION}
                               for a in self.agvs.values()):
            fail("two AGVs hold one packing station")
        taken = {n: a for n, a in self.station_agv.items() if a is not None}
        if taken != holding:
            fail(f"unavailable stations {taken} are not those AGVs hold {holding}")
        on_piles = {a.pile.name: a.id for a in self.agvs.values() if a.pile is not None}
        if len(on_piles) != sum(a.pile is not None for a in self.agvs.values()):
            fail("two AGVs hold one pile")
        if {n: a for n, a in self.pile_agv.items() if a is not None} != on_piles:
            fail(f"pile table disagrees with the AGVs on piles {on_piles}")
        pending = [o.id for q in self.queues.values() for o in q]
        active = [a.order.id for a in self.agvs.values() if a.order is not None]
        ids = pending + active + list(self.completed)
        if sorted(ids) != sorted(self.orders):
            fail("orders lost or counted twice: pending, in progress and complete do not "
                 "make up the released orders once each")
        if {a.order.shelf: a.id for a in self.agvs.values() if a.order} != self.active:
            fail(f"shelves in progress {self.active} disagree with the AGVs' orders")
        for a in self.agvs.values():
            if not 0.0 <= a.soc <= FULL:
                fail(f"AGV {a.id} has SOC {a.soc} outside 0..100 %")

    # -- internals -------------------------------------------------------------------

    def _agv(self, agv: int) -> Agv:
        if agv not in self.agvs:
            raise EventError(f"there is no AGV {agv!r} (AGVs are 1..{len(self.agvs)})")
        return self.agvs[agv]

    def _tick(self, now: float) -> None:
        if now < self.clock - EPS:
            raise EventError(f"event at {now} is before the last one at {self.clock}")
        self.clock = max(self.clock, now)

    def _event(self, agv: int, now: float, phase: Phase, what: str) -> Agv:
        a = self._agv(agv)
        if a.phase is not phase:
            raise EventError(f"AGV {agv} cannot {what}: it is {a.phase.value}, not "
                             f"{phase.value}")
        self._tick(now)
        return a

    def _drive(self, a: Agv, now: float, driven: float | None) -> None:
        leg = now - a.leg_start
        seconds = leg if driven is None else driven
        if seconds < 0 or seconds > leg + EPS:
            raise EventError(f"AGV {a.id} cannot have driven {seconds} s in the {leg} s since "
                             f"its trip began at {a.leg_start}")
        if self.battery.ran_flat(a.soc, seconds):
            self.ran_flat.append((a.id, now))
        a.soc = self.battery.after_driving(a.soc, seconds)

    def _slot_of(self, shelf: str) -> Slot:
        place = self.where[shelf]
        assert place.kind == "slot"
        return self.slots[str(place.at)]

    def _free_stations(self) -> list[PackingStation]:
        return [self.stations[n] for n, a in self.station_agv.items()
                if a is None and self.stations[n].cell not in self.blocked]

    @staticmethod
    def _nearest(places: Iterable[P], cell: Cell) -> P | None:
        """The nearest of `places` (slots, stations or piles) to `cell`, ties by lower row,
        then column; None if there are none."""
        return min(places, key=lambda p: (manhattan(p.cell, cell), _cell_key(p.cell)),
                   default=None)

    def _to_station(self, a: Agv, station: PackingStation, now: float) -> StationTrip:
        """The AGV leaves its slot with the shelf for `station`."""
        assert a.slot is not None and a.order is not None
        waited = now - a.since if a.phase is Phase.WAIT_STATION else 0.0
        self.station_agv[station.name] = a.id
        self.slot_state[a.slot.name] = SlotState.VACANT
        self.slot_shelf[a.slot.name] = None
        self.where[a.order.shelf] = Place("agv", a.id)
        a.phase, a.station, a.leg_start = Phase.TO_STATION, station, now
        return StationTrip(a.id, a.order, station, manhattan(a.slot.cell, station.cell), waited)

    def _to_pile(self, a: Agv, pile: Pile, now: float) -> ChargeTrip:
        assert a.charge_reason is not None
        self.pile_agv[pile.name] = a.id
        a.phase, a.pile, a.leg_start = Phase.TO_PILE, pile, now
        return ChargeTrip(a.id, pile, manhattan(a.cell, pile.cell), a.charge_reason)

    def _serve_pile_queue(self, now: float) -> ChargeTrip | None:
        """The first AGV waiting for a pile goes to the nearest free one, if any is."""
        if not self.pile_queue:
            return None
        waiting = self.agvs[self.pile_queue[0]]
        pile = self._nearest(self.free_piles(), waiting.cell)
        if pile is None:  # the one freed is blocked
            return None
        self.pile_queue.popleft()
        return self._to_pile(waiting, pile, now)

    def _serve_station_queue(self, now: float) -> StationTrip | None:
        """The first AGV waiting loaded for a station goes to the nearest free one, if any
        is."""
        if not self.station_queue:
            return None
        waiting = self.agvs[self.station_queue[0]]
        nearest = self._nearest(self._free_stations(), waiting.cell)
        if nearest is None:  # the one freed is blocked
            return None
        self.station_queue.popleft()
        return self._to_station(waiting, nearest, now)
