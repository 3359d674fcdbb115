"""Seed 002's order missions and battery as pure logic (fleet.mission.orders, .battery): the
nearest-pair assignment with its ties, station and return-slot choices recomputed here,
shelf conservation over simulated runs driven by a small event loop with made-up travel
times (Manhattan distance at 1 cell/s, no planner), the 20 % rule and N_op, bad input."""

from __future__ import annotations

import heapq
import itertools
import math
import random
from dataclasses import replace

import pytest

from fleet.mission.battery import BatteryParams, goes_to_charge, start_piles
from fleet.mission.orders import (
    CHARGING,
    LOWER_LEFT,
    EventError,
    InvariantError,
    Order,
    OrderBook,
    Phase,
    SlotState,
    area_shelves,
    release_orders,
)
from fleet.world.layout_file import load_layout

PAPER = load_layout("paper002")


def dist(a, b) -> int:
    return abs(a[0] - b[0]) + abs(a[1] - b[1])


def station_distance(cell) -> int:
    return min(dist(cell, p.cell) for p in PAPER.packing)


def run(book: OrderBook, on_step=None) -> list[tuple]:
    """Drives the book to the end: every trip takes its Manhattan distance in seconds.
    Calls book.check() after every step; returns the log of decisions."""
    events: list = []
    seq = itertools.count()
    log: list[tuple] = []

    def at(t, kind, agv):
        heapq.heappush(events, (t, next(seq), kind, agv))

    def assign(t):
        for a in book.assign(t):
            log.append(("assign", t, a))
            at(t + a.distance, "shelf", a.agv)
            if a.charge:
                log.append(("charge", t, a.charge))
                at(t + a.charge.distance, "pile", a.charge.agv)

    assign(0.0)
    book.check()
    while events:
        t, _, kind, agv = heapq.heappop(events)
        if kind == "shelf":
            trip = book.at_shelf(agv, t)
            log.append(("at_shelf", t, agv, trip))
            if trip:
                at(t + trip.distance, "station", agv)
        elif kind == "station":
            at(book.at_station(agv, t), "leave", agv)
        elif kind == "leave":
            vacant = {s.name for s in book.vacant_slots()}
            ret = book.left_station(agv, t)
            log.append(("left", t, agv, ret, vacant))
            at(t + ret.distance, "slot", agv)
            if ret.served:
                at(t + ret.served.distance, "station", ret.served.agv)
        elif kind == "slot":
            done = book.returned(agv, t)
            log.append(("done", t, agv, done, book.agvs[agv].soc, book_charging(book)))
            if done.charge:
                at(t + done.charge.distance, "pile", agv)
        elif kind == "pile":
            log.append(("pile", t, agv))
            at(book.at_pile(agv, t), "full", agv)
        elif kind == "full":
            book.charged(agv, t)
            log.append(("full", t, agv))
        book.check()
        if on_step:
            on_step(book, t)
        assign(t)
        book.check()
    return log


def book_charging(book: OrderBook) -> int:
    return sum(book.status(a) == CHARGING for a in book.agvs)


# -- release ---------------------------------------------------------------------------

def test_release_is_seeded_uniform_with_replacement():
    orders = release_orders(PAPER, 250, seed=4)
    assert orders == release_orders(PAPER, 250, seed=4)
    assert orders != release_orders(PAPER, 250, seed=5)
    assert [o.id for o in orders] == list(range(1, 251))
    assert {o.shelf for o in orders} <= set(PAPER.shelves)
    shelves = [o.shelf for o in orders]
    assert len(set(shelves)) < len(shelves)  # with replacement: 250 draws of 378 repeat
    rng = random.Random(4)
    names = [s.name for s in PAPER.slots]
    assert shelves == [rng.choice(names) for _ in range(250)]


def test_lower_left_area_is_the_18_slots_rows_2_3_columns_3_11():
    area = area_shelves(PAPER, LOWER_LEFT)
    cells = {PAPER.shelves[s].cell for s in area}
    assert cells == {(x, y) for x in range(3, 12) for y in (2, 3)}
    orders = release_orders(PAPER, 40, seed=1, area=LOWER_LEFT)
    assert {o.shelf for o in orders} <= set(area)
    assert set(area_shelves(PAPER, "a-1-1")) == {s.name for s in PAPER.slots
                                                 if s.area == "a-1-1"}


# -- assignment: hand-worked ---------------------------------------------------------

