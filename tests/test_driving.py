"""Where a forklift is at a sim time, from what it committed."""

import math
import time

import pytest

from fleet.mission.driving import Drive, state_period
from fleet.planning.planner import HybridAStar
from fleet.planning.reservations import ReservationTable
from fleet.planning.trajectory import Pose
from fleet.wire.protocol import ClockTick
from fleet.world.layout_file import load_layout
from vehicle_agent.clock import SimClock, tick_problem


def small_trip(t_start=10.0):
    layout = load_layout("small")
    planner = HybridAStar(layout.grid_map(), layout.vehicle.dims)
    return layout, planner.plan(1, layout.vehicle_starts[0], t_start, [Pose((1, 4), 2)],
                                ReservationTable())


def test_at_rest_before_driving_and_at_the_goal_after():
    layout, traj = small_trip()
    drive = Drive(1, traj.start, layout)
    drive.add(traj, loaded=True)
    before, after = drive.state_at(5.0), drive.state_at(traj.t_end + 1)
    assert (before.pose, before.maneuver, before.speed, before.loaded) == \
        (str(traj.start), "", 0, False)
    assert (after.pose, after.maneuver, after.speed, after.loaded) == \
        (str(traj.goal), "", 0, True)
    x0, y0 = layout.cell_center(traj.start.cell)
    assert (before.x, before.y) == (x0, y0)
    assert math.isclose(before.theta, traj.start.heading * math.pi / 2)


def test_inside_a_maneuver_the_position_moves_between_its_poses():
    layout, traj = small_trip()
    drive = Drive(1, traj.start, layout)
    drive.add(traj, loaded=False)
    step = next(s for s in traj.steps if s.manner.label == "forward")
    mid = drive.state_at((step.t0 + step.t1) / 2)
    assert mid.maneuver == "forward" and mid.pose == str(step.start) and mid.speed > 0
    (xa, ya), (xb, yb) = layout.cell_center(step.start.cell), layout.cell_center(step.end.cell)
    assert math.isclose(mid.x, (xa + xb) / 2) and math.isclose(mid.y, (ya + yb) / 2)


def test_states_are_due_on_the_shared_grid_each_instant_once():
    layout, traj = small_trip()
    drive = Drive(1, traj.start, layout)
    drive.add(traj, loaded=False)
    assert drive.due(1.2, 0.5) == [0.0, 0.5, 1.0]
    assert drive.due(1.4, 0.5) == []  # nothing new on the grid yet
    assert drive.due(3.0, 0.5) == [1.5, 2.0, 2.5, 3.0]  # a late wake-up catches up
    assert drive.due(2.0, 0.5) == []  # never twice, never back in time
    assert drive.due(4.0, 0.5, before=True) == [3.5]  # a fast tick at 4.0: 4.0 may change
    assert drive.due(4.0, 0.5) == [4.0]


def test_grid_instants_are_the_same_in_every_process():
    # Real time at speed 40: a state every 4 s of sim time, k * period computed alike.
    a, b = Drive(1, small_trip()[1].start, load_layout("small")), \
        Drive(2, small_trip()[1].start, load_layout("small"))
    period = 40 * 0.1
    assert a.due(17.3, period) == b.due(13.0, period) + b.due(17.3, period)
    assert a.due(17.3, period)[-1:] == [] and a.next_k == b.next_k == 5


def test_forgetting_old_legs_keeps_the_pose():
    layout, traj = small_trip(0.0)
    drive = Drive(1, traj.start, layout)
    drive.add(traj, loaded=True)
    back = HybridAStar(layout.grid_map(), layout.vehicle.dims).plan(
        1, traj.goal, traj.t_end + 5, [traj.start], ReservationTable())
    drive.add(back, loaded=False)
    drive.due(back.t_start, 0.5)  # fast mode published the first leg
    before = drive.state_at(traj.t_end + 1)
    drive.forget_before(back.t_start)
    assert len(drive.legs) == 1 and drive.rest_pose == traj.goal
    assert drive.state_at(traj.t_end + 1) == before  # the pose and the load it carries
    assert drive.state_at(traj.t_end + 1).pose == str(traj.goal)
    assert drive.pose == traj.start


def test_a_grid_without_instants_is_refused():
    drive = Drive(1, small_trip()[1].start, load_layout("small"))
    for until, period in ((math.inf, 0.5), (10.0, 0.0), (10.0, -0.1), (10.0, math.nan)):
        with pytest.raises(ValueError, match="no grid instants"):
            drive.due(until, period)


