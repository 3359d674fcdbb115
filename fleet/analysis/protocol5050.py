"""The VDA 5050 verdict of an external session, from the MQTT traffic its recording holds
(the gateway's copy of every message it sent and took, `MqttTraffic`), with this module's own
reading of the messages (nothing of the gateway's order book):

- **valid**: every message the vehicles sent passes the official 2.0.0 schema;
- **header ids**: on each vehicle's topic, the headerIds sent count up;
- **orders ended**: every order a vehicle's states carry ends executed or cancelled before
  the next order or the end of the session: its last state has no node or edge left and
  every action FINISHED or FAILED;
- **actions ended**: every action a state ever listed (order and instant) reaches FINISHED or
  FAILED.

What the master sent that was refused (not JSON, invalid, addressed elsewhere) is counted,
not held against the vehicles: answering it with an error is their job.
"""

from __future__ import annotations

import json
from collections.abc import Iterable
from dataclasses import dataclass, field

from fleet.vda5050.messages import serial_number
from fleet.vda5050.schemas import InvalidMessage, validate
from fleet.wire.protocol import MqttTraffic

ENDED = ("FINISHED", "FAILED")


@dataclass(frozen=True)
class ProtocolVerdict:
    sent: int
    received: int
    received_refused: int  # the master's messages that were not valid
    invalid_sent: list[str] = field(default_factory=list)
    header_faults: list[str] = field(default_factory=list)
    orders: int = 0
    orders_open: list[str] = field(default_factory=list)
    actions_open: list[str] = field(default_factory=list)

    @property
    def passed(self) -> bool:
        return not (self.invalid_sent or self.header_faults or self.orders_open
                    or self.actions_open)

    def line(self, mark: str) -> str:
        return (f"vda5050            {mark}: {self.sent} messages sent, {self.received} "
                f"received ({self.received_refused} refused), {len(self.invalid_sent)} "
                f"invalid sent, {len(self.header_faults)} header ids out of order, "
                f"{self.orders - len(self.orders_open)} of {self.orders} orders ended, "
                f"{len(self.actions_open)} actions left open")


def protocol_verdict(traffic: Iterable[MqttTraffic], kind: str = "forklift") -> ProtocolVerdict:
    """The VDA 5050 verdict of a session's MQTT traffic, its vehicles named as their serial
    numbers say (`kind`-N)."""
    sent = received = refused = 0
    invalid: list[str] = []
    headers: list[str] = []
    last_id: dict[tuple[int, str], int] = {}
    runs: dict[int, list[tuple[str, dict]]] = {}  # vehicle: (orderId, its last state) in turn
    actions: dict[tuple[int, str], str] = {}  # (vehicle, actionId): its latest status
    for t in traffic:
        where = f"{serial_number(kind, t.vehicle)} {t.topic}"
        message = _json(t.payload)
        if t.received:
            received += 1
            if message is None or not _valid(t.topic, message):
                refused += 1
            continue
        sent += 1
        if message is None or not _valid(t.topic, message):
            invalid.append(f"{where}: {t.payload[:80]}")
            continue
        header = message["headerId"]
        before = last_id.get((t.vehicle, t.topic))
        if before is not None and header <= before:
            headers.append(f"{where}: headerId {header} after {before}")
        last_id[(t.vehicle, t.topic)] = header
        if t.topic != "state":
            continue
        order_id = message["orderId"]
        states = runs.setdefault(t.vehicle, [])
        if order_id and (not states or states[-1][0] != order_id):
            states.append((order_id, message))
        elif order_id:
            states[-1] = (order_id, message)
        for a in message["actionStates"]:
            actions[(t.vehicle, a["actionId"])] = a["actionStatus"]
    open_orders = [f"{serial_number(kind, v)} {order_id}" for v, states in runs.items()
                   for order_id, last in states if not _ended(last)]
    open_actions = [f"{serial_number(kind, v)} {a} {status}" for (v, a), status in actions.items()
                    if status not in ENDED]
    return ProtocolVerdict(sent, received, refused, invalid, headers,
                           sum(len(s) for s in runs.values()), open_orders, open_actions)


def _ended(state: dict) -> bool:
    return not state["nodeStates"] and not state["edgeStates"] and all(
        a["actionStatus"] in ENDED for a in state["actionStates"])


def _json(text: str) -> dict | None:
    try:
        message = json.loads(text)
    except ValueError:
        return None
    return message if isinstance(message, dict) else None


def _valid(topic: str, message: dict) -> bool:
    try:
        validate(topic, message)
    except InvalidMessage:
        return False
    return True
