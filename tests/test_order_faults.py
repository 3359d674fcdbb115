"""Faults on seed 002's order missions, in one process (docs/faults.md, docs/agv-002.md): what a
trip cut short means to the order book, AGVs getting round one that stands for good and round
a closed zone, the scenarios written for paper002, and the order book's journal a restarted
dispatcher replays. The runs of processes are tests/test_order_fault_runs.py."""

from __future__ import annotations

import random
import re
from collections import Counter

import msgpack
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from dispatcher.work_journal import WorkJournal
from fleet.analysis.analyze import analyze
from fleet.cli import main
from fleet.dispatching.decision import Decision, Strategy, TaskKind
from fleet.errors import UserError
from fleet.mission.engine import Engine, EngineOptions, MissionStuck, engine_options
from fleet.mission.faults import Fault, FaultKind, Scenario, builtin_scenarios, load_scenario
from fleet.mission.freeze import ScheduledPacer
from fleet.mission.order_log import from_record
from fleet.mission.order_work import OrderWork
from fleet.mission.orders import OrderBook, Phase, release_orders
from fleet.mission.pickup import HeldLeg, recovered_orders
from fleet.mission.record import digest
from fleet.mission.seam import LocalExecutor, NoPacer
from fleet.mission.spec import Mission, MissionKind
from fleet.planning.lane_schedule import timed
from fleet.planning.reservations import INF, Interval, ReservationTable
from fleet.planning.trajectory import FailureReason, PlanFailure, Pose, Trajectory
from fleet.recording.inprocess import Interrupted, recorded_run, write_recording
from fleet.recording.reader import read_recording
from fleet.vehicles.agv import leg_of
from fleet.wire.protocol import ZONE
from fleet.world.lanes import floor_cells
from fleet.world.layout_file import load_layout
from fleet.world.site import planners_for

PAPER002 = load_layout("paper002")
VEHICLE_KINDS = ("kill_vehicle", "stall_vehicle", "cut_link", "vehicle_breakdown", "close_zone")


def orders(n: int = 16, vehicles: int = 4, seed: int = 0) -> Mission:
    return Mission("paper002", MissionKind.ORDERS, Strategy.NEAREST, vehicles, seed, orders=n)


def faulty(mission: Mission, scenario: Scenario) -> Engine:
    return Engine(mission, layout=PAPER002, pacer=ScheduledPacer(scenario))


def assert_every_order_once_and_shelves_kept(engine: Engine) -> None:
    """Every order done exactly once (done minus reopened, as the record keeps it), the book
    agreeing with itself, and every shelf back in a slot of its own."""
    done = Counter(index for _, index, _ in engine.record.stacks_done)
    assert sorted(done) == list(range(1, engine.mission.orders + 1)), done
    assert set(done.values()) == {1}
    book = engine.work.book
    book.check()
    shelves = [shelf for shelf in book.slot_shelf.values() if shelf is not None]
    assert sorted(shelves) == sorted(PAPER002.shelves)  # each in one slot, none elsewhere


# -- the order book ------------------------------------------------------------------------------
def test_an_agv_down_on_its_way_to_a_shelf_gives_the_order_back_and_takes_none():
    book = OrderBook(PAPER002, 2, release_orders(PAPER002, 3, seed=4))
    first = book.assign(0.0)
    agv = first[0].agv
    book.down(agv, 5.0)
    order = book.give_back(agv, 5.0, driven=4.0)
    assert order == first[0].order and book.agvs[agv].phase is Phase.IDLE
    assert book.pending()[0] == order  # back at the front of its shelf's queue
    assert book.soc(agv) < 100.0  # the 4 s it drove count
    assert all(a.agv != agv for a in book.assign(6.0))  # down: given nothing
    book.up(agv, 7.0, (5, 4))
    again = book.assign(8.0)
    assert [a.agv for a in again] == [agv] and book.agvs[agv].cell == (5, 4)
    book.check()


