"""Seed 004's order missions in process (fleet/mission/orders004.py): orders by popularity
handed to stations in turn, the nearest shelf (with recall), the nearest idle AGV, shelves
home, charging; judged from the events by code apart from the dispatcher."""

import itertools
from collections import Counter, defaultdict

import pytest

from fleet.analysis.verdicts004 import judge
from fleet.errors import UserError
from fleet.mission.battery import FULL, BatteryParams
from fleet.mission.orders004 import Mission004, Order004, WorkParams, generate_orders
from fleet.mission.tracking004 import LegDone, Moved, Paused, Picked
from fleet.planning.rules004 import Task
from fleet.world.floor004 import CLASSES, Floor004Shape, build, paper004

SMALL = build(Floor004Shape(blocks_across=4, double_rows=4, stations=2, piles_per_side=2,
                            block_width=3, transit_rows=2), "small004")


def _safe(result, floor, vehicles):
    """The verifiers apart from the tracker: cells, rules, slots, lanes, giving way."""
    verdict = judge(floor, result.events, {v: floor.parking[v - 1]
                                           for v in range(1, vehicles + 1)})
    assert verdict.passed, verdict
    return True


def test_orders_are_drawn_by_popularity_and_handed_to_the_stations_in_turn():
    orders = generate_orders(paper004(), 4200, 5)
    assert [o.station for o in orders[:9]] == [f"station-{k}" for k in range(1, 9)] + \
        ["station-1"]
    share = Counter(o.goods.split("-")[0] for o in orders)
    for colour, weight in zip(CLASSES, (6, 5, 4, 3, 2, 1), strict=True):
        assert share[colour] / len(orders) == pytest.approx(weight / 21, abs=0.02)
    assert generate_orders(paper004(), 50, 5) == orders[:50]
    # A floor without some goods is never asked for them.
    assert {o.goods for o in generate_orders(SMALL, 500, 5)} <= set(SMALL.goods)


def test_every_order_is_picked_once_at_its_station_and_every_shelf_ends_home():
    orders = generate_orders(SMALL, 40, 3)
    mission = Mission004(SMALL, 6, orders)
    result = mission.run()
    assert sorted(p.order for p in result.picked) == [o.id for o in orders]
    by_id = {o.id: o for o in orders}
    for p in result.picked:
        assert (p.station, p.goods) == (by_id[p.order].station, by_id[p.order].goods)
        assert SMALL.kind(p.shelf).value == "slot"
        assert p.shelf in {s.xy for s in SMALL.goods[p.goods]}
    assert result.completion_s == max(p.t for p in result.picked) < result.shelves_home_s
    assert _safe(result, SMALL, 6)
    # Each shelf is lifted at home and dropped at home, in turn, by one AGV at a time.
    on: dict[tuple[int, int], int] = {}
    for e in result.events:
        if isinstance(e, Paused) and e.label == "lift":
            assert e.at not in on.values() and e.vehicle not in on
            on[e.vehicle] = e.at
        elif isinstance(e, Paused) and e.label == "drop":
            assert on.pop(e.vehicle) == e.at
    assert on == {}
    # A station picks one shelf at a time.
    picks = defaultdict(list)
    for e in result.events:
        if isinstance(e, Paused) and e.label == "pick":
            picks[e.at].append((e.t0, e.t1))
    for spans in picks.values():
        assert all(b0 >= a1 for (_, a1), (b0, _) in itertools.pairwise(spans))
    # Idle at the end where its last leg ended (under the shelf it returned, unless it was
    # sent out of the way since), or where it started.
    last = {e.vehicle: e.leg for e in result.events if isinstance(e, LegDone)}
    for v, agv in mission.tracker.agvs.items():
        assert agv.leg is None and not agv.loaded
        assert agv.cell == (last[v].goal if v in last else SMALL.parking[v - 1])
        assert v not in last or last[v].task in (Task.RETURN, Task.CHARGE) or last[v].make_way


def test_a_shelf_on_its_way_home_is_recalled_when_it_is_the_nearest():
    orders = tuple(Order004(i + 1, "red-0", "station-1") for i in range(6))
    recalled = Mission004(SMALL, 2, orders).run()
    plain = Mission004(SMALL, 2, orders, work=WorkParams(recall=False)).run()
    assert any(p.recalled for p in recalled.picked)
    assert not any(p.recalled for p in plain.picked)
    assert recalled.counts["cells"] < plain.counts["cells"]
    assert recalled.completion_s < plain.completion_s
    assert _safe(recalled, SMALL, 2)


def test_agvs_below_the_threshold_charge_at_piles_one_at_a_time():
    battery = BatteryParams(drain_per_s=FULL / 400.0, charge_per_s=FULL / 200.0)
    orders = generate_orders(SMALL, 60, 9)
    mission = Mission004(SMALL, 4, orders, work=WorkParams(battery=battery))
    result = mission.run()
    assert result.charges >= 2 and 0.0 <= result.lowest_soc < battery.threshold
    charging = defaultdict(list)
    for e in result.events:
        if isinstance(e, Paused) and e.label == "charge":
            assert e.at in SMALL.piles
            assert 0 < e.t1 - e.t0 <= 400.0 * 0.5 + 1e-9  # rho times at most all it holds
            charging[e.at].append((e.t0, e.t1))
    for spans in charging.values():  # exclusive: nobody else charges there meanwhile
        assert all(b0 >= a1 for (_, a1), (b0, _) in itertools.pairwise(spans))
    assert not [e for e in result.events if isinstance(e, Moved) and e.task is Task.CHARGE
                and e.loaded]
    assert len([e for e in result.events if isinstance(e, Picked)]) == 60
    assert _safe(result, SMALL, 4)


def test_an_agv_waiting_for_a_pile_and_sent_out_of_the_way_charges_once_it_is_there():
    micro = build(Floor004Shape(blocks_across=2, double_rows=2, stations=1, piles_per_side=1,
                                block_width=3, transit_rows=2), "micro004")
    battery = BatteryParams(drain_per_s=FULL / 100.0, charge_per_s=FULL / 50.0)
    mission = Mission004(micro, 8, generate_orders(micro, 40, 0),
                         work=WorkParams(battery=battery))
    result = mission.run()
    assert len(result.picked) == 40 and result.charges > 0
    assert _safe(result, micro, 8)


def test_a_mission_is_a_function_of_its_inputs():
    orders = generate_orders(SMALL, 30, 4)
    assert Mission004(SMALL, 5, orders).run() == Mission004(SMALL, 5, orders).run()


def test_bad_missions_are_refused_naming_what_is_wrong():
    with pytest.raises(UserError, match="goods 'purple-1', which no shelf on small004 holds"):
        Mission004(SMALL, 2, (Order004(1, "purple-1", "station-1"),))
    with pytest.raises(UserError, match="small004 parks 1 to 16 AGVs, not 17"):
        Mission004(SMALL, 17, ())
    with pytest.raises(UserError, match="station 'station-9', which small004 does not have"):
        Mission004(SMALL, 2, (Order004(1, "red-1", "station-9"),))
    with pytest.raises(UserError, match="at least 1 order at a time"):
        WorkParams(q_max=0)
