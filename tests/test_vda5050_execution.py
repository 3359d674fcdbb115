"""One emulated forklift's VDA 5050 execution, pure (vda5050/execution.py): what it asks its
agent to drive, the node actions over the handling times, the goods they move, pause, cancel
and the answers that are not a plan. The map is `paper`'s; time is given by the test."""

from __future__ import annotations

import itertools
from typing import Any

import pytest

from fleet.vda5050.execution import BLOCKED_RETRY_S, RETRY_S, Execution, GoodsMoved, Handling
from fleet.vda5050.map import edge_id, nodes
from fleet.vda5050.orders import Position
from fleet.world.layout_file import load_layout

NODES = {n.node_id: n for n in nodes(load_layout("paper"))}
PICK_S, DROP_S = 5.0, 4.0


def order(path: list[str], actions: dict[int, list[str]] | None = None,
          order_id: str = "o1") -> dict[str, Any]:
    ids = itertools.count()
    return {
        "headerId": 0, "orderId": order_id, "orderUpdateId": 0,
        "nodes": [{"nodeId": n, "sequenceId": 2 * k, "released": True,
                   "actions": [{"actionId": f"a{next(ids)}", "actionType": kind,
                                "blockingType": "HARD"} for kind in (actions or {}).get(k, [])]}
                  for k, n in enumerate(path)],
        "edges": [{"edgeId": edge_id(a, b), "sequenceId": 2 * k + 1, "released": True,
                   "startNodeId": a, "endNodeId": b, "actions": []}
                  for k, (a, b) in enumerate(itertools.pairwise(path))]}


def forklift(at: str = "station-p1", *, drivable=lambda a, b: True,
             escapes=lambda pose, filled: True, filled: set | None = None) -> Execution:
    node = NODES[at]
    return Execution(NODES, node.pose, Position(node.x, node.y, node.theta),
                     Handling(PICK_S, DROP_S), set() if filled is None else filled, drivable,
                     escapes)


def statuses(execution: Execution) -> dict[str, str]:
    return {s.action.action_type + s.action.action_id[1:]: s.status
            for s in execution.book.actions.values()}


def drive(execution: Execution, t: float, took: float = 10.0) -> float:
    """Ask for the next leg at t, commit it arriving `took` later, arrive; the arrival time."""
    leg = execution.next_leg(t)
    assert leg is not None
    execution.planned(leg, t + took, "", t)
    assert execution.next_leg(t) is None  # one leg at a time
    assert not execution.observed(leg.goal, Position(0, 0, 0), True, t + took / 2)
    assert execution.observed(leg.goal, Position(0, 0, 0), False, t + took)
    return t + took


def test_pick_drive_drop_over_the_handling_times_moves_the_goods():
    stack = NODES["stack-s1-1-S"]
    f = forklift()
    assert f.order(order(["station-p1", "stack-s1-1-S"], {0: ["pick"], 1: ["drop"]})).accepted
    assert f.next_leg(0.0) is None  # the pick holds it (HARD, forks in the station)
    assert f.advance(0.0) == (True, [])
    assert statuses(f) == {"pick0": "RUNNING", "drop1": "WAITING"}
    assert f.advance(PICK_S - 0.1) == (False, [])
    assert f.advance(PICK_S)[0] and f.loaded
    leg = f.next_leg(PICK_S)
    assert (leg.start, leg.goal, leg.loaded) == (NODES["station-p1"].pose, stack.pose, True)
    f.planned(leg, 30.0, "", PICK_S)
    assert f.observed(stack.pose, Position(stack.x, stack.y, stack.theta), False, 30.0)
    f.advance(30.0)
    assert statuses(f)["drop1"] == "RUNNING"
    assert f.advance(30.0 + DROP_S) == (True, [GoodsMoved(stack.cell, True, 30.0 + DROP_S)])
    assert stack.cell in f.filled and not f.loaded
    assert not f.book.active


def test_a_pick_at_an_empty_stack_fails_and_the_order_goes_on():
    f = forklift()
    f.order(order(["station-p1", "stack-s1-1-S", "station-p1"], {1: ["pick"]}))
    t = drive(f, 0.0)
    f.advance(t)
    assert statuses(f) == {"pick0": "FAILED"}
    assert f.book.errors[0].error_type == "orderError"
    assert "holds no goods" in f.book.errors[0].description
    assert f.next_leg(t) is not None  # a failed action holds nothing