def test_the_book_chooses_no_place_that_is_blocked_and_retargets_one_that_becomes_so():
    book = OrderBook(PAPER002, 1, release_orders(PAPER002, 1, seed=0))
    (a,) = book.assign(0.0)
    trip = book.at_shelf(1, 10.0)
    assert trip is not None
    book.block(frozenset({trip.station.cell}), 11.0)  # a spill on its station
    station = book.retarget(1, 11.0)
    assert station is not None and station != trip.station
    assert book.station_available(trip.station.name)  # the old one is free again
    back = book.at_station(1, 20.0)
    book.block(frozenset(s.cell for s in book.vacant_slots()), back)
    left = book.left_station(1, back)  # every vacant slot closed: one anyway, to wait for
    assert left.slot.cell == a.slot.cell
    book.check()


def test_an_agv_back_on_a_lane_with_nothing_to_do_goes_to_a_pile():
    book = OrderBook(PAPER002, 1, release_orders(PAPER002, 1, seed=0))
    book.assign(0.0)  # it leaves its pile for a shelf
    book.down(1, 1.0)
    book.give_back(1, 1.0)
    book.up(1, 2.0, (6, 4))
    assert book.assign(2.0)  # the order again, from where it stands
    book.down(1, 3.0)
    book.give_back(1, 3.0)
    book.up(1, 4.0, (7, 4))
    book.queues.clear()  # the order done by another meanwhile: nothing to take
    book.orders.clear()
    trip = book.park(1, 4.0)
    assert trip is not None and trip.reason == "park" and book.agvs[1].phase is Phase.TO_PILE
    assert book.park(1, 4.0) is None  # on its way already
    book.check()


# -- runs with faults ------------------------------------------------------------------------------
@pytest.mark.parametrize("name", VEHICLE_KINDS)
def test_each_fault_on_an_order_mission_completes_every_order_once(name, tmp_path):
    """paper002's own scenario of each fault that moves the schedule, on 16 orders with four
    AGVs: every order done once, the shelves all back in slots, and the recording passes
    every verdict; the faulty AGV was halted and resumed."""
    mission, scenario = orders(), load_scenario(name, "paper002")
    engine = faulty(mission, scenario)
    engine.run()
    assert_every_order_once_and_shelves_kept(engine)
    (fault,) = scenario.faults
    if fault.vehicle is not None:
        assert fault.vehicle in {v for v, _, _ in engine.record.halts}
        assert (fault.vehicle, fault.until) in engine.record.resumes
    done, stream = recorded_run(mission, PAPER002, engine_options(mission, PAPER002, None),
                                scenario=scenario)
    assert done.ok and done.digest == digest(engine.record)  # a function of the scenario
    write_recording(tmp_path / "run.mcap", stream, PAPER002)
    report = analyze(read_recording(tmp_path / "run.mcap"))
    assert report.passed and report.complete, report.verdict_lines()
    assert (len(report.overlaps), len(report.outside_reservation)) == (0, 0)


def test_an_agv_down_for_good_on_its_way_to_a_shelf_leaves_its_order_to_another():
    """AGV 2 dies on its way to its first shelf and never comes back: its order goes to
    another AGV, the others go round where it stands, and every order is done."""
    engine = faulty(orders(12, 3), Scenario("dead", "", (
        Fault(FaultKind.KILL_VEHICLE, 8.0, 2),)))
    engine.run()
    assert_every_order_once_and_shelves_kept(engine)
    assert 2 in engine.faults.down


def test_an_agv_down_for_good_with_a_shelf_ends_the_mission_saying_so():
    """An AGV that breaks down for good carrying a shelf keeps it: the order it carries
    cannot be done, and the mission ends (it does not hang) saying how much is left and
    which AGV is down."""
    engine = faulty(orders(16, 4), Scenario("broken", "", (
        Fault(FaultKind.VEHICLE_BREAKDOWN, 70.3, 1),)))
    with pytest.raises(MissionStuck, match=r"the mission cannot finish: 1 of 16 not done by "
                                           r"t=[\d.]+ s, with vehicles 1 down for good"):
        engine.run()
    book = engine.work.book
    assert book.agvs[1].phase in (Phase.TO_STATION, Phase.TO_SLOT)  # the shelf on it
    book.check()


