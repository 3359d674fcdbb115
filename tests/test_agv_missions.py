"""Seed 002's AGV kind driven by the engine: its legs, the amendments its collision rules
make to legs already committed, and order missions on paper002 from the engine to the
recording (docs/agv-002.md)."""

import itertools
import json
import math
from collections import Counter

import pytest
from mission_check import journal_overlaps

from fleet.analysis.analyze import analyze
from fleet.cli import main
from fleet.dispatching.decision import Strategy, TaskKind
from fleet.mission.drive_log import AmendLeg
from fleet.mission.engine import Engine, EngineOptions, run_mission
from fleet.mission.record import digest
from fleet.mission.seam import LocalExecutor, Task
from fleet.mission.spec import Mission, MissionKind
from fleet.planning.lane_schedule import Schedule
from fleet.planning.reservations import INF, Amendment, Interval, ReservationTable, TimedRoute
from fleet.planning.trajectory import LaneMove, Pose, Trajectory
from fleet.recording.inprocess import vehicle_states
from fleet.recording.reader import read_recording
from fleet.runtime.local_run import RunSpec, run_processes
from fleet.vehicles.agv import leg_of, schedule_of
from fleet.wire.protocol import VehicleState
from fleet.wire.topics import Keys
from fleet.world.layout_file import load_layout
from fleet.world.site import planners_for

CROSS = load_layout("micro-cross")
PAPER002 = load_layout("paper002")


def orders(n: int, vehicles: int, seed: int = 0) -> Mission:
    return Mission(layout="paper002", kind=MissionKind.ORDERS, strategy=Strategy.NEAREST,
                   vehicles=vehicles, seed=seed, orders=n)


def test_a_leg_drives_its_schedule_waits_and_all():
    schedule = Schedule(3, ((2, 4), (3, 4), (4, 5), (4, 6)), (1.0, 2.0, 5.4, 6.4),
                        (0.0, 2.0, 0.0, INF), 1.0)
    leg = leg_of(schedule)
    assert [s.manner for s in leg.steps] == [LaneMove.MOVE, LaneMove.WAIT, LaneMove.DIAGONAL,
                                              LaneMove.MOVE]
    assert [(s.t0, s.t1) for s in leg.steps] == [(1.0, 2.0), (2.0, 4.0), (4.0, 5.4),
                                                  (5.4, 6.4)]
    assert leg.steps[2].cells == {(3, 4), (4, 5), (3, 5), (4, 4)}  # the diagonal's block
    assert (leg.t_start, leg.t_end, leg.goal.cell) == (1.0, 6.4, (4, 6))
    assert Interval((4, 6), 5.4, INF) in leg.intervals  # parked at the end, for good
    assert schedule_of(leg, 1.0) == schedule


def test_the_table_keeps_each_vehicles_route_beside_its_reservations():
    table = ReservationTable()
    route = TimedRoute(((0, 0), (1, 0)), (0.0, 1.0), (0.0, INF))
    assert table.commit(1, [Interval((0, 0), 0.0, 1.0), Interval((1, 0), 0.0, INF)],
                        route=route).ok
    assert table.route(1) == route
    later = TimedRoute(((0, 0), (1, 0)), (0.0, 3.0), (2.0, INF))
    amended = Amendment(1, 0.0, (Interval((0, 0), 0.0, 3.0), Interval((1, 0), 2.0, INF)),
                        later)
    assert table.commit(2, [Interval((5, 5), 0.0, INF)], None, [amended]).ok
    assert (table.route(1), table.route(2)) == (later, None)  # 2 gave none
    mirror = ReservationTable()
    for change in table.changes:
        mirror.apply(change)
    assert mirror.route(1) == later
    table.release(1, 1.0)
    assert table.route(1) is None  # what it still holds is no longer that route


