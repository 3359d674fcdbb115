"""`fleet vda5050 gateway`: every vehicle of a run (forklifts, or seed 002's lane AGVs) as a
VDA 5050 2.0.0 AGV on MQTT.

For each vehicle an MQTT client of its own under interfaceName/v2/manufacturer/KIND-ID/
(its last will CONNECTIONBROKEN on `connection`, QoS 1, retained; ONLINE when connected,
OFFLINE on a clean stop; the factsheet retained). It takes the master's `order` and
`instantActions`, checks each against the official schema, and runs it through the
vehicle's `Execution` (vda5050/execution.py); it talks to the vehicles over zenoh like any
other process, and takes the layout, the fleet and its start poses from the run's dispatcher
(which must run `--dispatch external`, or `vda5050` for its own mission): each released edge
goes to the vehicle's agent as a task (plan with its own planner against the reservation
store, commit, drive), the vehicle's states say where it is, and goods put on or taken off a
stack are held in the store (by the dispatcher itself when the mission is its own; a slot's
shelf stands off an AGV's lanes, and the gateway alone keeps account of it). A
`state` goes out on every event that changes it and at least every --state-interval, a
`visualization` every --visualization-interval. Every message sent is checked against its
schema first.

MQTT and zenoh callbacks only enqueue; one worker thread does the rest in arrival order, and
the agents' tasks are asked from a few threads of their own, their answers enqueued too.
"""

from __future__ import annotations

import contextlib
import functools
import json
import logging
import math
import queue
import threading
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from contextlib import ExitStack
from dataclasses import dataclass
from typing import Any

import paho.mqtt.client as mqtt
import zenoh

from fleet.errors import UserError
from fleet.mission.spec import ClockMode, MissionKind
from fleet.params import DispatchParams
from fleet.planning.geometry import Cell
from fleet.planning.reservations import Interval, Reservation
from fleet.planning.trajectory import FailureReason, Pose, Trajectory
from fleet.runtime.argtypes import mqtt_host_port
from fleet.runtime.bus import Requester, RequestFailed, Stream, open_session, wait_alive
from fleet.runtime.lifecycle import Stopped, process_main, stop_on_signals
from fleet.runtime.mission_info import mission_layout
from fleet.runtime.process_configs import GatewayConfig
from fleet.runtime.tasks import result_from_wire
from fleet.vda5050 import messages
from fleet.vda5050.execution import Execution, Handling, LegRequest
from fleet.vda5050.map import at_rest, nodes
from fleet.vda5050.messages import serial_number
from fleet.vda5050.orders import Position
from fleet.vda5050.schemas import InvalidMessage, validate
from fleet.wire.convert import leg_from_wire, leg_to_wire
from fleet.wire.protocol import (
    GOODS,
    AmendRequest,
    ClockTick,
    Envelope,
    LegCommitted,
    MqttTraffic,
    ProtocolError,
    Reply,
    TaskRequest,
    TaskResult,
    VehicleState,
    WireLeg,
    decode,
)
from fleet.wire.topics import GATEWAY, Keys, genuine
from fleet.world.layout import Layout
from fleet.world.site import planners_for
from reservation.client import ReservationClient
from reservation.mirror import TableMirror
from vehicle_agent.clock import SimClock, tick_problem

log = logging.getLogger("fleet.vda5050")
SENDER = GATEWAY  # the gateway's name on the bus
TASK_TIMEOUT_S = 120.0  # as the dispatcher's: a search is capped far below this
# Sim seconds between asking for a leg and its start: the agent's search and commit must fit
# (a plan ready after its start is refused as late). It starts at FIRST_LEAD_S, doubles on a
# late plan and follows twice the last search's wall time otherwise.
FIRST_LEAD_S = 2.0
MIN_LEAD_S, MAX_LEAD_S = 1.0, 30.0
TASK_THREADS = 16  # agents plan in their own processes: these threads only wait
WAKE_S = 0.05  # every vehicle is looked at this often (actions end, legs fall due)
MAJOR = "v2"


def main(argv=None) -> int:
    return process_main(GatewayConfig, serve, "fleet vda5050 gateway", argv)