def test_assignment_is_the_greedy_nearest_pair_hand_worked():
    # AGV 1 under s-8-2, AGV 2 under s-20-6, AGV 3 on pile c28 (30, 30).
    # o1 s-5-3: 4 / 18 / 52; o2 s-16-7: 13 / 5 / 37; o3 s-11-2: 3 / 13 / 47; o4 queues
    # behind o1 on s-5-3. Nearest pair (3, o3, 1), then (5, o2, 2), then (52, o1, 3).
    orders = [Order(1, "s-5-3"), Order(2, "s-16-7"), Order(3, "s-11-2"), Order(4, "s-5-3")]
    book = OrderBook(PAPER, 3, orders, starts=[(8, 2), (20, 6), (30, 30)])
    made = book.assign(0.0)
    assert [(a.order.id, a.agv, a.distance) for a in made] == [(3, 1, 3), (2, 2, 5),
                                                               (1, 3, 52)]
    assert [o.id for o in book.pending()] == [4]
    assert all(book.status(a) == "busy" for a in (1, 2, 3))
    assert book.pile_agv["c28"] is None  # AGV 3 left its pile
    book.check()


def test_assignment_ties_by_order_id_then_agv_id():
    # AGVs under s-8-2 and s-10-2; o1 s-9-3 is 2 from both, o2 s-7-3 is 2 from AGV 1 and 4
    # from AGV 2. Ties by order id first: (2, o1, AGV 1), not (2, o2, AGV 1).
    orders = [Order(2, "s-7-3"), Order(1, "s-9-3")]
    book = OrderBook(PAPER, 2, orders, starts=[(8, 2), (10, 2)])
    made = book.assign(0.0)
    assert [(a.order.id, a.agv, a.distance) for a in made] == [(1, 1, 2), (2, 2, 4)]
    # the AGV-id tie alone: one order, two AGVs 2 away
    book = OrderBook(PAPER, 2, [Order(1, "s-9-3")], starts=[(10, 2), (8, 2)])
    assert [a.agv for a in book.assign(0.0)] == [1]


def test_every_assignment_is_the_nearest_pair_recomputed():
    book = OrderBook(PAPER, 10, release_orders(PAPER, 120, seed=3))
    seen = []
    original = book.assign

    def checked(now):
        free = {a.id: a.cell for a in book.agvs.values() if a.phase is Phase.IDLE}
        ready = sorted((q[0] for s, q in book.queues.items()
                        if q and s not in book.active and book.where[s].kind == "slot"),
                       key=lambda o: o.id)
        slots = {o.shelf: book.slots[book.where[o.shelf].at].cell for o in ready}
        made = original(now)
        for a in made:
            best = min((dist(free[v], slots[o.shelf]), o.id, v) for o in ready for v in free)
            assert (a.distance, a.order.id, a.agv) == best
            ready = [o for o in ready if o.id != a.order.id]
            del free[a.agv]
            seen.append(a)
        assert not (ready and free)  # it stops only when one side runs out
        return made

    book.assign = checked  # type: ignore[method-assign]
    run(book)
    assert len(seen) == 120


# -- stations and return slots -------------------------------------------------------

def test_station_choice_and_return_slot_hand_worked():
    # s-5-3 (5, 3): nearest station p4 (0, 3), 5 away. s-6-3 then finds p4 taken: p3 (0, 2)
    # and p5 (0, 4) are both 7 away, the lower row wins: p3.
    book = OrderBook(PAPER, 2, [Order(1, "s-5-3"), Order(2, "s-6-3")],
                     starts=[(5, 2), (6, 2)])
    assert [(a.order.id, a.agv) for a in book.assign(0.0)] == [(1, 1), (2, 2)]
    first = book.at_shelf(1, 1.0)
    assert first is not None and (first.station.name, first.distance) == ("p4", 5)
    assert not book.station_available("p4")
    assert book.slot_state["s-5-3"] is SlotState.VACANT
    second = book.at_shelf(2, 1.0)
    assert second is not None and (second.station.name, second.distance) == ("p3", 7)
    book.at_station(2, 8.0)
    book.at_station(1, 8.0)
    # AGV 2 leaves p3 (0, 2) first: s-5-3 is 6 away, s-6-3 7: it takes s-5-3, not its home
    ret = book.left_station(2, 18.0)
    assert (ret.slot.name, ret.distance) == ("s-5-3", 6)
    assert book.slot_state["s-5-3"] is SlotState.RESERVED and book.station_available("p3")
    assert book.left_station(1, 18.0).slot.name == "s-6-3"
    book.returned(2, 24.0)
    book.returned(1, 24.0)
    assert book.where["s-6-3"].at == "s-5-3" and book.where["s-5-3"].at == "s-6-3"
    assert book.completed == {1: 24.0, 2: 24.0}
    book.check()