def test_a_committed_agv_from_the_horizontal_lane_is_made_to_wait_for_one_from_the_longitudinal():
    """Figure 11 (a) as legs: AGV 1 eastbound is committed through the crossroad first; AGV
    2 northbound plans after, and (13) gives it priority: AGV 1's committed leg is amended to
    wait at (3, 4), its last node before the crossroad, in the same commit."""
    kind = CROSS.vehicle_kind
    executor = LocalExecutor(kind, planners_for(CROSS))
    executor.park(1, Pose((2, 4), 0))
    executor.park(2, Pose((5, 2), 0))
    first = executor.execute(Task(1, TaskKind.FETCH, Pose((2, 4), 0), 0.0,
                                  (Pose((7, 4), 0),), frozenset(), False))
    assert isinstance(first, Trajectory) and executor.take_amended() == []
    assert not any(s.manner is LaneMove.WAIT for s in first.steps)
    second = executor.execute(Task(2, TaskKind.FETCH, Pose((5, 2), 0), 1.0,
                                   (Pose((5, 7), 0),), frozenset(), False))
    assert isinstance(second, Trajectory)
    assert not any(s.manner is LaneMove.WAIT for s in second.steps)  # it has priority
    [amended] = executor.take_amended()
    waits = [s for s in amended.steps if s.manner is LaneMove.WAIT]
    assert [w.start.cell for w in waits] == [(3, 4)] and waits[0].t0 == 1.0
    assert amended.t_end > first.t_end and amended.t_start == first.t_start
    table = executor.store
    assert schedule_of(amended, 1.0).arrivals == table.route(1).arrivals
    assert table.reservations(1) == sorted(
        (r for r in table.reservations() if r.vehicle == 1), key=lambda r: (r.cell, r.t0))
    for cell in {r.cell for r in table.reservations()}:  # held by one AGV at a time
        spans = sorted((r.t0, r.t1) for r in table.reservations() if r.cell == cell)
        assert all(a[1] <= b[0] for a, b in itertools.pairwise(spans)), cell


def test_an_order_mission_completes_every_order_once_and_is_the_same_every_time():
    mission = orders(40, 6, seed=3)
    first, again = run_mission(mission), run_mission(mission)
    assert digest(first) == digest(again)
    done = Counter(index for _, index, _ in first.stacks_done)
    assert sorted(done) == list(range(1, 41)) and set(done.values()) == {1}
    kinds = Counter(s.kind for s in first.subtasks)
    assert kinds[TaskKind.FETCH] == kinds[TaskKind.PACK] == kinds[TaskKind.STOW] == 40
    assert first.end_time == max(t for _, _, t in first.stacks_done)
    # Each AGV's legs follow one another, and each stops at the station for its dwell.
    for vehicle in first.vehicles:
        legs = [s for s in first.subtasks if s.vehicle == vehicle]
        assert all(a.t_done <= b.t_i for a, b in itertools.pairwise(legs))
        for a in legs:
            if a.kind is TaskKind.PACK:
                assert math.isclose(a.t_done - a.t_end, 10.0)


def test_collision_rules_amend_committed_legs_in_a_busy_mission():
    engine = Engine(orders(60, 10, seed=1))
    record = engine.run()
    last = {}  # each leg's last amendment
    for log in engine.drive_log.values():
        for order in log:
            if isinstance(order, AmendLeg):
                last[order.trajectory.vehicle, order.trajectory.t_start] = order.trajectory
    assert last, "ten AGVs on 60 orders meet at junctions: some committed leg must wait"
    for leg in last.values():  # the record holds each amended leg as the AGV drives it
        assert any(s.trajectory == leg for s in record.subtasks)


def test_fleet_run_runs_an_order_mission_in_process_and_its_recording_passes(tmp_path, capsys):
    out = tmp_path / "run"
    code = main(["run", "--layout", "paper002", "--orders", "30", "--vehicles", "5",
                 "--inprocess", "--out", str(out), "--json"])
    summary = json.loads(capsys.readouterr().out)
    assert code == 0, summary
    assert summary["mission"]["kind"] == "orders" and summary["mission"]["strategy"] == \
        "nearest"
    assert summary["verdicts"]["safety"] and summary["verdicts"]["passed"]
    assert summary["incomplete"] == []
    assert summary["digest"] == digest(run_mission(orders(30, 5)))


