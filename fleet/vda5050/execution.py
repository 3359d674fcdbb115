"""One emulated vehicle (a forklift, or a lane AGV of seed 002) as a VDA 5050 AGV, pure: its
order book, the leg it asks its agent to drive next, the node actions it does standing (pick
and drop, over the kind's handling times) and the goods they move (a stack's goods, a slot's
shelf). No I/O and no clock: the gateway (vda5050/gateway.py) feeds
it the master's messages, the vehicle's states and the agent's answers, each with the sim
time, and carries out what it asks for (a leg to plan and commit, goods to reserve).

A leg is a released edge: the agent plans it with the vehicle's own planner against the
reservation store and commits it, so whatever the master orders, two vehicles never hold a
cell at once. A leg the store or the map cannot give now is asked for again a second later,
and the state's `information` says what the vehicle waits for.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

from fleet.planning.geometry import Cell
from fleet.planning.trajectory import Pose
from fleet.vda5050.map import HOLDS_GOODS, SLOT
from fleet.vda5050.map import Node as MapNode
from fleet.vda5050.orders import FAILED, FINISHED, RUNNING, Action, Decision, OrderBook, Position

RETRY_S = 1.0  # sim seconds before a leg the agent could not plan is asked for again
BLOCKED_RETRY_S = 5.0  # ... when the static map has no way: until goods are taken away


@dataclass(frozen=True)
class Handling:
    """How long the forks work a stack or station, or the lift a shelf (the kind's handling
    times)."""

    pick_s: float
    drop_s: float


@dataclass(frozen=True)
class LegRequest:
    """Ask the agent to drive the released edge `sequence_id`: from `start` at rest at
    `t_i` to `goal`, carrying goods or not."""

    sequence_id: int
    start: Pose
    goal: Pose
    t_i: float
    loaded: bool
    filled: frozenset[Cell]  # the stacks holding goods when asked: the static map to plan on


@dataclass(frozen=True)
class GoodsMoved:
    """Goods put on (`placed`) or taken off a stack or slot at `t` (the store holds a stack's
    goods: a forklift's plans keep off them)."""

    cell: Cell
    placed: bool
    t: float


@dataclass
class _Underway:
    action: Action
    node: MapNode | None  # where it works (None: not a place of the map)
    left_s: float  # handling time still to go
    since: float  # the sim time it last went on


@dataclass
class _Driving:
    sequence_id: int  # the edge's
    end: str  # the node it ends on
    goal: Pose
    arrival: float


@dataclass
class Execution:
    """What the vehicle does with its orders. `pose` is where it stands, or will stand once
    the leg it drives ends; `filled` the stacks or slots holding goods (shared by the
    gateway's vehicles, changed only through this class's GoodsMoved)."""

    known: Mapping[str, MapNode]
    pose: Pose
    position: Position
    handling: Handling
    filled: set[Cell]
    drivable: Callable[[Pose, Pose], bool]  # whether the vehicle can drive between two poses
    # whether a vehicle standing there can still reach the rest of the floor with these
    # stacks filled
    escapes: Callable[[Pose, frozenset[Cell]], bool]
    noun: str = "forklift"  # what the vehicle is called in what it says
    # whether another vehicle stands or will stand in that slot with a shelf on its lift
    # (it may put it down there before this one arrives)
    shelf_coming: Callable[[Cell], bool] = lambda cell: False
    book: OrderBook = field(default_factory=OrderBook)
    loaded: bool = False
    moving: bool = False  # the last state heard says it drives
    driving: _Driving | None = None
    planning: int | None = None  # the edge whose plan is asked for
    due: list[tuple[Action, MapNode | None]] = field(default_factory=list)  # node actions next
    underway: _Underway | None = None
    waiting: str = ""  # why the vehicle waits, for the state's information
    retry_at: float = 0.0
    deferred: list[tuple[Mapping[str, Any], float]] = field(default_factory=list)

    def __post_init__(self) -> None:
        here = next((n for n in self.known.values() if n.pose == self.pose), None)
        if here is not None:  # it starts on a node of the map: an order may start there
            self.book.init_position(here.node_id, self.known)

    # --- from the master -------------------------------------------------------------------

    def order(self, message: Mapping[str, Any]) -> Decision:
        """A schema-valid order or update (vda5050.orders.OrderBook.receive)."""
        decision = self.book.receive(message, self.known, at=self.position,
                                     reachable=self._reachable)
        if decision.outcome == "new":  # what the last order waited for is over
            first = self.known.get(self.book.last_node_id)
            self.due = [(a, first) for a in decision.start_actions]
            self.waiting, self.retry_at = "", 0.0
        return decision

    def instant_actions(self, message: Mapping[str, Any], t: float) -> set[str]:
        """A schema-valid instantActions message; returns what to publish at once besides the
        state ("factsheet" on a factsheetRequest). While a plan is asked for, the message
        waits for its answer: the vehicle either stands or drives a committed edge then."""
        if self.planning is not None:
            self.deferred.append((message, t))
            return set()
        extra = set()
        for raw in message.get("instantActions", message.get("actions", ())):
            action = Action.read(raw)
            kind = action.action_type
            if kind == "startPause":
                self.book.pause(action.action_id)
                if self.underway is not None:  # the forks stop where they are
                    self.underway.left_s -= max(0.0, t - self.underway.since)
            elif kind == "stopPause":
                self.book.resume(action.action_id)
                if self.underway is not None:
                    self.underway.since = t
            elif kind == "cancelOrder":
                interrupted = self.book.cancel(action.action_id)
                self.due, self.waiting, self.retry_at = [], "", 0.0
                if self.underway is not None and self.underway.action.action_id in interrupted:
                    self.book.action_status(self.underway.action.action_id, FAILED,
                                            "interrupted by cancelOrder")
                    self.underway = None
            elif kind == "stateRequest":
                self.book.instant(action.action_id, kind)
            elif kind == "factsheetRequest":
                self.book.instant(action.action_id, kind)
                extra.add("factsheet")
            elif kind == "initPosition":
                self._init_position(action)
            else:
                self.book.refuse_instant(action.action_id, kind,
                                         f"the {self.noun} cannot do {kind!r} as an instant "
                                         "action (it does: startPause, stopPause, cancelOrder, "
                                         "stateRequest, factsheetRequest, initPosition)")
        return extra

    def _init_position(self, action: Action) -> None:
        """An emulated vehicle knows where it is: initPosition is taken on the node it stands
        on (which it then reports), refused anywhere else."""
        node_id = str(action.parameters.get("lastNodeId", ""))
        node = self.known.get(node_id)
        if node is not None and node.pose != self.pose:
            self.book.refuse_instant(action.action_id, "initPosition",
                                     f"the {self.noun} stands at {self.pose}, not on {node_id} "
                                     f"({node.pose}): an emulated {self.noun} is not moved by "
                                     "hand")
            return
        self.book.init_position(node_id, self.known, action.action_id)

    # --- what to do next -------------------------------------------------------------------

    def next_leg(self, t: float) -> LegRequest | None:
        """The leg to ask the agent for now, to start at `t`, if any: the next released edge,
        once the vehicle stands on its start, no action of the node holds it and the order is
        not paused."""
        if (self.planning is not None or self.driving is not None or self.due
                or self.underway is not None or t < self.retry_at or not self.book.on_node
                or not self.book.may_drive()):
            return None
        edge = next((e for e in self.book.edges
                     if e.sequence_id == self.book.last_node_sequence_id + 1 and e.released),
                    None)
        if edge is None:
            return None
        end = self.known[edge.end_node_id]  # an order names only nodes of the map
        if self.loaded and end.place == SLOT and (end.cell in self.filled
                                                  or self.shelf_coming(end.cell)):
            # a shelf on the lift does not go under another: until that one is taken away
            why = "it holds a shelf" if end.cell in self.filled else \
                "another vehicle brings a shelf there"
            self.waiting, self.retry_at = f"slot {end.of}: {why}", t + BLOCKED_RETRY_S
            self.book.edge_blocked(edge.sequence_id, f"a loaded {self.noun} cannot drive "
                                   f"into slot {end.of}: {why}")
            return None
        self.planning = edge.sequence_id
        return LegRequest(edge.sequence_id, self.pose, end.pose, t, self.loaded,
                          frozenset(self.filled))

    def planned(self, leg: LegRequest, arrival: float | None, why: str, t: float
                ) -> list[tuple[Mapping[str, Any], float]]:
        """The agent's answer: committed, arriving at `arrival`; or not (`why`), to be asked
        again for a start RETRY_S after the one refused (BLOCKED_RETRY_S with a noRouteError
        when the goods on the stacks close every way; `next_leg` is given the start it asks
        for, its lead ahead of now). Returns the instant actions that waited for it, to
        replay."""
        self.planning = None
        if arrival is None:
            self.waiting, self.retry_at = why, leg.t_i + RETRY_S
            if not self.drivable(leg.start, leg.goal):
                self.retry_at = leg.t_i + BLOCKED_RETRY_S
                self.book.edge_blocked(leg.sequence_id, f"no way from {leg.start} to "
                                       f"{leg.goal} as the goods on the stacks stand")
        else:
            edge = next(e for e in self.book.edges if e.sequence_id == leg.sequence_id)
            self.waiting = ""
            self.book.edge_started(leg.sequence_id)  # its actions: none a vehicle accepts
            self.driving = _Driving(leg.sequence_id, edge.end_node_id, leg.goal, arrival)
            self.pose = leg.goal
        replay, self.deferred = self.deferred, []
        return replay

    def observed(self, pose: Pose, position: Position, moving: bool, t: float) -> bool:
        """A state of the vehicle at sim time t; True if the order moved on (a node reached)."""
        self.position, self.moving = position, moving
        driving = self.driving
        if driving is None or t < driving.arrival or pose != driving.goal:
            return False
        self.driving = None
        actions = self.book.node_reached(driving.end, driving.sequence_id + 1)
        node = self.known.get(driving.end)
        self.due.extend((a, node) for a in actions)
        return True

    def advance(self, t: float) -> tuple[bool, list[GoodsMoved]]:
        """Node actions by sim time t: the one under way ends when its handling time is
        spent, the next starts. Returns whether any action changed and the goods moved."""
        changed, moved = False, []
        if self.book.paused:
            return False, []
        while True:
            if self.underway is not None:
                work = self.underway
                if t - work.since < work.left_s:
                    return changed, moved
                self.underway = None
                outcome = self._finish(work.action, work.node, work.since + work.left_s)
                changed = True
                if isinstance(outcome, GoodsMoved):
                    moved.append(outcome)
            if not self.due:
                return changed, moved
            action, node = self.due.pop(0)
            why = self._cannot(action, node)
            changed = True
            if why:
                self.book.action_status(action.action_id, FAILED, why, error_type="orderError")
                continue
            self.book.action_status(action.action_id, RUNNING)
            seconds = self.handling.pick_s if action.action_type == "pick" else \
                self.handling.drop_s
            self.underway = _Underway(action, node, seconds, t)

    def _cannot(self, action: Action, node: MapNode | None) -> str:
        """Why the forks or the lift cannot do this action here now ("" if they can)."""
        picking = action.action_type == "pick"
        if picking == self.loaded:
            return (f"{action.action_type}: the {self.noun} is "
                    f"{'' if self.loaded else 'not '}loaded")
        if node is not None and node.place in HOLDS_GOODS and node.cell is not None:
            if picking and node.cell not in self.filled:
                return f"pick: {node.place} {node.of} holds no goods"
            if not picking and node.cell in self.filled:
                return f"drop: {node.place} {node.of} is full"
            if not picking and not self.escapes(self.pose, frozenset(self.filled | {node.cell})):
                return (f"drop: the goods on {node.place} {node.of} would wall the {self.noun} "
                        f"in at {self.pose}; drop from another side")
        return ""

    def _finish(self, action: Action, node: MapNode | None, t: float) -> GoodsMoved | None:
        picking = action.action_type == "pick"
        self.loaded = picking
        self.book.action_status(action.action_id, FINISHED)
        if node is None or node.place not in HOLDS_GOODS or node.cell is None:
            return None  # a station has goods to give and takes what it is given
        if picking:
            self.filled.discard(node.cell)
        else:
            self.filled.add(node.cell)
        return GoodsMoved(node.cell, placed=not picking, t=t)

    def _reachable(self, edge) -> bool:
        start = self.known.get(edge.start_node_id)
        end = self.known.get(edge.end_node_id)
        return end is not None and self.drivable(start.pose if start else self.pose, end.pose)

    # --- what the state says ---------------------------------------------------------------

    @property
    def information(self) -> list[dict[str, Any]]:
        if not self.waiting:
            return []
        return [{"infoType": "waitingForTraffic", "infoLevel": "INFO",
                 "infoDescription": self.waiting}]