def random_scenario(rng: random.Random, vehicles: int, horizon: float) -> Scenario:
    """A few faults of the kinds that move the schedule, each over in time; zones on the
    lanes."""
    lanes = sorted(PAPER002.lane_directions)
    faults: list[Fault] = []
    for _ in range(rng.randint(2, 4)):
        kind = rng.choice([FaultKind.KILL_VEHICLE, FaultKind.STALL_VEHICLE, FaultKind.CUT_LINK,
                           FaultKind.VEHICLE_BREAKDOWN, FaultKind.CLOSE_ZONE])
        at, duration = round(rng.uniform(5, horizon), 1), round(rng.uniform(5, 90), 1)
        if kind is FaultKind.CLOSE_ZONE:
            c0, r0 = rng.choice(lanes)
            cells = tuple(c for c in ((c0 + i, r0 + j) for i in range(rng.randint(1, 3))
                                      for j in range(rng.randint(1, 2))) if c in lanes)
            faults.append(Fault(kind, at, duration=duration, cells=cells))
            continue
        vehicle = rng.randint(1, vehicles)
        if all(f.vehicle != vehicle or at > f.until or at + duration < f.at for f in faults):
            faults.append(Fault(kind, at, vehicle, duration))
    return Scenario("random", "", tuple(sorted(faults, key=lambda f: f.at)))


@pytest.mark.parametrize("seed", range(6))
def test_random_faults_on_an_order_mission_complete_every_order_once(seed, tmp_path):
    """Seeded random faults (kills, stalls, cut links, breakdowns, zones on the lanes) on 30
    orders with six AGVs: the mission completes with every order once, and its recording
    passes every verdict (no two AGVs on a cell, none outside its reservation)."""
    mission = orders(30, 6, seed)
    scenario = random_scenario(random.Random(seed), 6, 350.0)
    done, stream = recorded_run(mission, PAPER002, engine_options(mission, PAPER002, None),
                                scenario=scenario)
    assert done.ok, done.error
    assert Counter(i for _, i, _ in done.record["stacks_done"]) == Counter(range(1, 31))
    write_recording(tmp_path / "run.mcap", stream, PAPER002)
    report = analyze(read_recording(tmp_path / "run.mcap"))
    assert report.passed, report.verdict_lines()


# -- routes round what stands for good -------------------------------------------------------
def test_a_route_goes_round_an_agv_that_stands_for_good_and_a_closed_zone():
    planners = planners_for(PAPER002)
    planner = planners.get(frozenset())
    start, goal = Pose((2, 4), 0), Pose((13, 12), 0)  # east along h2, then north on v1
    table = ReservationTable()
    straight = planner.plan(1, start, 0.0, [goal], table)
    assert isinstance(straight, Trajectory)
    assert {s.end.cell for s in straight.steps} >= {(7, 4)}
    table.commit(2, [Interval((7, 4), 0.0, INF)])  # AGV 2 down on the lane, for good
    around = planner.plan(1, start, 0.0, [goal], table)
    assert isinstance(around, Trajectory) and around.goal == goal
    assert all((7, 4) not in s.cells for s in around.steps)  # north on v0 first
    assert table.commit(ZONE, [Interval((13, 12), 10.0, 100.0)]).ok  # the goal's cell closed
    closed = planner.plan(1, start, 0.0, [goal], table)
    assert isinstance(closed, PlanFailure) and closed.reason is FailureReason.NO_PATH
    assert isinstance(planner.plan(1, start, 100.0, [goal], table), Trajectory)  # open again


