"""The reservation service process: the authoritative space-time reservation table on zenoh.

A queryable on fleet/<run>/reservation/request answers commits, releases and snapshot
requests; every accepted change is journaled, then answered, then published on
fleet/<run>/reservation/change. Queries are handed from zenoh's callback thread to one worker
through a queue (no blocking zenoh call inside a callback), so requests are served one at a
time in arrival order: the table needs no locks and a commit is atomic.
"""

from __future__ import annotations

import logging
import queue
import socket
import threading
import time
from collections.abc import Sequence
from contextlib import ExitStack
from pathlib import Path

import zenoh

from fleet.runtime.bus import Stream, open_session, received
from fleet.runtime.lifecycle import process_main, stop_on_signals
from fleet.runtime.process_configs import ReservationConfig
from fleet.wire.convert import change_time
from fleet.wire.protocol import (
    CommitRequest,
    MissionDone,
    ProtocolError,
    ReleaseRequest,
    Reply,
    WireChange,
    decode,
    encode,
)
from fleet.wire.topics import RESERVATION, Keys, vehicle_of
from reservation.store import ReservationStore

log = logging.getLogger("fleet.reservation")
SENDER = RESERVATION


class ReservationService:
    def __init__(self, store: ReservationStore, session: zenoh.Session, keys: Keys) -> None:
        self.store = store
        self.session = session
        self.keys = keys
        self.inbox: queue.Queue[zenoh.Query | None] = queue.Queue()
        self.seq = 0
        self.rejected = 0

    def run(self) -> None:
        with Stream(self.session, self.keys.reservation_change, SENDER,
                    reliable=True) as publisher, \
                self.session.declare_queryable(self.keys.reservation_request("*"),
                                               self.inbox.put), \
                self.session.liveliness().declare_token(self.keys.reservation_alive):
            log.info("serving %s at revision %d", self.keys.reservation_request("*"),
                     self.store.revision)
            while (query := self.inbox.get()) is not None:
                for change in self.answer(query):
                    publisher.put(change, change_time(change))

    def answer(self, query: zenoh.Query) -> list[WireChange]:
        """Reply to one query; the changes to publish."""
        try:
            payload = query.payload.to_bytes() if query.payload is not None else b""
            try:
                envelope = decode(payload)
            except ProtocolError as exc:
                self.rejected += 1
                log.warning("rejected a request on %s: %s", query.key_expr, exc)
                query.reply(query.key_expr, self._encode(
                    Reply("", False, self.store.revision, reason=f"malformed request: {exc}")))
                return []
            refusal = not_theirs(str(query.key_expr), envelope.message)
            if refusal:
                self.rejected += 1
                log.warning("refused a request on %s: %s", query.key_expr, refusal)
                query.reply(query.key_expr, self._encode(
                    Reply(getattr(envelope.message, "request_id", ""), False,
                          self.store.revision, reason=refusal)))
                return []
            outcome = self.store.handle(envelope.message, time.time())
            query.reply(query.key_expr, self._encode(outcome.reply))
            return outcome.published
        finally:
            query.drop()

    def _encode(self, message) -> bytes:  # replies; the change stream counts its own
        self.seq += 1
        return encode(message, SENDER, self.seq, 0.0)

    def stop(self) -> None:
        # From a signal handler in the main thread, which may be inside inbox.get holding the
        # queue's lock: put from another thread, or it could wait on itself.
        threading.Thread(target=self.inbox.put, args=(None,), daemon=True).start()


def not_theirs(key: str, message) -> str:
    """Why the principal the key names may not make this request ("" if it may): a vehicle
    commits and releases only its own reservations (access control keeps it to its key).
    Its commit may amend other vehicles' holdings, which the store allows only as a
    postponement of what they hold (`ReservationTable.amended`)."""
    who = Keys.reservation_request.sender_on(key)
    vehicle = vehicle_of(who) if who is not None else None
    if vehicle is not None and isinstance(message, CommitRequest | ReleaseRequest) and \
            message.vehicle != vehicle:
        return f"{who} may change only its own reservations, not vehicle {message.vehicle}'s"
    return ""


def main(argv: Sequence[str] | None = None) -> int:
    return process_main(ReservationConfig, serve, "python -m reservation", argv)


def serve(config: ReservationConfig) -> int:
    journal = Path(str(config.journal).replace("{host}", socket.gethostname()))
    journal.parent.mkdir(parents=True, exist_ok=True)
    with ExitStack() as scope:
        store = ReservationStore(journal)
        scope.callback(store.close)
        if store.torn_bytes:
            log.warning("cut a torn last record (%d bytes) off %s", store.torn_bytes, journal)
        session = scope.enter_context(open_session(config.bus.config()))
        keys = Keys(config.bus.run)
        service = ReservationService(store, session, keys)
        stop_on_signals(service.stop)
        if config.exit_when_done:
            scope.enter_context(session.declare_subscriber(
                keys.dispatch_done,
                lambda sample: service.stop() if received(sample, MissionDone, log) else None))
        service.run()
    return 0