def test_with_no_station_free_the_agv_waits_loaded_fifo():
    one = replace(PAPER, packing=PAPER.packing[:1])  # p1 only
    orders = [Order(1, "s-3-2"), Order(2, "s-4-2"), Order(3, "s-5-2")]
    book = OrderBook(one, 3, orders, starts=[(3, 2), (4, 2), (5, 2)])
    book.assign(0.0)
    assert book.at_shelf(1, 0.0) is not None
    assert book.at_shelf(3, 1.0) is None  # waits first
    assert book.at_shelf(2, 2.0) is None
    assert book.where["s-5-2"].kind == "slot"  # still under its slot: not yet departed
    assert book.slot_state["s-5-2"] is SlotState.OCCUPIED
    book.check()
    book.at_station(1, 5.0)
    with pytest.raises(EventError, match="dwell"):
        book.left_station(1, 14.0)
    ret = book.left_station(1, 15.0)
    assert ret.served is not None and (ret.served.agv, ret.served.waited) == (3, 14.0)
    assert book.slot_state["s-5-2"] is SlotState.VACANT
    assert ret.slot.name == "s-3-2"  # (3, 2) nearer p1 (0, 0) than (5, 2)
    book.check()


def test_returns_go_to_the_nearest_vacant_slot_and_shelves_migrate():
    for seed in range(3):
        book = OrderBook(PAPER, 10, release_orders(PAPER, 100, seed=seed))
        log = run(book)
        picked = {e[2].order.id: e[2].slot for e in log if e[0] == "assign"}
        trips = [e[3] for e in log if e[0] == "at_shelf" and e[3] is not None]
        trips += [e[3].served for e in log if e[0] == "left" and e[3].served is not None]
        station = {trip.order.id: trip.station for trip in trips}
        returns = []
        for e in log:
            if e[0] != "left":
                continue
            _, _, _, ret, vacant = e
            stand = station[ret.order.id]
            # recomputed: the nearest vacant slot from the station, ties lower row, column
            want = min(vacant, key=lambda n: (dist(book.slots[n].cell, stand.cell),
                                              book.slots[n].cell[1], book.slots[n].cell[0]))
            assert ret.slot.name == want
            assert ret.distance == dist(stand.cell, ret.slot.cell)
            pick = picked[ret.order.id]
            if pick.name in vacant:  # its own slot was free: it comes back no farther
                assert ret.distance <= dist(stand.cell, pick.cell)
            returns.append((pick, ret.slot))
        half = returns[: len(returns) // 2]
        # while the run goes on, returns fill slots nearer the stations than pick-ups empty
        assert (sum(station_distance(r.cell) for _, r in half)
                < sum(station_distance(p.cell) for p, _ in half))
        # at the end every slot is full again, so over the run the two sums agree
        assert (sum(station_distance(r.cell) for _, r in returns)
                == sum(station_distance(p.cell) for p, _ in returns))
        assert sum(pl.at != s for s, pl in book.where.items()) > 50  # identity kept apart
        assert sorted(book.completed) == list(range(1, 101))


def test_every_order_completes_once_and_shelves_are_conserved():
    orders = release_orders(PAPER, 150, seed=9)
    book = OrderBook(PAPER, 15, orders)
    log = run(book)  # run() checks conservation after every step
    done = [e[3].order.id for e in log if e[0] == "done"]
    assert sorted(done) == list(range(1, 151)) and len(done) == len(set(done))
    assert not book.work_left() and not book.pending() and not book.active
    # FIFO per shelf: a shelf's orders complete in id order
    by_shelf: dict[str, list[int]] = {}
    for oid in done:
        by_shelf.setdefault(book.orders[oid].shelf, []).append(oid)
    assert all(ids == sorted(ids) for ids in by_shelf.values())
    assert any(len(ids) > 1 for ids in by_shelf.values())
    assert all(st is SlotState.OCCUPIED for st in book.slot_state.values())


def test_figure_19_orders_stay_in_the_lower_left_block():
    area = set(area_shelves(PAPER, LOWER_LEFT))
    book = OrderBook(PAPER, 10, release_orders(PAPER, 40, seed=2, area=LOWER_LEFT))
    run(book)
    assert {str(book.where[s].at) for s in area} == area  # they swap among their slots


def test_check_names_what_broke():
    book = OrderBook(PAPER, 2, [Order(1, "s-5-3")], starts=[(5, 2), (6, 2)])
    book.check()
    book.station_shelf["p1"] = "s-5-3"  # s-5-3 in its slot and at a station
    with pytest.raises(InvariantError, match="shelf s-5-3 is in 2 places: slot s-5-3, "
                                             "station p1"):
        book.check()
    book = OrderBook(PAPER, 2, [Order(1, "s-5-3")], starts=[(5, 2), (6, 2)])
    book.slot_shelf["s-6-2"] = "s-5-3"  # s-6-2 gone, s-5-3 twice
    with pytest.raises(InvariantError, match="shelf s-6-2 is in 0 places"):
        book.check()
    book = OrderBook(PAPER, 2, [Order(1, "s-5-3")], starts=[(5, 2), (6, 2)])
    book.assign(0.0)
    book.at_shelf(1, 1.0)
    book.station_agv["p4"] = None
    with pytest.raises(InvariantError, match="unavailable stations"):
        book.check()
    book = OrderBook(PAPER, 1, [Order(1, "s-5-3")], starts=[(5, 2)])
    book.queues["s-5-3"].clear()
    with pytest.raises(InvariantError, match="orders lost"):
        book.check()


# -- battery ---------------------------------------------------------------------------

def test_start_piles_spread_evenly():
    assert [p.name for p in start_piles(PAPER, 10)] == [
        f"c{math.ceil((i - 0.5) * 33 / 10)}" for i in range(1, 11)]
    assert [p.name for p in start_piles(PAPER, 3)] == ["c6", "c17", "c28"]
    assert [p.name for p in start_piles(PAPER, 33)] == [f"c{k}" for k in range(1, 34)]
    book = OrderBook(PAPER, 10)
    assert [a.cell for a in book.agvs.values()] == [p.cell for p in start_piles(PAPER, 10)]


def test_battery_numbers():
    b = BatteryParams()
    assert b.after_driving(100.0, 1440.0) == pytest.approx(90.0)
    assert b.after_charging(40.0, 1800.0) == pytest.approx(90.0)
    assert b.after_charging(90.0, 3600.0) == 100.0
    assert b.time_to_full(25.0) == pytest.approx(2700.0)
    assert b.after_driving(1.0, 3600.0) == 0.0 and b.ran_flat(1.0, 3600.0)


def test_soc_drains_only_while_driving():
    book = OrderBook(PAPER, 1, [Order(1, "s-5-3")], starts=[(5, 2)])
    book.assign(0.0)
    book.at_shelf(1, 100.0, driven=36.0)  # waited 64 s of the 100
    assert book.soc(1) == pytest.approx(100.0 - 36.0 / 144.0)
    free = book.at_station(1, 110.0)  # 10 s driving, then dwell
    book.left_station(1, free)
    assert book.soc(1) == pytest.approx(100.0 - 46.0 / 144.0)


def test_twenty_percent_rule_sends_to_the_nearest_free_pile():
    drain = BatteryParams(drain_per_s=1.0)  # 1 % per second, to see it act
    orders = [Order(1, "s-5-27"), Order(2, "s-30-27")]
    book = OrderBook(PAPER, 2, orders, battery=drain, initial_soc=[30.0, 90.0],
                     starts=[(5, 26), (30, 26)])
    book.assign(0.0)
    book.at_shelf(1, 1.0)
    book.at_station(1, 31.0)  # SOC 30 - 1 - 30 = -1: flat at 0 and recorded
    assert book.soc(1) == 0.0 and book.ran_flat == [(1, 31.0)]
    book = OrderBook(PAPER, 2, orders, battery=drain, initial_soc=[30.0, 90.0],
                     starts=[(5, 26), (30, 26)])
    book.assign(0.0)
    trip = book.at_shelf(1, 1.0, driven=0.0)
    book.at_station(1, 1.0 + trip.distance, driven=5.0)
    book.left_station(1, 50.0)
    done = book.returned(1, 60.0, driven=10.0)  # 30 - 15 = 15 % < 20 %
    assert done.charge is not None and done.charge.reason == "threshold"
    # nearest free pile from s-5-27 (5, 27): c3 at (5, 30), 3 away
    assert (done.charge.pile.name, done.charge.distance) == ("c3", 3)
    assert book.status(1) == CHARGING and book.assign(60.0) == []
    full = book.at_pile(1, 63.0, driven=3.0)  # 12 % then 100 % per 3 600 s
    assert full == pytest.approx(63.0 + 88.0 * 36.0)
    assert book.soc(1, now=63.0 + 44.0 * 36.0) == pytest.approx(56.0)
    with pytest.raises(EventError, match="not full"):
        book.charged(1, full - 1.0)
    book.charged(1, full)
    assert book.soc(1) == 100.0 and book.status(1) == "available"
    assert book.pile_agv["c3"] == 1  # still on its pile until it leaves
    book.check()


def test_with_every_pile_taken_the_agv_waits_where_it_is():
    one = replace(PAPER, piles=PAPER.piles[:1])  # c1 (3, 30) only
    low = BatteryParams(drain_per_s=0.0)
    orders = [Order(1, "s-3-27"), Order(2, "s-4-27"), Order(3, "s-5-27")]
    book = OrderBook(one, 2, orders, battery=low, initial_soc=[10.0, 15.0],
                     starts=[(3, 27), (4, 27)])
    assert [a.order.id for a in book.assign(0.0)] == [1, 2]
    trips = [book.at_shelf(1, 0.0), book.at_shelf(2, 0.0)]
    for agv, trip in sorted(zip((1, 2), trips, strict=True), key=lambda p: p[1].distance):
        book.at_station(agv, trip.distance)
    r1 = book.left_station(1, 40.0)
    r2 = book.left_station(2, 40.0)
    first = book.returned(1, 40.0 + r1.distance)
    assert first.charge is not None and first.charge.pile.name == "c1"
    second = book.returned(2, 40.0 + r2.distance)
    assert second.charge is None and second.charge_wait == "threshold"
    assert book.agvs[2].phase is Phase.WAIT_PILE and book.agvs[2].cell == r2.slot.cell
    book.check()
    full = book.at_pile(1, 100.0)
    book.charged(1, full)
    made = book.assign(full)  # AGV 1 takes o3 and leaves c1: AGV 2 gets it
    assert [(a.order.id, a.agv) for a in made] == [(3, 1)]
    assert made[0].charge is not None and made[0].charge.agv == 2
    assert made[0].charge.pile.name == "c1" and book.pile_agv["c1"] == 2
    book.check()


def test_staggered_rule_keeps_the_n_op_highest_operational():
    p = BatteryParams(n_op=2)
    ops = [(1, 90.0), (2, 80.0), (3, 70.0), (4, 60.0)]
    assert goes_to_charge(p, 4, 60.0, ops, 4) == "staggered"
    assert goes_to_charge(p, 1, 90.0, ops, 4) is None
    assert goes_to_charge(p, 2, 80.0, ops[:3], 4) is None  # rank 2 of 3
    assert goes_to_charge(p, 3, 70.0, ops[:3], 4) == "staggered"
    assert goes_to_charge(p, 2, 80.0, ops[:2], 4) is None  # only N_op left
    assert goes_to_charge(p, 2, 15.0, ops[:2], 4) == "threshold"  # 20 % rule regardless
    assert goes_to_charge(p, 3, 70.0, [(1, 70.0), (2, 70.0), (3, 70.0)], 4) == "staggered"
    assert goes_to_charge(p, 1, 70.0, [(1, 70.0), (2, 70.0), (3, 70.0)], 4) is None
    assert goes_to_charge(p, 4, 100.0, [*ops[:3], (4, 100.0)], 4) is None  # full: no use
    assert goes_to_charge(BatteryParams(), 4, 60.0, ops, 4) is None  # N_op = n


@pytest.mark.parametrize(("n_op", "drain"), [(10, None), (6, None), (10, 1 / 18), (6, 1 / 18)])
def test_charging_scenario_a_bat_1(n_op, drain):
    """Note A.7 check 14: initial SOC uniform in [15 %, 40 %], 10 AGVs, 200 orders, N_op 10
    or 6; with the default numbers, and with a battery drained in 30 min of driving."""
    rng = random.Random(14)
    socs = [rng.uniform(15.0, 40.0) for _ in range(10)]
    battery = (BatteryParams(n_op=n_op) if drain is None
               else BatteryParams(n_op=n_op, drain_per_s=drain))
    book = OrderBook(PAPER, 10, release_orders(PAPER, 200, seed=14), battery=battery,
                     initial_soc=socs)

    def on_step(b, t):
        on = [a.pile.name for a in b.agvs.values() if a.pile is not None]
        assert len(on) == len(set(on))  # piles exclusive
        assert all(0.0 <= a.soc <= 100.0 for a in b.agvs.values())

    log = run(book, on_step)
    assert sorted(book.completed) == list(range(1, 201))
    assert not book.ran_flat
    dones = [e for e in log if e[0] == "done"]
    for _, _, _, done, soc, charging in dones:
        if soc < 20.0:  # below 20 % at a task completion: to a pile next
            reason = done.charge.reason if done.charge else done.charge_wait
            assert reason == "threshold"
        else:
            assert done.charge is None or done.charge.reason == "staggered"
        if done.charge is not None and done.charge.reason == "staggered":
            assert charging <= 10 - n_op  # never more than n - N_op by the staggered rule
    # next event of an AGV sent to charge is its pile, never an order
    for i, e in enumerate(log):
        if e[0] == "done" and e[3].charge is not None:
            agv = e[2]
            nxt = next(x for x in log[i + 1:] if (x[0] == "assign" and x[2].agv == agv)
                       or (x[0] == "pile" and x[2] == agv))
            assert nxt[0] == "pile"
    reasons = {e[3].charge.reason for e in dones if e[3].charge}
    assert "threshold" in reasons
    assert ("staggered" in reasons) == (n_op < 10)


# -- bad input -----------------------------------------------------------------------

@pytest.mark.parametrize(("make", "message"), [
    (lambda: BatteryParams(drain_per_s=-0.1), "drain rate"),
    (lambda: BatteryParams(charge_per_s=0.0), "charge rate"),
    (lambda: BatteryParams(charge_per_s=-1.0), "charge rate"),
    (lambda: BatteryParams(threshold=120.0), "threshold"),
    (lambda: BatteryParams(n_op=0), "n_op"),
    (lambda: OrderBook(PAPER, 4, battery=BatteryParams(n_op=5)), "only 4 AGVs"),
    (lambda: OrderBook(PAPER, 2, initial_soc=101.0), "initial SOC of AGV 1"),
    (lambda: OrderBook(PAPER, 2, initial_soc=[50.0, -1.0]), "initial SOC of AGV 2"),
    (lambda: OrderBook(PAPER, 2, initial_soc=[50.0]), "1 values for 2 AGVs"),
    (lambda: OrderBook(PAPER, 34), "more AGVs than piles"),
    (lambda: OrderBook(PAPER, 0), "at least 1"),
    (lambda: OrderBook(PAPER, 1, [Order(1, "s-0-0")]), "shelf 's-0-0'"),
    (lambda: OrderBook(PAPER, 1, [Order(1, "s-3-2"), Order(1, "s-4-2")]), "given twice"),
    (lambda: OrderBook(PAPER, 1, starts=[(1, 0)]), "neither a shelf slot nor"),
    (lambda: OrderBook(PAPER, 2, starts=[(3, 2), (3, 2)]), "one cell"),
    (lambda: OrderBook(load_layout("micro-channel"), 1), "no packing stations"),
    (lambda: release_orders(PAPER, -1, seed=0), "number of orders"),
    (lambda: release_orders(PAPER, 5, seed=0, area="a-9-9"), "no shelf area 'a-9-9'"),
    (lambda: release_orders(PAPER, 5, seed=0, area=["s-3-2", "nope"]), "no shelf 'nope'"),
])
def test_nonsense_raises_a_clear_value_error(make, message):
    with pytest.raises(ValueError, match=message):
        make()


def test_events_out_of_phase_or_time_are_refused():
    book = OrderBook(PAPER, 1, [Order(1, "s-5-3")], starts=[(5, 2)])
    with pytest.raises(EventError, match="AGV 1 cannot reach a shelf: it is idle"):
        book.at_shelf(1, 0.0)
    with pytest.raises(EventError, match="no AGV 7"):
        book.returned(7, 0.0)
    book.assign(5.0)
    with pytest.raises(EventError, match="before the last one"):
        book.at_shelf(1, 4.0)
    with pytest.raises(EventError, match="driven 9"):
        book.at_shelf(1, 8.0, driven=9.0)
