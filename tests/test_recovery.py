"""Who stops, and where, when a forklift cannot follow its schedule (fleet/mission/freeze.py), and
whole in-process missions with faults: safe, and every stack exactly once."""

import math
import random

from hypothesis import given, settings
from hypothesis import strategies as st

from fleet.analysis.safety import double_bookings, replay
from fleet.dispatching.decision import Strategy
from fleet.mission.engine import Engine, MissionStuck
from fleet.mission.faults import Fault, FaultKind, Scenario
from fleet.mission.freeze import Motion, ScheduledPacer, cascade, freeze_of
from fleet.mission.seam import freeze_changes
from fleet.mission.spec import Mission, MissionKind
from fleet.planning.maneuvers import Manner
from fleet.planning.reservations import Interval, ReservationTable
from fleet.planning.trajectory import Pose, Step, Trajectory
from fleet.planning.velocity import Speed
from fleet.recording.inprocess import recorded_run, write_recording
from fleet.recording.reader import read_recording
from fleet.wire.protocol import GOODS, ZONE
from fleet.world.layout_file import load_layout


def drive_east(vehicle: int, row: int, cols: range, t0: float, dt: float = 1.0) -> Trajectory:
    """A forklift driving east along a row, one cell per `dt`, parked at the end."""
    steps = []
    for k, c in enumerate(cols[:-1]):
        steps.append(Step(Manner.FORWARD, Pose((c, row), 0), Pose((c + 1, row), 0),
                          t0 + k * dt, t0 + (k + 1) * dt, Speed.MID, Speed.MID,
                          frozenset({(c, row), (c + 1, row), (c + 2, row)})))
    last = cols[-1]
    return Trajectory(vehicle, Pose((cols[0], row), 0), Pose((last, row), 0), t0,
                      tuple(steps), (), 0)


def commit(table: ReservationTable, traj: Trajectory) -> None:
    """Each step's cells over its window, the goal's cells to infinity (as the planner does)."""
    intervals = [Interval(c, s.t0, s.t1) for s in traj.steps for c in s.cells]
    end = traj.goal.cell
    intervals += [Interval(c, traj.t_end, math.inf) for c in (end, (end[0] + 1, end[1]))]
    assert table.commit(traj.vehicle, intervals, release_from=traj.t_start).ok


def test_a_frozen_forklift_keeps_the_cells_of_its_maneuver_in_progress():
    traj = drive_east(1, 0, range(0, 5), t0=10.0)
    motion = Motion(1, Pose((0, 0), 0), (traj,))
    at_rest = freeze_of(motion, 5.0)
    assert (at_rest.step, at_rest.pose, at_rest.cells) == (None, Pose((0, 0), 0),
                                                          frozenset({(0, 0), (1, 0)}))
    moving = freeze_of(motion, 11.25)  # a quarter into the second maneuver
    assert moving.step == traj.steps[1]
    assert (moving.pose, moving.t_stand) == (Pose((2, 0), 0), 12.0)
    assert moving.cells == traj.steps[1].cells
    between = freeze_of(motion, 12.0)  # exactly between two maneuvers: at rest there
    assert (between.step, between.pose) == (None, Pose((2, 0), 0))
    after = freeze_of(motion, 99.0)
    assert after.pose == traj.goal and after.cells == frozenset({(4, 0), (5, 0)})


def test_those_whose_plans_cross_a_stopped_forklift_stop_too_and_nobody_else():
    table = ReservationTable()
    a = drive_east(1, 0, range(0, 6), t0=0.0)  # along row 0
    b = drive_east(2, 0, range(-8, 3), t0=0.0, dt=2.0)  # behind it, into its cells later
    c = drive_east(3, 5, range(0, 6), t0=0.0)  # elsewhere
    for traj in (a, b, c):
        commit(table, traj)
    motions = {v: Motion(v, t.start, (t,)) for v, t in ((1, a), (2, b), (3, c))}
    found = cascade(table, 2.5, motions, {1}, lambda cell: None)
    assert set(found.freezes) == {1, 2}  # b drives into a's frozen cells; c does not care
    assert found.freezes[1].cells == a.steps[2].cells
    _apply(table, found.freezes.values(), [], frozenset(), 0.0)
    held = replay([("commit" if c.intervals else "release", c.vehicle,
                    [(iv.cell[0], iv.cell[1], iv.t0, iv.t1) for iv in c.intervals],
                    c.release_from, c.release_cells) for c in table.changes])
    assert double_bookings(held) == []
    assert all(r.t1 == math.inf for r in table.reservations(1) if r.cell in
               found.freezes[1].cells)


