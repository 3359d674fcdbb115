"""The reservation service's client: how a process writes the table (a `ReservationWriter`,
as the table itself is in one process) and keeps its `TableMirror` following the service.

Every write is one request the service applies whole or not at all. The requester sends a
request again when its reply is lost, under the same request id, and the store answers a
known id with its first answer, so a retry is never applied twice.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Collection, Sequence
from typing import TypeVar

import zenoh

from fleet.planning.geometry import Cell
from fleet.planning.reservations import (
    INF,
    Amendment,
    Interval,
    ReservationTable,
    TimedRoute,
    WriteResult,
)
from fleet.runtime.bus import Requester, RequestFailed, received, wait_alive
from fleet.wire.convert import (
    amends_to_wire,
    intervals_to_wire,
    route_to_wire,
    snapshot_from_wire,
)
from fleet.wire.protocol import (
    CommitRequest,
    Message,
    ReleaseRequest,
    Reply,
    SnapshotRequest,
    WireChange,
    WireSnapshot,
)
from fleet.wire.topics import Keys
from reservation.mirror import TableMirror

log = logging.getLogger("fleet.mirror")
Answer = TypeVar("Answer", bound=Message)


def wait_for_service(session: zenoh.Session, keys: Keys, timeout_s: float) -> None:
    """Block until the reservation service is up (its liveliness token), or fail naming it."""
    if not wait_alive(session, keys.reservation_alive, timeout_s):
        raise RuntimeError(f"no reservation service on {keys.root} within {timeout_s:g} s")


class ReservationClient:
    """Writes and reads the service under the requester's name (the request key names it,
    and the service lets a forklift change only its own reservations). `now` is the sim time
    the requests carry in their envelopes."""

    def __init__(self, session: zenoh.Session, keys: Keys, requester: Requester,
                 now: Callable[[], float] = lambda: 0.0) -> None:
        self.session = session
        self.keys = keys
        self.requester = requester
        self.now = now

    # -- ReservationWriter ---------------------------------------------------------------------
    def commit(self, vehicle: int, intervals: Sequence[Interval],
               release_from: float | None = None, amends: Sequence[Amendment] = (),
               route: TimedRoute | None = None, *,
               based_on: int | None = None, deadline: float | None = None,
               request_id: str | None = None) -> WriteResult:
        """The table's commit (with `amends`, other vehicles' holdings postponed in the same
        step), and two refusals only the service can make: `based_on`, the table revision a
        task was issued at (refused if the dispatcher has halted the vehicle, or one it
        amends, since); `deadline`, the Unix time after which it is refused. `request_id`
        names the commit (by default a fresh one), so a restarted sender that repeats a
        commit under its old id is answered as before."""
        request = CommitRequest(request_id or self.requester.next_id(), vehicle,
                                intervals_to_wire(intervals), release_from, based_on, deadline,
                                amends_to_wire(amends), route_to_wire(route))
        return self._write(request)

    def release(self, vehicle: int, from_t: float = -INF,
                cells: Collection[Cell] | None = None) -> WriteResult:
        if cells is not None and not cells:  # on the wire, no cells means every cell
            raise ValueError("a release of no cells releases nothing; give None for all")
        return self._write(ReleaseRequest(self.requester.next_id(), vehicle, from_t,
                                          list(cells or [])))

    def _write(self, request: CommitRequest | ReleaseRequest) -> WriteResult:
        reply = self._ask(request, Reply)
        cell = tuple(reply.conflict_cell) if reply.conflict_cell else None
        return WriteResult(reply.ok, reply.revision, reply.reason, reply.conflict_vehicle,
                           cell)

    # -- following -----------------------------------------------------------------------------
    def follow(self, mirror: TableMirror) -> zenoh.Subscriber:
        """Subscribe to the service's changes, then load a snapshot (changes that arrive in
        between wait in the mirror's buffer). Returns the subscriber; undeclare it to stop
        following."""

        def on_sample(sample: zenoh.Sample) -> None:
            message = received(sample, WireChange, log)
            if message is not None:
                mirror.on_change(message)

        subscriber = self.session.declare_subscriber(self.keys.reservation_change, on_sample)
        self.resync(mirror)
        return subscriber

    def table(self) -> ReservationTable:
        """The whole table as the service holds it now."""
        snapshot = self._ask(SnapshotRequest(-1), WireSnapshot)
        return ReservationTable.from_snapshot(snapshot_from_wire(snapshot))

    def resync(self, mirror: TableMirror) -> None:
        """Catch up: a diff when the copy is synced, else the whole table."""
        mirror.load(self._ask(SnapshotRequest(mirror.revision if mirror.synced else -1),
                              WireSnapshot))

    def _ask(self, request: Message, expected: type[Answer]) -> Answer:
        """The service's answer, of the type a request of this kind gets (RequestFailed if
        none comes, or another kind does)."""
        key = self.keys.reservation_request(self.requester.sender)
        reply = self.requester.request(key, request, self.now()).message
        if not isinstance(reply, expected):
            raise RequestFailed(f"{key}: the reservation service answered a {reply.TYPE} to "
                                f"a {request.TYPE}")
        return reply
