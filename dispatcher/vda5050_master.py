"""`fleet run --dispatch vda5050`: the dispatcher as a VDA 5050 master. The engine decides
as it always does (rank, Algorithm 1, scores, MLP); each subtask it decides goes to the
forklift as a VDA 5050 order over MQTT, through the gateway, and the forklift drives it as
it drives any master's order (its agent plans the edge with its own planner against the
reservation store and commits it).

Each forklift has one order for the whole mission, `mission-N`, and each subtask is a release
of it, every one after the first an update stitched at the node the last one ended on
(6.6.2): one edge to the subtask's node, `drop` on a stack and `pick` at a station in a
fill mission, the other way round in an empty one. The
gateway has the edge planned once the forklift stands ready to drive it (the last node's
action done), so a leg starts a little after the engine's decision instant, and the end time
is the direct run's only within a tolerance (docs/vda5050.md). A fill mission starts every
forklift with goods on its forks (the engine's model: claimed before the start), an empty
one every stack full, and so does the gateway of such a run; the engine holds the stacks'
goods in the store, as in the direct run (the gateway holds them only for an outside master,
and leaves the question which way is open to the engine, which planned it).

What a master cannot learn over MQTT, the leg's times (VDA 5050 2.0.0 states carry none),
comes from the gateway's `vda5050/N/leg` (LegCommitted), so the engine goes on from the very
trajectory the forklift drives. A subtask's goals are poses; the master orders the node of
the one the forklift's own planner would reach, planning it on its copy of the reservation
table first (a master plans its routes): a subtask it cannot plan is a plan failure, as in
the direct run, and no order goes out.
"""

from __future__ import annotations

import json
import logging
import os
import queue
import threading
import time
from dataclasses import dataclass
from typing import Any

import paho.mqtt.client as mqtt
import zenoh

from dispatcher.liveness import Liveness, ParticipantLost
from dispatcher.remote import RemoteExecutor
from fleet.dispatching.decision import TaskKind
from fleet.mission.seam import Task
from fleet.mission.spec import MissionKind
from fleet.planning.trajectory import FailureReason, PlanFailure, Pose, Trajectory
from fleet.runtime.argtypes import mqtt_host_port
from fleet.runtime.process_configs import GatewayConfig
from fleet.vda5050.map import PARK, Node, nodes, released_order
from fleet.vda5050.messages import Headers
from fleet.vda5050.schemas import InvalidMessage, validate
from fleet.wire.convert import leg_from_wire
from fleet.wire.protocol import LegCommitted, ProtocolError, decode
from fleet.wire.topics import Keys, genuine
from fleet.world.layout import Layout
from fleet.world.site import planners_for
from reservation.client import ReservationClient
from reservation.mirror import TableMirror

log = logging.getLogger("fleet.dispatcher")
# at the subtask's node, by mission: a fill puts goods on the stacks, an empty takes them
ACTIONS = {MissionKind.FILL: {TaskKind.DELIVER: "drop", TaskKind.RETURN: "pick"},
           MissionKind.EMPTY: {TaskKind.DELIVER: "pick", TaskKind.RETURN: "drop"}}
LEG_TIMEOUT_S = 300.0  # wall seconds for an order's edge to be committed: the gateway asks
# again while the store cannot give it, so this only ends a fleet that stopped answering
ONLINE_TIMEOUT_S = 60.0  # for the gateway to say each forklift is there
# Wall seconds the engine decides ahead of an instant (dispatcher/pacing.py's lead): the
# gateway plans an edge only once the forklift is ready for it, so the master waits for its
# forklift from the decision on, and the other forklifts' decisions wait behind it. A small
# lead keeps that wait short; the search it leaves room for is the master's own.
VDA5050_LEAD_WALL_S = 0.25
CONNECT_TIMEOUT_S = 10.0
MAJOR = "v2"


@dataclass
class _Order:
    """One forklift's order: its id, the last update sent, the node it ends on."""

    order_id: str
    node: Node  # the last node released
    sequence_id: int = 0  # that node's
    update_id: int = -1  # the last update sent (-1: none yet)


