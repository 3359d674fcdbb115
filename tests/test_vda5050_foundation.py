"""The ground issue 22's gateway stands on: the official VDA 5050 2.0.0 schemas check messages,
and a master controller nobody here wrote (vda-5050-lib's MasterController, in Node) sees an AGV
that publishes through a real broker (mosquitto).

The AGV here is no gateway: a paho client that publishes hand-written messages, each checked
with vda5050.schemas.validate before it goes out, and that reads what the master sends."""

from __future__ import annotations

import json
import queue
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from datetime import UTC, datetime
from typing import Any

import paho.mqtt.client as mqtt
import pytest
from master_controller import DEADLINE, Master, running_master

from fleet.errors import UserError
from fleet.runtime.mqtt_broker import mosquitto
from fleet.vda5050.schemas import TOPICS, InvalidMessage, validate

INTERFACE = "uagv"
MANUFACTURER = "fleet-test"
SERIAL = "forklift-1"

Message = dict[str, Any]


def now() -> str:
    return datetime.now(UTC).isoformat(timespec="milliseconds").replace("+00:00", "Z")


def header(header_id: int = 0) -> Message:
    return {"headerId": header_id, "timestamp": now(), "version": "2.0.0",
            "manufacturer": MANUFACTURER, "serialNumber": SERIAL}


def connection(state: str = "ONLINE") -> Message:
    return {**header(), "connectionState": state}


def factsheet() -> Message:
    return {
        **header(),
        "typeSpecification": {
            "seriesName": "fleet-forklift", "agvKinematic": "THREEWHEEL", "agvClass": "FORKLIFT",
            "maxLoadMass": 1000.0, "localizationTypes": ["GRID"],
            "navigationTypes": ["AUTONOMOUS"],
        },
        "physicalParameters": {
            "speedMin": 0.0, "speedMax": 1.0, "accelerationMax": 0.5, "decelerationMax": 0.5,
            "heightMax": 2.0, "width": 1.0, "length": 2.0,
        },
        "protocolLimits": {
            "maxStringLens": {}, "maxArrayLens": {},
            "timing": {"minOrderInterval": 1.0, "minStateInterval": 0.5},
        },
        "protocolFeatures": {
            "optionalParameters": [],
            "agvActions": [{"actionType": "pick", "actionScopes": ["NODE"]},
                           {"actionType": "drop", "actionScopes": ["NODE"]}],
        },
        "agvGeometry": {},
        "loadSpecification": {},
    }


def state() -> Message:
    return {
        **header(), "orderId": "", "orderUpdateId": 0, "lastNodeId": "", "lastNodeSequenceId": 0,
        "nodeStates": [], "edgeStates": [], "driving": False, "paused": False,
        "agvPosition": {"x": 1.5, "y": 2.5, "theta": 0.0, "mapId": "paper",
                        "positionInitialized": True},
        "actionStates": [], "batteryState": {"batteryCharge": 80.0, "charging": False},
        "operatingMode": "AUTOMATIC", "errors": [],
        "safetyState": {"eStop": "NONE", "fieldViolation": False},
    }


def order() -> Message:
    return {
        **header(), "orderId": "o1", "orderUpdateId": 0,
        "nodes": [
            {"nodeId": "n1", "sequenceId": 0, "released": True, "actions": []},
            {"nodeId": "n2", "sequenceId": 2, "released": True,
             "nodePosition": {"x": 3.0, "y": 2.5, "mapId": "paper"},
             "actions": [{"actionId": "a1", "actionType": "pick", "blockingType": "HARD"}]},
        ],
        "edges": [{"edgeId": "e1", "sequenceId": 1, "released": True, "startNodeId": "n1",
                   "endNodeId": "n2", "actions": []}],
    }


def instant_actions() -> Message:
    # the 2.0.0 schema's own spelling: items name `actionName` (see the gap test below)
    return {**header(), "actions": [{"actionId": "i1", "actionName": "startPause",
                                     "blockingType": "HARD"}]}


def visualization() -> Message:
    return {**header(), "agvPosition": {"x": 1.5, "y": 2.5, "theta": 0.0, "mapId": "paper",
                                        "positionInitialized": True},
            "velocity": {"vx": 0.0, "vy": 0.0, "omega": 0.0}}


VALID: dict[str, Callable[[], Message]] = {
    "order": order, "instantActions": instant_actions, "state": state,
    "visualization": visualization, "connection": connection, "factsheet": factsheet,
}


# --- the schemas ---------------------------------------------------------------------------


def test_the_six_topics_of_the_specification():
    assert set(TOPICS) == set(VALID)


