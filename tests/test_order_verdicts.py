"""Seed 002's verdicts from a recording alone (fleet/analysis/lane_traffic.py,
fleet/analysis/shelves.py, fleet/analysis/battery.py): the AGVs' executed moves judged by the
lane rules, nodes shared, swaps and crossed diagonals named; every order packed and its shelf
put back once, shelves conserved; batteries within their bounds, rates and the 20 % rule.
Each check on states made by hand, then on a real order mission's recording, as it is and
with one thing broken in it."""

from __future__ import annotations

import dataclasses
import itertools
import json
from pathlib import Path

import pytest

from fleet.analysis.battery import Charge, battery_verdict
from fleet.analysis.lane_traffic import Grid, Seen, lane_breaches, meetings, tracks
from fleet.analysis.shelves import Announced, Carrying, Claim, orders_verdict
from fleet.cli import main
from fleet.dispatching.decision import Strategy, TaskKind
from fleet.mission.drive_log import AmendLeg
from fleet.mission.engine import Engine, engine_options
from fleet.mission.spec import Mission, MissionKind
from fleet.recording.inprocess import Outgoing, recorded_run, write_recording
from fleet.recording.mission_record import summary_of
from fleet.recording.reader import read_recording
from fleet.wire.protocol import MissionInfo, StackDone, VehicleState
from fleet.world.layout_file import load_layout

CHANNEL = load_layout("micro-channel")
PAPER002 = load_layout("paper002")
GRID = Grid(CHANNEL.origin, CHANNEL.cell_size)
PERIOD = 0.5


def driven(vehicle: int, cells: list[tuple[int, int]], t0: float = 0.0,
           layout=CHANNEL) -> list[Seen]:
    """States every PERIOD of an AGV driving through `cells` at one cell a second, a
    diagonal in 1.4 s, a repeated cell standing a second there."""
    ox, oy = layout.origin
    size = layout.cell_size
    knots = [(t0, cells[0])]
    for a, b in itertools.pairwise(cells):
        d = 1.4 if a[0] != b[0] and a[1] != b[1] else 1.0
        knots.append((knots[-1][0] + d, b))
    out, t = [], t0
    while t <= knots[-1][0] + 1e-9:
        for (ta, a), (tb, b) in itertools.pairwise(knots):
            if ta <= t <= tb:
                s = (t - ta) / (tb - ta)
                x, y = a[0] + s * (b[0] - a[0]), a[1] + s * (b[1] - a[1])
                break
        else:
            x, y = knots[-1][1]
        out.append(Seen(vehicle, round(t, 9), ox + x * size, oy + y * size))
        t += PERIOD
    return out


def met(*routes: list[Seen]) -> list[tuple[str, tuple[int, int]]]:
    pieces = tracks([s for r in routes for s in r], GRID, 1.5 * PERIOD)
    return [(m.kind, m.vehicles) for m in meetings(pieces, 1.0, {})]


def test_a_follower_one_cell_behind_meets_nobody():
    leader = driven(1, [(1, 0), (2, 0), (3, 0), (4, 0), (5, 0)])
    follower = driven(2, [(0, 0), (1, 0), (2, 0), (3, 0), (4, 0)])
    assert met(leader, follower) == []


def test_two_agvs_on_one_node_at_once_meet_there():
    east = driven(1, [(0, 0), (1, 0), (2, 0), (3, 0)])
    later = driven(2, [(1, 0), (2, 0)], t0=1.5)  # on (2, 0) from 2.5 s: east is there until 2.5
    later_still = driven(2, [(1, 0), (2, 0)], t0=2.0)  # enters (2, 0) as east leaves it
    assert ("node", (1, 2)) in met(east, later)
    assert met(east, later_still) == []


def test_a_swap_along_an_edge_is_named_a_swap():
    west_bound = driven(1, [(3, 1), (2, 1)])
    east_bound = driven(2, [(2, 1), (3, 1)])  # they pass through each other at 0.5 s
    assert met(west_bound, east_bound) == [("swap", (1, 2))]


def test_crossing_diagonals_of_one_block_are_caught_and_one_diagonal_later_is_not():
    ne = driven(1, [(0, 0), (1, 1)])
    nw = driven(2, [(1, 0), (0, 1)])
    assert met(ne, nw) == [("diagonal", (1, 2))]
    assert met(ne, driven(2, [(1, 0), (0, 1)], t0=1.4)) == []