@pytest.mark.parametrize("argv, says", [
    (["--orders", "10", "--inprocess", "--strategy", "ann"],
     "--strategy ann does not dispatch orders missions"),
    (["--orders", "10", "--inprocess", "--vehicles", "40"],
     "--vehicles 40: the AGVs of layout paper002 start on its 33 charging piles, one each"),
    (["--orders", "10", "--inprocess", "--mission", "fill"],
     "--orders is for order missions, not --mission fill"),
    (["--orders", "s-3-3,s-99-3,s-4-3,s-0-0"],  # checked before any process starts
     "--orders: order 2 is for shelf 's-99-3', which layout paper002 does not have (and 1 "
     "more)"),
    (["--orders", "s-3-3", "--order-area", "lower-left"],
     "--order-area draws orders: give it with --orders N"),
    (["--order-area", "nowhere"], "layout paper002 has no shelf area 'nowhere'"),
    (["--vehicles", "4", "--battery", "n_op=5"],
     "--battery: n_op (AGVs kept operational) is 5 but the fleet has only 4 AGVs"),
])
def test_fleet_run_refuses_what_an_order_mission_cannot_do_in_one_line(argv, says, capsys):
    assert main(["run", "--layout", "paper002", *argv]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err and says in err, err


def test_orders_given_by_shelf_are_released_in_their_order(tmp_path, capsys):
    """`--orders` takes a file of shelf names or the names themselves: the same orders, the
    same record, as processes too."""
    listed = tmp_path / "orders.txt"
    listed.write_text("# three orders, two on one shelf\ns-3-3\ns-14-3  # the next block\n"
                      "\ns-3-3\n")
    runs = {}
    for given, mode in ((str(listed), "--inprocess"), ("s-3-3,s-14-3,s-3-3", None)):
        out = tmp_path / f"run-{len(runs)}"
        argv = ["run", "--layout", "paper002", "--orders", given, "--vehicles", "2",
                "--out", str(out), "--json", *([mode] if mode else [])]
        assert main(argv) == 0
        runs[given] = json.loads(capsys.readouterr().out)
    first, second = runs.values()
    assert first["digest"] == second["digest"] and first["verdicts"]["passed"]
    assert first["orders"]["expected"] == first["orders"]["done"] == 3
    info = read_recording(tmp_path / "run-1" / "run.mcap").info
    assert info.released == ["s-3-3", "s-14-3", "s-3-3"] and info.orders == 3


def test_a_stack_mission_on_a_lane_layout_is_refused_naming_what_it_runs():
    with pytest.raises(Exception, match="layout paper002 has no stacks for a fill mission: "
                                        "it runs order missions"):
        Engine(Mission(layout="paper002", kind=MissionKind.FILL), EngineOptions())


def test_an_amendment_with_a_route_may_retake_later_a_cell_its_agv_had_just_left():
    """An AGV arrived at (0, 0) from (1, 0) at t=2 and leaves at once back over (1, 0): the
    table holds (1, 0) as one interval across t=2. Postponed to wait at (0, 0) first, it
    leaves (1, 0) free for a while: allowed, since its route has it on (0, 0) at t=2; the
    cell it stands on must still be held on without a gap."""
    def arrived() -> ReservationTable:
        table = ReservationTable()
        assert table.commit(1, [Interval((1, 0), 1.0, 2.0), Interval((0, 0), 1.0, INF)]).ok
        leg = [Interval((0, 0), 2.0, 3.0), Interval((1, 0), 2.0, 4.0),
               Interval((2, 0), 3.0, INF)]
        assert table.commit(1, leg, release_from=2.0).ok
        return table

    table = arrived()
    waited = (Interval((0, 0), 2.0, 8.0), Interval((1, 0), 7.0, 9.0),
              Interval((2, 0), 8.0, INF))
    route = TimedRoute(((0, 0), (1, 0), (2, 0)), (2.0, 8.0, 9.0), (5.0, 0.0, INF))
    without = table.commit(2, [Interval((5, 5), 0.0, INF)], None,
                           [Amendment(1, 2.0, waited)])
    assert not without.ok and "cell (1, 0)" in without.reason
    assert table.commit(2, [Interval((5, 5), 0.0, INF)], None,
                        [Amendment(1, 2.0, waited, route)]).ok
    assert table.conflict(3, (1, 0), 2.5, 6.5) is None  # free while it waits
    gap = (Interval((0, 0), 4.0, 8.0), *waited[1:])  # leaves the cell it stands on a while
    refused = arrived().commit(2, [], None, [Amendment(1, 2.0, gap, route)])
    assert not refused.ok and "cell (0, 0)" in refused.reason


def test_fast_mode_agv_processes_equal_the_inprocess_reference(tmp_path):
    """One agent process per AGV on zenoh: the legs amended by the collision rules go through
    the reservation service and the dispatcher tells each AGV, so the record is the one the
    engine keeps in process, bit for bit, and every AGV drives as there."""
    mission = orders(40, 8, seed=2)
    engine = Engine(mission)
    reference = engine.run()
    assert any(isinstance(o, AmendLeg) for log in engine.drive_log.values() for o in log)
    outcome = run_processes(RunSpec(mission, 8, tmp_path))
    assert outcome.error == ""
    assert outcome.done.digest == digest(reference)
    assert journal_overlaps(tmp_path / "reservation.journal") == []
    recording = read_recording(tmp_path / "run.mcap")
    report = analyze(recording)
    assert report.passed and report.complete and report.finished
    assert (len(report.overlaps), len(report.outside_reservation)) == (0, 0)
    recorded = sorted((r.key, r.envelope.sim_time, m) for r, m in recording.of(VehicleState))
    driven = sorted((o.key, o.sim_time, o.message)
                    for o in vehicle_states(reference, PAPER002, Keys(), engine.drive_log,
                                            info=recording.info))
    assert all(0 < m.battery <= 100 for _, _, m in recorded)  # each AGV's charge, as driven
    assert recorded == driven
