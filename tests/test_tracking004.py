"""Seed 004's tracking (fleet/mission/tracking004.py): lifting AGVs driving cell by cell
against the reservation store. Safety is judged from the moves alone by an oracle written
here, apart from the tracker and its planner: each AGV holds a cell from the instant it
starts into it until the instant it is in the next one."""

import itertools
import random

import pytest

from fleet.analysis.cells004 import Move, clashes, held
from fleet.analysis.verdicts004 import judge
from fleet.mission.tracking004 import (
    Conflict,
    Leg,
    LegDone,
    MadeWay,
    Met,
    Moved,
    Picked,
    Replanned,
    Stuck,
    Tracker,
    TrackingParams,
)
from fleet.planning.rules004 import STEP, Direction, Kind, Task, allowed, direction_code
from fleet.world.floor004 import Floor004Shape, build

MICRO = build(Floor004Shape(blocks_across=2, double_rows=2, stations=1, piles_per_side=1,
                            block_width=3, transit_rows=2), "micro004")
SMALL = build(Floor004Shape(blocks_across=4, double_rows=4, stations=2, piles_per_side=2,
                            block_width=3, transit_rows=2), "small004")


def held_spans(tracker: Tracker, starts: dict[int, tuple[int, int]]):
    """The AGVs' cells over time from their moves, by the verifier (fleet/analysis/cells004),
    which knows nothing of the tracker; every move must be drivable."""
    moves = [Move(e.vehicle, e.t0, e.t1, e.origin, e.to) for e in tracker.events
             if isinstance(e, Moved)]
    spans, bad = held(moves, starts)
    assert bad == []
    return spans


def test_a_head_on_conflict_is_given_way_by_the_empty_agv_the_loaded_one_waits():
    """Figure 3 (B-DL-2): a loaded AGV returning its shelf finds an empty AGV passing under
    the slot on its way out through the loaded one's cell."""
    slot = (2, 7)
    tracker = Tracker(MICRO)
    tracker.place(1, (2, 6), Direction.DOWN, loaded=True)
    tracker.place(2, slot, Direction.UP)
    tracker.assign(1, Leg(Task.RETURN, slot, home=slot))
    tracker.assign(2, Leg(Task.FETCH, (2, 3)))
    done = tracker.run()
    assert sorted((d.vehicle, d.leg.task) for d in done) == [(1, Task.RETURN), (2, Task.FETCH)]
    met = [e for e in tracker.events if isinstance(e, Met)]
    assert {(m.vehicle, m.kind) for m in met} == {(1, Conflict.HEAD_ON), (2, Conflict.HEAD_ON)}
    replans = [e for e in tracker.events if isinstance(e, Replanned)]
    assert [(r.vehicle, r.why) for r in replans] == [(2, "head-on")]
    assert not tracker.agvs[1].loaded and tracker.agvs[1].cell == slot
    assert judge(MICRO, tracker.events, {1: (2, 6), 2: slot}, {1: slot}).passed


def test_a_shelf_lifted_inside_a_block_leaves_under_the_delivery_rules():
    """Figure 2 (B-DL-1): under the empty AGV's rules every way out of (3, 7) leads into
    another slot, which a loaded AGV may not enter; the delivery's rules free its own slot in
    every direction, so it lifts and leaves into the aisle above."""
    slot, grid = (3, 7), MICRO.grid
    ways_out = {d: (slot[0] + dx, slot[1] + dy) for d, (dx, dy) in STEP.items()}
    assert {MICRO.kind(ways_out[d]) for d in allowed(grid, Task.FETCH, slot)} == {Kind.SLOT}
    assert Direction.UP in allowed(grid, Task.DELIVER, slot, home=slot)
    tracker = Tracker(MICRO)
    tracker.place(1, slot, Direction.UP)
    tracker.assign(1, Leg(Task.FETCH, slot))
    assert [d.leg.task for d in tracker.run()] == [Task.FETCH]
    station = MICRO.stations[0]
    tracker.assign(1, Leg(Task.DELIVER, station.entrance, home=slot, station=station))
    assert [type(m) for m in tracker.run()] == [Picked, LegDone]
    first = next(e for e in tracker.events if isinstance(e, Moved))
    assert (first.origin, first.to, first.loaded) == (slot, (3, 6), True)


