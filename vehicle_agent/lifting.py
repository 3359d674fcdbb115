"""A seed-004 lifting AGV's agent: one AGV, its own OS process, talking only over zenoh.

It answers the tracker's requests on fleet/<run>/vehicle/<id>/task (dispatcher/remote004.py):
take the next cell from the store before entering it (one commit of [t, forever), which the
store refuses while another AGV holds the cell: the race-free form of the seed's "enter when
the cell's value allows"), let the cell behind go, and plan the leg's path with the improved
A* on the grid values derived from its copy of the store's table (fleet/mission/tracking004.py,
`route`).

The table a plan reads comes with the request: the reservations that hold from the plan's
instant on, as the mission's table has them (the store's, once every request so far is
answered). The agent keeps no copy of its own: a hundred AGVs each decoding every take and
let-go of the fleet cost more than the fleet's driving, and asking the store at each plan
doubled a plan's round trips (docs/benchmarks.md, runtime004).

Zenoh callbacks only enqueue; one worker thread answers, in arrival order.
"""

from __future__ import annotations

import logging
import queue
import time
from collections import Counter
from contextlib import ExitStack

import zenoh

from fleet.mission.tracking004 import RouteQuery, TrackingParams, route
from fleet.planning.reservations import INF, Interval, ReservationTable, Snapshot
from fleet.planning.rules004 import Direction, Task
from fleet.runtime.bus import Requester, RequestFailed, asked, received
from fleet.runtime.lifecycle import Stopped
from fleet.wire.convert import held_from_wire
from fleet.wire.protocol import (
    CellReply,
    CellRequest,
    Message,
    MissionDone,
    RouteReply,
    RouteRequest,
    encode,
)
from fleet.wire.topics import Keys, vehicle_sender
from fleet.world.floor004 import Floor004
from reservation.client import ReservationClient, wait_for_service

log = logging.getLogger("fleet.agent")
MAX_HOLDS_A_CELL = 4  # after a plan's instant: its holder, maybe a zone closing it, ...


class LiftingAgent:
    def __init__(self, session: zenoh.Session, keys: Keys, vehicle: int, floor: Floor004,
                 params: TrackingParams | None = None) -> None:
        self.session, self.keys, self.vehicle = session, keys, vehicle
        self.floor, self.params = floor, params or TrackingParams()
        self.sender = vehicle_sender(vehicle)
        self.now = 0.0  # the instant of the request in hand (its envelopes carry it)
        self.reservations = ReservationClient(session, keys, Requester(session, self.sender),
                                              lambda: self.now)
        self.inbox: queue.Queue[zenoh.Query | zenoh.Sample] = queue.Queue()
        self.seq = 0
        # The last request and its answer: the same request again is answered again.
        self.last: tuple[CellRequest | RouteRequest, Message] | None = None

    def run(self, service_timeout_s: float = 60.0, exit_when_done: bool = False) -> None:
        """Serve until stopped, or (`exit_when_done`) until the mission's result is out."""
        wait_for_service(self.session, self.keys, service_timeout_s)
        with ExitStack() as scope:
            session, keys, put = self.session, self.keys, self.inbox.put
            scope.enter_context(session.declare_queryable(keys.vehicle_task(self.vehicle), put))
            scope.enter_context(session.declare_subscriber(keys.dispatch_done, put))
            scope.enter_context(session.liveliness().declare_token(
                keys.vehicle_alive(self.vehicle)))
            log.info("lifting AGV %d ready", self.vehicle)
            while True:
                item = self.inbox.get()
                if isinstance(item, zenoh.Query):
                    self._answer(item)
                elif exit_when_done and received(item, MissionDone, log) is not None:
                    log.info("AGV %d: the mission is over", self.vehicle)
                    return

    def stop(self) -> None:
        """Stop now, from a signal handler: a commit is one request the service applies
        whole or not at all, so nothing is left half done."""
        raise Stopped("stopped by a signal")

    def _answer(self, query: zenoh.Query) -> None:
        try:
            message = asked(query, (CellRequest, RouteRequest), log)
            if message is None:
                return
            if message.vehicle != self.vehicle:
                query.reply_err(f"a request for AGV {message.vehicle} sent to AGV "
                                f"{self.vehicle}".encode())
                return
            if self.last is not None and self.last[0] == message:
                answer = self.last[1]
            else:
                self.now = message.t
                try:
                    answer = self._cell(message) if isinstance(message, CellRequest) else \
                        self._route(message)
                except (ValueError, RequestFailed) as exc:  # a cell off the floor; no service
                    log.warning("refused %s %s: %s", message.TYPE, message.request_id, exc)
                    query.reply_err(f"refused: {exc}".encode())
                    return
                self.last = (message, answer)
            self.seq += 1
            query.reply(query.key_expr, encode(answer, self.sender, self.seq, message.t))
        finally:
            query.drop()

    def _on_floor(self, *cells: tuple[int, int] | None) -> None:
        for xy in cells:
            if xy is not None and not (0 <= xy[0] < self.floor.width
                                       and 0 <= xy[1] < self.floor.height):
                raise ValueError(f"{xy} is not a cell of {self.floor.name}")

    def _cell(self, request: CellRequest) -> CellReply:
        self._on_floor(request.cell)
        cell = self.floor.cell(request.cell)
        if request.take:
            written = self.reservations.commit(self.vehicle, [Interval(cell, request.t, INF)])
        else:
            written = self.reservations.release(self.vehicle, request.t, [cell])
        return CellReply(request.request_id, written.ok, written.revision, written.reason)

    def _held_table(self, request: RouteRequest) -> ReservationTable:
        """The table a plan reads, as the request brings it: a cell is held by one AGV (or
        a closed zone) at a time, so a cell held more often is no table of this floor (and a
        table of thousands of holds of one cell would take the agent seconds to load)."""
        held = held_from_wire(request.held)
        crowded = [cell for cell, n in Counter(r.cell for r in held).items()
                   if n > MAX_HOLDS_A_CELL]
        if crowded:
            raise ValueError(f"the table sent holds cell {crowded[0]} more than "
                             f"{MAX_HOLDS_A_CELL} times")
        return ReservationTable.from_snapshot(Snapshot(0, held))  # (no revision of its own)

    def _route(self, request: RouteRequest) -> RouteReply:
        self._on_floor(request.start, request.goal, request.home, *request.blocked)
        table = self._held_table(request)
        query = RouteQuery(self.vehicle, request.t, Task(request.task), request.start,
                           request.goal, Direction(request.heading), request.home,
                           request.relaxed, frozenset(request.blocked),
                           frozenset(request.moving), frozenset(request.stagnant))
        started = time.perf_counter()
        cells = route(self.floor, table, query, self.params.costs, self.params.heap)
        spent = time.perf_counter() - started
        return RouteReply(request.request_id, cells is not None, list(cells or ()), spent)
