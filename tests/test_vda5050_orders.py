"""The pure core of a VDA 5050 vehicle's orders (vda5050.orders): hand-written orders on the
nodes of the `small` layout's map, accepted, stitched, rejected and cancelled as the 2.0.0
text says, and every state built from the book valid by the official schema."""

from __future__ import annotations

import copy
from datetime import UTC, datetime
from itertools import pairwise
from typing import Any

import pytest

from fleet.vda5050.map import STACK, edge_id, nodes, vda_map
from fleet.vda5050.orders import (
    FAILED,
    FINISHED,
    INITIALIZING,
    NO_ORDER_TO_CANCEL,
    NO_ROUTE_ERROR,
    ORDER_ERROR,
    ORDER_UPDATE_ERROR,
    PAUSED,
    RUNNING,
    VALIDATION_ERROR,
    WAITING,
    Action,
    OrderBook,
    Position,
)
from fleet.vda5050.schemas import validate
from fleet.world.layout_file import load_layout

Message = dict[str, Any]

LAYOUT = load_layout("small")
MAP = vda_map(LAYOUT)
KNOWN = {n.node_id: n for n in nodes(LAYOUT)}
POSITIONS = {n["nodeId"]: n["nodePosition"] for n in MAP["nodes"]}
HEADER_IDS = iter(range(1_000_000))


# --- messages ------------------------------------------------------------------------------


def header() -> Message:
    return {"headerId": next(HEADER_IDS),
            "timestamp": datetime.now(UTC).isoformat(timespec="milliseconds"),
            "version": "2.0.0", "manufacturer": "fleet-test", "serialNumber": "forklift-1"}


def action(action_id: str, action_type: str = "pick", blocking: str = "HARD") -> Message:
    return {"actionId": action_id, "actionType": action_type, "blockingType": blocking,
            "actionParameters": [{"key": "stationType", "value": "floor"}]}


def order(order_id: str, update_id: int, path: list[str], *, base: int | None = None,
          start: int = 0, actions: dict[int, list[Message]] | None = None) -> Message:
    """An order along `path` (node ids of the map), its first `base` nodes released (all by
    default), sequenceIds from `start`, `actions` by node index; valid by the schema."""
    base = len(path) if base is None else base
    actions = actions or {}
    message = {
        **header(), "orderId": order_id, "orderUpdateId": update_id,
        "nodes": [{"nodeId": n, "sequenceId": start + 2 * i, "released": i < base,
                   "nodePosition": dict(POSITIONS[n]), "actions": actions.get(i, [])}
                  for i, n in enumerate(path)],
        "edges": [{"edgeId": edge_id(a, b), "sequenceId": start + 2 * i + 1,
                   "released": i + 1 < base, "startNodeId": a, "endNodeId": b, "actions": []}
                  for i, (a, b) in enumerate(pairwise(path))],
    }
    validate("order", message)
    return message


def state(book: OrderBook) -> Message:
    """A full state message around the book's fields, checked by the official schema."""
    message = {**header(), **book.state_fields(), "driving": False,
               "agvPosition": {"x": 9.0, "y": 13.0, "theta": 0.0, "mapId": MAP["mapId"],
                               "positionInitialized": True},
               "batteryState": {"batteryCharge": 80.0, "charging": False},
               "operatingMode": "AUTOMATIC",
               "safetyState": {"eStop": "NONE", "fieldViolation": False}}
    validate("state", message)
    return message


def refs(error: Message) -> dict[str, str]:
    return {r["referenceKey"]: r["referenceValue"] for r in error["errorReferences"]}


def statuses(book: OrderBook) -> dict[str, str]:
    return {s["actionId"]: s["actionStatus"] for s in state(book)["actionStates"]}


def master_sees(message: Message, base_actions: set[str]) -> str:
    """vda-5050-lib 1.4.0 MasterController._isOrderProcessed: finished when nodeStates and
    edgeStates are empty, active when only horizon is left; both once every base action has
    ended."""
    if not message["nodeStates"] and not message["edgeStates"]:
        verdict = "finished"
    elif all(not s["released"] for s in message["nodeStates"] + message["edgeStates"]):
        verdict = "active"
    else:
        return "running"
    ended = {s["actionId"] for s in message["actionStates"]
             if s["actionStatus"] in (FINISHED, FAILED)}
    return verdict if base_actions <= ended else "running"


def at(node_id: str) -> OrderBook:
    book = OrderBook()
    assert book.init_position(node_id, KNOWN)
    return book


