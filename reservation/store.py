"""The reservation service's state machine, without I/O: requests in, replies and published
changes out. Every accepted change is journaled before it is answered; request ids make a
retried request answer the same way without applying twice."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path

from fleet.planning.reservations import Amendment, Change, Interval, ReservationTable, TimedRoute
from fleet.wire.convert import (
    amends_from_wire,
    change_from_wire,
    change_to_wire,
    held_to_wire,
    intervals_from_wire,
    route_from_wire,
    route_to_wire,
)
from fleet.wire.protocol import (
    CommitRequest,
    Message,
    ReleaseRequest,
    Reply,
    SnapshotRequest,
    WireChange,
    WireSnapshot,
    body_of,
)
from reservation.journal import Journal

REMEMBERED_REQUESTS = 100_000  # replies kept for retries (the oldest are forgotten first)


@dataclass
class Outcome:
    reply: Message
    published: list[WireChange] = field(default_factory=list)


class ReservationStore:
    def __init__(self, journal_path: Path | None = None) -> None:
        self.table = ReservationTable()
        self.replies: dict[str, Reply] = {}
        self.journal = Journal(journal_path) if journal_path else None
        self.torn_bytes = 0
        self.log: list[WireChange] = []
        self.halted_at: dict[int, int] = {}  # vehicle -> revision of its last release
        if self.journal is not None:
            replayed = self.journal.replay()
            self.torn_bytes = replayed.torn_bytes
            for change in replayed.changes:
                self._apply(change, change_from_wire(change))

    @property
    def revision(self) -> int:
        return self.table.revision

    def handle(self, message: Message, wall: float = 0.0) -> Outcome:
        """`wall`: the Unix time the request arrived (a commit's deadline is checked
        against it)."""
        if isinstance(message, CommitRequest | ReleaseRequest):
            known = self.replies.get(message.request_id)
            if known is not None:
                return Outcome(known)  # a retry: same answer, nothing applied twice
        if isinstance(message, CommitRequest):
            return self._commit(message, wall)
        if isinstance(message, ReleaseRequest):
            cells = [tuple(c) for c in message.cells] or None
            revision = self.revision + 1
            return self._accept(
                WireChange(revision, "release", message.vehicle, [], message.from_t,
                           message.request_id, cells),
                Change(revision, message.vehicle, message.from_t, (),
                       None if cells is None else frozenset(cells), op="release"))
        if isinstance(message, SnapshotRequest):
            return Outcome(self.snapshot(message.since_revision, message.held_after))
        return Outcome(Reply("", False, self.revision,
                             reason=f"{message.TYPE} is not a request the store answers"))

    def _commit(self, request: CommitRequest, wall: float) -> Outcome:
        try:
            intervals = intervals_from_wire(request.intervals)  # the one validation
            amends = amends_from_wire(request.amends)
            route = route_from_wire(request.route)
        except ValueError as exc:
            return Outcome(Reply(request.request_id, False, self.revision, reason=str(exc)))
        refusal = self._halted_since(request.based_on,
                                     [request.vehicle, *(a.vehicle for a in amends)])
        if not refusal and request.deadline is not None and wall > request.deadline:
            refusal = f"arrived {wall - request.deadline:.3f} s after its deadline (the " \
                f"plan's start has passed)"
        if refusal:  # no conflict: the requester must not replan the same task
            reply = Reply(request.request_id, False, self.revision, reason=refusal)
            self._remember(reply)
            return Outcome(reply)
        if amends:
            return self._amend(request, intervals, amends, route)
        # Only other vehicles' intervals can conflict, so releasing first changes nothing here.
        conflict = self.table.first_conflict(request.vehicle, intervals)
        if conflict is not None:
            reply = Reply(request.request_id, False, self.revision, conflict.other,
                          list(conflict.cell), conflict.reason)
            self._remember(reply)
            return Outcome(reply)
        # Published as requested (decoding made the wire form canonical); the table takes the
        # intervals just validated.
        revision = self.revision + 1
        return self._accept(
            WireChange(revision, "commit", request.vehicle, request.intervals,
                       request.release_from, request.request_id, route=request.route),
            Change(revision, request.vehicle, request.release_from, intervals, route=route))

    def _halted_since(self, based_on: int | None, vehicles: list[int]) -> str:
        """Why a commit issued at table revision `based_on` may no longer change these
        vehicles ("" if it may): the dispatcher has halted one since."""
        for vehicle in vehicles:
            halted = self.halted_at.get(vehicle, -1)
            if based_on is not None and halted > based_on:
                return f"vehicle {vehicle} was halted at revision {halted}, after the " \
                    f"commit's task was issued at revision {based_on}"
        return ""

    def _amend(self, request: CommitRequest, intervals: tuple[Interval, ...],
               amends: tuple[Amendment, ...], route: TimedRoute | None) -> Outcome:
        """A commit that postpones other vehicles' holdings: checked whole, then journaled
        in one write and published as the table's steps (`ReservationTable.amended`). The
        last carries the request's id, so a retry after a lost reply is answered as the
        first time; the others name it as the request they are part of, so a journal cut
        short inside them replays none of them."""
        planned = self.table.amended(request.vehicle, intervals, request.release_from, amends,
                                     route)
        if not isinstance(planned, list):
            reply = Reply(request.request_id, False, self.revision, reason=planned) \
                if isinstance(planned, str) else \
                Reply(request.request_id, False, self.revision, planned.other,
                      list(planned.cell), planned.reason)
            self._remember(reply)
            return Outcome(reply)
        steps = [dataclasses.replace(change_to_wire(c), part_of=request.request_id)
                 for c in planned[:-1]]
        steps.append(dataclasses.replace(change_to_wire(planned[-1]),
                                         request_id=request.request_id))
        if self.journal is not None:
            self.journal.append(*steps)
        for step, change in zip(steps, planned, strict=True):
            self._apply(step, change)
        return Outcome(self.replies[request.request_id], steps)

    def _accept(self, change: WireChange, as_table: Change) -> Outcome:
        if self.journal is not None:
            self.journal.append(change)  # on disk before anyone hears of it
        self._apply(change, as_table)
        return Outcome(self.replies[change.request_id] if change.request_id else
                       Reply("", True, self.revision), [change])

    def _apply(self, change: WireChange, as_table: Change) -> None:
        """`change` and `as_table` are one change, in its wire and its table form."""
        self.table.apply(as_table)
        self.log.append(change)
        if change.op == "release":  # only the dispatcher releases: a freeze (docs/faults.md)
            self.halted_at[change.vehicle] = change.revision
        if change.request_id:
            self._remember(Reply(change.request_id, True, change.revision))

    def _remember(self, reply: Reply) -> None:
        self.replies[reply.request_id] = reply
        if len(self.replies) > REMEMBERED_REQUESTS:
            del self.replies[next(iter(self.replies))]

    def snapshot(self, since: int = -1, held_after: float | None = None) -> WireSnapshot:
        if 0 <= since <= self.revision:  # the log holds every change since revision 0
            return WireSnapshot(self.revision, [], [body_of(c) for c in self.log[since:]],
                                diff=True)
        held = self.table.reservations() if held_after is None else \
            self.table.reservations_after(held_after)
        snap = self.table.snapshot()
        return WireSnapshot(self.revision, held_to_wire(held),
                            routes=[(v, route_to_wire(r)) for v, r in snap.routes])

    def close(self) -> None:
        if self.journal is not None:
            self.journal.close()