class MasterExecutor(RemoteExecutor):
    """The engine's executor, each subtask a VDA 5050 order (the module's docstring)."""

    def __init__(self, session: zenoh.Session, keys: Keys, reservations: ReservationClient,
                 mirror: TableMirror, liveness: Liveness, vehicles: list[int], layout: Layout,
                 mqtt_url: str, mission: MissionKind = MissionKind.FILL) -> None:
        super().__init__(session, keys, reservations, mirror, liveness, vehicles,
                         layout.vehicle_kind)
        self.map_id = layout.name
        self.actions = ACTIONS[mission]
        self.planners = planners_for(layout)
        self.nodes = nodes(layout)
        # a pose's node: a station's or stack's before a park that shares it (the first node
        # of an order is the one the forklift's last order ended on)
        self.node_at: dict[Pose, Node] = {}
        for node in sorted(self.nodes, key=lambda n: n.place == PARK):
            self.node_at.setdefault(node.pose, node)
        self.root = f"{GatewayConfig.interface}/{MAJOR}/{GatewayConfig.manufacturer}"
        self.headers = {v: Headers(GatewayConfig.manufacturer, f"forklift-{v}") for v in vehicles}
        self.orders: dict[int, _Order] = {}
        self.legs: dict[int, queue.Queue[LegCommitted]] = {v: queue.Queue() for v in vehicles}
        self.states: dict[int, dict[str, Any]] = {}  # each forklift's latest state
        self.heard = threading.Condition()
        self.client = self._connect(mqtt_url)
        self.subscriber = session.declare_subscriber(keys.vda5050_leg("*"), self._on_leg)

    def _connect(self, url: str) -> mqtt.Client:
        host, port = mqtt_host_port(url)
        client = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2,
                             client_id=f"fleet-dispatcher-{os.getpid()}")
        client.on_connect = lambda c, *_: c.subscribe(f"{self.root}/+/state", qos=0)
        client.on_message = self._on_state
        try:
            client.connect(host, port)
        except OSError as exc:
            raise ParticipantLost(f"--dispatch vda5050: no MQTT broker at {url}: "
                                  f"{exc}") from None
        client.loop_start()
        return client

    def close(self) -> None:
        self.client.loop_stop()
        self.client.disconnect()
        self.subscriber.undeclare()

    # --- what the forklifts say ------------------------------------------------------------

    def _on_state(self, client, userdata, message: mqtt.MQTTMessage) -> None:
        """A forklift's state, believed only if it is one by the schema (anyone may publish
        on an open broker)."""
        serial = message.topic.split("/")[-2]
        try:
            vehicle = int(serial.removeprefix("forklift-"))
            state = json.loads(message.payload)
            if not isinstance(state, dict):
                raise InvalidMessage("not a JSON object")
            validate("state", state)
        except (ValueError, InvalidMessage, RecursionError) as exc:
            log.warning("ignored a state on %s: %s", message.topic, exc)
            return
        if vehicle not in self.legs:
            return
        with self.heard:
            self.states[vehicle] = state
            self.heard.notify_all()

    def _on_leg(self, sample: zenoh.Sample) -> None:
        try:
            envelope = decode(sample.payload.to_bytes())
        except ProtocolError as exc:
            log.warning("a malformed message on %s: %s", sample.key_expr, exc)
            return
        leg = envelope.message
        if isinstance(leg, LegCommitted) and genuine(str(sample.key_expr), envelope) \
                and leg.vehicle in self.legs:
            self.legs[leg.vehicle].put(leg)

    # --- the executor ----------------------------------------------------------------------

    def park(self, vehicle: int, pose: Pose) -> None:
        """Parked in the store, and heard on MQTT standing there."""
        super().park(vehicle, pose)
        with self.heard:
            if not self.heard.wait_for(lambda: vehicle in self.states, ONLINE_TIMEOUT_S):
                raise ParticipantLost(f"forklift {vehicle} said nothing on MQTT within "
                                      f"{ONLINE_TIMEOUT_S:g} s (is the gateway up?)")
            start = self.states[vehicle].get("lastNodeId", "")
        node = next((n for n in self.nodes if n.node_id == start), None)
        if node is None or node.pose != pose:
            raise ParticipantLost(f"forklift {vehicle} stands on {start!r}, not at {pose}")
        self.orders[vehicle] = _Order(f"mission-{vehicle}", self.node_at[pose])

    def execute(self, task: Task) -> Trajectory | PlanFailure:
        order = self.orders[task.vehicle]
        self._check_errors(task.vehicle, order)  # the last update's actions too
        if task.start != order.node.pose:
            raise ParticipantLost(f"forklift {task.vehicle}: the engine has it at {task.start}, "
                                  f"its order at {order.node.node_id}")
        goals = tuple(g for g in task.goals if g in self.node_at)
        if not goals:
            return PlanFailure(FailureReason.NO_PATH, f"no goal of the {task.kind.value} is a "
                               "node of the VDA 5050 map")
        with self.mirror.frozen() as mirror:
            planned = self.planners.get(task.filled).plan(task.vehicle, task.start, task.t_i,
                                                          goals, mirror.table)
        if isinstance(planned, PlanFailure):
            return planned
        goal = self.node_at[planned.goal]
        self._send(task.vehicle, order, [goal], self.actions.get(task.kind))
        leg = self._committed(task.vehicle, order)
        self._sync(leg.revision)
        order.node, order.sequence_id = goal, order.sequence_id + 2
        return leg_from_wire(leg.leg, f"{self.keys.vda5050_leg(task.vehicle)}")

    def freeze(self, *_) -> None:
        raise ParticipantLost("--dispatch vda5050 runs no faults")

    def resume(self, *_) -> None:
        raise ParticipantLost("--dispatch vda5050 runs no faults")

    # --- orders ----------------------------------------------------------------------------

    def _send(self, vehicle: int, order: _Order, path: list[Node], action: str | None) -> None:
        """The next release: from the node the order ends on along `path`, `action` on the
        last node."""
        order.update_id += 1
        acts = [{"actionId": f"{order.order_id}-{order.update_id}-{action}",
                 "actionType": action, "blockingType": "HARD"}] if action else []
        # the first release starts where it stands, each later one where the last ended
        message = {**self.headers[vehicle].next("order", time.time()),
                   **released_order(order.order_id, order.update_id, [order.node, *path],
                                    self.map_id, order.sequence_id, acts)}
        validate("order", message)  # ours: a bug if not
        # QoS 1: a lost order would leave the engine waiting for its leg
        self.client.publish(f"{self.root}/forklift-{vehicle}/order", json.dumps(message), qos=1)

    def _committed(self, vehicle: int, order: _Order) -> LegCommitted:
        """The leg committed for the order's next edge; an error the forklift reports on
        this update ends the mission, naming it."""
        edge = order.sequence_id + 1
        deadline = time.monotonic() + LEG_TIMEOUT_S
        while time.monotonic() < deadline:
            self._check_errors(vehicle, order)
            try:
                leg = self.legs[vehicle].get(timeout=0.5)
            except queue.Empty:
                continue
            if leg.order_id == order.order_id and leg.sequence_id == edge:
                return leg
        raise ParticipantLost(f"forklift {vehicle}: no leg for edge {edge} of "
                              f"{order.order_id} within {LEG_TIMEOUT_S:g} s")

    def _check_errors(self, vehicle: int, order: _Order) -> None:
        with self.heard:
            state = self.states.get(vehicle, {})
        for action in state.get("actionStates", []):
            if action.get("actionId", "").startswith(f"{order.order_id}-") and \
                    action.get("actionStatus") == "FAILED":
                raise ParticipantLost(f"forklift {vehicle} could not {action['actionType']} "
                                      f"({action['actionId']}): "
                                      f"{action.get('resultDescription', '')}")
        for error in state.get("errors", []):
            refs = {r["referenceKey"]: r["referenceValue"]
                    for r in error.get("errorReferences", [])}
            if refs.get("orderId") == order.order_id and \
                    refs.get("orderUpdateId") == str(order.update_id):
                raise ParticipantLost(f"forklift {vehicle} refused update {order.update_id} "
                                      f"of {order.order_id}: {error['errorType']}: "
                                      f"{error.get('errorDescription', '')}")