def order_part(book: OrderBook) -> Message:
    """The state's order fields but its errors: what a rejection must leave as it was."""
    return {k: v for k, v in book.state_fields().items() if k != "errors"}


# The work of the tests: pick at a stack, drop at a station, with a horizon beyond.
PATH = ["park-1", "stack-a-1-E", "station-p2", "stack-b-1-E", "park-2"]


def started() -> OrderBook:
    """A forklift at park-1 with o1: base park-1 .. station-p2 (pick, drop), horizon beyond."""
    book = at("park-1")
    decision = book.receive(order("o1", 0, PATH, base=3,
                                  actions={1: [action("pick-1")],
                                           2: [action("drop-1", "drop")]}), KNOWN)
    assert decision.outcome == "new", decision
    return book


def drive(book: OrderBook, node_id: str, sequence_id: int) -> list[str]:
    """Drive the next edge to `node_id` and do its actions; returns the actions done."""
    book.edge_started(sequence_id - 1)
    done = []
    for due in book.node_reached(node_id, sequence_id):
        for status in (INITIALIZING, RUNNING, FINISHED):
            book.action_status(due.action_id, status)
        done.append(due.action_id)
    state(book)
    return done


# --- accepting -----------------------------------------------------------------------------


def test_the_nodes_are_the_maps():
    assert set(PATH) <= set(POSITIONS) and set(POSITIONS) == set(KNOWN)
    assert KNOWN["stack-a-1-E"].place == STACK


def test_a_new_order_where_the_vehicle_stands_is_accepted():
    book = at("park-1")
    decision = book.receive(order("o1", 0, ["park-1", "stack-a-1-E"],
                                  actions={1: [action("pick-1")]}), KNOWN)
    assert decision.accepted and decision.outcome == "new" and decision.error is None
    (leg,) = decision.legs
    assert (leg.edge.edge_id, leg.edge.sequence_id) == ("park-1>stack-a-1-E", 1)
    assert (leg.edge.start_node_id, leg.end.node_id, leg.end.sequence_id) == (
        "park-1", "stack-a-1-E", 2)
    assert [a.action_id for a in leg.end.actions] == ["pick-1"]
    assert leg.end.actions[0].parameters == {"stationType": "floor"}
    seen = state(book)
    # 6.6.1, 6.10.2: the first node is trivially reachable, so it counts as traversed
    assert (seen["orderId"], seen["orderUpdateId"]) == ("o1", 0)
    assert (seen["lastNodeId"], seen["lastNodeSequenceId"]) == ("park-1", 0)
    assert [(n["nodeId"], n["sequenceId"], n["released"]) for n in seen["nodeStates"]] == [
        ("stack-a-1-E", 2, True)]
    assert seen["nodeStates"][0]["nodePosition"]["mapId"] == "small"
    assert [(e["edgeId"], e["sequenceId"]) for e in seen["edgeStates"]] == [
        ("park-1>stack-a-1-E", 1)]
    assert seen["actionStates"] == [
        {"actionId": "pick-1", "actionType": "pick", "actionStatus": WAITING}]
    assert seen["errors"] == [] and seen["paused"] is False and seen["newBaseRequest"] is False


def test_the_first_nodes_actions_are_due_at_once():
    book = at("station-p1")
    decision = book.receive(order("o1", 0, ["station-p1"], actions={0: [action("pick-0")]}),
                            KNOWN)
    assert [a.action_id for a in decision.start_actions] == ["pick-0"]
    assert decision.legs == ()
    assert not book.may_drive()  # a HARD pick on the node reached
    book.action_status("pick-0", RUNNING)
    book.action_status("pick-0", FINISHED, "picked")
    assert statuses(book) == {"pick-0": FINISHED}
    assert master_sees(state(book), {"pick-0"}) == "finished"
    assert book.may_drive()


