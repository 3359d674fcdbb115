"""Vehicle kinds (fleet/vehicles): the registry a layout's `[vehicle] kind` is looked up in, and
seed 000's forklift, whose motion model must keep the vehicle inside what its planner commits."""

import math

import pytest

from fleet.analysis.safety import Body, covered_cells
from fleet.params import VehicleDims
from fleet.planning.reservations import Interval, ReservationTable
from fleet.planning.trajectory import PlanFailure, Pose, Trajectory
from fleet.vehicles.registry import UnknownVehicleKind, vehicle_kind
from fleet.world.layout import LayoutError
from fleet.world.layout_file import layout_source, load_layout, parse_layout
from fleet.world.site import planners_for


def test_the_registry_refuses_an_unknown_kind_naming_the_known_ones():
    with pytest.raises(UnknownVehicleKind, match=r"^kind 'drone' is not one of the known "
                                                  r"vehicle kinds: forklift, agv, lifting-agv$"):
        vehicle_kind("drone", VehicleDims(), 2.0)
    assert vehicle_kind("forklift", VehicleDims(), 2.0).name == "forklift"


@pytest.mark.parametrize("kind", ["hovercraft", "Forklift"])
def test_a_layout_naming_an_unknown_kind_is_a_one_line_layout_error(kind):
    text = layout_source("small").replace("[bounds]", f'[vehicle]\nkind = "{kind}"\n\n[bounds]')
    with pytest.raises(LayoutError) as refused:
        parse_layout(text, "t")
    assert str(refused.value) == (f"t: vehicle: kind {kind!r} is not one of the known vehicle "
                                  f"kinds: forklift, agv, lifting-agv")


def test_a_forklift_layout_naming_the_kind_not_built_yet_cannot_check_its_poses():
    text = layout_source("small").replace("[bounds]",
                                          '[vehicle]\nkind = "lifting-agv"\n\n[bounds]')
    with pytest.raises(LayoutError, match="station p1: a pose is checked with the vehicle "
                                          "kind's body, and the lifting-agv vehicle kind is not "
                                          "built"):
        parse_layout(text, "t")


def held_at(table: ReservationTable, vehicle: int, t: float) -> set:
    return {r.cell for r in table.reservations(vehicle) if r.t0 <= t < r.t1}


# Vehicle 2 holding a cell ahead for a while makes the planner wait (a stop maneuver) or go
# round it (a lane change); on a free floor it drives straight and turns.
@pytest.mark.parametrize("other", [None, Interval((4, 4), 0.0, 4.0),
                                   Interval((4, 4), 0.0, 5.0)])
def test_the_forklift_drives_inside_what_its_planner_commits(other):
    layout = load_layout("small")
    kind = layout.vehicle_kind
    start = layout.vehicle_starts[0]
    table = ReservationTable()
    table.park(1, kind.body_cells_at_rest(start), 0.0)
    if other is not None:
        table.commit(2, [other])
    planned = kind.planner(layout.grid_map()).plan(1, start, 3.0, [Pose((1, 4), 2)], table)
    assert isinstance(planned, Trajectory)
    leg = planners_for(layout).policy.commitment(planned, table)
    assert not isinstance(leg, PlanFailure)
    assert leg.write(table).ok
    traj = leg.trajectory
    outline = kind.outline
    body = Body(outline.front, outline.rear, outline.width, layout.cell_size, (0.0, 0.0))

    def cells(at) -> frozenset:
        return covered_cells(body, at.x, at.y, at.theta)

    def same_place(a, b) -> bool:
        turn = (a.theta - b.theta) % (2 * math.pi)
        return math.isclose(a.x, b.x, abs_tol=1e-9) and math.isclose(a.y, b.y, abs_tol=1e-9) \
            and min(turn, 2 * math.pi - turn) < 1e-9

    assert cells(kind.at_rest(start)) == set(kind.body_cells_at_rest(start)) <= \
        held_at(table, 1, 0.0)
    for step in traj.steps:
        assert same_place(kind.on_step(step, step.t0), kind.at_rest(step.start))
        end = kind.on_step(step, math.nextafter(step.t1, -math.inf))
        assert math.dist((end.x, end.y), (kind.at_rest(step.end).x,
                                          kind.at_rest(step.end).y)) < 1e-6
        for k in range(40):
            t = step.t0 + (step.t1 - step.t0) * k / 40
            at = kind.on_step(step, t)
            assert at.pose == step.start and at.step == step.manner.label
            assert (at.speed == 0) == kind.is_wait(at.step)
            assert cells(at) <= held_at(table, 1, t), (step, t)
    goal = kind.at_rest(traj.goal)
    assert cells(goal) == set(kind.body_cells_at_rest(traj.goal)) <= held_at(table, 1, 1e9)
    here = kind.at_rest(start)
    driven = sum(kind.path_length_m(s.manner.label) for s in traj.steps)
    assert driven >= math.dist((here.x, here.y), (goal.x, goal.y)) > 0
