"""The reservation service's state machine, without I/O: requests in, replies and published
changes out. Every accepted change is journaled before it is answered; request ids make a
retried request answer the same way without applying twice."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from fleet.planning.reservations import Change as TableChange
from fleet.planning.reservations import Interval, ReservationTable
from fleet.wire.protocol import (
    Change,
    CommitRequest,
    Message,
    ReleaseRequest,
    Reply,
    Snapshot,
    SnapshotRequest,
    WireInterval,
    body_of,
)
from reservation.journal import Journal

REMEMBERED_REQUESTS = 100_000  # replies kept for retries (the oldest are forgotten first)


def to_intervals(wire: list[WireInterval]) -> tuple[Interval, ...]:
    return tuple(Interval((c, r), t0, t1) for c, r, t0, t1 in wire)


def to_wire(intervals) -> list[WireInterval]:
    return [(iv.cell[0], iv.cell[1], iv.t0, iv.t1) for iv in intervals]


def table_change(change: Change) -> TableChange:
    """A published change as the table applies it."""
    cells = None if change.release_cells is None else \
        frozenset((c, r) for c, r in change.release_cells)
    return TableChange(change.revision, change.vehicle, change.release_from,
                       to_intervals(change.intervals), cells)


def change_time(change: Change) -> float:
    """The sim time a change is about (its publish time in a recording): where it releases
    from, else where its first interval starts."""
    if change.release_from is not None:
        return change.release_from
    return min((iv[2] for iv in change.intervals), default=0.0)


@dataclass
class Outcome:
    reply: Message
    published: list[Change] = field(default_factory=list)


class ReservationStore:
    def __init__(self, journal_path: Path | None = None) -> None:
        self.table = ReservationTable()
        self.replies: dict[str, Reply] = {}
        self.journal = Journal(journal_path) if journal_path else None
        self.torn_bytes = 0
        self.log: list[Change] = []
        self.halted_at: dict[int, int] = {}  # vehicle -> revision of its last release
        if self.journal is not None:
            replayed = self.journal.replay()
            self.torn_bytes = replayed.torn_bytes
            for change in replayed.changes:
                self._apply(change)

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
            change = Change(self.revision + 1, "release", message.vehicle, [],
                            message.from_t, message.request_id,
                            [tuple(c) for c in message.cells] or None)
            return self._accept(change)
        if isinstance(message, SnapshotRequest):
            return Outcome(self.snapshot(message.since_revision))
        return Outcome(Reply("", False, self.revision,
                             reason=f"{message.TYPE} is not a request the store answers"))

    def _commit(self, request: CommitRequest, wall: float) -> Outcome:
        try:
            intervals = to_intervals(request.intervals)
        except ValueError as exc:
            return Outcome(Reply(request.request_id, False, self.revision, reason=str(exc)))
        halted = self.halted_at.get(request.vehicle, -1)
        refusal = ""
        if request.based_on is not None and halted > request.based_on:
            refusal = f"vehicle {request.vehicle} was halted at revision {halted}, after " \
                f"its task's revision {request.based_on}"
        elif request.deadline is not None and wall > request.deadline:
            refusal = f"arrived {wall - request.deadline:.3f} s after its deadline (the " \
                f"plan's start has passed)"
        if refusal:  # no conflict: the requester must not replan the same task
            reply = Reply(request.request_id, False, self.revision, reason=refusal)
            self._remember(reply)
            return Outcome(reply)
        # Only other vehicles' intervals can conflict, so releasing first changes nothing here.
        conflict = self.table.first_conflict(request.vehicle, intervals)
        if conflict is not None:
            reply = Reply(request.request_id, False, self.revision, conflict.other,
                          list(conflict.cell), f"cell {conflict.cell} is held by vehicle "
                          f"{conflict.other} over [{conflict.t0}, {conflict.t1})")
            self._remember(reply)
            return Outcome(reply)
        change = Change(self.revision + 1, "commit", request.vehicle,
                        to_wire(intervals), request.release_from, request.request_id)
        return self._accept(change)

    def _accept(self, change: Change) -> Outcome:
        if self.journal is not None:
            self.journal.append(change)  # on disk before anyone hears of it
        self._apply(change)
        return Outcome(self.replies[change.request_id] if change.request_id else
                       Reply("", True, self.revision), [change])

    def _apply(self, change: Change) -> None:
        self.table.apply(table_change(change))
        self.log.append(change)
        if change.op == "release":  # only the dispatcher releases: a freeze (docs/faults.md)
            self.halted_at[change.vehicle] = change.revision
        if change.request_id:
            self._remember(Reply(change.request_id, True, change.revision))

    def _remember(self, reply: Reply) -> None:
        self.replies[reply.request_id] = reply
        if len(self.replies) > REMEMBERED_REQUESTS:
            del self.replies[next(iter(self.replies))]

    def snapshot(self, since: int = -1) -> Snapshot:
        if 0 <= since <= self.revision:  # the log holds every change since revision 0
            return Snapshot(self.revision, [], [body_of(c) for c in self.log[since:]],
                            diff=True)
        rows = [(r.vehicle, r.cell[0], r.cell[1], r.t0, r.t1)
                for r in self.table.reservations()]
        return Snapshot(self.revision, rows)

    def close(self) -> None:
        if self.journal is not None:
            self.journal.close()