def test_an_order_is_driven_through_to_the_masters_finish():
    book = at("park-1")
    book.receive(order("o1", 0, PATH[:3], actions={1: [action("pick-1")],
                                                    2: [action("drop-1", "drop")]}), KNOWN)
    assert master_sees(state(book), {"pick-1", "drop-1"}) == "running"
    assert book.edge_started(1) == ()
    assert not book.on_node
    due = book.node_reached("stack-a-1-E", 2)
    assert [a.action_id for a in due] == ["pick-1"]
    seen = state(book)
    assert (seen["lastNodeId"], seen["lastNodeSequenceId"]) == ("stack-a-1-E", 2)
    assert [n["nodeId"] for n in seen["nodeStates"]] == ["station-p2"]
    assert [e["sequenceId"] for e in seen["edgeStates"]] == [3]
    # 6.12: the HARD pick keeps the vehicle standing until it ends
    assert not book.may_drive()
    with pytest.raises(ValueError, match="may not drive"):
        book.edge_started(3)
    book.action_status("pick-1", INITIALIZING)
    book.action_status("pick-1", RUNNING)
    assert statuses(book)["pick-1"] == RUNNING and not book.may_drive()
    book.action_status("pick-1", FINISHED, "pallet on the forks")
    assert book.may_drive()
    assert drive(book, "station-p2", 4) == ["drop-1"]
    seen = state(book)
    assert seen["nodeStates"] == [] and seen["edgeStates"] == []
    assert {s["actionId"]: s.get("resultDescription") for s in seen["actionStates"]} == {
        "pick-1": "pallet on the forks", "drop-1": None}
    assert master_sees(seen, {"pick-1", "drop-1"}) == "finished"
    assert not book.active and seen["orderId"] == "o1"  # kept until a new order (6.10.6)


def test_events_out_of_turn_are_the_gateways_bug():
    book = started()
    with pytest.raises(ValueError, match="next released edge"):
        book.edge_started(3)
    with pytest.raises(ValueError, match="next node"):
        book.node_reached("stack-a-1-E", 2)  # not left park-1 yet
    book.edge_started(1)
    with pytest.raises(ValueError, match="already on edge"):
        book.edge_started(1)
    with pytest.raises(ValueError, match="next node"):
        book.node_reached("station-p2", 4)
    with pytest.raises(ValueError, match="no action"):
        book.action_status("nothing", RUNNING)


def test_a_multi_node_order_with_a_horizon_stops_at_the_last_released_node():
    book = started()
    seen = state(book)
    assert [(n["nodeId"], n["released"]) for n in seen["nodeStates"]] == [
        ("stack-a-1-E", True), ("station-p2", True), ("stack-b-1-E", False), ("park-2", False)]
    assert [(e["sequenceId"], e["released"]) for e in seen["edgeStates"]] == [
        (1, True), (3, True), (5, False), (7, False)]
    assert book.decision_point() == ("station-p2", 4)
    assert seen["newBaseRequest"] is False
    drive(book, "stack-a-1-E", 2)
    assert state(book)["newBaseRequest"] is True  # on the way to the decision point
    drive(book, "station-p2", 4)
    seen = state(book)
    assert [n["nodeId"] for n in seen["nodeStates"]] == ["stack-b-1-E", "park-2"]
    assert master_sees(seen, {"pick-1", "drop-1"}) == "active"
    assert book.active  # waiting for its update
    with pytest.raises(ValueError, match="next released edge"):
        book.edge_started(5)  # 6.6.1: a horizon edge must not be traversed


def test_the_decision_only_lists_released_edges():
    book = at("park-1")
    decision = book.receive(order("o1", 0, PATH, base=3), KNOWN)
    assert [(leg.edge.sequence_id, leg.end.node_id) for leg in decision.legs] == [
        (1, "stack-a-1-E"), (3, "station-p2")]


# --- updates -------------------------------------------------------------------------------


def update_at_decision_point(update_id: int = 1, **kwargs: Any) -> Message:
    return order("o1", update_id, PATH[2:], start=4,
                 actions={1: [action("drop-2", "drop")]}, **kwargs)


def test_an_update_is_stitched_at_the_decision_point_before_the_vehicle_gets_there():
    book = started()
    drive(book, "stack-a-1-E", 2)
    decision = book.receive(update_at_decision_point(base=2), KNOWN)
    assert decision.outcome == "update" and decision.start_actions == ()
    assert [(leg.edge.edge_id, leg.end.node_id, leg.end.sequence_id) for leg in decision.legs
            ] == [("station-p2>stack-b-1-E", "stack-b-1-E", 6)]
    seen = state(book)
    assert seen["orderUpdateId"] == 1
    assert [(n["nodeId"], n["sequenceId"], n["released"]) for n in seen["nodeStates"]] == [
        ("station-p2", 4, True), ("stack-b-1-E", 6, True), ("park-2", 8, False)]
    assert [(e["sequenceId"], e["released"]) for e in seen["edgeStates"]] == [
        (3, True), (5, True), (7, False)]
    assert statuses(book) == {"pick-1": FINISHED, "drop-1": WAITING, "drop-2": WAITING}
    assert book.decision_point() == ("stack-b-1-E", 6)
    assert drive(book, "station-p2", 4) == ["drop-1"]
    assert drive(book, "stack-b-1-E", 6) == ["drop-2"]
    assert master_sees(state(book), {"pick-1", "drop-1", "drop-2"}) == "active"


