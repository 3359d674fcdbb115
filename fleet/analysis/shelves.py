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
- **Windows without a recorder.** What an AGV did between two states further apart than
  the state period (no recorder ran) is taken on the dispatcher's word: the trips it
  announced ending in the window (`Claim`: a fetch lifts its shelf, a packing whose dwell
  ended there packs, a stow puts the shelf in its slot), squared with what the state after
  shows (carrying or not). A packing the states saw only in part is taken as done. The
  orders whose shelves were moved so are listed as `unverified`, not failed. Where the word
  is missing too, `_Shelves` names a shelf lifted unseen by the first move that contradicts
  it, and an order not seen done that may have been done unseen is `unseen`, not lost. An
  AGV that is down says nothing but stands where its halt says: the caller gives those
  instants as states too.
"""

from __future__ import annotations

import itertools
import math
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
    unseen: bool = False  # its states just before are not known (no recorder ran then)


@dataclass(frozen=True)
class Claim:
    """A trip as the dispatcher announced it (dispatch/subtask): the word the check takes
    where the AGV's own states were not recorded."""

    vehicle: int
    kind: str  # "fetch", "pack", "stow" or "charge"
    target: str  # the shelf, station, slot or pile
    t_end: float  # arrived (a fetch lifts, a stow puts down then)
    t_done: float  # left (a packing's dwell ends then)


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
    unverified: list[str] = field(default_factory=list)  # done on the dispatcher's word
    unseen: list[str] = field(default_factory=list)  # not seen done: their shelves moved
    # where neither a state nor the dispatcher's recorded word says

    @property
    def passed(self) -> bool:
        return (self.done + len(self.unseen) == self.expected and not self.duplicated
                and not self.lost and not self.not_served and not self.misnamed
                and not self.shelf_faults)


def orders_verdict(layout: Layout, released: list[str], states: Iterable[Carrying],
                   announced: list[Announced], finished: bool,
                   claims: Iterable[Claim] = ()) -> OrdersVerdict:
    """What the states say of the released orders (order i + 1's shelf is `released[i]`)."""
    stations = {tuple(p.cell): p for p in layout.packing}
    book = _Shelves({tuple(s.cell): s.name for s in layout.slots},
                    {s.name: tuple(s.cell) for s in layout.slots},
                    min((p.dwell for p in layout.packing), default=math.inf))
    faults: list[ShelfFault] = []
    for event in _events(states, stations, claims):
        t, vehicle, what, cell = event.t, event.vehicle, event.what, event.cell
        if event.word or what == "gap":
            book.taken_on_word(event)
        elif what == "lift":
            if cell not in book.slots:
                faults.append(ShelfFault(t, vehicle, f"lifted a shelf away from a slot "
                                                     f"({_where(cell)})"))
            elif vehicle in book.carried:
                faults.append(ShelfFault(t, vehicle, f"lifted at {_where(cell)} while "
                                                     f"carrying {book.carried[vehicle]}"))
            elif book.slots[cell] is None and not book.astray:  # each astray excuses one
                faults.append(ShelfFault(t, vehicle, f"lifted at the vacant slot "
                                                     f"{_where(cell)}"))
            else:
                book.lift(vehicle, cell)
        elif what == "drop":
            shelf = book.carried.get(vehicle)
            if shelf is None:
                continue  # a lift already judged wrong
            if cell not in book.slots:
                faults.append(ShelfFault(t, vehicle, f"put {shelf} down away from a slot "
                                                     f"({_where(cell)})"))
                del book.carried[vehicle]
            elif book.slots[cell] is not None and not book.unknown:  # each unknown: one
                faults.append(ShelfFault(t, vehicle, f"put {shelf} down on {book.slots[cell]} "
                                                     f"in {_where(cell)}"))
                del book.carried[vehicle]
            else:
                book.drop(vehicle, cell, t)
        else:  # a stay at a packing station
            shelf = book.carried.get(vehicle)
            station = stations[cell]
            if shelf is None:
                continue  # an empty AGV passing or waiting there packs nothing
            if event.unseen and event.span < station.dwell - event.tolerance:
                book.pack(shelf, t, on_word=True)  # the rest of its dwell was unseen
            elif event.span < station.dwell - event.tolerance:
                faults.append(ShelfFault(t, vehicle, f"left packing station {station.name} "
                                                     f"with {shelf} after {event.span:.2f} s, "
                                                     f"before its dwell of {station.dwell} s"))
            else:
                book.pack(shelf, t)
    if finished:
        faults += [ShelfFault(float("inf"), v, f"still carried {shelf} at the end")
                   for v, shelf in sorted(book.carried.items())
                   if shelf not in book.on_word and shelf not in book.unknown]
    named = {shelf: drops for shelf, drops in book.done_at.items() if shelf not in book.unknown}
    verdict = _accounted(released, named, announced, faults)
    # An order not seen done may have been done unseen if its shelf moved unseen; or, as
    # many as the packings the windows nobody said anything of could hold, if its shelf was
    # never seen to move.
    shelf_of = {f"order {o} ({s})": s for o, s in enumerate(released, 1)}
    moved = [o for o, shelf in shelf_of.items() if shelf in book.on_word]
    never = [o for o in verdict.lost if o not in moved and shelf_of[o] not in book.lifted]
    verdict.unverified = [o for o in moved if o not in verdict.lost]
    verdict.unseen = [o for o in verdict.lost if o in moved] + never[:book.hidden_packings]
    verdict.lost = [o for o in verdict.lost if o not in verdict.unseen]
    verdict.not_served = [o for o in verdict.not_served if o not in verdict.unseen]
    return verdict