def test_executed_moves_are_judged_by_the_lane_rules():
    legal = driven(1, [(0, 0), (1, 0), (2, 0), (3, 0)])  # h1-east, eastward
    wrong_way = driven(2, [(3, 0), (2, 0), (1, 0)], t0=10.0)
    pieces = tracks(legal + wrong_way, GRID, 1.5 * PERIOD)
    breaches = lane_breaches(CHANNEL, pieces)
    assert {b.vehicle for b in breaches} == {2}
    assert {b.rule for b in breaches} == {"wrong-way"}
    assert breaches[0].move == ((3, 0), (2, 0)) and breaches[0].t == pytest.approx(10.5)


def test_a_slot_driven_straight_through_is_a_breach_and_one_stopped_at_is_not():
    # Slot (2, 2) is entered from the near lane (2, 1); (2, 3) is a slot too.
    through = driven(1, [(2, 1), (2, 2), (2, 3)])
    stopped = driven(2, [(3, 1), (2, 1), (2, 2), (2, 2), (2, 1)], t0=20.0)
    pieces = tracks(through + stopped, GRID, 1.5 * PERIOD)
    assert {(b.vehicle, b.rule) for b in lane_breaches(CHANNEL, pieces)} >= {
        (1, "through-place")}
    assert all(b.vehicle == 1 for b in lane_breaches(CHANNEL, pieces))


def test_a_route_whose_start_was_not_recorded_may_have_left_through_a_door():
    """Stepping from the lane beside slot (2, 2) across the channel is a door's move only
    for a route that began at the slot. Seen from the mission's start it is a breach; seen
    after a window without states (the AGV may have left the slot unseen) it is not judged,
    but a wrong-way move after it still is."""
    across = [(2, 1), (2, 0), (3, 0), (4, 0)]
    assert {b.rule for b in lane_breaches(CHANNEL, tracks(driven(1, across), GRID,
                                                          1.5 * PERIOD))} == {"crossing-lane"}
    seen_before = driven(1, [(5, 0), (6, 0)])
    resumed = seen_before + driven(1, across, t0=10.0)
    assert lane_breaches(CHANNEL, tracks(resumed, GRID, 1.5 * PERIOD)) == []
    back = seen_before + driven(1, [(2, 1), (2, 0), (3, 0), (2, 0), (1, 0)], t0=10.0)
    assert [b.move for b in lane_breaches(CHANNEL, tracks(back, GRID, 1.5 * PERIOD))] == [
        ((3, 0), (2, 0)), ((2, 0), (1, 0))]


def test_states_further_apart_than_the_gap_are_not_joined():
    jumped = driven(1, [(0, 0), (1, 0)]) + driven(1, [(5, 0), (6, 0)], t0=5.0)
    pieces = tracks(jumped, GRID, 1.5 * PERIOD)
    assert len(pieces[1]) == 2 and lane_breaches(CHANNEL, pieces) == []


# -- shelves and orders ------------------------------------------------------------------------

SLOT = PAPER002.shelves["s-3-3"]
OTHER = PAPER002.shelves["s-4-3"]
STATION = PAPER002.packing[0]


def carrying(vehicle: int, plan: list[tuple[float, tuple[int, int] | None, bool, bool]]
             ) -> list[Carrying]:
    """States from (t, cell, loaded, standing), each passing through its own cell only."""
    return [Carrying(vehicle, t, cell, frozenset([cell]) if cell else frozenset(), loaded,
                     standing) for t, cell, loaded, standing in plan]


def trip(vehicle: int, slot, back, t0: float = 0.0, dwell: float = 10.0) -> list[Carrying]:
    """Lift at `slot`, stand `dwell` at the packing station, put down at `back`."""
    s, p, b = tuple(slot.cell), tuple(STATION.cell), tuple(back.cell)
    plan = [(t0, s, False, False), (t0 + 0.5, s, True, False),
            (t0 + 20.0, p, True, False)]
    plan += [(t0 + 20.0 + k * 0.5, p, True, True) for k in range(1, int(dwell * 2) + 1)]
    plan += [(t0 + 50.0, b, True, False), (t0 + 50.5, b, False, False)]
    return carrying(vehicle, plan)