def test_an_update_is_stitched_when_the_vehicle_waits_at_the_decision_point():
    book = started()
    drive(book, "stack-a-1-E", 2)
    drive(book, "station-p2", 4)
    decision = book.receive(update_at_decision_point(), KNOWN)
    assert [leg.edge.sequence_id for leg in decision.legs] == [5, 7]
    seen = state(book)
    assert [(n["nodeId"], n["released"]) for n in seen["nodeStates"]] == [
        ("stack-b-1-E", True), ("park-2", True)]
    assert seen["newBaseRequest"] is False  # no horizon left to ask for
    drive(book, "stack-b-1-E", 6)
    drive(book, "park-2", 8)
    assert master_sees(state(book), {"pick-1", "drop-1", "drop-2"}) == "finished"


def test_an_update_may_delete_the_horizon():
    book = started()
    decision = book.receive(order("o1", 1, ["station-p2"], start=4), KNOWN)
    assert decision.outcome == "update" and decision.legs == ()
    assert [n["nodeId"] for n in state(book)["nodeStates"]] == ["stack-a-1-E", "station-p2"]


def test_the_stitching_node_keeps_its_first_actions():
    book = started()
    repeat = update_at_decision_point()
    repeat["nodes"][0]["actions"] = [action("drop-1", "drop")]  # as first sent: fine
    assert book.receive(repeat, KNOWN).outcome == "update"
    assert list(statuses(book)) == ["pick-1", "drop-1", "drop-2"]


@pytest.mark.parametrize("spoil", ["node", "sequence", "actions"])
def test_an_update_off_the_decision_point_is_rejected_and_the_order_left_as_it_was(spoil):
    book = started()
    drive(book, "stack-a-1-E", 2)
    before = order_part(book)
    if spoil == "node":
        wrong = order("o1", 1, ["stack-a-1-E", "station-p2"], start=4)
        wrong["nodes"][0]["sequenceId"] = 4  # keeps the sequence, names another node
        wrong["nodes"][1]["sequenceId"], wrong["edges"][0]["sequenceId"] = 6, 5
    elif spoil == "sequence":
        wrong = order("o1", 1, ["station-p2", "stack-b-1-E"], start=2)
    else:
        wrong = update_at_decision_point()
        wrong["nodes"][0]["actions"] = [action("new-drop", "drop")]
    decision = book.receive(wrong, KNOWN)
    assert decision.outcome == "rejected" and not decision.accepted
    assert decision.error is not None and decision.error["errorType"] == ORDER_UPDATE_ERROR
    assert decision.error["errorLevel"] == "WARNING"
    assert refs(decision.error) | {"headerId": "-"} == {
        "topic": "order", "headerId": "-", "orderId": "o1", "orderUpdateId": "1",
        "nodeId": wrong["nodes"][0]["nodeId"],
        "sequenceId": str(wrong["nodes"][0]["sequenceId"])}
    assert order_part(book) == before
    assert state(book)["errors"] == [decision.error]
    # the vehicle goes on with its order, and a right update is taken afterwards
    assert drive(book, "station-p2", 4) == ["drop-1"]
    assert book.receive(update_at_decision_point(), KNOWN).accepted
    assert state(book)["errors"] == []  # 6.6.4: reported until an order is accepted


def test_an_update_continues_a_finished_order_from_its_last_node():
    book = at("park-1")
    book.receive(order("o1", 0, PATH[:3]), KNOWN)
    drive(book, "stack-a-1-E", 2)
    drive(book, "station-p2", 4)
    assert not book.active
    wrong = order("o1", 1, ["stack-a-1-E", "park-2"], start=2)
    assert book.receive(wrong, KNOWN).error["errorType"] == ORDER_UPDATE_ERROR
    decision = book.receive(order("o1", 2, ["station-p2", "park-2"], start=4), KNOWN)
    assert decision.outcome == "update"
    assert [leg.end.node_id for leg in decision.legs] == ["park-2"]
    assert state(book)["orderUpdateId"] == 2


