"""A local copy of the reservation table that follows the service: agents and the dispatcher
plan against it (it is a `ReservationView`) and commit through the service
(reservation/client.py, which also keeps the copy following).

It starts from a snapshot and applies published changes in revision order. Changes that
arrive before the snapshot, or out of order, wait in a buffer; a change older than the copy
is dropped; a gap that the buffer cannot fill makes `needs_resync` true so the owner asks for
a diff (`since_revision`) or a new snapshot.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager

from fleet.planning.reservations import ReservationTable
from fleet.wire.convert import change_from_wire, snapshot_from_wire
from fleet.wire.protocol import WireChange, WireSnapshot, build_message

MAX_BUFFERED = 10_000


class TableMirror:
    """`table` stays the same object for the mirror's life (a snapshot is loaded in place),
    so a planner may be handed the table itself; hold `frozen()` while it reads."""

    def __init__(self) -> None:
        self.table = ReservationTable()
        self.synced = False
        self.needs_resync = False
        self._pending: dict[int, WireChange] = {}
        self._changed = threading.Condition()
        self._frozen = 0

    # -- ReservationView ---------------------------------------------------------------------
    def conflict(self, vehicle: int, cell, t0: float, t1: float) -> int | None:
        return self.table.conflict(vehicle, cell, t0, t1)

    def parked_from(self, vehicle: int, cell) -> float:
        return self.table.parked_from(vehicle, cell)

    def busy(self, vehicle: int, cell, after: float = -math.inf) -> list[tuple[float, float]]:
        return self.table.busy(vehicle, cell, after)

    @property
    def revision(self) -> int:
        return self.table.revision

    # -- following -----------------------------------------------------------------------------
    def load(self, snapshot: WireSnapshot) -> None:
        """A whole snapshot, or a diff (`changes`) on top of the current copy."""
        with self._changed:
            if snapshot.diff:  # an empty diff is "nothing new", not an empty table
                for body in snapshot.changes:
                    change = build_message(WireChange, body)
                    assert isinstance(change, WireChange)
                    self._pending.setdefault(change.revision, change)
            else:
                self.table.load(snapshot_from_wire(snapshot))
            self.synced = True
            self._drain()

    def on_change(self, change: WireChange) -> None:
        with self._changed:
            if change.revision <= self.table.revision and self.synced:
                return  # already in the copy
            self._pending[change.revision] = change
            if self.synced:
                self._drain()
            if len(self._pending) > MAX_BUFFERED:
                self._pending.clear()
                self.needs_resync = True

    @contextmanager
    def frozen(self) -> Iterator[TableMirror]:
        """Hold the copy still (changes wait in the buffer) while a planner reads it: the
        change callback never blocks on a search and a search never sees a half-applied
        change."""
        with self._changed:
            self._frozen += 1
        try:
            yield self
        finally:
            with self._changed:
                self._frozen -= 1
                self._drain()

    def _drain(self) -> None:
        if self._frozen:
            return
        for old in [r for r in self._pending if r <= self.table.revision]:
            del self._pending[old]
        while (change := self._pending.pop(self.table.revision + 1, None)) is not None:
            self.table.apply(change_from_wire(change))
        self.needs_resync = bool(self._pending)  # a gap the buffer cannot fill yet
        self._changed.notify_all()

    def wait_for(self, revision: int, timeout: float) -> bool:
        """Block until the copy has reached `revision` (True) or the timeout passed."""
        return self.wait_until(lambda table: table.revision >= revision, timeout)

    def wait_until(self, predicate: Callable[[ReservationTable], bool], timeout: float) -> bool:
        """Block until `predicate(table)` holds (True) or the timeout passed."""
        with self._changed:
            return self._changed.wait_for(lambda: predicate(self.table), timeout)

