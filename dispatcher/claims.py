"""Forklift ids for agents started without one (`fleet agent --id auto`): the replicas of a
compose service are all alike, so each asks the dispatcher for an id (docs/deployment.md).

The same name (a container's host name, which it keeps across restarts) always gets the same
id back, so a restarted forklift is the forklift it was. Until the fleet is closed, a new name
gets the lowest free id; once the mission starts, only names already known are answered.
"""

from __future__ import annotations

import logging
import threading
import time
from dataclasses import dataclass, field

import zenoh

from fleet.wire.protocol import ClaimReply, ProtocolError, VehicleClaim, decode, encode
from fleet.wire.topics import DISPATCHER, Keys

log = logging.getLogger("fleet.dispatcher")
SENDER = DISPATCHER


@dataclass
class Roster:
    """Who holds which id. Pure: `claim` decides, the Claims server only serves it."""

    limit: int  # no more forklifts than this (the layout's start poses, or --vehicles)
    ids: dict[str, int] = field(default_factory=dict)
    closed: bool = False

    def claim(self, name: str) -> int | str:
        """The id for `name`, or why there is none."""
        if not name:
            return "a claim must name the claimant"
        if name in self.ids:
            return self.ids[name]
        if self.closed:
            return f"the mission has started with {len(self.ids)} forklifts"
        taken = set(self.ids.values())
        free = next((v for v in range(1, self.limit + 1) if v not in taken), None)
        if free is None:
            return f"the fleet is complete: {self.limit} forklifts at most"
        self.ids[name] = free
        return free


class Claims:
    """Serves `dispatch/claim` and gathers the fleet before the mission starts."""

    def __init__(self, session: zenoh.Session, keys: Keys, roster: Roster) -> None:
        self.roster = roster
        self.changed = threading.Condition()
        self.last_claim = 0.0  # monotonic time of the last new claim
        self.queryable = session.declare_queryable(keys.dispatch_claim, self._on_query)

    def _on_query(self, query: zenoh.Query) -> None:
        try:
            message = decode(query.payload.to_bytes() if query.payload else b"").message
        except ProtocolError as exc:
            log.warning("rejected a claim: %s", exc)
            return
        if not isinstance(message, VehicleClaim):
            log.warning("rejected a %s on the claim key", message.TYPE)
            return
        with self.changed:
            known = message.name in self.roster.ids
            answer = self.roster.claim(message.name)
            if isinstance(answer, int) and not known:
                self.last_claim = time.monotonic()
                log.info("forklift %d claimed by %s", answer, message.name)
                self.changed.notify_all()
        reply = ClaimReply(message.request_id, True, answer) if isinstance(answer, int) \
            else ClaimReply(message.request_id, False, reason=answer)
        query.reply(query.key_expr, encode(reply, SENDER, 0, 0.0))

    def gather(self, expected: int | None, quiet_s: float, timeout: float,
               stop: threading.Event) -> list[int]:
        """Wait for `expected` claims, or (None) for claims to stop coming for `quiet_s`
        after the first; then close the fleet. Returns the ids handed out (a closed roster,
        a restarted dispatcher's, at once)."""
        def ready() -> bool:
            n = len(self.roster.ids)
            if self.roster.closed or stop.is_set():
                return True
            if expected is not None:
                return n >= expected
            return n > 0 and time.monotonic() - self.last_claim >= quiet_s

        deadline = time.monotonic() + timeout
        with self.changed:
            while not ready():
                left = deadline - time.monotonic()
                if left <= 0:
                    break
                self.changed.wait(min(left, 0.25))  # also re-checks the quiet time
            self.roster.closed = True
            return sorted(self.roster.ids.values())

    def close(self) -> None:
        self.queryable.undeclare()
