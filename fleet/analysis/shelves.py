"""Seed 002's work as the recording shows it: where each shelf went, which orders were
really packed, and whether the dispatcher's announcements agree.

Read from the AGVs' published states (the centre of the body and whether it carries a
shelf) and the layout (each slot holds the shelf of its own name at the start), with this
module's own bookkeeping: nothing of the order book or the engine is used.

- **Lift and drop.** An AGV's `loaded` turning on between two states is a lift, turning off
  a drop. Between the two states the AGV must have stayed on one shelf slot (its centre
  inside that cell, or on its edge): the lift takes the shelf standing there
  (there must be one, and the AGV must carry none); the drop puts the carried shelf there
  (the slot must be vacant). Anything else is a `ShelfFault`.
- **Packing.** A loaded AGV standing on a packing station packs the shelf it carries; it must
  stand there the station's dwell (less two state periods, for the states on either side).
- **Orders.** The mission message lists each order's shelf. A shelf's packings serve its
  orders first in, first out; an order is done when the shelf packed for it is next put
  down in a slot (the paper's makespan ends with the last such drop). An announcement
  (`dispatch.stack`: the shelf and the order) must name a released order and its shelf,
  once, and the order must be done physically.
- **Conservation.** Every shelf is in one place at every instant, by construction of the
  bookkeeping; at the end of a finished mission every shelf stands in a slot.
"""

from __future__ import annotations

import itertools
from collections import Counter, defaultdict
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # the layout is only read, through its attributes
    from fleet.world.layout import Layout, PackingStation

Cell = tuple[int, int]


@dataclass(frozen=True)
class Carrying:
    """One state, as the shelf checks read it: the cell holding the body's centre (None
    on a cell's edge), the cells it passed through since the state before, and whether the
    AGV carries a shelf."""

    vehicle: int
    t: float
    cell: Cell | None
    through: frozenset[Cell]
    loaded: bool
    standing: bool  # at the same position as its state before


@dataclass(frozen=True)
class ShelfFault:
    t: float
    vehicle: int | None  # None: no one AGV's doing
    why: str


@dataclass(frozen=True)
class Announced:
    shelf: str
    order: int
    vehicle: int
    t: float


@dataclass
class OrdersVerdict:
    """The orders of the mission and what became of them (the work verdict of an order
    mission)."""

    expected: int  # orders released
    done: int = 0  # packed, and their shelf put back in a slot
    announced: int = 0  # distinct released orders announced done
    duplicated: list[str] = field(default_factory=list)  # orders announced twice
    lost: list[str] = field(default_factory=list)  # released, not done
    not_served: list[str] = field(default_factory=list)  # announced, not done physically
    misnamed: list[str] = field(default_factory=list)  # announced with another shelf, or
    # an order never released
    shelf_faults: list[ShelfFault] = field(default_factory=list)
    last_done_s: float = 0.0  # the first state showing the last order's shelf put down

    @property
    def passed(self) -> bool:
        return (self.done == self.expected and not self.duplicated and not self.lost
                and not self.not_served and not self.misnamed and not self.shelf_faults)


def orders_verdict(layout: Layout, released: list[str], states: Iterable[Carrying],
                   announced: list[Announced], finished: bool) -> OrdersVerdict:
    """What the states say of the released orders (order i + 1's shelf is `released[i]`)."""
    slots: dict[Cell, str | None] = {tuple(s.cell): s.name for s in layout.slots}
    stations = {tuple(p.cell): p for p in layout.packing}
    faults: list[ShelfFault] = []
    carried: dict[int, str] = {}
    packed: dict[str, list[float]] = defaultdict(list)  # shelf -> packings not yet put back
    done_at: dict[str, list[float]] = defaultdict(list)  # shelf -> drops after a packing
    for event in _events(states, stations):
        t, vehicle, what, cell = event.t, event.vehicle, event.what, event.cell
        if what == "lift":
            shelf = slots.get(cell) if cell is not None else None
            if cell not in slots:
                faults.append(ShelfFault(t, vehicle, f"lifted a shelf away from a slot "
                                                     f"({_where(cell)})"))
            elif vehicle in carried:
                faults.append(ShelfFault(t, vehicle, f"lifted at {_where(cell)} while "
                                                     f"carrying {carried[vehicle]}"))
            elif shelf is None:
                faults.append(ShelfFault(t, vehicle, f"lifted at the vacant slot "
                                                     f"{_where(cell)}"))
            else:
                carried[vehicle], slots[cell] = shelf, None
        elif what == "drop":
            shelf = carried.pop(vehicle, None)
            if shelf is None:
                continue  # a lift already judged wrong
            if cell not in slots:
                faults.append(ShelfFault(t, vehicle, f"put {shelf} down away from a slot "
                                                     f"({_where(cell)})"))
            elif slots[cell] is not None:
                faults.append(ShelfFault(t, vehicle, f"put {shelf} down on {slots[cell]} in "
                                                     f"{_where(cell)}"))
            else:
                slots[cell] = shelf
                done_at[shelf] += [t] * len(packed.pop(shelf, []))
        else:  # a stay at a packing station
            shelf = carried.get(vehicle)
            station = stations[cell]
            if shelf is None:
                continue  # an empty AGV passing or waiting there packs nothing
            if event.span < station.dwell - event.tolerance:
                faults.append(ShelfFault(t, vehicle, f"left packing station {station.name} "
                                                     f"with {shelf} after {event.span:.2f} s, "
                                                     f"before its dwell of {station.dwell} s"))
            else:
                packed[shelf].append(t)
    if finished:
        faults += [ShelfFault(float("inf"), v, f"still carried {shelf} at the end")
                   for v, shelf in sorted(carried.items())]
    return _accounted(released, done_at, announced, faults)


