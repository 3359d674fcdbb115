"""The VDA 5050 verdict of an external session (fleet/analysis/protocol5050.py), on MQTT
traffic written here: valid messages, header ids counting up, every order and action ended."""

from __future__ import annotations

import json
from typing import Any

from fleet.analysis.protocol5050 import protocol_verdict
from fleet.wire.protocol import MqttTraffic


def state(header_id: int, order_id: str = "", nodes: int = 0,
          actions: dict[str, str] | None = None) -> dict[str, Any]:
    return {"headerId": header_id, "timestamp": "2026-12-05T10:00:00.000Z",
            "version": "2.0.0", "manufacturer": "m", "serialNumber": "forklift-1",
            "orderId": order_id, "orderUpdateId": 0, "lastNodeId": "park-1",
            "lastNodeSequenceId": 0,
            "nodeStates": [{"nodeId": f"n{k}", "sequenceId": 2 * k + 2, "released": True}
                           for k in range(nodes)],
            "edgeStates": [{"edgeId": f"e{k}", "sequenceId": 2 * k + 1, "released": True}
                           for k in range(nodes)],
            "driving": False,
            "actionStates": [{"actionId": a, "actionStatus": s}
                             for a, s in (actions or {}).items()],
            "batteryState": {"batteryCharge": 100.0, "charging": False},
            "operatingMode": "AUTOMATIC", "errors": [],
            "safetyState": {"eStop": "NONE", "fieldViolation": False}}


def sent(message: dict[str, Any], vehicle: int = 1, topic: str = "state") -> MqttTraffic:
    return MqttTraffic(vehicle, topic, False, json.dumps(message))


def test_orders_ended_and_header_ids_counting_up_pass():
    verdict = protocol_verdict([
        sent(state(0)),
        MqttTraffic(1, "order", True, "{not json"),  # the master's: counted, not held against
        sent(state(1, "o1", nodes=1, actions={"a": "RUNNING"})),
        sent(state(2, "o1", actions={"a": "FINISHED"})),
        sent(state(3, "o2", actions={"b": "FAILED"})),
        sent(state(0), vehicle=2),
    ])
    assert verdict.passed, verdict
    assert (verdict.sent, verdict.received, verdict.received_refused, verdict.orders) == \
        (5, 1, 1, 2)


def test_an_order_replaced_while_open_and_an_action_never_ended_fail():
    verdict = protocol_verdict([sent(state(0, "o1", nodes=1, actions={"a": "WAITING"})),
                                sent(state(1, "o2", actions={"b": "RUNNING"}))])
    assert verdict.orders_open == ["forklift-1 o1", "forklift-1 o2"]
    assert verdict.actions_open == ["forklift-1 a WAITING", "forklift-1 b RUNNING"]
    assert not verdict.passed


def test_a_header_id_that_does_not_count_up_and_an_invalid_message_fail():
    bad = state(2)
    del bad["driving"]
    verdict = protocol_verdict([sent(state(1)), sent(state(1)), sent(bad)])
    assert verdict.header_faults == ["forklift-1 state: headerId 1 after 1"]
    assert len(verdict.invalid_sent) == 1 and not verdict.passed
