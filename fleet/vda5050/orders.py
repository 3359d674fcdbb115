"""One vehicle's VDA 5050 2.0.0 orders, pure: what it accepts, what it must drive and do next,
and the order fields of its `state`. No I/O and no clock: the gateway feeds the messages and
the vehicle's events in, and publishes what comes out.

Clauses are the 2.0.0 text's (VDA5050_EN_V1.md); where its Figure 8 is ambiguous, 2.1.0's
numbered reading of the same figure decides (said where). The gateway feeds, in this order:
`receive` for every schema-valid order (it publishes a state after each, 6.10); `edge_started`
when the vehicle sets off on the next released edge (its actions are due then); `node_reached`
when it stands on the edge's end node (that node's actions are due); `action_status` as each
action progresses; `cancel`, `pause`, `resume`, `init_position` and `instant` for instant
actions; and builds each `state` around `state_fields()`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from itertools import pairwise
from typing import Any, Final, Literal, Protocol

from fleet.vda5050.map import HANDLED
from fleet.vda5050.map import Node as MapNode

Message = Mapping[str, Any]

# 6.11, Table 1
WAITING, INITIALIZING, RUNNING, PAUSED, FINISHED, FAILED = (
    "WAITING", "INITIALIZING", "RUNNING", "PAUSED", "FINISHED", "FAILED")
STATUSES: Final = frozenset({WAITING, INITIALIZING, RUNNING, PAUSED, FINISHED, FAILED})
ENDED: Final = frozenset({FINISHED, FAILED})

# The error types the text names (6.6.3.2, 6.6.4, Figure 8), all reported as WARNING.
VALIDATION_ERROR: Final = "validationError"
ORDER_ERROR: Final = "orderError"
ORDER_UPDATE_ERROR: Final = "orderUpdateError"
NO_ROUTE_ERROR: Final = "noRouteError"
NO_ORDER_TO_CANCEL: Final = "noOrderToCancel"
INSTANT_ACTION_ERROR: Final = "instantActionError"  # not in the text: vda-5050-lib's name

# The actions a vehicle does in an order (6.8.1), and the map places it does them at: on
# nodes only, standing still, its forks working a stack or a station (a forklift) or its lift
# a shelf in its slot (an AGV).
ORDER_ACTIONS: Final[Mapping[str, frozenset[str]]] = {"pick": HANDLED, "drop": HANDLED}
INSTANT_ACTIONS: Final = ("startPause", "stopPause", "cancelOrder", "stateRequest",
                          "factsheetRequest", "initPosition")
HANDLING: Final = frozenset({"pick", "drop"})

# 6.7 nodePosition: an allowed deviation of 0 means "within the normal tolerance of the AGV
# manufacturer"; this is ours (an emulated forklift stands exactly on its poses).
TOLERANCE_XY: Final = 0.05  # m
TOLERANCE_THETA: Final = 0.05  # rad

HEADER: Final = ("headerId", "timestamp", "version", "manufacturer", "serialNumber")


class Located(Protocol):
    """Anything with a pose on the map: vda5050.map.Node, Position."""

    @property
    def x(self) -> float: ...
    @property
    def y(self) -> float: ...
    @property
    def theta(self) -> float: ...


@dataclass(frozen=True)
class Position:
    x: float
    y: float
    theta: float


@dataclass(frozen=True)
class Action:
    action_id: str
    action_type: str
    blocking_type: str  # NONE, SOFT or HARD (6.12)
    parameters: Mapping[str, Any] = field(default_factory=dict)  # actionParameters as a dict
    description: str | None = None

    @classmethod
    def read(cls, action: Message) -> Action:
        # the 2.0.0 instantActions schema spells the type `actionName` (vda5050.schemas)
        kind = action.get("actionType", action.get("actionName", ""))
        return cls(action["actionId"], kind, action.get("blockingType", "HARD"),
                   {p["key"]: p["value"] for p in action.get("actionParameters", ())},
                   action.get("actionDescription"))

    @property
    def stops_driving(self) -> bool:
        # 6.12: SOFT and HARD forbid driving; a pick or drop does whatever its blockingType,
        # since the forks are in the stack
        return self.blocking_type != "NONE" or self.action_type in HANDLING


@dataclass(frozen=True)
class OrderNode:
    node_id: str
    sequence_id: int
    released: bool
    actions: tuple[Action, ...] = ()
    position: Mapping[str, Any] | None = None  # the order's nodePosition, as sent
    description: str | None = None

    @classmethod
    def read(cls, node: Message) -> OrderNode:
        return cls(node["nodeId"], node["sequenceId"], node["released"],
                   tuple(Action.read(a) for a in node["actions"]), node.get("nodePosition"),
                   node.get("nodeDescription"))

    def state(self) -> dict[str, Any]:
        out: dict[str, Any] = {"nodeId": self.node_id, "sequenceId": self.sequence_id,
                               "released": self.released}
        if self.description is not None:
            out["nodeDescription"] = self.description
        keys = ("x", "y", "theta", "mapId")
        # the state schema requires theta in a nodeState's position, the order's does not
        if self.position is not None and all(k in self.position for k in keys):
            out["nodePosition"] = {k: self.position[k] for k in keys}
        return out


@dataclass(frozen=True)
class OrderEdge:
    edge_id: str
    sequence_id: int
    released: bool
    start_node_id: str
    end_node_id: str
    actions: tuple[Action, ...] = ()
    description: str | None = None
    trajectory: Mapping[str, Any] | None = None

    @classmethod
    def read(cls, edge: Message) -> OrderEdge:
        return cls(edge["edgeId"], edge["sequenceId"], edge["released"], edge["startNodeId"],
                   edge["endNodeId"], tuple(Action.read(a) for a in edge["actions"]),
                   edge.get("edgeDescription"), edge.get("trajectory"))

    def state(self) -> dict[str, Any]:
        out: dict[str, Any] = {"edgeId": self.edge_id, "sequenceId": self.sequence_id,
                               "released": self.released}
        if self.description is not None:
            out["edgeDescription"] = self.description
        return out


@dataclass(frozen=True)
class Leg:
    """A released edge to drive and the node it ends on (whose actions are due on arrival)."""

    edge: OrderEdge
    end: OrderNode


Outcome = Literal["new", "update", "ignored", "rejected"]


@dataclass(frozen=True)
class Decision:
    outcome: Outcome
    legs: tuple[Leg, ...] = ()  # newly released edges, in driving order
    start_actions: tuple[Action, ...] = ()  # a new order's first node's, due at once
    error: dict[str, Any] | None = None  # the error now in the state, if rejected

    @property
    def accepted(self) -> bool:
        return self.outcome in ("new", "update")


@dataclass
class ActionState:
    action: Action
    status: str = WAITING
    result: str = ""
    sequence_id: int | None = None  # its order node's or edge's; None for an instant action

    def state(self) -> dict[str, Any]:
        # The 2.0.0 state schema lacks PAUSED (the text has it, 6.11): a paused action is
        # reported as still RUNNING, and `paused` says why.
        out: dict[str, Any] = {"actionId": self.action.action_id,
                               "actionType": self.action.action_type,
                               "actionStatus": RUNNING if self.status == PAUSED else self.status}
        if self.action.description is not None:
            out["actionDescription"] = self.action.description
        if self.result:
            out["resultDescription"] = self.result
        return out


@dataclass(frozen=True)
class Error:
    error_type: str
    description: str
    references: tuple[tuple[str, str], ...]
    # what clears it: accepting any order or update ("accept": a rejection, 6.6.4), or
    # accepting a new order ("order": an action's failure, kept with the order's actionStates)
    lasts: Literal["accept", "order"] = "accept"
    level: str = "WARNING"

    def state(self) -> dict[str, Any]:
        return {"errorType": self.error_type, "errorLevel": self.level,
                "errorDescription": self.description,
                "errorReferences": [{"referenceKey": k, "referenceValue": v}
                                    for k, v in self.references]}


class _Refused(Exception):
    def __init__(self, error_type: str, description: str, *references: tuple[str, str]):
        super().__init__(description)
        self.error_type, self.description, self.references = error_type, description, references


@dataclass
class OrderBook:
    """One vehicle's order: ids, the nodes and edges still to traverse (base then horizon),
    where it stands, its action states, its order errors and its pause."""

    order_actions: Mapping[str, frozenset[str]] = field(default_factory=lambda: ORDER_ACTIONS)
    order_id: str = ""
    order_update_id: int = 0
    last_node_id: str = ""
    last_node_sequence_id: int = 0
    on_node: bool = False  # standing on the last node (False: on the edge after it, or unknown)
    nodes: list[OrderNode] = field(default_factory=list)
    edges: list[OrderEdge] = field(default_factory=list)
    actions: dict[str, ActionState] = field(default_factory=dict)
    errors: list[Error] = field(default_factory=list)
    paused: bool = False
    cancelling: str | None = None  # the actionId of a cancelOrder still RUNNING
    cancelled: bool = False  # the current order was cancelled (6.6.3.2)
    _decision: OrderNode | None = field(default=None, init=False, repr=False)
    _body: dict[str, Any] | None = field(default=None, init=False, repr=False)

    # --- what the book says --------------------------------------------------------------

    @property
    def active(self) -> bool:
        """Still executing an order or waiting for its update. Figure 8 of 2.0.0 joins its
        conditions with "and" (a vehicle driving an order without actions would be idle);
        2.1.0's reading of the figure, followed here: nodes left, or order actions not ended."""
        return bool(self.nodes) or any(s.sequence_id is not None and s.status not in ENDED
                                       for s in self.actions.values())

    def decision_point(self) -> tuple[str, int]:
        """The last base node (6.6.2): where an update must start; the last node once the
        base is done."""
        base = [n for n in self.nodes if n.released]
        if base:
            return base[-1].node_id, base[-1].sequence_id
        return self.last_node_id, self.last_node_sequence_id

    @property
    def new_base_request(self) -> bool:
        # 6.10.3: a horizon is waiting and at most the base's last node is left to reach
        return (any(not n.released for n in self.nodes)
                and sum(n.released for n in self.nodes) <= 1)

    def may_drive(self) -> bool:
        """Not paused, and no action of a node reached that stops driving is still under way
        (6.12, Figure 15: a node's SOFT or HARD actions end before the vehicle goes on)."""
        return not self.paused and not any(
            s.status not in ENDED and s.sequence_id is not None
            and s.sequence_id <= self.last_node_sequence_id and s.action.stops_driving
            for s in self.actions.values())

    def state_fields(self) -> dict[str, Any]:
        """The order fields of a `state` message (6.10.6), named as the 2.0.0 schema names
        them; the gateway adds header, driving, position, battery, mode and safety."""
        return {
            "orderId": self.order_id,
            "orderUpdateId": self.order_update_id,
            "lastNodeId": self.last_node_id,
            "lastNodeSequenceId": self.last_node_sequence_id,
            "nodeStates": [n.state() for n in self.nodes],
            "edgeStates": [e.state() for e in self.edges],
            "actionStates": [s.state() for s in self.actions.values()],
            "errors": [e.state() for e in self.errors],
            "paused": self.paused,
            "newBaseRequest": self.new_base_request,
        }

    # --- orders ----------------------------------------------------------------------------

    def receive(self, order: Message, known_nodes: Mapping[str, MapNode], *,
                at: Located | None = None,
                reachable: Callable[[OrderEdge], bool] | None = None) -> Decision:
        """Take a schema-valid order or update (Figure 8). `at` is the vehicle's pose (default:
        the node it stands on, if the book knows it); `reachable` says whether the vehicle can
        drive a released edge (its start may be a temporary node off the map, 6.6.3.1). A
        rejection leaves the order as it was and reports the error until an order is
        accepted (6.6.4)."""
        try:
            nodes, edges = _read(order)
            mode = self._mode(order, nodes)
            if mode == "ignored":
                return Decision("ignored")
            if mode == "new":
                self._check_start(nodes[0], known_nodes, at)
            self._check_capabilities(nodes, edges, known_nodes, mode == "new", reachable)
        except _Refused as refused:
            refs = [("topic", "order"), ("headerId", str(order.get("headerId", ""))),
                    ("orderId", str(order.get("orderId", ""))),
                    ("orderUpdateId", str(order.get("orderUpdateId", "")))]
            error = Error(refused.error_type, refused.description,
                          (*refs, *refused.references))
            self._report(error)
            return Decision("rejected", error=error.state())
        self._body = _body(order)
        if mode == "new":
            return self._start(order, nodes, edges)
        return self._stitch(order, nodes, edges)

    def _mode(self, order: Message, nodes: tuple[OrderNode, ...]) -> str:
        if self._body is None or order["orderId"] != self.order_id:
            if self.active:  # Figure 8: a new order while one runs
                raise _Refused(ORDER_UPDATE_ERROR,
                               f"order {self.order_id!r} is still active (nodes to traverse or "
                               f"actions under way): cancel it first (6.6.2, Figure 8)")
            return "new"
        update = order["orderUpdateId"]
        if update < self.order_update_id:
            raise _Refused(ORDER_UPDATE_ERROR, f"orderUpdateId {update} is lower than the "
                           f"current {self.order_update_id} (6.6.4.3)")
        if update == self.order_update_id:
            if _body(order) == self._body:
                return "ignored"  # 6.6.4.3: the same order twice, the second is ignored
            raise _Refused(ORDER_UPDATE_ERROR, f"orderUpdateId {update} was accepted with "
                           "other content: an update needs a higher orderUpdateId (6.6.4.3)")
        if self.cancelled:  # 6.8.1 cancelOrder: "the order is deleted"
            raise _Refused(ORDER_UPDATE_ERROR, f"order {self.order_id!r} was cancelled: send "
                           "a new order (6.6.3)")
        first, (node_id, sequence_id) = nodes[0], self.decision_point()
        if (first.node_id, first.sequence_id) != (node_id, sequence_id):
            raise _Refused(ORDER_UPDATE_ERROR,
                           f"the update starts at {first.node_id} ({first.sequence_id}), not at "
                           f"the decision point {node_id} ({sequence_id}) (6.6.2)",
                           ("nodeId", first.node_id), ("sequenceId", str(first.sequence_id)))
        kept = {a.action_id for a in self._decision.actions} if self._decision else set()
        if not {a.action_id for a in first.actions} <= kept:
            raise _Refused(ORDER_UPDATE_ERROR, f"the stitching node {first.node_id} brings new "
                           "actions: its content must not change (6.6.2)",
                           ("nodeId", first.node_id), ("sequenceId", str(first.sequence_id)))
        return "update"

    def _check_start(self, first: OrderNode, known_nodes: Mapping[str, MapNode],
                     at: Located | None) -> None:
        """6.6.1: the first node must be trivially reachable, the vehicle on it or within its
        deviation range (6.6.3.1: a temporary node off the map where it stands will do)."""
        here = at if at is not None else (known_nodes.get(self.last_node_id) if self.on_node
                                          else None)
        if here is None or not _within(first, known_nodes.get(first.node_id), here):
            raise _Refused(NO_ROUTE_ERROR, f"the first node {first.node_id} is not where the "
                           "vehicle stands nor within its deviation range (6.6.1, Figure 8)",
                           ("nodeId", first.node_id))

    def _check_capabilities(self, nodes: tuple[OrderNode, ...], edges: tuple[OrderEdge, ...],
                            known_nodes: Mapping[str, MapNode], new: bool,
                            reachable: Callable[[OrderEdge], bool] | None) -> None:
        for index, node in enumerate(nodes):
            place = known_nodes.get(node.node_id)
            if index == 0:
                continue  # checked by _check_start, or the stitching node (6.6.2)
            if place is None:
                raise _Refused(NO_ROUTE_ERROR, f"node {node.node_id} is not on the vehicle's "
                               "map", ("nodeId", node.node_id))
            for action in node.actions:
                self._check_action(action, ("nodeId", node.node_id), place)
        if new:  # the first node's actions are done where the vehicle stands
            first = nodes[0]
            for action in first.actions:
                self._check_action(action, ("nodeId", first.node_id),
                                   known_nodes.get(first.node_id))
        for edge in edges:
            where = ("edgeId", edge.edge_id)
            if edge.trajectory is not None:  # 6.6.4.2: a field the vehicle cannot use
                raise _Refused(ORDER_ERROR, f"edge {edge.edge_id} has a trajectory: the "
                               "vehicle plans its own path", where, ("field", "trajectory"))
            for action in edge.actions:
                self._check_action(action, where, None)
            if edge.released and reachable is not None and not reachable(edge):
                raise _Refused(NO_ROUTE_ERROR, f"the vehicle cannot drive edge {edge.edge_id} "
                               f"from {edge.start_node_id} to {edge.end_node_id}", where)

    def _check_action(self, action: Action, where: tuple[str, str],
                      place: MapNode | None) -> None:
        """6.6.4.2: an action the vehicle cannot do is an orderError naming it (vda-5050-lib
        reads an error that names an actionId as an order's only if it is an orderError)."""
        refs = (("actionId", action.action_id), ("actionType", action.action_type), where)
        places = self.order_actions.get(action.action_type)
        if places is None:
            known = ", ".join(sorted(self.order_actions)) or "none"
            raise _Refused(ORDER_ERROR, f"the vehicle cannot do {action.action_type!r} in an "
                           f"order (it does: {known})", *refs)
        if where[0] == "edgeId":
            raise _Refused(ORDER_ERROR, f"{action.action_type} is done on a node, standing, "
                           "not on an edge", *refs)
        if place is None or place.place not in places:
            raise _Refused(ORDER_ERROR, f"{action.action_type} is done at a "
                           f"{' or '.join(sorted(places))} node, not at {where[1]}", *refs)

    def _start(self, order: Message, nodes: tuple[OrderNode, ...],
               edges: tuple[OrderEdge, ...]) -> Decision:
        """Figure 8, a new order: the previous order's states go (its actionStates were
        "kept until a new order is received", 6.10.6); instant actions under way stay."""
        self.order_id, self.order_update_id = order["orderId"], order["orderUpdateId"]
        self.cancelled = False
        self.actions = {i: s for i, s in self.actions.items()
                        if s.sequence_id is None and s.status not in ENDED}
        self.errors = []
        first = nodes[0]
        # 6.6.1 + 6.10.2: the first node is trivially reachable, so it counts as traversed at
        # once and its actions are due
        self.last_node_id, self.last_node_sequence_id, self.on_node = (
            first.node_id, first.sequence_id, True)
        self.nodes, self.edges = list(nodes[1:]), list(edges)
        self._decision = [n for n in nodes if n.released][-1]
        self._track(nodes, edges)
        return Decision("new", _legs(nodes, edges), first.actions)

    def _stitch(self, order: Message, nodes: tuple[OrderNode, ...],
                edges: tuple[OrderEdge, ...]) -> Decision:
        """Figure 8, an update: clear the horizon, append the new base and horizon; the
        stitching node keeps what the first order said of it (6.6.2)."""
        self.order_update_id = order["orderUpdateId"]
        self.errors = [e for e in self.errors if e.lasts == "order"]
        self.nodes = [n for n in self.nodes if n.released] + list(nodes[1:])
        self.edges = [e for e in self.edges if e.released] + list(edges)
        base = [n for n in nodes[1:] if n.released]
        if base:
            self._decision = base[-1]
        self._track(nodes[1:], edges)
        return Decision("update", _legs(nodes, edges))

    def _track(self, nodes: Iterable[OrderNode], edges: Iterable[OrderEdge]) -> None:
        # 6.11: an action received is represented in actionStates, WAITING for its node or
        # edge; only the base's (a horizon's actions may change before they are released,
        # and vda-5050-lib's master counts only released ones)
        for step in (*nodes, *edges):
            if step.released:
                for action in step.actions:
                    self.actions[action.action_id] = ActionState(
                        action, sequence_id=step.sequence_id)

    # --- events from the vehicle -----------------------------------------------------------

    def edge_started(self, sequence_id: int) -> tuple[Action, ...]:
        """The vehicle sets off on the next released edge; returns the edge's actions, due
        now (6.10.2). A call out of turn is the gateway's bug: ValueError."""
        edge = next((e for e in self.edges
                     if e.sequence_id == self.last_node_sequence_id + 1), None)
        if edge is None or edge.sequence_id != sequence_id or not edge.released:
            raise ValueError(f"edge {sequence_id} is not the next released edge")
        if not self.on_node:
            raise ValueError(f"the vehicle is already on edge {sequence_id}")
        if not self.may_drive():
            raise ValueError("the vehicle may not drive: paused, or a node's action that "
                             "stops driving is under way (6.12)")
        self.on_node = False
        self.errors = [e for e in self.errors if not (e.error_type == NO_ROUTE_ERROR and
                                                      ("edgeId", edge.edge_id) in e.references)]
        return edge.actions

    def node_reached(self, node_id: str, sequence_id: int) -> tuple[Action, ...]:
        """The vehicle stands on the next node (6.10.2): the node leaves nodeStates, the edge
        to it leaves edgeStates and its actions end, lastNode* move on; returns the node's
        actions, due now (none once the order is being cancelled)."""
        if (not self.nodes or not self.nodes[0].released or self.on_node
                or (self.nodes[0].node_id, self.nodes[0].sequence_id) != (node_id, sequence_id)):
            raise ValueError(f"node {node_id} ({sequence_id}) is not the next node to reach")
        node = self.nodes.pop(0)
        self.edges = [e for e in self.edges if e.sequence_id != sequence_id - 1]
        for state in self.actions.values():  # 6.10.2: leaving the edge finishes its actions
            if state.sequence_id == sequence_id - 1 and state.status not in ENDED:
                state.status = FINISHED
        self.last_node_id, self.last_node_sequence_id, self.on_node = node_id, sequence_id, True
        if self.cancelling is not None:
            self._settle()
            return ()
        return node.actions

    def action_status(self, action_id: str, status: str, description: str = "", *,
                      error_type: str | None = None) -> None:
        """An action's progress (Figure 14). A FAILED one may bring an error of `error_type`
        naming the action (6.8.2: a failed pick "should correspond with an error"), kept until
        a new order."""
        state = self.actions.get(action_id)
        if state is None:
            raise ValueError(f"no action {action_id!r}")
        if status not in STATUSES or (status == WAITING and state.status != WAITING):
            raise ValueError(f"{action_id}: {status!r} cannot follow {state.status}")
        if state.status in ENDED:
            raise ValueError(f"{action_id} already ended {state.status} (Figure 14)")
        state.status = status
        if description:
            state.result = description
        if status == FAILED and error_type is not None:
            topic = "order" if state.sequence_id is not None else "instantActions"
            self._report(Error(error_type, description or f"{state.action.action_type} failed",
                               (("topic", topic), ("actionId", action_id),
                                ("actionType", state.action.action_type)), lasts="order"))
        self._settle()

    # --- instant actions -------------------------------------------------------------------

    def instant(self, action_id: str, action_type: str, status: str = FINISHED,
                description: str = "") -> None:
        """Record an instant action's state (6.9: it is added to actionStates)."""
        self.actions[action_id] = ActionState(Action(action_id, action_type, "NONE"), status,
                                              description)

    def cancel(self, action_id: str) -> tuple[str, ...]:
        """cancelOrder (6.6.3, Figure 9). WAITING actions fail; returns the actions under way,
        which the vehicle interrupts and reports FAILED (or their own end if it cannot). A
        forklift stops on a node, not between two: on an edge it keeps the node it drives to.
        The cancelOrder stays RUNNING until the vehicle stands and every action has ended.
        No order, or one already cancelled: FAILED and noOrderToCancel (6.6.3.2)."""
        if not self.active or self.cancelling is not None:
            self.instant(action_id, "cancelOrder", FAILED, "no order to cancel")
            self._report(Error(NO_ORDER_TO_CANCEL, "there is no order to cancel (6.6.3.2)",
                               (("topic", "instantActions"), ("actionId", action_id),
                                ("actionType", "cancelOrder"))))
            return ()
        self.instant(action_id, "cancelOrder", RUNNING)
        self.cancelling, self.cancelled = action_id, True
        under_way = []
        for state in self.actions.values():
            if state.sequence_id is None or state.status in ENDED:
                continue
            if state.status == WAITING:
                state.status = FAILED
            else:
                under_way.append(state.action.action_id)
        self.nodes = [] if self.on_node else self.nodes[:1]
        self.edges = []
        self._settle()
        return tuple(under_way)

    def pause(self, action_id: str | None = None) -> None:
        """startPause (6.8.1): no more driving; actions may go on (the vehicle pauses the
        ones it can and reports them PAUSED). Idempotent."""
        self.paused = True
        if action_id is not None:
            self.instant(action_id, "startPause")

    def resume(self, action_id: str | None = None) -> None:
        """stopPause (6.8.1): driving and paused actions resume. Idempotent."""
        self.paused = False
        if action_id is not None:
            self.instant(action_id, "stopPause")

    def init_position(self, node_id: str, known_nodes: Mapping[str, MapNode],
                      action_id: str | None = None) -> bool:
        """initPosition (6.8.1) on a node of the map: the vehicle stands there, lastNodeId
        says so. Refused (FAILED) off the map, or while an order is active: the order's
        lastNode* track its progress."""
        reason = ("" if node_id in known_nodes and not self.active else
                  f"{node_id} is not on the map" if node_id not in known_nodes else
                  "an order is active")
        if not reason:
            self.last_node_id, self.last_node_sequence_id, self.on_node = node_id, 0, True
        if action_id is not None:
            self.instant(action_id, "initPosition", FAILED if reason else FINISHED, reason)
        return not reason

    def edge_blocked(self, sequence_id: int, why: str) -> None:
        """The next released edge cannot be driven as the floor stands (goods close every way):
        a noRouteError naming it, until it is driven (`edge_started`) or the order ends."""
        edge = next(e for e in self.edges if e.sequence_id == sequence_id)
        self._report(Error(NO_ROUTE_ERROR, why, (("orderId", self.order_id),
                                                 ("edgeId", edge.edge_id),
                                                 ("sequenceId", str(sequence_id))),
                           lasts="order"))

    def refuse_instant(self, action_id: str, action_type: str, why: str) -> None:
        """An instant action the vehicle cannot do: FAILED, with an instantActionError naming
        it (as vda-5050-lib's own AGV controller reports one)."""
        self.instant(action_id, action_type, FAILED, why)
        self._report(Error(INSTANT_ACTION_ERROR, why, (("topic", "instantActions"),
                                                       ("actionId", action_id),
                                                       ("actionType", action_type))))

    def invalid(self, topic: str, why: str, header_id: object = None) -> None:
        """A message on `topic` that is not JSON or not valid against its schema: a
        validationError naming the topic (and its headerId, if it has one), until an order is
        accepted; nothing else changes (6.6.4.1)."""
        refs = (("topic", topic),) + ((("headerId", str(header_id)),)
                                      if header_id is not None else ())
        self._report(Error(VALIDATION_ERROR, why, refs))

    # --- inside ----------------------------------------------------------------------------

    def _settle(self) -> None:
        # 6.6.3: cancelOrder FINISHED once the vehicle stands and all actions have ended
        if self.cancelling is None or self.nodes or any(
                s.sequence_id is not None and s.status not in ENDED
                for s in self.actions.values()):
            return
        self.actions[self.cancelling].status = FINISHED
        self.cancelling = None

    def _report(self, error: Error) -> None:
        if error not in self.errors:  # the same bad message again: one error, not two
            self.errors.append(error)