def test_a_lower_update_id_is_rejected():
    book = started()
    assert book.receive(update_at_decision_point(), KNOWN).accepted
    before = order_part(book)
    decision = book.receive(order("o1", 0, PATH, base=3), KNOWN)
    assert decision.error["errorType"] == ORDER_UPDATE_ERROR
    assert refs(decision.error)["orderUpdateId"] == "0"
    assert order_part(book) == before


def test_the_same_update_twice_is_ignored():
    book = started()
    first = update_at_decision_point()
    assert book.receive(first, KNOWN).accepted
    before = book.state_fields()
    again = {**copy.deepcopy(first), **header()}  # resent: another header, the same order
    assert book.receive(again, KNOWN).outcome == "ignored"
    assert book.state_fields() == before


def test_the_same_update_id_with_other_content_is_an_error():
    book = started()
    assert book.receive(update_at_decision_point(), KNOWN).accepted
    before = order_part(book)
    other = update_at_decision_point(base=2)
    decision = book.receive(other, KNOWN)
    assert decision.error["errorType"] == ORDER_UPDATE_ERROR
    assert "other content" in decision.error["errorDescription"]
    assert order_part(book) == before


# --- new orders ----------------------------------------------------------------------------


def test_a_new_order_while_one_is_active_is_rejected():
    book = started()
    decision = book.receive(order("o2", 0, ["park-1", "station-p2"]), KNOWN)
    assert decision.error["errorType"] == ORDER_UPDATE_ERROR
    assert refs(decision.error)["orderId"] == "o2"
    assert state(book)["orderId"] == "o1"
    drive(book, "stack-a-1-E", 2)
    drive(book, "station-p2", 4)
    # only the horizon is left: still waiting for an update (2.1.0's reading of Figure 8)
    assert book.receive(order("o2", 0, ["station-p2", "park-2"]), KNOWN).outcome == "rejected"


def test_a_new_order_after_the_last_one_finished_starts_afresh():
    book = at("park-1")
    book.receive(order("o1", 0, PATH[:2], actions={1: [action("pick-1")]}), KNOWN)
    drive(book, "stack-a-1-E", 2)
    book.receive(order("o1", 9, ["park-2"]), KNOWN)  # rejected: an error to clear
    assert state(book)["errors"]
    decision = book.receive(order("o2", 0, ["stack-a-1-E", "station-p2"]), KNOWN)
    assert decision.outcome == "new"
    seen = state(book)
    assert (seen["orderId"], seen["orderUpdateId"], seen["lastNodeId"]) == (
        "o2", 0, "stack-a-1-E")
    assert seen["actionStates"] == [] and seen["errors"] == []  # the old order's states go


def test_a_new_order_far_from_the_vehicle_is_no_route():
    book = at("park-1")
    decision = book.receive(order("o1", 0, ["stack-a-1-E", "station-p2"]), KNOWN)
    assert decision.error["errorType"] == NO_ROUTE_ERROR
    assert refs(decision.error)["nodeId"] == "stack-a-1-E"
    assert state(book)["orderId"] == "" and not book.active


def test_a_vehicle_that_knows_not_where_it_is_takes_no_order():
    assert OrderBook().receive(order("o1", 0, ["park-1"]), KNOWN).outcome == "rejected"


@pytest.mark.parametrize("how", ["same-pose-node", "pose-given", "temporary-node", "deviation"])
def test_a_first_node_within_reach_is_accepted(how):
    book = at("park-1")
    path, where = ["park-1", "stack-a-1-E"], None
    if how == "same-pose-node":
        path[0] = "station-p1"  # another node on park-1's pose
    elif how == "pose-given":
        book, where = OrderBook(), Position(9.0, 13.0, -1.5708)
    message = order("o1", 0, path)
    first = message["nodes"][0]
    if how == "temporary-node":  # 6.6.3.1: a node off the map where the vehicle stands
        first["nodeId"] = message["edges"][0]["startNodeId"] = "here"
    elif how == "deviation":  # 6.6.3.1: another node with a deviation range reaching here
        first["nodeId"] = message["edges"][0]["startNodeId"] = "park-2"
        first["nodePosition"] = {**POSITIONS["park-2"], "allowedDeviationXY": 2.5}
    decision = book.receive(message, KNOWN, at=where)
    assert decision.outcome == "new", decision.error
    assert state(book)["lastNodeId"] == first["nodeId"]


def test_a_first_node_at_another_heading_is_out_of_reach():
    book = OrderBook()
    decision = book.receive(order("o1", 0, ["park-1"]), KNOWN, at=Position(9.0, 13.0, 0.0))
    assert decision.error["errorType"] == NO_ROUTE_ERROR