def test_an_agv_leaves_its_pile_outward_and_another_charges_beside_an_occupied_one():
    """Figure 4 (B-DL-3): the pile column is only left outward, and a pile is reached from
    the column beside it while the next pile is taken."""
    tracker = Tracker(SMALL)
    tracker.place(1, (0, 6), Direction.RIGHT)
    tracker.place(2, (0, 9), Direction.RIGHT)
    tracker.place(3, (10, 0))
    tracker.assign(2, Leg(Task.CHARGE, (0, 9), charge_s=120.0))  # charging where it stands
    tracker.assign(1, Leg(Task.FETCH, (6, 7)))
    done = tracker.run()
    tracker.assign(3, Leg(Task.CHARGE, (0, 6)))
    done += tracker.run()
    assert sorted(d.vehicle for d in done) == [1, 2, 3]
    moves = [e for e in tracker.events if isinstance(e, Moved)]
    assert [(m.origin, m.to) for m in moves if m.origin[0] == 0] == [((0, 6), (1, 6))]
    assert [(m.vehicle, m.origin) for m in moves if m.to[0] == 0] == [(3, (1, 6))]
    assert tracker.agvs[3].cell == (0, 6) and tracker.agvs[2].cell == (0, 9)


def test_of_two_empty_agvs_head_on_the_relaxed_one_gives_way():
    tracker = Tracker(MICRO)
    tracker.place(1, (3, 2), Direction.LEFT)
    tracker.place(2, (2, 2), Direction.RIGHT)
    tracker.assign(1, Leg(Task.FETCH, (1, 2)))
    tracker.agvs[1].relaxed = True  # as after N_relax failed plans, its relaxed path west
    tracker.agvs[1].path = [(2, 2), (1, 2)]
    tracker.assign(2, Leg(Task.FETCH, (6, 2)))
    tracker.run()
    gave_way = [e.vehicle for e in tracker.events if isinstance(e, Replanned)]
    assert gave_way[:1] == [1] and 2 not in gave_way
    assert not tracker.agvs[1].relaxed  # relaxed mode ends at the head-on conflict


@pytest.mark.parametrize("until", [0.0, 0.5, 1.5, 3.5])
def test_a_shelf_on_its_way_home_is_delivered_instead_wherever_its_agv_is(until):
    """Recall (Equation 5) while the AGV stands, turns or moves: it delivers from the cell
    it is in or entering, and the station picks."""
    station = MICRO.stations[0]
    tracker = Tracker(MICRO)
    tracker.place(1, (2, 1), Direction.DOWN, loaded=True)
    tracker.assign(1, Leg(Task.RETURN, (7, 8), home=(7, 8)))
    tracker.advance(until)
    assert tracker.recallable(1)
    tracker.recall(1, Leg(Task.DELIVER, station.entrance, home=(7, 8), station=station))
    assert [type(m) for m in tracker.run()] == [Picked, LegDone]
    assert tracker.agvs[1].loaded and tracker.agvs[1].cell == station.exit_point
    assert judge(MICRO, tracker.events, {1: (2, 1)}, {1: (7, 8)}).passed
    with pytest.raises(ValueError, match="returns no shelf that can be recalled"):
        tracker.recall(1, Leg(Task.DELIVER, station.entrance, home=(7, 8), station=station))


def test_walled_in_by_stagnant_agvs_an_empty_agv_relaxes_the_rules_after_n_failures():
    """Figure 5 (B-DL-4): both exits the rules allow out of (3, 7), left and down, hold idle
    AGVs that turn stagnant; after N_relax failed plans the AGV plans without the rules."""
    start = (3, 7)
    grid = MICRO.grid
    assert allowed(grid, Task.FETCH, start) == {Direction.LEFT, Direction.DOWN}
    tracker = Tracker(MICRO)
    tracker.place(1, start, Direction.UP)
    tracker.place(2, (2, 7))
    tracker.place(3, (3, 8))
    tracker.assign(1, Leg(Task.FETCH, (8, 3)))
    (done,) = tracker.run()
    assert done.vehicle == 1 and tracker.agvs[1].cell == (8, 3)
    replans = [e for e in tracker.events if isinstance(e, Replanned)]
    failed = [r for r in replans if not r.found]
    assert len(failed) == TrackingParams().n_relax and replans[len(failed)].found
    assert replans[len(failed)].relaxed
    moves = [e for e in tracker.events if isinstance(e, Moved)]
    first = moves[0]
    assert first.relaxed and first.origin == start and first.to in ((4, 7), (3, 6))
    starts = {1: start, 2: (2, 7), 3: (3, 8)}
    assert clashes(held_spans(tracker, starts)) == []
    # The judge finds the relaxed episode earned; without the failed plans it would not be.
    assert judge(MICRO, tracker.events, starts).passed
    unearned = [e for e in tracker.events if not (isinstance(e, Replanned) and not e.found)]
    breaches = judge(MICRO, unearned, starts).rule_breaches
    assert breaches and all("without the rules" in b.what for b in breaches)
    assert len(breaches) == sum(m.relaxed for m in moves)