def test_a_leg_through_an_agv_frozen_mid_move_is_no_plan_to_commit():
    """An AGV halted in the middle of a move holds both its cells for good, with no route in
    time the collision rules could settle with: a leg across them fails (to be tried again
    once it has moved) rather than reach the store."""
    planners = planners_for(PAPER002)
    table = ReservationTable()
    table.commit(2, [Interval((8, 5), 0.0, INF), Interval((7, 5), 0.0, INF)])
    route = planners.get(frozenset()).routes.route((10, 5), (5, 5))  # westbound along h2
    assert route is not None and (7, 5) in route.cells
    leg = leg_of(timed(1, route.cells, 0.0, 1.0))
    result = planners.policy.commitment(leg, table)
    assert isinstance(result, PlanFailure) and result.reason is FailureReason.NO_PATH
    assert "held by vehicle 2" in result.detail


# -- scenarios for paper002 ------------------------------------------------------------------
@pytest.mark.parametrize("name", builtin_scenarios())
def test_paper002_ships_its_own_version_of_every_scenario(name, capsys):
    scenario = load_scenario(name, "paper002")
    assert scenario != load_scenario(name)  # not paper's forklifts and cells
    assert all(set(f.cells) <= floor_cells(PAPER002) for f in scenario.faults)
    assert main(["faults", "check", name, "--layout", "paper002", "--vehicles", "4"]) == 0
    assert "fine for paper002 with 4 AGVs" in capsys.readouterr().out