def test_an_order_is_done_once_its_shelf_is_packed_and_put_back():
    verdict = orders_verdict(PAPER002, ["s-3-3"], trip(1, SLOT, SLOT),
                             [Announced("s-3-3", 1, 1, 50.5)], finished=True)
    assert verdict.passed and verdict.done == 1 and verdict.last_done_s == 50.5


def test_a_shelf_left_at_the_station_too_soon_packs_nothing():
    verdict = orders_verdict(PAPER002, ["s-3-3"], trip(1, SLOT, SLOT, dwell=5.0),
                             [Announced("s-3-3", 1, 1, 50.5)], finished=True)
    assert not verdict.passed and verdict.lost == ["order 1 (s-3-3)"]
    assert "before its dwell of 10.0 s" in verdict.shelf_faults[0].why
    assert verdict.not_served == ["order 1 (s-3-3)"]


def test_a_shelf_put_down_on_another_is_a_fault_and_one_lifted_from_nothing_too():
    onto_other = orders_verdict(PAPER002, ["s-3-3"], trip(1, SLOT, OTHER), [], True)
    assert ["put s-3-3 down on s-4-3" in f.why for f in onto_other.shelf_faults] == [True]
    twice = trip(1, SLOT, SLOT) + trip(2, SLOT, SLOT, t0=10.0)  # the slot is empty then
    faults = orders_verdict(PAPER002, ["s-3-3"], twice, [], True).shelf_faults
    assert [f.vehicle for f in faults] == [2] and "vacant slot" in faults[0].why


def test_shelves_still_carried_at_the_end_break_conservation():
    unfinished = trip(1, SLOT, SLOT)[:-1]  # never put down
    verdict = orders_verdict(PAPER002, ["s-3-3"], unfinished, [], finished=True)
    assert "still carried s-3-3 at the end" in verdict.shelf_faults[-1].why
    assert orders_verdict(PAPER002, ["s-3-3"], unfinished, [], finished=False
                          ).shelf_faults == []


def test_announcements_must_name_a_released_order_and_its_shelf_once():
    states = trip(1, SLOT, SLOT)
    wrong_shelf = orders_verdict(PAPER002, ["s-3-3"], states,
                                 [Announced("s-4-3", 1, 1, 50.5)], True)
    assert wrong_shelf.misnamed and not wrong_shelf.passed
    twice = orders_verdict(PAPER002, ["s-3-3"], states,
                           [Announced("s-3-3", 1, 1, 50.5)] * 2, True)
    assert twice.duplicated == ["order 1"] and not twice.passed
    unknown = orders_verdict(PAPER002, ["s-3-3"], states,
                             [Announced("s-3-3", 1, 1, 50.5), Announced("s-3-3", 7, 1, 60)],
                             True)
    assert unknown.misnamed == ["order 7 announced for s-3-3 by AGV 1 at t=60.00 s"]


def test_two_orders_of_one_shelf_need_two_packings():
    once = orders_verdict(PAPER002, ["s-3-3", "s-3-3"], trip(1, SLOT, SLOT), [], True)
    assert once.done == 1 and once.lost == ["order 2 (s-3-3)"]
    both = trip(1, SLOT, SLOT) + trip(1, SLOT, SLOT, t0=100.0)
    assert orders_verdict(PAPER002, ["s-3-3", "s-3-3"], both, [], True).done == 2


def unseen_from(states: list[Carrying], t0: float, t1: float) -> list[Carrying]:
    """The states with those in (t0, t1) not recorded: the first after the window says so."""
    kept = [s for s in states if not t0 < s.t < t1]
    return [dataclasses.replace(s, unseen=True) if s.t >= t1 and kept[i - 1].t <= t0 else s
            for i, s in enumerate(kept)]


TRIP_SAID = [Claim(1, "fetch", "s-3-3", 0.5, 0.5), Claim(1, "pack", STATION.name, 20.0, 30.0),
             Claim(1, "stow", "s-3-3", 50.5, 50.5)]


def test_a_packing_no_recorder_saw_is_taken_on_the_dispatchers_word():
    """The recorder was down from t=10 to t=40: the packing is the dispatcher's word, the
    drop seen after it completes the order, which is listed as unverified, not lost."""
    states = unseen_from(trip(1, SLOT, SLOT), 10.0, 40.0)
    verdict = orders_verdict(PAPER002, ["s-3-3"], states, [], True, TRIP_SAID)
    assert verdict.passed and verdict.unverified == ["order 1 (s-3-3)"]
    unsaid = orders_verdict(PAPER002, ["s-3-3"], states, [], True)
    assert unsaid.unseen == ["order 1 (s-3-3)"] and unsaid.done == 0