def _orders(tracker: Tracker, floor, vehicles: int, seed: int, trips: int):
    """Each AGV fetches a shelf of its own, takes it to a station, brings it home, `trips`
    times; a new trip as each leg ends (in the order legs end)."""
    rng = random.Random(seed)
    slots = rng.sample([s.xy for s in floor.slots], vehicles * trips)
    plans = {v: [slots[(v - 1) * trips + k] for k in range(trips)]
             for v in range(1, vehicles + 1)}
    for v in range(1, vehicles + 1):
        tracker.place(v, floor.parking[v - 1])
    station = itertools.cycle(floor.stations)
    home: dict[int, tuple[int, int]] = {}

    def following(d: LegDone) -> Leg | None:
        task = d.leg.task
        if d.leg.make_way:
            return None
        if task is Task.FETCH:
            s = next(station)
            return Leg(Task.DELIVER, s.entrance, home=home[d.vehicle], station=s)
        if task is Task.DELIVER:
            return Leg(Task.RETURN, home[d.vehicle], home=home[d.vehicle])
        if not plans[d.vehicle]:
            return None
        home[d.vehicle] = plans[d.vehicle].pop(0)
        return Leg(Task.FETCH, home[d.vehicle])

    for v in range(1, vehicles + 1):
        home[v] = plans[v].pop(0)
        tracker.assign(v, Leg(Task.FETCH, home[v]))
    done = []
    while (d := tracker.advance()) is not None:
        if not isinstance(d, LegDone):
            continue
        done.append(d)
        if (leg := following(d)) is not None:
            tracker.assign(d.vehicle, leg)
    return done


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_a_fleet_fetching_delivering_and_returning_never_shares_a_cell_and_finishes(seed):
    tracker = Tracker(SMALL)
    done = _orders(tracker, SMALL, 8, seed, 3)
    assert len(done) == 8 * 3 * 3
    starts = {v: SMALL.parking[v - 1] for v in range(1, 9)}
    assert clashes(held_spans(tracker, starts)) == []
    assert judge(SMALL, tracker.events, starts).passed
    # A loaded AGV enters no slot but the home of the shelf it returns (B-SAF-2).
    returned = {(e.vehicle, e.leg.goal) for e in tracker.events
                if isinstance(e, LegDone) and e.leg.task is Task.RETURN}
    assert {(m.vehicle, m.to) for m in tracker.events if isinstance(m, Moved) and m.loaded
            and SMALL.kind(m.to) is Kind.SLOT} <= returned
    # Every move outside a station's route and not in relaxed mode kept its task's rules.
    lanes = {c for s in SMALL.stations for c in s.route[1:-1]}
    for m in (e for e in tracker.events if isinstance(e, Moved)):
        if m.relaxed or m.origin in lanes or m.to in lanes:
            continue
        dx, dy = m.to[0] - m.origin[0], m.to[1] - m.origin[1]
        home = m.to if m.task is Task.RETURN and SMALL.kind(m.to) is Kind.SLOT else \
            m.origin if m.task is Task.DELIVER and SMALL.kind(m.origin) is Kind.SLOT else None
        assert Direction(direction_code(dx, dy)) in allowed(SMALL.grid, m.task, m.origin, home), m
    for v in range(1, 9):
        assert not tracker.agvs[v].loaded and tracker.agvs[v].leg is None
    # The store agrees: each AGV ends holding exactly the cell it stands on.
    for v, agv in tracker.agvs.items():
        assert {r.cell for r in tracker.vehicles.view.reservations(v) if r.t1 == float("inf")} == \
            {SMALL.cell(agv.cell)}


def test_tracking_is_deterministic_and_the_heap_and_list_drive_the_same():
    runs = []
    for heap in (True, True, False):
        tracker = Tracker(SMALL, TrackingParams(heap=heap))
        _orders(tracker, SMALL, 6, 7, 2)
        runs.append(tracker.events)
    assert runs[0] == runs[1] == runs[2]