@pytest.mark.parametrize("topic", TOPICS)
def test_a_valid_message_of_each_topic_passes(topic):
    validate(topic, VALID[topic]())


@pytest.mark.parametrize(("topic", "spoil", "where", "what"), [
    ("state", lambda m: m["batteryState"].update(batteryCharge="full"),
     "$.batteryState.batteryCharge", "'full' is not of type 'number'"),
    ("order", lambda m: m["nodes"][1].update(sequenceId=2.5),
     "$.nodes[1].sequenceId", "is not of type 'integer'"),
    ("connection", lambda m: m.update(connectionState="UP"),
     "$.connectionState", "'UP' is not one of"),
    ("order", lambda m: m.pop("orderUpdateId"), "$", "'orderUpdateId' is a required property"),
    ("state", lambda m: m["safetyState"].pop("eStop"),
     "$.safetyState", "'eStop' is a required property"),
    ("order", lambda m: m["edges"][0].pop("endNodeId"),
     "$.edges[0]", "'endNodeId' is a required property"),
    ("state", lambda m: m.update(timestamp="2024-05-01T12:00:00"),  # no zone: not RFC 3339
     "$.timestamp", "is not a 'date-time'"),
], ids=["wrong-type", "float-for-integer", "not-in-enum", "missing", "missing-nested",
        "missing-in-array", "timestamp-without-zone"])
def test_an_invalid_message_is_refused_naming_topic_and_field(topic, spoil, where, what):
    message = VALID[topic]()
    spoil(message)
    with pytest.raises(InvalidMessage) as refused:
        validate(topic, message)
    text = str(refused.value)
    assert f"{topic} message at {where}: " in text
    assert what in text
    assert isinstance(refused.value, UserError)  # reaches the user as one line


def test_an_unknown_topic_is_a_user_error():
    with pytest.raises(UserError, match="unknown VDA 5050 topic 'orders'"):
        validate("orders", order())


def test_known_gap_of_the_2_0_0_schema_instant_actions_as_the_text_writes_them():
    """The 2.0.0 text gives instant actions an `actionType`, its schema demands `actionName`
    (2.1.0 fixed it): a gateway that checks inbound instantActions by the 2.0.0 schema alone
    refuses a master that follows the text."""
    message = {**header(), "actions": [{"actionId": "i1", "actionType": "startPause",
                                        "blockingType": "HARD"}]}
    with pytest.raises(InvalidMessage, match=r"\$\.actions\[0\]: 'actionName' is a required"):
        validate("instantActions", message)


# --- a real master controller over a real broker ----------------------------------------------


@dataclass
class FakeAgv:
    """A paho client under uagv/v2/MANUFACTURER/SERIAL: publishes what a test hands it (checked
    by the official schemas first) and collects what the master sends it."""

    client: mqtt.Client
    received: queue.Queue[tuple[str, Message]] = field(default_factory=queue.Queue)
    header_ids: dict[str, int] = field(default_factory=dict)

    @staticmethod
    def topic(name: str) -> str:
        return f"{INTERFACE}/v2/{MANUFACTURER}/{SERIAL}/{name}"

    def publish(self, name: str, message: Message, *, qos: int = 0, retain: bool = False) -> None:
        message = {**message, "headerId": self.header_ids.get(name, 0)}
        self.header_ids[name] = message["headerId"] + 1  # per topic, as the spec says
        validate(name, message)
        info = self.client.publish(self.topic(name), json.dumps(message), qos=qos, retain=retain)
        info.wait_for_publish(timeout=DEADLINE)
        assert info.is_published(), f"{name} not published"

    def next_received(self, name: str) -> Message:
        deadline = time.monotonic() + DEADLINE
        while (left := deadline - time.monotonic()) > 0:
            try:
                topic, message = self.received.get(timeout=left)
            except queue.Empty:
                break
            if topic == self.topic(name):
                return message
        raise AssertionError(f"no {name} from the master within {DEADLINE} s")


@pytest.fixture
def broker(tmp_path) -> Iterator[str]:
    with mosquitto(tmp_path / "broker") as url:
        yield url


@pytest.fixture
def master(broker, tmp_path) -> Iterator[Master]:
    with running_master(broker, tmp_path, MANUFACTURER) as master:
        yield master