def test_a_whole_trip_no_recorder_saw_is_the_trips_announced_in_the_window():
    states = unseen_from(trip(1, SLOT, SLOT), 0.2, 50.4)  # lift to put-back unseen
    verdict = orders_verdict(PAPER002, ["s-3-3"], states, [], True, TRIP_SAID)
    assert verdict.passed and verdict.unverified == ["order 1 (s-3-3)"]
    without_stow = orders_verdict(PAPER002, ["s-3-3"], states, [], True, TRIP_SAID[:2])
    assert without_stow.unseen == ["order 1 (s-3-3)"]  # put down where no one says


def test_a_packing_seen_in_part_counts_and_one_seen_whole_is_still_judged():
    partly = unseen_from(trip(1, SLOT, SLOT), 25.0, 40.0)
    assert orders_verdict(PAPER002, ["s-3-3"], partly, [], True, TRIP_SAID).passed
    too_short = trip(1, SLOT, SLOT, dwell=5.0)
    too_short[1] = dataclasses.replace(too_short[1], unseen=True)  # the lift unseen
    verdict = orders_verdict(PAPER002, ["s-3-3"], too_short, [], True, TRIP_SAID)
    assert "before its dwell of 10.0 s" in verdict.shelf_faults[0].why


def test_a_shelf_lifted_where_no_one_saw_or_said_is_named_by_the_next_move_it_explains():
    """AGV 1 lifts s-3-3 in a window nobody recorded and nobody announced; AGV 2 then puts
    s-4-3 into s-3-3's slot: the book learns that AGV 1 carries s-3-3, and nothing is a
    fault. Both orders are done, s-3-3's on the word of the move that named it."""
    first = unseen_from(trip(1, SLOT, OTHER, t0=10.0), 10.2, 20.0)  # s-3-3 lifted unseen
    second = trip(2, OTHER, SLOT)  # s-4-3 taken first, put in s-3-3's slot at t=50.5
    verdict = orders_verdict(PAPER002, ["s-3-3", "s-4-3"], first + second, [], True)
    assert verdict.shelf_faults == [] and verdict.passed, verdict
    assert "order 1 (s-3-3)" in verdict.unverified


def test_an_order_whose_whole_trip_no_one_saw_or_said_is_not_verified_not_lost():
    states = unseen_from(trip(1, SLOT, SLOT), 0.2, 50.4)
    verdict = orders_verdict(PAPER002, ["s-3-3"], states, [], True)
    assert verdict.lost == [] and verdict.unseen == ["order 1 (s-3-3)"] and verdict.passed


AISLE = next(iter(PAPER002.lane_directions))  # a lane cell: no slot, no station


def idle(vehicle: int, t0: float, t1: float, loaded_after: bool = False) -> list[Carrying]:
    """An AGV on a lane, its states between t0 and t1 not recorded."""
    return [Carrying(vehicle, t0, AISLE, frozenset([AISLE]), False, False),
            Carrying(vehicle, t1, AISLE, frozenset([AISLE]), loaded_after, False, unseen=True)]


def test_a_window_too_short_to_hide_a_packing_excuses_no_order():
    """AGV 2 was not recorded for 5 s: no packing fits; the order whose shelf nobody moved
    is lost (and its announcement not served). One of 60 s could hide a packing: an order
    whose shelf was never seen to move is then not verified, as many as fit, no more."""
    short = trip(1, SLOT, SLOT) + idle(2, 0.0, 5.0)
    said = [Announced("s-3-3", 1, 1, 50.5), Announced("s-4-3", 2, 2, 60.0)]
    verdict = orders_verdict(PAPER002, ["s-3-3", "s-4-3"], short, said, True)
    assert verdict.lost == verdict.not_served == ["order 2 (s-4-3)"] and not verdict.passed
    long = trip(1, SLOT, SLOT) + idle(2, 0.0, 15.0)  # one packing of 10 s fits
    three = ["s-3-3", "s-4-3", "s-5-3"]
    verdict = orders_verdict(PAPER002, three, long, [], True)
    assert verdict.unseen == ["order 2 (s-4-3)"] and verdict.lost == ["order 3 (s-5-3)"]