def test_bad_legs_and_places_are_refused_naming_why():
    tracker = Tracker(MICRO)
    tracker.place(1, (2, 1))
    with pytest.raises(ValueError, match="AGV 1 is empty: it cannot take a deliver leg"):
        s = MICRO.stations[0]
        tracker.assign(1, Leg(Task.DELIVER, s.entrance, station=s))
    with pytest.raises(ValueError, match="is taken"):
        tracker.place(2, (2, 1))
    with pytest.raises(ValueError, match="not a cell an AGV can stand on"):
        tracker.place(3, (0, 0))
    with pytest.raises(ValueError, match="ends at its entrance"):
        Leg(Task.DELIVER, (3, 3), station=MICRO.stations[0])


def test_an_idle_agv_under_the_slot_a_shelf_returns_to_is_sent_out_of_the_way():
    slot = (2, 7)
    tracker = Tracker(MICRO)
    tracker.place(1, (2, 6), Direction.DOWN, loaded=True)
    tracker.place(2, slot)  # idle, resting under the slot (assumption 4)
    tracker.assign(1, Leg(Task.RETURN, slot, home=slot))
    done = tracker.run()
    (made,) = [e for e in tracker.events if isinstance(e, MadeWay)]
    assert (made.vehicle, made.idle, made.at) == (1, 2, slot)
    assert made.t == pytest.approx(TrackingParams().t_evict, abs=1.0)
    assert made.to != slot and made.to != (2, 6)
    assert sorted((d.vehicle, d.leg.make_way) for d in done) == [(1, False), (2, True)]
    assert tracker.agvs[2].cell == made.to and not tracker.agvs[2].loaded
    assert clashes(held_spans(tracker, {1: (2, 6), 2: slot})) == []


def test_an_idle_agv_resting_under_the_shelf_to_fetch_is_sent_away_not_planned_around():
    """The goal cannot be planned around: the fetcher waits, and the idle AGV resting under
    the shelf (assumption 4), stagnant by then, is sent out of the way."""
    slot = (2, 7)
    tracker = Tracker(MICRO)
    tracker.place(1, (2, 6), Direction.DOWN)
    tracker.place(2, slot)
    tracker.assign(1, Leg(Task.FETCH, slot))
    done = tracker.run()
    assert sorted((d.vehicle, d.leg.make_way) for d in done) == [(1, False), (2, True)]
    assert [e for e in tracker.events if isinstance(e, Replanned)] == []
    assert [e.idle for e in tracker.events if isinstance(e, MadeWay)] == [2]
    assert tracker.agvs[1].loaded and tracker.agvs[1].cell == slot


def test_an_agv_that_can_never_move_on_is_named_by_the_watchdog():
    """A loaded AGV cannot be sent away: the one returning to the slot it stands on waits
    until the watchdog says who waits for whom, rather than forever."""
    slot = (2, 7)
    tracker = Tracker(MICRO, TrackingParams(watchdog_s=60.0))
    tracker.place(1, (2, 6), Direction.DOWN, loaded=True)
    tracker.place(2, slot, loaded=True)
    tracker.assign(1, Leg(Task.RETURN, slot, home=slot))
    with pytest.raises(Stuck, match=r"AGV 1 at \(2, 6\) has stood 6\d s waiting for "
                                    r"\(2, 7\), held by AGV 2"):
        tracker.run()


def test_a_cell_held_by_someone_outside_the_mission_is_a_closed_cell():
    """A store that others write to too (a run without access control): a cell held by a
    vehicle the mission does not know is driven round by an empty AGV, never taken."""
    from fleet.mission.tracking004 import LocalVehicles
    from fleet.planning.reservations import INF, Interval, ReservationTable

    def fetch(table: ReservationTable) -> Tracker:
        tracker = Tracker(MICRO, vehicles=LocalVehicles(MICRO, TrackingParams(), table))
        tracker.place(1, (2, 7), Direction.UP)
        tracker.assign(1, Leg(Task.FETCH, (2, 2)))
        (done,) = tracker.run()
        assert done.vehicle == 1 and tracker.agvs[1].cell == (2, 2)
        return tracker

    free_way = [e.to for e in fetch(ReservationTable()).events if isinstance(e, Moved)]
    blocked, stranger = free_way[len(free_way) // 2], 999
    table = ReservationTable()
    table.commit(stranger, [Interval(MICRO.cell(blocked), 0.0, INF)])
    tracker = fetch(table)
    assert blocked not in {e.to for e in tracker.events if isinstance(e, Moved)}
    assert any(isinstance(e, Replanned) for e in tracker.events)
    assert table.conflict(1, MICRO.cell(blocked), 0.0, INF) == stranger