@dataclass
class _Shelves:
    """Where every shelf is, as far as the recording tells. A window no state or trip
    explains leaves a shelf of unknown name on an AGV (`unknown`) or a known one put down at
    an unknown slot (`astray`); the first seen move that contradicts the book names it, so
    each excuses one contradiction at most: a shelf put down on a slot the book says is full
    names that slot's shelf as the AGV's own unknown one, else the oldest; a shelf lifted at
    a slot the book says is vacant is the astray one whose home it is, else the oldest."""

    slots: dict[Cell, str | None]  # what each slot holds
    homes: dict[str, Cell]  # each slot's cell by its name
    min_dwell: float  # the shortest packing: a window shorter cannot hide one
    carried: dict[int, str] = field(default_factory=dict)
    packed: dict[str, list[float]] = field(default_factory=lambda: defaultdict(list))
    done_at: dict[str, list[float]] = field(default_factory=lambda: defaultdict(list))
    on_word: set[str] = field(default_factory=set)  # shelves an unseen move moved
    unknown: list[str] = field(default_factory=list)
    astray: list[str] = field(default_factory=list)
    lifted: set[str] = field(default_factory=set)  # shelves seen or said to move
    hidden_packings: int = 0  # packings the windows nobody said anything of could hold

    def lift(self, vehicle: int, cell: Cell) -> None:
        if self.slots[cell] is None:  # a shelf put down unseen: the one at home here first
            home = [s for s in self.astray if self.homes.get(s) == cell]
            self.slots[cell] = (home or self.astray)[0]
            self.astray.remove(self.slots[cell])
            self.on_word.add(self.slots[cell])
        self.carried[vehicle], self.slots[cell] = self.slots[cell], None
        self.lifted.add(self.carried[vehicle])

    def drop(self, vehicle: int, cell: Cell, t: float) -> None:
        occupant, self.slots[cell] = self.slots[cell], None
        own = self.carried[vehicle]
        home = [s for s in self.astray if self.homes.get(s) == cell]
        if occupant is not None:  # it was lifted unseen: the AGV's own unknown one first
            unknown = own if own in self.unknown else self.unknown[0]
            self.unknown.remove(unknown)
            self._name(unknown, occupant)
        elif own in self.unknown and home:  # an unknown one put down at an astray one's home
            self.unknown.remove(own)
            self.astray.remove(home[0])
            self._name(own, home[0])
        shelf = self.carried.pop(vehicle)
        self.slots[cell] = shelf
        self.done_at[shelf] += [t] * len(self.packed.pop(shelf, []))

    def pack(self, shelf: str, t: float, on_word: bool = False) -> None:
        self.packed[shelf].append(t)
        if on_word:
            self.on_word.add(shelf)

    def taken_on_word(self, event: _Event) -> None:
        """A trip's end in a window the AGV's states were not recorded in, as the
        dispatcher announced it; at the window's end ("gap"), what the state after it shows
        carried."""
        vehicle, what = event.vehicle, event.what
        shelf = self.carried.get(vehicle)
        if what == "lift" and shelf is None:
            cell = next((c for c, there in self.slots.items() if there == event.word), None)
            if cell is not None:
                self.lift(vehicle, cell)
            else:  # the book lost it: it is no longer where it was thought to be
                self.carried[vehicle] = event.word
                self.lifted.add(event.word)
                if event.word in self.astray:
                    self.astray.remove(event.word)
            self.on_word.add(event.word)
        elif what == "pack" and shelf is not None:
            self.pack(shelf, event.t, on_word=True)
        elif what == "drop" and shelf is not None:
            self.on_word.add(shelf)
            cell = self.homes.get(event.word)
            if cell is not None and self.slots[cell] is None:
                self.drop(vehicle, cell, event.t)
            else:
                self.astray.append(self.carried.pop(vehicle))
        elif what == "gap":
            unsaid = not event.explained
            if unsaid:
                self.hidden_packings += int(event.span // self.min_dwell)
            if event.loaded and shelf is None:
                self.carried[vehicle] = f"an unseen shelf (AGV {vehicle}, t={event.t:.2f} s)"
                self.unknown.append(self.carried[vehicle])
            elif not event.loaded and shelf is not None:
                self.on_word.add(shelf)  # put down where no state or trip says
                self.astray.append(self.carried.pop(vehicle))
            elif shelf is not None and unsaid and event.span >= self.min_dwell:
                self.on_word.add(shelf)  # carried through: it may have been packed unseen,
                if event.loaded:  # or put down, and another taken up: known no longer
                    self.astray.append(shelf)
                    self.carried[vehicle] = f"an unseen shelf (AGV {vehicle}, t={event.t:.2f} s)"
                    self.unknown.append(self.carried[vehicle])

    def _name(self, unknown: str, shelf: str) -> None:
        """The unknown shelf is `shelf`: it is where the unknown one is, with its history."""
        self.on_word.add(shelf)
        for vehicle, there in self.carried.items():
            if there == unknown:
                self.carried[vehicle] = shelf
        for cell, there in self.slots.items():
            if there == unknown:
                self.slots[cell] = shelf
        for book in (self.packed, self.done_at):
            if unknown in book:
                book[shelf] += book.pop(unknown)


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
    what: str  # "lift", "drop", "stay" (at a packing station) or "gap" (states unseen)
    cell: Cell | None
    span: float = 0.0  # a stay's length, a gap's
    tolerance: float = 0.0  # how much shorter than the truth a stay may be seen
    unseen: bool = False  # a stay next to a window the AGV's states were not recorded in
    loaded: bool = False  # carrying at a gap's end
    explained: bool = False  # a gap some announced trip ended in
    word: str = ""  # taken on the dispatcher's word: the shelf lifted, the slot put into,
    # the station packed at


def _events(states: Iterable[Carrying], stations: dict[Cell, PackingStation],
            claims: Iterable[Claim]) -> list[_Event]:
    """Lifts, drops and stays at packing stations, of every AGV, in time order (at one
    instant: drops before lifts, so a shelf put down can be taken up at once); in a window
    the AGV's states were not recorded in, its trips that ended there, at their ends."""
    by_vehicle: dict[int, list[Carrying]] = defaultdict(list)
    for s in states:
        by_vehicle[s.vehicle].append(s)
    said: dict[int, list[Claim]] = defaultdict(list)
    for c in sorted(claims, key=lambda c: c.t_end):
        said[c.vehicle].append(c)
    events = []
    for vehicle, seen in by_vehicle.items():
        seen.sort(key=lambda s: s.t)
        stay: list[Carrying] = []
        for before, s in zip([None, *seen], seen, strict=False):
            if before is not None and s.unseen:
                trips = _trips_unseen(said[vehicle], before.t, s.t)
                events += trips
                events.append(_Event(s.t, vehicle, "gap", None, s.t - before.t,
                                     loaded=s.loaded, explained=bool(trips)))
            elif before is not None and before.loaded != s.loaded:
                where = next(iter(s.through)) if len(s.through) == 1 else None
                events.append(_Event(s.t, vehicle, "lift" if s.loaded else "drop", where))
            at_station = s.cell in stations and s.standing
            if stay and not (at_station and s.cell == stay[-1].cell and s.loaded):
                events.append(_stay(stay, cut=s.unseen))
                stay = []
            if at_station and s.loaded:
                stay = stay or ([before] if before is not None and before.cell == s.cell
                                else [])
                stay.append(s)
        if stay:
            events.append(_stay(stay))
    # At one instant: the trips taken on word, then what a window's end shows, then what
    # the states show.
    order = {"drop": 0, "pack": 1, "stay": 1, "lift": 2, "gap": 0}
    return sorted(events, key=lambda e: (e.t, 0 if e.word else 1 if e.what == "gap" else 2,
                                         order[e.what], e.vehicle))


def _trips_unseen(claims: list[Claim], since: float, until: float) -> list[_Event]:
    """The trips announced as ending in (since, until] as events: a fetch lifts its shelf, a
    stow puts it into its slot, a packing whose dwell also ended there packs (one seen in
    part is a stay's to judge)."""
    what = {"fetch": "lift", "stow": "drop", "pack": "pack"}
    return [_Event(c.t_end, c.vehicle, what[c.kind], None, word=c.target) for c in claims
            if since < c.t_end <= until and c.kind in what
            and (c.kind != "pack" or c.t_done <= until)]


def _stay(seen: list[Carrying], cut: bool = False) -> _Event:
    """A stay at a packing station; `cut`: the states after it were not recorded, so it may
    have gone on unseen (as one that began unseen may have begun earlier)."""
    period = max((b.t - a.t for a, b in itertools.pairwise(seen)), default=0.0)
    return _Event(seen[0].t, seen[0].vehicle, "stay", seen[0].cell, seen[-1].t - seen[0].t,
                  2 * period, unseen=cut or seen[0].unseen)


def _where(cell: Cell | None) -> str:
    return "between two cells" if cell is None else f"cell {cell}"