def test_a_shelf_lifted_unseen_excuses_one_contradiction_not_two():
    """AGV 9 came out of a window carrying a shelf nobody named: AGV 2 putting a shelf on a
    slot the book says is full is explained by it (that slot's shelf is the one lifted
    unseen); AGV 3 doing the same after it is a fault."""
    states = (idle(9, 0.0, 30.0, loaded_after=True)
              + [dataclasses.replace(s, t=s.t + 40.0) for s in trip(2, OTHER, SLOT)]
              + [dataclasses.replace(s, t=s.t + 100.0)
                 for s in trip(3, PAPER002.shelves["s-5-3"], PAPER002.shelves["s-6-3"])])
    faults = orders_verdict(PAPER002, ["s-4-3"], states, [], False).shelf_faults
    assert [(f.vehicle, f.why) for f in faults] == [(3, "put s-5-3 down on s-6-3 in cell "
                                                        f"{tuple(PAPER002.shelves['s-6-3'].cell)}")]


def test_shelves_lifted_unseen_and_put_back_home_are_each_their_own():
    """AGVs 1 and 2 each lift a shelf where nobody saw or said, and each puts its own back
    home, seen: each is named as its own AGV's, and a later seen trip of s-3-3 is sound."""
    def back_home(vehicle: int, slot, seen_from: float, down_at: float) -> list[Carrying]:
        cell = tuple(slot.cell)
        return idle(vehicle, 0.0, seen_from, loaded_after=True) + carrying(vehicle, [
            (down_at - 0.5, cell, True, False), (down_at, cell, False, False)])
    # AGV 2's shelf was seen first, AGV 1's is put back first: neither is the other's.
    states = (back_home(1, SLOT, 30.0, 40.5) + back_home(2, OTHER, 25.0, 45.5)
              + trip(3, SLOT, SLOT, t0=100))
    verdict = orders_verdict(PAPER002, ["s-3-3"], states, [], True)
    assert verdict.shelf_faults == [] and verdict.done == 1 and verdict.passed, verdict


# -- a real recording ----------------------------------------------------------------------

@pytest.fixture(scope="module")
def order_stream() -> list[Outgoing]:
    mission = Mission("paper002", MissionKind.ORDERS, Strategy.NEAREST, vehicles=6, seed=3,
                      orders=24)
    return recorded_run(mission, PAPER002, engine_options(mission, PAPER002, None))[1]


def judged(tmp_path: Path, stream: list[Outgoing], capsys) -> tuple[int, dict]:
    path = tmp_path / "run.mcap"
    write_recording(path, stream, PAPER002)
    status = main(["analyze", str(path), "--json"])
    return status, json.loads(capsys.readouterr().out)


def test_an_order_mission_passes_every_verdict_from_its_recording(order_stream, tmp_path,
                                                                  capsys):
    status, report = judged(tmp_path, order_stream, capsys)
    assert status == 0 and report["passed"]
    orders = report["orders"]
    assert orders["expected"] == orders["done"] == orders["announced"] == 24
    assert orders["shelf_faults"] == 0 and orders["lost"] == []
    assert report["lane_breaches"] == 0 and report["meetings"] == 0
    [info] = [o.message for o in order_stream if isinstance(o.message, MissionInfo)]
    assert len(info.released) == 24
    # the makespan is the last shelf put down, as the dispatcher's record says too (the
    # states show it at the next instant of their grid)
    assert report["end_time_s"] <= orders["last_done_s"] < report["end_time_s"] + PERIOD


def test_an_agv_moved_onto_another_is_caught_as_a_meeting(order_stream, tmp_path, capsys):
    states = [k for k, o in enumerate(order_stream) if isinstance(o.message, VehicleState)]
    moving = next(k for k in states if order_stream[k].message.vehicle == 1
                  and order_stream[k].message.maneuver == "move" and order_stream[k].sim_time > 5)
    t = order_stream[moving].sim_time
    [other] = [k for k in states if order_stream[k].message.vehicle == 2
               and order_stream[k].sim_time == t]
    broken = list(order_stream)
    m1 = order_stream[moving].message
    broken[other] = dataclasses.replace(order_stream[other], message=dataclasses.replace(
        order_stream[other].message, x=m1.x, y=m1.y))
    status, report = judged(tmp_path, broken, capsys)
    assert status == 1 and not report["safe"]
    assert report["meetings"] >= 1 and report["meetings_first"][0]["vehicles"] == [1, 2]