@dataclass(frozen=True)
class _Mqtt:
    vehicle: int
    topic: str  # order or instantActions
    payload: bytes


@dataclass(frozen=True)
class _Connected:
    vehicle: int


@dataclass(frozen=True)
class _State:
    vehicle: int
    state: VehicleState
    t: float


@dataclass(frozen=True)
class _Postponed:
    """Another AGV's commit postponed this one's leg, which its agent now drives."""

    vehicle: int
    wire: WireLeg
    leg: Trajectory
    revision: int


@dataclass(frozen=True)
class _Planned:
    vehicle: int
    leg: LegRequest
    arrival: float | None
    why: str
    wall_s: float = 0.0  # how long the agent took
    late: bool = False  # the plan was ready only after its start


class VehicleLink:
    """One vehicle's MQTT client: its topics, its last will, what it publishes."""

    def __init__(self, config: GatewayConfig, serial: str, vehicle: int, inbox: queue.Queue,
                 record: Callable[[str, bool, str], None]) -> None:
        self.serial = serial
        self.record = record  # (topic, received, text): the recording's copy
        self.root = f"{config.interface}/{MAJOR}/{config.manufacturer}/{self.serial}"
        self.headers = messages.Headers(config.manufacturer, self.serial)
        self.lock = threading.Lock()  # headers count in one order, from the worker alone
        client = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2,
                             client_id=f"{config.manufacturer}-{self.serial}-{id(self):x}")
        will = {**self.headers.next("connection", time.time()),
                "connectionState": "CONNECTIONBROKEN"}
        client.will_set(f"{self.root}/connection", json.dumps(will), qos=1, retain=True)
        client.reconnect_delay_set(0.1, 2)

        def on_connect(client, userdata, flags, reason, properties) -> None:
            if reason.is_failure:
                log.warning("%s: the broker refused the connection: %s", self.serial, reason)
                return
            for topic in ("order", "instantActions"):
                client.subscribe(f"{self.root}/{topic}", qos=1)
            inbox.put(_Connected(vehicle))

        def on_message(client, userdata, message) -> None:
            inbox.put(_Mqtt(vehicle, message.topic.rsplit("/", 1)[-1], bytes(message.payload)))

        client.on_connect, client.on_message = on_connect, on_message
        host, port = mqtt_host_port(config.mqtt)
        client.connect_async(host, port, keepalive=10)
        client.loop_start()
        self.client = client

    def publish(self, topic: str, body: dict[str, Any], *, qos: int = 0,
                retain: bool = False) -> mqtt.MQTTMessageInfo | None:
        """Send a message (its header added); one that fails its schema is our bug: logged,
        not sent."""
        message = {**self.headers.next(topic, time.time()), **body}
        try:
            validate(topic, message)
        except InvalidMessage as exc:
            log.error("%s: not sending an invalid %s: %s", self.serial, topic, exc)
            return None
        text = json.dumps(message)
        self.record(topic, False, text)
        return self.client.publish(f"{self.root}/{topic}", text, qos=qos, retain=retain)

    def close(self) -> None:
        """OFFLINE, then a clean disconnect (the last will is not sent)."""
        sent = self.publish("connection", {"connectionState": "OFFLINE"}, qos=1, retain=True)
        if sent is not None and self.client.is_connected():
            with contextlib.suppress(RuntimeError, ValueError):  # not connected after all:
                sent.wait_for_publish(timeout=2.0)  # the will says it
        self.client.disconnect()
        self.client.loop_stop()


