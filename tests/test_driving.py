"""Where a forklift is at a sim time, from what it committed."""

import math

from fleet.layout import load_layout
from fleet.planner import HybridAStar
from fleet.reservations import ReservationTable
from fleet.trajectory import Pose
from vehicle_agent.driving import Drive


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


def test_fast_mode_publishes_each_maneuver_start_and_arrival_once():
    layout, traj = small_trip()
    drive = Drive(1, traj.start, layout)
    drive.add(traj, loaded=False)
    first = drive.due(traj.steps[2].t0)
    rest = drive.due(traj.t_end + 100)
    assert first == [s.t0 for s in traj.steps[:3]]
    assert rest == sorted({s.t0 for s in traj.steps[3:]} | {traj.t_end})
    assert drive.due(math.inf) == []


def test_a_leg_committed_at_the_instant_of_the_last_tick_still_gets_its_first_state():
    layout, traj = small_trip(0.0)
    drive = Drive(1, traj.start, layout)
    drive.add(traj, loaded=False)
    assert drive.due(traj.t_end + 5) != []  # the clock stands at t_end + 5 ...
    back = HybridAStar(layout.grid_map(), layout.vehicle.dims).plan(
        1, traj.goal, traj.t_end + 5, [traj.start], ReservationTable())
    drive.add(back, loaded=False)  # ... and the next leg starts right then
    assert drive.due(traj.t_end + 5) == [back.t_start]


def test_forgetting_old_legs_keeps_the_pose():
    layout, traj = small_trip(0.0)
    drive = Drive(1, traj.start, layout)
    drive.add(traj, loaded=False)
    back = HybridAStar(layout.grid_map(), layout.vehicle.dims).plan(
        1, traj.goal, traj.t_end + 5, [traj.start], ReservationTable())
    drive.add(back, loaded=False)
    drive.due(back.t_start)  # fast mode published the first leg
    drive.forget_before(back.t_start)
    assert len(drive.legs) == 1 and drive.rest_pose == traj.goal
    assert drive.state_at(traj.t_end + 1).pose == str(traj.goal)
    assert drive.pose == traj.start