def test_an_announcement_repeated_fails_the_work_verdict(order_stream, tmp_path, capsys):
    [first] = [k for k, o in enumerate(order_stream) if isinstance(o.message, StackDone)][:1]
    broken = list(order_stream)
    broken.insert(first + 1, order_stream[first])
    status, report = judged(tmp_path, broken, capsys)
    assert status == 1 and not report["work_done"]
    assert report["orders"]["duplicated"] == [f"order {order_stream[first].message.index}"]


def test_an_order_whose_last_leg_is_postponed_is_done_when_it_arrives(tmp_path):
    """A collision rule postpones a committed stow leg: the order is done, and the mission
    ends, when the postponed leg puts the shelf down, in the record and in the recording."""
    mission = Mission("paper002", MissionKind.ORDERS, Strategy.NEAREST, vehicles=6, seed=3,
                      orders=24)
    engine = Engine(mission)
    record = engine.run()
    stows = [s for s in record.subtasks if s.kind is TaskKind.STOW]
    postponed = [s for s in stows if any(
        isinstance(o, AmendLeg) and o.trajectory.t_start == s.trajectory.t_start
        for o in engine.drive_log[s.vehicle])]
    assert postponed  # seed 3 has two
    assert sorted(t for _, _, t in record.stacks_done) == sorted(s.t_done for s in stows)
    assert record.end_time == max(s.t_done for s in stows)
    _, stream = recorded_run(mission, PAPER002, engine_options(mission, PAPER002, None))
    write_recording(tmp_path / "run.mcap", stream, PAPER002)
    summary = summary_of(read_recording(tmp_path / "run.mcap"))
    assert sorted(s.t for s in summary.stacks_done) == sorted(s.t_done for s in stows)
    assert summary.end_time_s == record.end_time


# -- batteries -------------------------------------------------------------------------------

PILE = tuple(PAPER002.piles[0].cell)
PILES, PLACES = {PILE}, {PILE, tuple(SLOT.cell), tuple(STATION.cell)}
DRAIN, CHARGE = 100 / 14_400, 100 / 3_600


def charges(plan: list[tuple[float, float, tuple[int, int] | None, bool, bool]]
            ) -> list[Charge]:
    """States of AGV 1 from (t, soc, cell, moved, loaded)."""
    return [Charge(1, t, soc, cell, moved, loaded) for t, soc, cell, moved, loaded in plan]


def judge(plan) -> list[str]:
    return [f.why for f in battery_verdict(charges(plan), PILES, PLACES, DRAIN, CHARGE,
                                           20.0).faults]


def test_a_battery_that_drains_driving_and_charges_on_a_pile_passes():
    lane = (5, 5)
    plan = [(0.0, 50.0, lane, False, False), (10.0, 50.0 - 10 * DRAIN, lane, True, False),
            (20.0, 50.0 - 10 * DRAIN, PILE, True, False),
            (30.0, 50.0 - 10 * DRAIN + 10 * CHARGE, PILE, False, False)]
    verdict = battery_verdict(charges(plan), PILES, PLACES, DRAIN, CHARGE, 20.0)
    assert verdict.passed and verdict.charged == 1
    assert verdict.lowest == pytest.approx(50.0 - 10 * DRAIN)


def test_a_charge_off_bounds_or_against_its_rates_is_a_fault():
    lane = (5, 5)
    assert "outside 0..100 %" in judge([(0.0, -1.0, lane, False, False)])[0]
    assert "off a pile" in judge([(0.0, 50.0, lane, False, False),
                                  (1.0, 50.5, lane, False, False)])[0]
    assert "faster than its rate" in judge([(0.0, 50.0, PILE, False, False),
                                            (1.0, 51.0, PILE, False, False)])[0]
    assert "standing still" in judge([(0.0, 50.0, lane, False, False),
                                      (1.0, 49.0, lane, False, False)])[0]
    assert "faster than its rate" in judge([(0.0, 50.0, lane, False, False),
                                            (1.0, 49.0, (5, 6), True, False)])[0]