def _accounted(released: list[str], done_at: dict[str, list[float]],
               announced: list[Announced], faults: list[ShelfFault]) -> OrdersVerdict:
    """Each shelf's drops after a packing given to its orders, first in, first out."""
    verdict = OrdersVerdict(len(released), shelf_faults=faults)
    done: dict[int, float] = {}
    queues: dict[str, list[int]] = defaultdict(list)
    for order, shelf in enumerate(released, 1):
        queues[shelf].append(order)
    for shelf, drops in done_at.items():
        orders = queues.get(shelf, [])
        for order, t in zip(orders, drops, strict=False):
            done[order] = t
        if len(drops) > len(orders):
            faults.append(ShelfFault(drops[len(orders)], None, f"{shelf} packed "
                                     f"{len(drops)} times for {len(orders)} orders"))
    names = Counter(a.order for a in announced)
    for a in announced:
        if not 1 <= a.order <= len(released) or released[a.order - 1] != a.shelf:
            verdict.misnamed.append(f"order {a.order} announced for {a.shelf} by AGV "
                                    f"{a.vehicle} at t={a.t:.2f} s")
    good = {a.order for a in announced if 1 <= a.order <= len(released)}
    verdict.done = len(done)
    verdict.announced = len(good)
    verdict.duplicated = [f"order {o}" for o, n in sorted(names.items()) if n > 1]
    verdict.lost = [f"order {o} ({released[o - 1]})" for o in range(1, len(released) + 1)
                    if o not in done]
    verdict.not_served = [f"order {o} ({released[o - 1]})" for o in sorted(good)
                          if o not in done]
    verdict.last_done_s = max(done.values(), default=0.0)
    return verdict


@dataclass(frozen=True)
class _Event:
    t: float
    vehicle: int
    what: str  # "lift", "drop" or "stay" (at a packing station)
    cell: Cell | None
    span: float = 0.0  # a stay's length
    tolerance: float = 0.0  # how much shorter than the truth a stay may be seen


def _events(states: Iterable[Carrying], stations: dict[Cell, PackingStation]
            ) -> list[_Event]:
    """Lifts, drops and stays at packing stations, of every AGV, in time order (at one
    instant: drops before lifts, so a shelf put down can be taken up at once)."""
    by_vehicle: dict[int, list[Carrying]] = defaultdict(list)
    for s in states:
        by_vehicle[s.vehicle].append(s)
    events = []
    for vehicle, seen in by_vehicle.items():
        seen.sort(key=lambda s: s.t)
        stay: list[Carrying] = []
        for before, s in zip([None, *seen], seen, strict=False):
            if before is not None and before.loaded != s.loaded:
                where = next(iter(s.through)) if len(s.through) == 1 else None
                events.append(_Event(s.t, vehicle, "lift" if s.loaded else "drop", where))
            at_station = s.cell in stations and s.standing
            if stay and not (at_station and s.cell == stay[-1].cell and s.loaded):
                events.append(_stay(stay))
                stay = []
            if at_station and s.loaded:
                stay = stay or ([before] if before is not None and before.cell == s.cell
                                else [])
                stay.append(s)
        if stay:
            events.append(_stay(stay))
    order = {"drop": 0, "stay": 1, "lift": 2}
    return sorted(events, key=lambda e: (e.t, order[e.what], e.vehicle))


def _stay(seen: list[Carrying]) -> _Event:
    period = max((b.t - a.t for a, b in itertools.pairwise(seen)), default=0.0)
    return _Event(seen[0].t, seen[0].vehicle, "stay", seen[0].cell, seen[-1].t - seen[0].t,
                  2 * period)


def _where(cell: Cell | None) -> str:
    return "between two cells" if cell is None else f"cell {cell}"