@pytest.mark.parametrize("tick,why", [
    (ClockTick(5, "fast", 10.0), "not after tick 5"),
    (ClockTick(6, "slow", 10.0), "unknown mode"),
    (ClockTick(6, "fast", 1e300), "outside"),
    (ClockTick(6, "fast", 9.0), "before the last tick's 10.0"),
    (ClockTick(6, "realtime", 10.0, 2.0, 1e9), "is not the clock's fast"),
])
def test_a_tick_that_cannot_be_the_clocks_next_is_named(tick, why):
    assert why in tick_problem(tick, ClockTick(5, "fast", 10.0))


def test_real_time_ticks_need_a_positive_speed_and_keep_it():
    good = ClockTick(1, "realtime", 0.0, 2.0, 1e9)
    assert tick_problem(good, None) == ""
    assert tick_problem(ClockTick(2, "realtime", 1.0, 2.0, 1e9 + 0.5), good) == ""
    for speed in (0.0, -1.0, 1e9):
        assert "speed" in tick_problem(ClockTick(1, "realtime", 0.0, speed, 1e9), None)
    assert "speed 3.0" in tick_problem(ClockTick(2, "realtime", 1.0, 3.0, 1e9), good)


def test_a_tick_that_waited_in_a_buffer_sets_the_time_but_is_not_the_clock_heard_now():
    """A stalled or cut-off agent finds old ticks waiting when it wakes: they tell the time,
    not that the clock speaks (nor who is down now), so it stays silent until a fresh one."""
    clock = SimClock()
    assert clock.silent_for() == math.inf
    now = time.time()
    clock.take(ClockTick(7, "realtime", 300.0, 40.0, now - 100.0 / 40.0))
    assert clock.now() == pytest.approx(400.0, abs=1.0)
    assert clock.silent_for() == pytest.approx(2.5, abs=0.5)
    clock.take(ClockTick(8, "realtime", 400.0, 40.0, now))
    assert clock.silent_for() < 0.5
    starting = SimClock()  # before the start the anchor is still to come: sent now
    starting.take(ClockTick(1, "realtime", 0.0, 40.0, now + 5.0))
    assert starting.silent_for() < 0.5


def test_real_time_states_are_never_coarser_than_fast_mode():
    assert state_period("realtime", 1.0) == pytest.approx(0.1)  # 10 Hz of wall time
    assert state_period("realtime", 40.0) == 0.5  # not 4 s of sim time apart
    assert state_period("fast", 40.0) == 0.5


# -- faults: cut, stop, resume, restart ---------------------------------------------------------

def test_a_cut_forklift_completes_its_maneuver_and_drives_nothing_after():
    layout, traj = small_trip()
    step = traj.steps[2]
    t = (step.t0 + step.t1) / 2
    drive = Drive(1, traj.start, layout)
    drive.add(traj, loaded=True)
    _, later = small_trip(t_start=traj.t_end + 5)  # a leg committed for later goes too
    drive.add(later, loaded=False)
    drive.cut(t)
    assert drive.pose == step.end and len(drive.legs) == 1
    assert drive.state_at(step.t1 + 100).pose == str(step.end)


def test_a_stopped_forklift_stands_still_until_it_resumes_then_completes_its_maneuver():
    layout, traj = small_trip()
    step = traj.steps[2]
    t_stop = step.t0 + 0.25 * (step.t1 - step.t0)
    reference = Drive(1, traj.start, layout)
    reference.add(traj, loaded=True)
    drive = Drive(1, traj.start, layout)
    drive.add(traj, loaded=True)
    drive.stop(t_stop)
    frozen = reference.state_at(t_stop)
    assert drive.state_at(t_stop + 50) == frozen  # down: where it was at t_stop
    drive.resume(t_stop + 100)
    assert drive.state_at(t_stop + 100) == frozen
    halfway = t_stop + 100 + 0.25 * (step.t1 - step.t0)  # as far in as it was at t0 + half
    assert drive.state_at(halfway) == reference.state_at((step.t0 + step.t1) / 2)
    assert drive.state_at(step.t1 + 100 + 1).pose == str(step.end)
    assert drive.pose == step.end


def test_a_restarted_agent_becomes_what_the_dispatcher_says_and_skips_the_silence():
    layout, traj = small_trip()
    step = traj.steps[2]
    t_stop = (step.t0 + step.t1) / 2
    reference = Drive(1, traj.start, layout)
    reference.add(traj, loaded=True)
    drive = Drive(1, layout.vehicle_starts[1], layout)  # knows nothing of itself
    drive.restart(step.end, True, step, t_stop, t_stop + 40)
    drive.skip_to(t_stop + 40, 0.5)
    assert drive.state_at(t_stop + 20) == reference.state_at(t_stop)
    assert drive.pose == step.end
    due = drive.due(t_stop + 42, 0.5)
    assert due[0] >= t_stop + 40 and due[0] - 0.5 < t_stop + 40