def test_an_unknown_node_is_no_route():
    book = at("park-1")
    message = order("o1", 0, ["park-1", "stack-a-1-E"])
    message["nodes"][1]["nodeId"] = message["edges"][0]["endNodeId"] = "stack-z-9-E"
    decision = book.receive(message, KNOWN)
    assert decision.error["errorType"] == NO_ROUTE_ERROR
    assert refs(decision.error)["nodeId"] == "stack-z-9-E"
    assert order_part(book) == order_part(at("park-1"))
    assert book.receive(order("o1", 0, ["park-1", "stack-a-1-E"]), KNOWN).accepted


def test_an_edge_the_vehicle_cannot_drive_is_no_route():
    book = at("park-1")
    decision = book.receive(order("o1", 0, PATH[:3]), KNOWN,
                            reachable=lambda edge: edge.end_node_id != "station-p2")
    assert decision.error["errorType"] == NO_ROUTE_ERROR
    assert refs(decision.error)["edgeId"] == "stack-a-1-E>station-p2"


def test_a_trajectory_is_a_field_the_vehicle_cannot_use():
    message = order("o1", 0, PATH[:2])
    message["edges"][0]["trajectory"] = {"degree": 1, "knotVector": [0, 0, 1, 1],
                                         "controlPoints": [{"x": 9, "y": 13}, {"x": 3, "y": 15}]}
    validate("order", message)
    decision = at("park-1").receive(message, KNOWN)
    assert decision.error["errorType"] == ORDER_ERROR
    assert refs(decision.error)["field"] == "trajectory"


@pytest.mark.parametrize(("where", "kind", "why"), [
    (1, "weld", "cannot do 'weld'"),
    (1, "startPause", "cannot do 'startPause'"),  # an instant action only (6.8.1)
    ("edge", "pick", "not on an edge"),
    (2, "drop", "not at park-2"),
    (3, "pick", "cannot do"),  # a horizon node's action is checked too
])
def test_an_action_the_vehicle_cannot_do_is_an_order_error_naming_it(where, kind, why):
    message = order("o1", 0, ["park-1", "stack-a-1-E", "park-2", "station-p2"], base=3)
    if where == "edge":
        message["edges"][0]["actions"] = [action("a1", kind)]
    elif where == 3:
        message["nodes"][3]["actions"] = [action("a1", "weld")]
    else:
        message["nodes"][where]["actions"] = [action("a1", kind)]
    book = at("park-1")
    decision = book.receive(message, KNOWN)
    error = decision.error
    assert error["errorType"] == ORDER_ERROR and why in error["errorDescription"]
    found = refs(error)
    assert (found["topic"], found["orderId"], found["orderUpdateId"]) == ("order", "o1", "0")
    assert (found["actionId"], found["actionType"]) == ("a1", kind if where != 3 else "weld")
    assert not book.active and state(book)["actionStates"] == []


def spoiled(how: str) -> Message:
    message = order("o1", 0, PATH, base=3)
    nodes_, edges_ = message["nodes"], message["edges"]
    if how == "node-sequence-gap":
        nodes_[2]["sequenceId"], edges_[2]["sequenceId"] = 6, 7  # 0, 2, 6: not consecutive
    elif how == "odd-first-node":
        for step in (*nodes_, *edges_):
            step["sequenceId"] += 1
    elif how == "edge-sequence":
        edges_[1]["sequenceId"] = 5
    elif how == "edge-not-joining":
        edges_[1]["startNodeId"] = "park-2"
    elif how == "released-after-horizon":
        nodes_[4]["released"] = True
    elif how == "released-edge-to-horizon":
        edges_[2]["released"] = True
    elif how == "edge-count":
        del edges_[3]
    elif how == "first-not-released":
        for step in (*nodes_, *edges_):
            step["released"] = False
    elif how == "duplicate-action":
        nodes_[1]["actions"] = [action("a1")]
        nodes_[2]["actions"] = [action("a1", "drop")]
    elif how == "no-node":
        del nodes_[:], edges_[:]
    validate("order", message)  # all of these pass the schema
    return message


@pytest.mark.parametrize("how", [
    "node-sequence-gap", "odd-first-node", "edge-sequence", "edge-not-joining",
    "released-after-horizon", "released-edge-to-horizon", "edge-count", "first-not-released",
    "duplicate-action", "no-node"])