def test_a_drop_that_would_wall_the_forklift_in_fails():
    f = forklift(escapes=lambda pose, filled: False)
    f.loaded = True
    f.order(order(["station-p1", "stack-s1-1-E"], {1: ["drop"]}))
    t = drive(f, 0.0)
    assert f.advance(t) == (True, [])
    assert statuses(f) == {"drop0": "FAILED"} and f.loaded and not f.filled
    assert "wall the forklift in" in f.book.errors[0].description


def test_a_pause_holds_the_next_leg_and_the_forks():
    f = forklift()
    f.order(order(["station-p1", "stack-s1-1-S"], {0: ["pick"]}))
    f.advance(0.0)
    f.instant_actions({"instantActions": [{"actionId": "p", "actionType": "startPause"}]}, 2.0)
    assert f.advance(20.0) == (False, []) and statuses(f)["pick0"] == "RUNNING"
    assert f.next_leg(20.0) is None
    f.instant_actions({"instantActions": [{"actionId": "r", "actionType": "stopPause"}]}, 20.0)
    assert f.advance(20.0 + PICK_S - 2.0 - 0.1) == (False, [])  # 2 s were done before
    assert f.advance(20.0 + PICK_S - 2.0)[0] and f.loaded
    assert f.next_leg(23.0) is not None


def test_a_cancel_while_planning_waits_for_the_answer_and_stops_on_the_next_node():
    f = forklift()
    f.order(order(["station-p1", "stack-s1-1-S", "station-p1"]))
    leg = f.next_leg(0.0)
    cancel = {"instantActions": [{"actionId": "c", "actionType": "cancelOrder"}]}
    assert f.instant_actions(cancel, 0.5) == set()
    assert "c" not in f.book.actions  # deferred: the answer decides where it stands
    replay = f.planned(leg, 10.0, "", 1.0)
    assert replay == [(cancel, 0.5)]
    f.instant_actions(*replay[0])
    assert [n.node_id for n in f.book.nodes] == ["stack-s1-1-S"]  # it cannot stop between
    assert f.observed(leg.goal, Position(0, 0, 0), False, 10.0)
    assert f.book.actions["c"].status == "FINISHED" and not f.book.active
    assert f.next_leg(10.0) is None


def test_a_leg_not_given_now_is_asked_again_and_a_closed_way_is_a_no_route_error():
    ways = {"open": True}
    f = forklift(drivable=lambda a, b: ways["open"])
    f.order(order(["station-p1", "stack-s1-1-S"]))
    leg = f.next_leg(0.0)
    f.planned(leg, None, "cell held by vehicle 2", 0.0)
    assert f.information[0]["infoDescription"] == "cell held by vehicle 2"
    assert f.next_leg(RETRY_S - 0.1) is None
    again = f.next_leg(RETRY_S)
    assert again is not None
    ways["open"] = False
    f.planned(again, None, "no path", RETRY_S)
    assert [e.error_type for e in f.book.errors] == ["noRouteError"]
    assert f.next_leg(RETRY_S + BLOCKED_RETRY_S - 0.1) is None
    ways["open"] = True
    drive(f, RETRY_S + BLOCKED_RETRY_S)
    assert f.book.errors == []  # driven: the error went with it


def test_a_refused_leg_asked_ahead_is_asked_again_for_a_start_a_second_later():
    """The gateway asks for a leg its lead ahead of now (here 2 s, more than RETRY_S): the
    next try is for a start RETRY_S after the refused one, not at once."""
    f = forklift()
    f.order(order(["station-p1", "stack-s1-1-S"]))
    lead = 2.0
    leg = f.next_leg(0.0 + lead)
    f.planned(leg, None, "cell held by vehicle 2", 0.05)  # answered at once
    assert f.next_leg(0.1 + lead) is None
    assert f.next_leg(RETRY_S - 0.1 + lead) is None and f.next_leg(RETRY_S + lead) is not None


def test_an_edge_the_forklift_cannot_drive_is_refused_with_the_order():
    f = forklift(drivable=lambda a, b: False)
    decision = f.order(order(["station-p1", "stack-s1-1-S"]))
    assert decision.outcome == "rejected"
    assert decision.error["errorType"] == "noRouteError"


@pytest.mark.parametrize("node_id, ok", [("station-p1", True), ("stack-s1-1-S", False)])
def test_init_position_is_taken_only_where_the_forklift_stands(node_id, ok):
    f = forklift()
    f.instant_actions({"instantActions": [{"actionId": "i", "actionType": "initPosition",
                                           "actionParameters": [
                                               {"key": "lastNodeId", "value": node_id}]}]}, 0.0)
    assert f.book.actions["i"].status == ("FINISHED" if ok else "FAILED")
    assert (f.book.last_node_id == node_id) == ok