def test_a_shelf_put_down_below_the_threshold_sends_the_agv_to_a_pile_next():
    slot, station = tuple(SLOT.cell), tuple(STATION.cell)
    drop = [(0.0, 15.0, slot, False, True), (0.5, 15.0, slot, False, False)]
    to_pile = [(30.0, 15.0 - 29.5 * DRAIN, PILE, True, False),
               (31.0, 15.0 - 29.5 * DRAIN, PILE, False, False)]
    to_station = [(30.0, 15.0 - 29.5 * DRAIN, station, True, False),
                  (31.0, 15.0 - 29.5 * DRAIN, station, False, False)]
    assert judge(drop + to_pile) == []
    assert "not a pile" in judge(drop + to_station)[0]
    above = [(0.0, 25.0, slot, False, True), (0.5, 25.0, slot, False, False)]
    then = [(30.0, 25.0 - 29.5 * DRAIN, station, True, False),
            (31.0, 25.0 - 29.5 * DRAIN, station, False, False)]
    assert judge(above + then) == []


def test_low_batteries_charge_and_pass_every_verdict_as_the_seed_pack_asks(tmp_path, capsys):
    """The note's A-BAT-1, shortened: start charges drawn in 15..40 %, N_op 6 of 10 AGVs."""
    code = main(["run", "--inprocess", "--layout", "paper002", "--orders", "60",
                 "--vehicles", "10", "--battery", "start=15..40,n_op=6", "--out",
                 str(tmp_path / "run"), "--json"])
    summary = json.loads(capsys.readouterr().out)
    assert code == 0 and summary["verdicts"]["passed"] and summary["verdicts"]["battery"]
    battery = summary["battery"]
    assert battery["charged"] >= 4 and battery["faults"] == []
    assert 10.0 < battery["lowest"] < 20.0  # one drew below 20 % and went to charge
    assert summary["orders"]["done"] == 60


@pytest.mark.parametrize("flag, named", [
    ("start=15..abc", "start='abc' is not a number"),
    ("start=40..15", "runs backwards"),
    ("below=120", "between 0 and 100 %"),
    ("drive_hours=0", "drive_hours=0 must be more than 0"),
    ("volts=48", "KEY=VALUE with KEY one of start, below"),
])
def test_nonsense_battery_numbers_are_refused_naming_them(flag, named, capsys):
    with pytest.raises(SystemExit) as refused:  # argparse refuses by exiting
        main(["run", "--inprocess", "--layout", "paper002", "--battery", flag])
    assert refused.value.code == 2
    err = capsys.readouterr().err
    last = err.strip().splitlines()[-1]  # under argparse's usage lines
    assert last.startswith("fleet run: error: argument --battery: ") and named in last
    assert "Traceback" not in err


def test_more_agvs_kept_operational_than_the_fleet_is_refused(capsys):
    assert main(["run", "--inprocess", "--layout", "paper002", "--vehicles", "4",
                 "--battery", "n_op=6"]) == 2
    assert "n_op (AGVs kept operational) is 6 but the fleet has only 4" in \
        capsys.readouterr().err


def carried_through_a_window(back) -> list[Carrying]:
    """AGV 1 lifts s-3-3 and packs it, seen; its states from t=31 to t=61 are not recorded
    and nobody said what it did (time to put s-3-3 down and take another up); it comes out
    loaded at `back`'s cell and puts a shelf down there."""
    slot, station, cell = tuple(SLOT.cell), tuple(STATION.cell), tuple(back.cell)
    plan = [(0.0, slot, False, False), (0.5, slot, True, False), (20.0, station, True, False)]
    plan += [(20.0 + k * 0.5, station, True, True) for k in range(1, 21)]
    plan += [(31.0, AISLE, True, False)]
    return [*carrying(1, plan),
            Carrying(1, 61.0, cell, frozenset([cell]), True, False, unseen=True),
            Carrying(1, 61.5, cell, frozenset([cell]), False, False)]


def test_a_loaded_agv_out_of_a_long_window_may_carry_another_shelf():
    """Loaded before and after a window that could hide a put-down and a pick-up, the AGV's
    shelf is not known to be the one it took in: putting one down on s-4-3's full slot
    names it s-4-3 (no fault; s-3-3 put down unseen, its order not verified); putting it
    down at s-3-3's vacant home names it s-3-3, whose order is then done."""
    swapped = orders_verdict(PAPER002, ["s-3-3"], carried_through_a_window(OTHER), [], True)
    assert swapped.shelf_faults == [] and swapped.passed, swapped
    assert swapped.unseen == ["order 1 (s-3-3)"]
    home = orders_verdict(PAPER002, ["s-3-3"], carried_through_a_window(SLOT), [], True)
    assert home.shelf_faults == [] and home.passed and home.done == 1, home