def test_a_malformed_order_is_a_validation_error(how):
    book = at("park-1")
    decision = book.receive(spoiled(how), KNOWN)
    assert decision.error["errorType"] == VALIDATION_ERROR, decision.error
    found = refs(decision.error)
    assert (found["topic"], found["orderId"], found["orderUpdateId"]) == ("order", "o1", "0")
    assert "actionId" not in found  # else vda-5050-lib would not read it as the order's error
    assert order_part(book) == order_part(at("park-1"))


def test_rejections_are_reported_once_each_until_an_order_is_accepted():
    book = at("park-1")
    bad = spoiled("edge-sequence")
    book.receive(bad, KNOWN)
    book.receive(bad, KNOWN)  # the same bad order again
    book.receive(order("o2", 0, ["park-2"]), KNOWN)
    assert [e["errorType"] for e in state(book)["errors"]] == [VALIDATION_ERROR, NO_ROUTE_ERROR]
    assert book.receive(order("o3", 0, ["park-1"]), KNOWN).accepted
    assert state(book)["errors"] == []


# --- cancelling ----------------------------------------------------------------------------


def test_cancel_on_an_edge_drives_to_its_end_node_then_finishes():
    book = started()
    book.edge_started(1)
    assert book.cancel("c1") == ()
    seen = state(book)
    # Figure 9: a vehicle that cannot stop between nodes keeps the node it drives to
    assert [n["nodeId"] for n in seen["nodeStates"]] == ["stack-a-1-E"]
    assert seen["edgeStates"] == []
    assert statuses(book) == {"pick-1": FAILED, "drop-1": FAILED, "c1": RUNNING}
    assert book.node_reached("stack-a-1-E", 2) == ()  # the cancelled pick is not done
    seen = state(book)
    assert statuses(book)["c1"] == FINISHED
    assert seen["nodeStates"] == [] and seen["edgeStates"] == []
    assert (seen["orderId"], seen["orderUpdateId"]) == ("o1", 0)  # 6.6.3: kept
    assert master_sees(seen, {"pick-1", "drop-1"}) == "finished"
    assert not book.active


def test_cancel_waits_for_the_actions_under_way():
    book = started()
    drive(book, "stack-a-1-E", 2)
    book.receive(update_at_decision_point(), KNOWN)  # stitched, then cancelled
    book.edge_started(3)
    book.node_reached("station-p2", 4)
    book.action_status("drop-1", RUNNING)
    assert book.cancel("c1") == ("drop-1",)
    seen = state(book)
    assert seen["nodeStates"] == [] and seen["edgeStates"] == []
    assert statuses(book) == {"pick-1": FINISHED, "drop-1": RUNNING, "drop-2": FAILED,
                              "c1": RUNNING}
    assert book.active
    book.action_status("drop-1", FAILED, "interrupted")
    assert statuses(book)["c1"] == FINISHED and not book.active


def test_cancel_without_an_order_fails_with_no_order_to_cancel():
    for book in (OrderBook(), at("park-1")):
        assert book.cancel("c1") == ()
        seen = state(book)
        assert statuses(book) == {"c1": FAILED}
        (error,) = seen["errors"]
        assert (error["errorType"], error["errorLevel"]) == (NO_ORDER_TO_CANCEL, "WARNING")
        # 6.6.3.2: the instant action's id; vda-5050-lib also wants the topic
        assert refs(error) == {"topic": "instantActions", "actionId": "c1",
                               "actionType": "cancelOrder"}


def test_a_cancelled_order_is_over():
    book = started()
    book.cancel("c1")
    assert statuses(book)["c1"] == FINISHED  # standing on park-1, nothing under way
    book.cancel("c2")  # 6.6.3.2: the previous order was cancelled
    assert statuses(book)["c2"] == FAILED
    assert state(book)["errors"][0]["errorType"] == NO_ORDER_TO_CANCEL
    update = order("o1", 1, ["park-1", "stack-a-1-E"])
    assert book.receive(update, KNOWN).error["errorType"] == ORDER_UPDATE_ERROR
    decision = book.receive(order("o2", 0, ["park-1", "stack-a-1-E"]), KNOWN)
    assert decision.outcome == "new"  # 6.6.3.1: ready for a new order where it stands
    assert state(book)["errors"] == [] and statuses(book) == {}


# --- pause, instant actions, action states -------------------------------------------------