def _read(order: Message) -> tuple[tuple[OrderNode, ...], tuple[OrderEdge, ...]]:
    """The order's nodes and edges, or a validationError (6.6.4.1) for what the schema lets
    through: counts, sequenceIds, neighbours, base before horizon, actionIds."""
    nodes = tuple(OrderNode.read(n) for n in order["nodes"])
    edges = tuple(OrderEdge.read(e) for e in order["edges"])

    def refuse(why: str, *refs: tuple[str, str]) -> _Refused:
        return _Refused(VALIDATION_ERROR, why, *refs)

    if not nodes:
        raise refuse("an order has at least one node (6.6.1)")
    if len(edges) != len(nodes) - 1:
        raise refuse(f"{len(nodes)} nodes need {len(nodes) - 1} edges, not {len(edges)} (6.6.1)")
    if not nodes[0].released:
        raise refuse("the first node starts the base: it must be released (6.6.2)",
                     ("nodeId", nodes[0].node_id))
    if nodes[0].sequence_id % 2:
        raise refuse("nodes take even sequenceIds, edges odd (6.6.2)",
                     ("nodeId", nodes[0].node_id), ("sequenceId", str(nodes[0].sequence_id)))
    for before, node in pairwise(nodes):
        refs = (("nodeId", node.node_id), ("sequenceId", str(node.sequence_id)))
        if node.sequence_id != before.sequence_id + 2:
            raise refuse(f"node {node.node_id} has sequenceId {node.sequence_id} after "
                         f"{before.sequence_id}: they run on by one over nodes and edges "
                         "(6.6.2)", *refs)
        if node.released and not before.released:
            raise refuse(f"released node {node.node_id} follows the horizon (6.6.1)", *refs)
    for edge, (start, end) in zip(edges, pairwise(nodes), strict=True):
        refs = (("edgeId", edge.edge_id), ("sequenceId", str(edge.sequence_id)))
        if edge.sequence_id != start.sequence_id + 1:
            raise refuse(f"edge {edge.edge_id} has sequenceId {edge.sequence_id} between nodes "
                         f"{start.sequence_id} and {end.sequence_id} (6.6.2)", *refs)
        if (edge.start_node_id, edge.end_node_id) != (start.node_id, end.node_id):
            raise refuse(f"edge {edge.edge_id} joins {edge.start_node_id} to {edge.end_node_id}"
                         f", its neighbours are {start.node_id} and {end.node_id} (6.6.1)", *refs)
        if edge.released != end.released:  # 6.6.1: both ends released, none after the horizon
            raise refuse(f"edge {edge.edge_id} is {'' if edge.released else 'not '}released, "
                         f"its end node {end.node_id} is{'' if end.released else ' not'} "
                         "(6.6.1)", *refs)
    seen: set[str] = set()
    for step in (*nodes, *edges):
        for action in step.actions:
            if action.action_id in seen:
                # no actionId reference: vda-5050-lib would not read it as this order's error
                where = (("nodeId", step.node_id) if isinstance(step, OrderNode)
                         else ("edgeId", step.edge_id))
                raise refuse(f"actionId {action.action_id} twice: each is unique (6.7)", where)
            seen.add(action.action_id)
    return nodes, edges


def _legs(nodes: tuple[OrderNode, ...], edges: tuple[OrderEdge, ...]) -> tuple[Leg, ...]:
    return tuple(Leg(e, n) for e, n in zip(edges, nodes[1:], strict=True) if e.released)


def _body(order: Message) -> dict[str, Any]:
    return {k: v for k, v in order.items() if k not in HEADER}


def _within(node: OrderNode, known: MapNode | None, here: Located) -> bool:
    """`here` within the node's deviation range (6.7 nodePosition): the order's position and
    allowed deviations if it gives them, else the map's pose with none (our tolerance)."""
    if node.position is not None:
        p = node.position
        x, y, theta = p["x"], p["y"], p.get("theta")
        xy, turn = p.get("allowedDeviationXY", 0.0), p.get("allowedDeviationTheta", 0.0)
    elif known is not None:
        x, y, theta, xy, turn = known.x, known.y, known.theta, 0.0, 0.0
    else:
        return False
    if math.hypot(here.x - x, here.y - y) > max(xy, TOLERANCE_XY):
        return False
    return theta is None or abs(math.remainder(here.theta - theta, math.tau)) <= max(
        turn, TOLERANCE_THETA)