def test_a_zone_off_a_lane_layouts_floor_is_refused_in_one_line(tmp_path, capsys):
    path = tmp_path / "spill.toml"
    path.write_text('[[fault]]\nkind = "close_zone"\nat = 10.0\nduration = 5.0\n'
                    'cells = "0,29..2,30"\n')
    assert main(["faults", "check", str(path), "--layout", "paper002"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err
    assert "cell (0, 30) is off the floor of layout paper002" in err
    assert main(["run", "--layout", "paper002", "--orders", "4", "--inprocess", "--faults",
                 str(path)]) == 2
    assert "off the floor of layout paper002" in capsys.readouterr().err


# -- the order book's journal ----------------------------------------------------------------
def journaled(mission: Mission, scenario: Scenario) -> tuple[Engine, list]:
    """The mission run with its order work journaling into a list, as msgpack gives it back."""
    records: list = []

    class Log:
        def append(self, record: list) -> None:
            records.append(msgpack.unpackb(msgpack.packb(record)))

    engine = faulty(mission, scenario)
    engine.work.log = Log()
    engine.run()
    return engine, records


def book_state(work: OrderWork) -> tuple:
    b = work.book
    return (b.completed, b.where, b.slot_state, b.station_agv, b.pile_agv,
            {k: (a.phase, a.order, a.cell, a.soc, a.slot, a.station, a.pile)
             for k, a in b.agvs.items()}, work.trips, work.legs,
            sorted((e.t, e.seq, e.agv, e.what) for e in work.events if e.live))


def test_the_journal_replays_the_order_book_exactly():
    mission = orders()
    engine, records = journaled(mission, load_scenario("mixed", "paper002"))
    assert {r[0] for r in records} >= {"advance", "served", "amended", "cancelled", "down",
                                      "up", "closed"}
    for cut in (len(records) // 3, len(records)):  # part of the way, and the whole of it
        again = OrderWork.replayed(PAPER002, mission, 4, records[:cut])
        if cut == len(records):
            assert book_state(again) == book_state(engine.work)
        assert again.done() == sorted(again.done(), key=lambda d: (d[2], d[1]))


def test_a_restarted_dispatcher_takes_a_leg_its_journal_never_heard_of():
    """The dead dispatcher had a trip committed but never the answer: the journal lacks it,
    the AGV's agent holds it, and the pick-up feeds it to the book."""
    mission = orders()
    engine, records = journaled(mission, Scenario("none", "", ()))
    k = max(i for i, r in enumerate(records) if r[0] == "served" and r[1] == 3)
    _, vehicle, t_start, t_end, _ = records[k]
    replayed = OrderWork.replayed(PAPER002, mission, 4, records[:k])
    assert replayed.last_leg(vehicle) != (t_start, t_end)
    leg = next(s.trajectory for s in engine.record.subtasks
               if s.vehicle == vehicle and s.trajectory.t_start == t_start)
    held = [HeldLeg(vehicle, leg.goal, leg, True, "")]
    recovered = recovered_orders(replayed, held, t_start)
    assert replayed.last_leg(vehicle) == (t_start, t_end) and recovered.work is replayed
    assert recovered.poses[vehicle] == leg.goal and recovered.t_free[vehicle] >= t_end
    stray = HeldLeg(1, leg.goal, Trajectory(1, leg.start, leg.goal, 1e5, leg.steps, (), 0),
                    False, "")
    with pytest.raises(UserError, match=r"AGV 1 drives a leg from t=100000\.00 that its "
                                        r"order book never decided"):
        recovered_orders(OrderWork.replayed(PAPER002, mission, 4, records), [stray], 0.0)


@pytest.mark.parametrize("record, says", [
    (["served", 0, 1.0, 2.0, 1.0], "vehicle must be a number from 1"),
    (["advance"], "a advance record has 1 fields, not 0"),
    (["teleport", 1], "unknown record kind 'teleport'"),
    (["cancelled", 1, "dance", 1.0], "unknown trip kind 'dance'"),
    (["up", 1, 5.0, [1]], "a cell is [col, row]"),
    ({"advance": 1}, "not a record"),
])
def test_a_malformed_journal_record_is_named(record, says):
    with pytest.raises(ValueError, match=re.escape(says)):
        from_record(record)
    with pytest.raises(UserError, match=r"the order book's journal, record 2: "):
        OrderWork.replayed(PAPER002, orders(), 4, [["advance", 0.0], record])


def test_a_torn_journal_record_is_cut_off_and_garbage_named(tmp_path):
    journal = WorkJournal(tmp_path / "dispatcher.journal")
    journal.append(["advance", 1.0])
    journal.append(["served", 1, 1.0, 5.0, 4.0])
    journal.close()
    whole = (tmp_path / "dispatcher.journal").read_bytes()
    (tmp_path / "dispatcher.journal").write_bytes(whole + msgpack.packb(["advance", 9.0])[:-2])
    assert journal.records() == [["advance", 1.0], ["served", 1, 1.0, 5.0, 4.0]]
    assert (tmp_path / "dispatcher.journal").read_bytes() == whole  # the tail cut off
    (tmp_path / "dispatcher.journal").write_bytes(b"\xc1" + whole)
    with pytest.raises(UserError, match="record 1 at byte 0 is not msgpack"):
        journal.records()


def test_the_served_decision_of_a_replayed_book_is_the_same():
    """Serving the decided trip through the seam journals what a replay takes again."""
    mission = orders(4, 2)
    work = OrderWork(PAPER002, mission, 2)
    trip = work.trips[1]
    leg = Trajectory(1, Pose((3, 30), 0), trip.goals[0], 0.0, (), (), 0)
    records: list = []
    work.log = type("Log", (), {"append": lambda self, r: records.append(r)})()
    work.serve(Decision(1, 0.0, TaskKind.FETCH, trip, False), leg, 0.0)
    assert records == [["served", 1, 0.0, 0.0, 0]]
    again = OrderWork.replayed(PAPER002, mission, 2, records)
    assert again.last_leg(1) == (0.0, 0.0) and 1 not in again.trips


def test_a_dispatcher_refuses_another_missions_journal_in_one_line(tmp_path, capsys):
    """A journal with records belongs to a mission to pick up: a new mission does not write
    over it (nor start at all)."""
    journal = tmp_path / "dispatcher.journal"
    journal.write_bytes(msgpack.packb(["advance", 1.0]))
    assert main(["dispatcher", "--layout", "paper002", "--orders", "3", "--journal",
                 str(journal), "--connect", "tcp/127.0.0.1:1"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "holds an earlier mission's order book: pick that " \
        "mission up (--recover) or give another file" in err


records = st.recursive(
    st.none() | st.booleans() | st.integers(-5, 40) | st.floats(allow_nan=True) |
    st.sampled_from(["advance", "served", "amended", "cancelled", "down", "up", "closed",
                     "fetch", "stow"]),
    lambda inner: st.lists(inner, max_size=5), max_leaves=12)


@settings(max_examples=300, deadline=None, derandomize=True)
@given(st.lists(records, max_size=6))
def test_any_journal_replays_or_is_refused_naming_the_record(raws):
    """Whatever a journal holds, replaying it gives a book or a UserError naming the record,
    never another error."""
    try:
        OrderWork.replayed(PAPER002, orders(4, 2), 2, raws)
    except UserError as exc:
        assert str(exc).startswith("the order book's journal, record ")


class _StopAfter(NoPacer):
    """A pacer that ends the run (as a killed dispatcher's) before its n-th decision."""

    def __init__(self, decisions: int) -> None:
        self.left = decisions

    def before_decision(self, t_next: float, t_free: dict[int, float]) -> dict[int, float]:
        self.left -= 1
        if self.left < 0:
            raise Interrupted("killed")
        return t_free


class Parked(LocalExecutor):
    """The dead engine's table, each AGV already parked where its last leg ends."""

    def __init__(self, table: ReservationTable) -> None:
        super().__init__(PAPER002.vehicle_kind, planners_for(PAPER002))
        self.table = table

    def park(self, vehicle: int, pose: Pose) -> None:
        pass


@pytest.mark.parametrize("decisions", [25, 40, 70])  # at 40 a leg picked up is postponed
def test_a_restarted_engine_picks_an_order_mission_up_from_its_journal(decisions):
    """The engine dies part of the way (its journal and table left); a new one replays the
    journal, takes each AGV's last leg as its agent would hold it, and finishes: every
    order once, the book whole, legs committed before the restart postponed as well."""
    mission = orders(40, 6)
    records: list = []

    class Log:
        def append(self, record: list) -> None:
            records.append(msgpack.unpackb(msgpack.packb(record)))

    first = Engine(mission, EngineOptions(work_log=Log()), PAPER002, pacer=_StopAfter(decisions))
    with pytest.raises(Interrupted):
        first.run()
    held = [HeldLeg(v, slot.pose, (first.faults.driven[v] or [None])[-1], False, "")
            for v, slot in first.fleet.items()]
    work = OrderWork.replayed(PAPER002, mission, 6, records, Log())
    recovered = recovered_orders(work, held, first.now)
    second = Engine(mission, EngineOptions(), PAPER002, Parked(first.executor.store),
                    recovered=recovered)
    record = second.run()
    assert Counter(i for _, i, _ in record.stacks_done) == Counter(range(1, 41))
    second.work.book.check()


def test_an_agv_walled_in_by_one_that_is_down_is_told_apart_from_one_kept_waiting():
    """The wait-for graph's question (fleet/mission/deadlock.py): on h2 between two vertical
    channels the only way east passes AGV 2, which stands there for good. Down, it walls
    AGV 1 in (the engine says so, `dispatch/deadlock` walled, and AGV 1 waits for it to come
    back); able to move, it is AGV 1's one blocker."""
    planner = planners_for(PAPER002).get(frozenset())
    table = ReservationTable()
    table.commit(2, [Interval((7, 4), 0.0, INF)])
    start, goal = Pose((3, 4), 0), Pose((11, 4), 0)
    assert planner.blockage(1, start, [goal], table, lambda v: v != 2) is None
    way = planner.blockage(1, start, [goal], table, lambda v: True)
    assert way is not None and way.blockers == {2} and way.goal == goal
    assert (7, 4) in way.cells and start.cell in way.cells
    free = planner.blockage(1, start, [Pose((13, 12), 0)], ReservationTable(), lambda v: True)
    assert free is not None and free.blockers == frozenset()