def test_pause_and_resume():
    book = started()
    book.pause("p1")
    seen = state(book)
    assert seen["paused"] is True and statuses(book) == {
        "pick-1": WAITING, "drop-1": WAITING, "p1": FINISHED}
    assert not book.may_drive()
    with pytest.raises(ValueError, match="may not drive"):
        book.edge_started(1)
    book.pause()  # idempotent (6.8.1)
    assert book.receive(update_at_decision_point(), KNOWN).accepted  # orders still come in
    book.resume("r1")
    assert state(book)["paused"] is False and statuses(book)["r1"] == FINISHED
    assert book.may_drive()
    assert drive(book, "stack-a-1-E", 2) == ["pick-1"]


def test_action_status_progression():
    book = started()
    drive(book, "stack-a-1-E", 2)
    book.edge_started(3)
    book.node_reached("station-p2", 4)
    assert statuses(book)["drop-1"] == WAITING
    book.action_status("drop-1", INITIALIZING)
    assert statuses(book)["drop-1"] == INITIALIZING
    book.action_status("drop-1", RUNNING)
    book.action_status("drop-1", PAUSED)
    # the 2.0.0 state schema has no PAUSED: reported as still RUNNING (state() validates)
    assert statuses(book)["drop-1"] == RUNNING and book.actions["drop-1"].status == PAUSED
    with pytest.raises(ValueError, match="cannot follow"):
        book.action_status("drop-1", WAITING)
    book.action_status("drop-1", RUNNING)
    book.action_status("drop-1", FAILED, "stack occupied", error_type="dropError")
    with pytest.raises(ValueError, match="already ended FAILED"):
        book.action_status("drop-1", FINISHED)
    (error,) = state(book)["errors"]
    assert (error["errorType"], error["errorDescription"]) == ("dropError", "stack occupied")
    assert refs(error) == {"topic": "order", "actionId": "drop-1", "actionType": "drop"}
    book.receive(order("o1", 1, ["station-p2", "park-2"], start=4), KNOWN)
    assert state(book)["errors"] == [error]  # an update keeps the order's action errors
    drive(book, "park-2", 6)
    book.receive(order("o2", 0, ["park-2"]), KNOWN)
    assert state(book)["errors"] == []  # a new order does not


def test_an_action_that_does_not_block_lets_the_vehicle_drive():
    book = OrderBook(order_actions={"detectObject": frozenset({STACK})})
    assert book.init_position("park-1", KNOWN)
    book.receive(order("o1", 0, ["park-1", "stack-a-1-E", "station-p2"],
                       actions={1: [action("d1", "detectObject", "NONE")]}), KNOWN)
    book.edge_started(1)
    book.node_reached("stack-a-1-E", 2)
    book.action_status("d1", RUNNING)
    assert book.may_drive()  # 6.12: NONE allows driving
    book.edge_started(3)


def test_init_position():
    book = OrderBook()
    assert not book.init_position("nowhere", KNOWN, "i1")
    assert book.init_position("park-2", KNOWN, "i2")
    seen = state(book)
    assert (seen["lastNodeId"], seen["lastNodeSequenceId"]) == ("park-2", 0)
    assert statuses(book) == {"i1": FAILED, "i2": FINISHED}
    book.receive(order("o1", 0, ["park-2", "stack-a-1-E"]), KNOWN)
    assert not book.init_position("park-1", KNOWN, "i3")  # not while an order is active
    assert state(book)["lastNodeId"] == "park-2"


def test_instant_actions_are_recorded_and_kept_past_a_new_order_while_under_way():
    book = at("park-1")
    book.instant("s1", "stateRequest")
    book.instant("f1", "factsheetRequest", RUNNING)
    assert statuses(book) == {"s1": FINISHED, "f1": RUNNING}
    book.receive(order("o1", 0, ["park-1"]), KNOWN)
    assert statuses(book) == {"f1": RUNNING}


def test_an_instant_action_as_the_2_0_0_schema_spells_it():
    read = Action.read({"actionId": "i1", "actionName": "startPause", "blockingType": "HARD"})
    assert (read.action_id, read.action_type) == ("i1", "startPause")


def test_a_node_position_without_theta_stays_out_of_the_state():
    """The state schema requires theta in a nodeState's nodePosition, the order's does not."""
    message = order("o1", 0, ["park-1", "stack-a-1-E"])
    del message["nodes"][1]["nodePosition"]["theta"]
    validate("order", message)
    book = at("park-1")
    assert book.receive(message, KNOWN).accepted
    assert "nodePosition" not in state(book)["nodeStates"][0]