def test_goods_a_cancelled_delivery_reserved_go_with_it():
    table = ReservationTable()
    a = drive_east(1, 0, range(0, 6), t0=0.0)
    commit(table, a)
    b = drive_east(2, 3, range(0, 3), t0=0.0)  # delivering: goods on (3, 0) from t=20
    commit(table, b)
    assert table.commit(GOODS, [Interval((3, 0), 20.0, math.inf)]).ok
    motions = {1: Motion(1, a.start, (a,)), 2: Motion(2, b.start, (b,))}
    found = cascade(table, 2.5, motions, {1}, {(3, 0): 2}.get)
    assert set(found.freezes) == {1, 2}


def test_a_zone_closes_around_whoever_stands_in_it_and_stops_who_would_enter():
    table = ReservationTable()
    a = drive_east(1, 0, range(0, 8), t0=0.0)  # will cross the zone
    commit(table, a)
    parked = Interval((6, 3), 0.0, math.inf)  # forklift 2 parked inside the zone
    assert table.commit(2, [parked, Interval((7, 3), 0.0, math.inf)]).ok
    motions = {1: Motion(1, a.start, (a,)), 2: Motion(2, Pose((6, 3), 0))}
    zone = frozenset({(5, 0), (6, 0), (6, 3), (5, 3)})
    found = cascade(table, 1.5, motions, set(), lambda cell: None, zone, 50.0)
    assert found.zone == zone - {(6, 3)}  # no spill on a forklift
    assert set(found.freezes) == {1}
    _apply(table, found.freezes.values(), [], found.zone, 50.0)
    assert {r.cell for r in table.reservations(ZONE)} == found.zone


def _apply(table, freezes, goods, zone, until) -> None:
    freezes = list(freezes)
    t = freezes[0].t if freezes else 0.0
    for owner, intervals, release_from, cells in freeze_changes(t, freezes, goods, zone,
                                                                until):
        if intervals:
            assert table.commit(owner, intervals).ok
        else:
            table.release(owner, release_from, cells)


# -- whole missions, in one process ------------------------------------------------------------

def random_scenario(rng: random.Random, vehicles: int, horizon: float) -> Scenario:
    faults = []
    for v in range(1, vehicles + 1):
        kind = rng.choice([FaultKind.KILL_VEHICLE, FaultKind.STALL_VEHICLE,
                           FaultKind.CUT_LINK, FaultKind.VEHICLE_BREAKDOWN])
        faults.append(Fault(kind, round(rng.uniform(0, horizon), 2), v,
                            round(rng.uniform(5, 60), 2)))
    faults.append(Fault(FaultKind.CLOSE_ZONE, round(rng.uniform(0, horizon), 2),
                        duration=30.0, cells=((rng.randrange(2, 6), rng.randrange(2, 6)),)))
    return Scenario("random", "", tuple(faults))


@settings(max_examples=15, deadline=None, derandomize=True)
@given(st.integers(0, 10**6))
def test_random_faults_never_make_a_forklift_collide_or_a_stack_repeat(seed):
    """Random faults on the small layout: if the mission finishes its recording passes every
    verdict; if the faults wall a forklift in for good (a deadlock no planner can break),
    what was done up to then is still safe and without repeats."""
    layout = load_layout("small")
    mission = Mission("small", MissionKind.FILL, Strategy.COMPREHENSIVE, 2, 0)
    scenario = random_scenario(random.Random(seed), 2, 300.0)
    engine = Engine(mission, layout=layout, pacer=ScheduledPacer(scenario))
    try:
        engine.run()
    except MissionStuck:
        done = engine.record.stacks_done
        assert len({(c, i) for c, i, _ in done}) == len(done)
        held = replay([("commit" if c.intervals else "release", c.vehicle,
                        [(iv.cell[0], iv.cell[1], iv.t0, iv.t1) for iv in c.intervals],
                        c.release_from, c.release_cells) for c in engine.executor.store.changes])
        assert double_bookings(held) == []
        return
    assert len(engine.record.stacks_done) == len(layout.stacks)


def test_a_mixed_fault_mission_in_one_process_passes_every_verdict(tmp_path):
    from fleet.analysis.analyze import analyze
    from fleet.mission.engine import engine_options
    from fleet.mission.faults import load_scenario

    layout = load_layout("paper")
    mission = Mission("paper", MissionKind.FILL, Strategy.ANN, 4, 0)
    done, stream = recorded_run(mission, layout, engine_options(mission, layout, None),
                                scenario=load_scenario("mixed"))
    write_recording(tmp_path / "run.mcap", stream, layout)
    report = analyze(read_recording(tmp_path / "run.mcap"))
    assert report.passed and report.stacks_done == 136
    assert (len(report.overlaps), len(report.outside_reservation)) == (0, 0)
    halts = done.record["halts"]
    assert {h[0] for h in halts} >= {1, 2, 3} and len(done.record["resumes"]) == 4