def test_an_instant_action_the_forklift_lacks_is_an_instant_action_error():
    f = forklift()
    f.instant_actions({"instantActions": [{"actionId": "x", "actionType": "liftForks"}]}, 0.0)
    assert f.book.actions["x"].status == "FAILED"
    assert f.book.errors[0].error_type == "instantActionError"


LANE_NODES = {n.node_id: n for n in nodes(load_layout("paper002"))}


def lane_agv(at: str = "pile-c9") -> Execution:
    """A seed 002 AGV: shelves in every slot, a lift that works at once."""
    node = LANE_NODES[at]
    slots = {n.cell for n in LANE_NODES.values() if n.place == "slot"}
    return Execution(LANE_NODES, node.pose, Position(node.x, node.y, node.theta),
                     Handling(0.0, 0.0), slots, lambda a, b: True, lambda pose, filled: True,
                     noun="AGV")


def test_a_lane_agv_lifts_a_shelf_and_does_not_drive_it_under_another():
    """Its slot's shelf lifted, the AGV takes it to a station; sent on into a slot that
    holds a shelf, it asks for no leg and says why (a noRouteError naming the slot), until
    that shelf is lifted away; then it drives in and puts its own down."""
    agv = lane_agv()
    home, full = LANE_NODES["slot-s-10-27"], LANE_NODES["slot-s-11-27"]
    assert agv.order(order(["pile-c9", "slot-s-10-27", "station-p29", "slot-s-11-27"],
                           {1: ["pick"], 3: ["drop"]})).accepted
    t = drive(agv, 0.0)
    assert agv.advance(t)[1] == [GoodsMoved(home.cell, False, t)]  # lifted at once
    assert agv.loaded and home.cell not in agv.filled
    t = drive(agv, t)
    assert agv.next_leg(t) is None
    assert agv.waiting == "slot s-11-27: it holds a shelf"
    assert [(e.error_type, e.description) for e in agv.book.errors] == [
        ("noRouteError", "a loaded AGV cannot drive into slot s-11-27: it holds a shelf")]
    assert agv.next_leg(t + BLOCKED_RETRY_S - 0.1) is None
    agv.filled.discard(full.cell)  # another AGV lifted it
    t = drive(agv, t + BLOCKED_RETRY_S)
    assert agv.advance(t)[1] == [GoodsMoved(full.cell, True, t)]
    assert not agv.loaded and full.cell in agv.filled and not agv.book.active


def test_a_lane_agv_with_nothing_on_its_lift_has_nothing_to_put_down():
    agv = lane_agv("slot-s-10-27")
    assert agv.order(order(["slot-s-10-27"], {0: ["drop"]})).accepted
    agv.advance(0.0)
    assert statuses(agv) == {"drop0": "FAILED"}
    assert agv.book.errors[0].description == "drop: the AGV is not loaded"


@pytest.mark.parametrize(("at", "kind"), [("station-p29", "pick"), ("station-p29", "drop"),
                                          ("pile-c9", "pick"), ("pile-c9", "drop")])
def test_a_lane_agv_lifts_and_puts_down_in_slots_only(at, kind):
    """A packing station works the shelf the AGV stands with, a pile charges it: an order
    that lifts or puts down there is refused, naming the action."""
    agv = lane_agv(at)
    assert not agv.order(order([at], {0: [kind]})).accepted
    (error,) = agv.book.errors
    assert error.error_type == "orderError" and kind in error.description
    assert "slot" in error.description  # it says where the action may be


def test_a_loaded_lane_agv_waits_for_a_slot_another_brings_a_shelf_to():
    """Another AGV stands, or will, in the slot with a shelf on its lift: it may put it down
    before this one arrives, so this one does not drive in yet."""
    coming = {LANE_NODES["slot-s-11-27"].cell}
    node = LANE_NODES["station-p29"]
    agv = Execution(LANE_NODES, node.pose, Position(node.x, node.y, node.theta),
                    Handling(0.0, 0.0), set(), lambda a, b: True, lambda pose, filled: True,
                    noun="AGV", loaded=True, shelf_coming=lambda cell: cell in coming)
    assert agv.order(order(["station-p29", "slot-s-11-27"], {1: ["drop"]})).accepted
    assert agv.next_leg(0.0) is None
    assert agv.waiting == "slot s-11-27: another vehicle brings a shelf there"
    coming.clear()  # it went on without putting its shelf down there
    assert agv.next_leg(BLOCKED_RETRY_S) is not None