class Gateway:
    def __init__(self, session: zenoh.Session, keys: Keys, layout: Layout,
                 starts: tuple[Pose, ...], config: GatewayConfig,
                 dispatch: str = "external", mission: str = "") -> None:
        self.session, self.keys, self.layout, self.config = session, keys, layout, config
        self.map_id = layout.name
        self.known = {n.node_id: n for n in nodes(layout)}
        self.kind = layout.vehicle_kind
        self.type = messages.VEHICLE_TYPES[self.kind.name]
        self.planners = planners_for(layout)
        # A forklift's plans keep off the stacks' goods (the store holds them, and it plans
        # on the stacks filled); an AGV drives the lanes, and the shelves stand in slots off
        # them, each in its own from the start.
        self.goods_block = not layout.has_lanes
        self.inbox: queue.Queue = queue.Queue()
        self.clock = SimClock()
        self.tasks = Requester(session, SENDER, TASK_TIMEOUT_S, retry_s=0.0)
        self.reservations = ReservationClient(session, keys, Requester(session, SENDER))
        self.store = TableMirror()  # followed for our own dispatcher's mission only
        self.pool = ThreadPoolExecutor(TASK_THREADS, thread_name_prefix="vda5050-task")
        self.stopping = threading.Event()
        self.vehicles = list(range(1, len(starts) + 1))
        # --dispatch vda5050: our dispatcher's fill or empty mission, which starts its
        # forklifts with goods claimed (fill) or its stacks full (empty), holds the stacks'
        # goods in the store itself, as in the direct run, and plans every leg it orders
        self.ours = dispatch == "vda5050"
        self.emptying = self.ours and mission == MissionKind.EMPTY.value
        self.stacks = frozenset(s.cell for s in layout.stacks)
        self.piles = frozenset(p.cell for p in layout.piles)
        # the stacks or slots holding goods, as the master's picks and drops
        self.filled: set[Cell] = set(self._goods_at_start(layout))
        dispatch = DispatchParams()
        # an AGV's lift takes up and puts down at once (note A.3)
        handling = Handling(pick_s=dispatch.t_claim, drop_s=dispatch.t_unload) \
            if self.goods_block else Handling(pick_s=0.0, drop_s=0.0)
        self.executions: dict[int, Execution] = {}
        self.motion: dict[int, messages.Motion] = {}
        for v, start in zip(self.vehicles, starts, strict=True):  # as the dispatcher has it
            position = Position(*at_rest(layout, start))
            self.executions[v] = Execution(self.known, start, position, handling,
                                           self.filled, self._drivable, self._escapes,
                                           noun=self.kind.noun,
                                           loaded=self.ours and not self.emptying,
                                           shelf_coming=functools.partial(self._shelf_coming,
                                                                          v))
            self.motion[v] = messages.Motion(position, False)
        self.links: dict[int, VehicleLink] = {}
        self.legs: dict[int, Stream] = {}  # each vehicle's committed legs (LegCommitted)
        self.lead = dict.fromkeys(self.vehicles, FIRST_LEAD_S)
        self.due_state = dict.fromkeys(self.vehicles, 0.0)  # monotonic time of the next one
        self.due_visualization = dict.fromkeys(self.vehicles, 0.0)

    # --- the process -----------------------------------------------------------------------

    def run(self) -> None:
        with ExitStack() as scope:
            scope.enter_context(self.session.declare_subscriber(self.keys.clock,
                                                                self._on_clock))
            scope.enter_context(self.session.declare_subscriber(
                self.keys.vehicle_state("*"), self._on_state))
            self._wait_for_the_fleet()
            if self.ours:  # the engine's goods, as its store holds them
                scope.enter_context(self.reservations.follow(self.store))
            for v in self.vehicles:
                stream = scope.enter_context(Stream(self.session, self.keys.vda5050_mqtt(v),
                                                    SENDER, reliable=True))
                self.links[v] = VehicleLink(self.config, serial_number(self.kind.name, v), v,
                                            self.inbox,
                                            functools.partial(self._record, stream, v))
                self.legs[v] = scope.enter_context(Stream(self.session, self.keys.vda5050_leg(v),
                                                          SENDER, reliable=True))
            scope.callback(self._close_links)
            scope.callback(self.pool.shutdown, wait=False, cancel_futures=True)
            # up: a compose health check, and anyone else, can see it
            scope.enter_context(self.session.liveliness().declare_token(
                self.keys.vda5050_alive))
            log.info("%d %ss on MQTT at %s under %s/%s/%s/", len(self.vehicles), self.kind.noun,
                     self.config.mqtt, self.config.interface, MAJOR, self.config.manufacturer)
            self._work()

    def _wait_for_the_fleet(self) -> None:
        timeout = self.config.startup_timeout_s
        if not wait_alive(self.session, self.keys.reservation_alive, timeout):
            raise Stopped(f"no reservation service within {timeout:g} s")
        for v in self.vehicles:
            if not wait_alive(self.session, self.keys.vehicle_alive(v), timeout):
                raise Stopped(f"{self.kind.noun} {v}'s agent was not up within {timeout:g} s")
        deadline = time.monotonic() + timeout
        while not self.clock.realtime:
            if time.monotonic() > deadline:
                raise Stopped(f"no real-time clock within {timeout:g} s (the dispatcher runs "
                              "it with --dispatch external or vda5050 and --clock realtime)")
            self.stopping.wait(WAKE_S)

    def _record(self, stream: Stream, vehicle: int, topic: str, received: bool,
                text: str) -> None:
        stream.put(MqttTraffic(vehicle, topic, received, text), self.clock.now())

    def _close_links(self) -> None:
        for link in self.links.values():
            link.close()

    def stop(self) -> None:
        self.stopping.set()
        raise Stopped("stopped by a signal")

    def _work(self) -> None:
        """Events as they come, each stepping its own vehicle at once; every vehicle stepped
        at least every WAKE_S (actions end and legs are due with time alone)."""
        sweep = time.monotonic()
        while not self.stopping.is_set():
            try:
                event = self.inbox.get(timeout=max(0.0, sweep - time.monotonic()))
            except queue.Empty:
                event = None
            now = self.clock.now()
            if event is not None:
                self._step(self._handle(event, now), now)
            if time.monotonic() >= sweep:
                for v in self.vehicles:
                    self._step(v, now)
                sweep = time.monotonic() + WAKE_S

    def _handle(self, event: _Mqtt | _Connected | _State | _Planned | _Postponed,
                now: float) -> int:
        """Take one event; the vehicle it concerns."""
        match event:
            case _Mqtt(vehicle, topic, payload):
                self._from_master(vehicle, topic, payload, now)
            case _Connected(vehicle):
                link = self.links[vehicle]
                link.publish("connection", {"connectionState": "ONLINE"}, qos=1, retain=True)
                self._publish_factsheet(vehicle)
                self._publish_state(vehicle)
            case _State(vehicle, state, t):
                self._observed(vehicle, state, t)
            case _Postponed(vehicle, wire, leg, revision):
                execution = self.executions[vehicle]
                if execution.driving is not None:  # published as the leg it now drives
                    execution.driving.arrival = leg.t_end
                    self.legs[vehicle].put(LegCommitted(
                        vehicle, execution.book.order_id, execution.driving.sequence_id,
                        revision, wire), leg.t_start)
            case _Planned(vehicle, leg, arrival, why, wall_s, late):
                execution = self.executions[vehicle]
                speed = self.clock.tick.speed if self.clock.tick else 1.0
                self.lead[vehicle] = min(MAX_LEAD_S, 2 * self.lead[vehicle]) if late else \
                    max(MIN_LEAD_S, min(MAX_LEAD_S, 2 * wall_s * speed))
                if arrival is None and why != execution.waiting:
                    log.info("%s %d: edge %d to %s not now: %s", self.kind.noun, vehicle,
                             leg.sequence_id, leg.goal, why)
                for message, t in execution.planned(leg, arrival, why, now):
                    self._instant_actions(vehicle, message, t)
                self._publish_state(vehicle)
        return event.vehicle

    def _step(self, vehicle: int, now: float) -> None:
        """What time brings: actions that end or start, the next leg, the periodic messages."""
        execution = self.executions[vehicle]
        changed, moved = execution.advance(now)
        for goods in moved if self.goods_block and not self.ours else ():
            self._hold_goods(goods)
        waiting = execution.waiting
        leg = execution.next_leg(now + self.lead[vehicle])
        changed = changed or execution.waiting != waiting
        if leg is not None:
            self.pool.submit(self._ask_for_leg, vehicle, leg, execution.book.order_id)
        wall = time.monotonic()
        if changed or wall >= self.due_state[vehicle]:
            self._publish_state(vehicle)
        if wall >= self.due_visualization[vehicle] and vehicle in self.links:
            self.due_visualization[vehicle] = wall + self.config.visualization_interval_s
            self.links[vehicle].publish("visualization", messages.visualization(
                self.motion[vehicle], self.map_id))

    # --- the master's messages -------------------------------------------------------------

    def _from_master(self, vehicle: int, topic: str, payload: bytes, now: float) -> None:
        execution = self.executions[vehicle]
        link = self.links[vehicle]
        link.record(topic, True, payload.decode("utf-8", "replace"))
        message: Any = None
        try:
            message = json.loads(payload)
            if not isinstance(message, dict):
                raise InvalidMessage(f"a {topic} message is a JSON object, not "
                                     f"{type(message).__name__}")
            validate(topic, message)
            if message.get("version") != messages.VERSION:
                raise InvalidMessage(f"version {message.get('version')!r}: this vehicle "
                                     f"speaks VDA 5050 {messages.VERSION}")
            if (message.get("manufacturer"), message.get("serialNumber")) != (
                    self.config.manufacturer, link.serial):
                raise InvalidMessage(f"addressed to {message.get('manufacturer')}/"
                                     f"{message.get('serialNumber')}, sent to "
                                     f"{self.config.manufacturer}/{link.serial}")
        except (ValueError, InvalidMessage, RecursionError) as exc:  # JSONDecodeError is a
            # ValueError; JSON nested deeper than Python's recursion limit a RecursionError
            header = message.get("headerId") if isinstance(message, dict) else None
            log.warning("%s: refused a %s message: %s", link.serial, topic, exc)
            execution.book.invalid(topic, f"invalid {topic} message: {exc}", header)
            self._publish_state(vehicle)
            return
        if topic == "order":
            decision = execution.order(message)
            log.info("%s: order %s/%s %s", link.serial, message["orderId"],
                     message["orderUpdateId"], decision.outcome)
            self._publish_state(vehicle)
        else:
            self._instant_actions(vehicle, message, now)

    def _instant_actions(self, vehicle: int, message: dict, t: float) -> None:
        extra = self.executions[vehicle].instant_actions(message, t)
        if "factsheet" in extra:
            self._publish_factsheet(vehicle)
        self._publish_state(vehicle)

    # --- the vehicles ----------------------------------------------------------------------

    def _on_clock(self, sample: zenoh.Sample) -> None:
        envelope = _believed(sample, ClockTick)
        tick = envelope.message if envelope is not None else None
        if tick is not None and tick.mode == ClockMode.REALTIME and \
                tick_problem(tick, self.clock.tick) == "":
            self.clock.take(tick)

    def _on_state(self, sample: zenoh.Sample) -> None:
        envelope = _believed(sample, VehicleState)
        if envelope is not None and envelope.message.vehicle in self.executions:
            state = envelope.message
            self.inbox.put(_State(state.vehicle, state, envelope.sim_time))

    def _observed(self, vehicle: int, state: VehicleState, t: float) -> None:
        try:
            pose = Pose.parse(state.pose)
        except ValueError:
            return
        position = Position(state.x, state.y, state.theta)
        driving = bool(state.maneuver) and not self.kind.is_wait(state.maneuver)
        last = self.motion[vehicle].position
        # an AGV that moves without turning: its velocity along the way it went since
        direction = math.atan2(position.y - last.y, position.x - last.x) \
            if self.type.kinematic == "OMNI" and (position.x, position.y) != (last.x, last.y) \
            else None
        # a battery charges while its AGV stands on a pile (seed 002's model)
        charging = not driving and state.battery is not None and state.battery < 100.0 \
            and pose.cell in self.piles
        self.motion[vehicle] = messages.Motion(
            position, driving, self.type.speed(state.speed, self.layout.cell_size),
            state.battery, direction, charging)
        execution = self.executions[vehicle]
        was_driving = execution.moving
        if execution.observed(pose, position, driving, t) or was_driving != driving:
            self._publish_state(vehicle)

    def _shelf_coming(self, vehicle: int, cell: Cell) -> bool:
        """Whether another AGV stands, or will once its leg ends, in that slot with a shelf
        on its lift: it may put it down there before `vehicle` drives in."""
        return any(e.loaded and e.pose.cell == cell for v, e in self.executions.items()
                   if v != vehicle)

    def _goods_at_start(self, layout: Layout) -> frozenset[Cell]:
        """Where goods stand when the session starts: every slot's own shelf (AGVs), every
        stack full for our own empty mission, else nothing (an outside master fills)."""
        if not self.goods_block:
            return frozenset(s.cell for s in layout.slots)
        return self.stacks if self.emptying else frozenset()

    def _static(self, filled: frozenset[Cell]) -> tuple[frozenset[Cell], int]:
        """The static map's goods, and the store's revision the agent plans on at least: the
        stacks filled (an AGV's lanes have none); for our own dispatcher's mission, the
        stacks its engine plans on as filled, read off its store (`engine_map`)."""
        if not self.ours:
            return (frozenset(filled) if self.goods_block else frozenset()), 0
        with self.store.frozen() as store:
            goods = store.table.reservations(GOODS)
            revision = store.revision
        return engine_map(goods, self.stacks, self.emptying), revision

    def _drivable(self, start: Pose, goal: Pose) -> bool:
        """Whether the vehicle can drive from one pose to another on today's static map (the
        same part of the floor): the spec's noRouteError otherwise. Our own dispatcher's
        orders are its plans: it knows its goods to the instant, the gateway a little later."""
        if self.ours:
            return True
        planner = self.planners.get(frozenset(self.filled) if self.goods_block
                                    else frozenset())
        here, there = planner.component(start), planner.component(goal)
        return here is not None and here == there

    def _escapes(self, pose: Pose, filled: frozenset) -> bool:
        """Whether a forklift at `pose` still reaches the stations with `filled` stacks full
        (goods dropped from inside a cluster can wall the forklift in; a shelf put down in
        its slot walls no AGV in)."""
        if not self.goods_block or self.ours:
            return True
        planner = self.planners.get(filled)
        here = planner.component(pose)
        return here is not None and here == planner.component(self.layout.stations[0].dock)

    def _ask_for_leg(self, vehicle: int, leg: LegRequest, order_id: str) -> None:
        """In a task thread: the agent plans and commits the leg; its answer is enqueued,
        the leg it committed published, the legs it postponed (seed 002's collision rules)
        told to their AGVs."""
        started = time.monotonic()
        try:
            filled, revision = self._static(leg.filled)
            request = TaskRequest(self.tasks.next_id(), vehicle, "return", str(leg.start),
                                  leg.t_i, [str(leg.goal)], sorted(filled), leg.loaded,
                                  revision)
            reply = self.tasks.request(self.keys.vehicle_task(vehicle), request, leg.t_i).message
            if not isinstance(reply, TaskResult) or reply.task_id != request.task_id:
                raise ProtocolError(f"{self.kind.noun} {vehicle} answered with {reply}")
            result = result_from_wire(reply)
        except (RequestFailed, ProtocolError) as exc:
            self.inbox.put(_Planned(vehicle, leg, None, f"{self.kind.noun} {vehicle}: {exc}"))
            return
        except Exception as exc:  # a bug here must not leave the vehicle waiting forever
            log.exception("%s %d: asking for edge %d failed", self.kind.noun, vehicle,
                          leg.sequence_id)
            self.inbox.put(_Planned(vehicle, leg, None, f"internal error: {exc}"))
            return
        wall_s = time.monotonic() - started
        if reply.ok:
            log.info("%s %d: edge %d to %s committed, arriving at t=%.2f", self.kind.noun,
                     vehicle, leg.sequence_id, leg.goal, result.t_end)
            self.legs[vehicle].put(LegCommitted(vehicle, order_id, leg.sequence_id,
                                                reply.revision, leg_to_wire(result)),
                                   result.t_start)
            self.inbox.put(_Planned(vehicle, leg, result.t_end, "", wall_s))
            for wire in reply.amended:
                self._amend(wire, leg.t_i)
        else:
            self.inbox.put(_Planned(vehicle, leg, None, f"no way to {leg.goal} now: "
                                    f"{reply.failure}: {reply.detail}", wall_s,
                                    reply.failure == FailureReason.LATE.value))

    def _amend(self, wire: WireLeg, t: float) -> None:
        """Another AGV's committed leg, postponed by a commit (seed 002's collision rules):
        its agent drives it so from now on, as it does when the dispatcher tells it."""
        try:
            postponed = leg_from_wire(wire, "TaskResult.amended")
            reply = self.tasks.request(self.keys.vehicle_task(postponed.vehicle), AmendRequest(
                self.tasks.next_id(), postponed.vehicle, wire), t).message
        except (RequestFailed, ProtocolError) as exc:
            reply = exc
        if not (isinstance(reply, Reply) and reply.ok):  # its own leg stands: only say so
            log.error("%s: a postponed leg was not taken: %s", self.kind.noun,
                      getattr(reply, "reason", reply))
            return
        log.info("%s %d: its leg postponed, now arriving at t=%.2f", self.kind.noun,
                 postponed.vehicle, postponed.t_end)
        self.inbox.put(_Postponed(postponed.vehicle, wire, postponed, reply.revision))

    def _hold_goods(self, goods) -> None:
        """The store holds a stack's goods from the instant they are put there, so no plan
        drives through them; taken off, the stack is free again from then on."""
        try:
            if goods.placed:
                written = self.reservations.commit(GOODS, [Interval(goods.cell, goods.t,
                                                                    math.inf)])
            else:
                written = self.reservations.release(GOODS, goods.t, [goods.cell])
        except RequestFailed as exc:
            log.error("the reservation service did not take the goods at %s: %s",
                      goods.cell, exc)
            return
        if not written.ok:
            log.error("the reservation service refused the goods at %s: %s", goods.cell,
                      written.reason)

    # --- what goes out ---------------------------------------------------------------------

    def _publish_state(self, vehicle: int) -> None:
        link = self.links.get(vehicle)
        if link is None:
            return
        execution = self.executions[vehicle]
        link.publish("state", messages.state(execution.book.state_fields(),
                                             self.motion[vehicle], self.map_id,
                                             self.type.load_position if execution.loaded
                                             else None, execution.information))
        self.due_state[vehicle] = time.monotonic() + self.config.state_interval_s

    def _publish_factsheet(self, vehicle: int) -> None:
        self.links[vehicle].publish("factsheet", messages.factsheet(
            self.kind, self.layout.cell_size, self.config.state_interval_s,
            self.config.visualization_interval_s), qos=1, retain=True)