@pytest.fixture
def agv(broker) -> Iterator[FakeAgv]:
    host, port = broker.removeprefix("mqtt://").rsplit(":", 1)
    client = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id=f"fake-{SERIAL}")
    fake = FakeAgv(client)
    connected, subscribed = threading.Event(), threading.Event()
    client.on_connect = lambda *_: connected.set()
    client.on_subscribe = lambda *_: subscribed.set()
    client.on_message = lambda _c, _u, m: fake.received.put((m.topic, json.loads(m.payload)))
    # the spec's last will: CONNECTIONBROKEN, retained, should the link die
    will = connection("CONNECTIONBROKEN")
    validate("connection", will)
    client.will_set(fake.topic("connection"), json.dumps(will), qos=1, retain=True)
    client.connect(host, int(port))
    client.loop_start()
    try:
        assert connected.wait(DEADLINE), "the fake AGV did not connect"
        client.subscribe([(fake.topic("order"), 1), (fake.topic("instantActions"), 1)])
        assert subscribed.wait(DEADLINE), "the fake AGV did not subscribe"
        yield fake
    finally:
        client.disconnect()
        client.loop_stop()


def test_the_master_sees_the_agv_online_its_factsheet_and_its_state(master, agv):
    agv.publish("connection", connection("ONLINE"), qos=1, retain=True)
    agv.publish("factsheet", factsheet(), qos=1, retain=True)
    agv.publish("state", state())

    def mine(event: Message) -> bool:
        return event.get("serialNumber") == SERIAL

    online = master.expect("the AGV online",
                           lambda e: e["event"] == "connection" and mine(e))
    assert online["connectionState"] == "ONLINE"
    assert online["manufacturer"] == MANUFACTURER
    sheet = master.expect("the factsheet", lambda e: e["event"] == "factsheet" and mine(e))
    assert sheet["factsheet"]["typeSpecification"]["agvClass"] == "FORKLIFT"
    seen = master.expect("the state", lambda e: e["event"] == "state" and mine(e))
    assert seen["state"]["agvPosition"]["mapId"] == "paper"
    assert seen["state"]["batteryState"] == {"batteryCharge": 80.0, "charging": False}

    master.send(cmd="track", serialNumber=SERIAL, id=1)
    tracked = master.expect("the tracked AGV", lambda e: e["event"] == "tracked")
    assert tracked["connectionState"] == "ONLINE"
    assert not [e for e in master.seen if e["event"] in
                ("dropped", "uncaught", "handlerError", "libraryError", "fatal")]


def test_what_the_master_sends_passes_the_official_schemas(master, agv):
    """Its order as sent is valid by the 2.0.0 schema; its instant actions are too, though
    only because that schema requires no key: vda-5050-lib names the array `instantActions`
    (the 2.0 text: `actions`) and its items carry `actionType`. The gateway must read both."""
    agv.publish("connection", connection("ONLINE"), qos=1, retain=True)
    master.expect("the AGV online", lambda e: e["event"] == "connection")
    wanted = order()
    for key in ("headerId", "timestamp", "version", "manufacturer", "serialNumber"):
        del wanted[key]  # the master fills in the header
    master.send(cmd="order", serialNumber=SERIAL, order=wanted, id=2)
    assigned = master.expect("the order sent", lambda e: e.get("id") == 2)
    assert assigned["event"] == "orderAssigned", assigned
    sent = agv.next_received("order")
    validate("order", sent)
    assert (sent["orderId"], sent["version"], sent["serialNumber"]) == ("o1", "2.0.0", SERIAL)

    pause = {"actionId": "i1", "actionType": "startPause", "blockingType": "HARD"}
    master.send(cmd="instantActions", serialNumber=SERIAL, actions=[pause], id=3)
    initiated = master.expect("the instant actions sent", lambda e: e.get("id") == 3)
    assert initiated["event"] == "instantActionsSent", initiated
    sent = agv.next_received("instantActions")
    validate("instantActions", sent)
    assert "actions" not in sent
    assert sent["instantActions"] == [pause]


def test_the_master_reports_a_message_it_refuses(master, agv):
    """A state of another protocol version is dropped by the library's own validation, and
    master.mjs says so instead of going quiet."""
    agv.publish("connection", connection("ONLINE"), qos=1, retain=True)
    master.expect("the AGV online", lambda e: e["event"] == "connection")
    old = {**state(), "version": "1.1.0"}  # valid by the 2.0.0 schema, which pins no version
    agv.publish("state", old)
    dropped = master.expect("the refused state", lambda e: e["event"] == "dropped")
    assert dropped["mqttTopic"] == agv.topic("state")
    assert "version" in dropped["reason"].lower()
    master.send(cmd="quit")
    master.expect("its stop", lambda e: e["event"] == "stopped")
    assert master.process.wait(timeout=DEADLINE) == 0