def engine_map(goods: list[Reservation], stacks: frozenset[Cell], emptying: bool
               ) -> frozenset[Cell]:
    """The stacks our engine plans on as filled, from the goods its store holds (`goods`,
    owner GOODS): in a fill, those held for good (placed when the drop's leg is committed);
    in an empty, every stack but those held for a while (claimed: off its map from the commit
    of the leg that claims them, held until the claim is done)."""
    if emptying:
        return stacks - {r.cell for r in goods}
    return frozenset(r.cell for r in goods if r.t1 == math.inf)


def _believed(sample: zenoh.Sample, expected: type) -> Envelope | None:
    """The sample's envelope if it carries an `expected` message from its key's own sender
    (anyone could put a forged one); None otherwise, a malformed one logged."""
    try:
        envelope = decode(sample.payload.to_bytes())
    except ProtocolError as exc:
        log.warning("a malformed message on %s: %s", sample.key_expr, exc)
        return None
    if isinstance(envelope.message, expected) and genuine(str(sample.key_expr), envelope):
        return envelope
    return None


def serve(config: GatewayConfig) -> int:
    keys = Keys(config.bus.run)
    with open_session(config.bus.config()) as session:
        info, layout, starts = mission_layout(session, keys, config.startup_timeout_s)
        if info.dispatch == "internal":
            raise UserError(f"the run's dispatcher hands its {info.kind} mission to the "
                            "vehicles itself: a master drives a fleet started with --dispatch "
                            "external (or vda5050)")
        nodes(layout)  # a layout without a VDA 5050 map is refused by name
        gateway = Gateway(session, keys, layout, starts[:info.vehicles], config,
                          info.dispatch, info.kind)
        stop_on_signals(gateway.stop)
        try:
            gateway.run()
        except Stopped as exc:
            log.info("%s", exc)
    return 0
