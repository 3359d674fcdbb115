"""Maneuver geometry: hand-worked cases from the Table 3 body on 2 m cells."""

import math

import pytest

from fleet.params import VehicleDims
from fleet.planning.geometry import body_corners, point_in_rectangle
from fleet.planning.maneuvers import Manner, end_offset, move_table, rotate

N = 1  # heading north
TABLE = move_table()


def test_eleven_manners_in_four_kinds():
    assert len(Manner) == 11
    kinds = {m.kind.value for m in Manner}
    assert kinds == {"stop", "straight", "turn", "lane"}


def test_body_at_rest_covers_two_cells():
    # P at the centre of (0,0): forks 1 m behind (on the cell border), front 1.8 m ahead.
    for heading in range(4):
        move = TABLE[Manner.STOP, heading]
        ahead = rotate((1, 0), heading)
        assert move.start_cells == {(0, 0), ahead}
        assert move.middle_cells == frozenset()


def test_straight_forward_sweeps_three_cells():
    move = TABLE[Manner.FORWARD, N]
    assert move.end_delta == (0, 1) and move.end_heading == N
    assert move.swept == {(0, 0), (0, 1), (0, 2)}


def test_turn_left_sweeps_one_notch_cell():
    # The rear axle runs a quarter circle of radius 2 m centred 2 m to the left (-2, 0). The
    # outer front corner (0.5 m right, 1.8 m ahead of P) is sqrt(2.5^2 + 1.8^2) = 3.08 m from
    # that centre, so at the top of its arc it reaches y = 3.08 > 3: 8 cm into cell (-1, 2).
    move = TABLE[Manner.TURN_LEFT, N]
    assert move.end_delta == (-1, 1) and move.end_heading == 2
    assert move.start_cells == {(0, 0), (0, 1)}
    assert move.end_cells == {(-1, 1), (-2, 1)}
    assert move.middle_cells == {(-1, 2)}
    assert math.hypot(2.5, 1.8) > 3.0


def test_lane_change_shifts_one_cell_over_two():
    move = TABLE[Manner.LANE_LEFT, N]
    assert move.end_delta == (-1, 2) and move.end_heading == N
    assert move.end_cells == {(-1, 2), (-1, 3)}
    assert move.middle_cells == {(-1, 1), (0, 2)}


@pytest.mark.parametrize("manner", [m for m in Manner if m.direction == 1])
def test_every_forward_move_is_undone_by_one_reverse_move(manner):
    for heading in range(4):
        move = TABLE[manner, heading]
        undo = [m for (mn, h), m in TABLE.items()
                if h == move.end_heading and mn.direction == -1 and mn.kind is manner.kind
                and (m.end_delta[0] + move.end_delta[0], m.end_delta[1] + move.end_delta[1])
                == (0, 0) and m.end_heading == heading]
        assert len(undo) == 1
        shifted = {(c[0] + move.end_delta[0], c[1] + move.end_delta[1]) for c in undo[0].swept}
        assert shifted == move.swept


@pytest.mark.parametrize("manner", list(Manner))
def test_moves_are_rotations_of_each_other(manner):
    east = TABLE[manner, 0]
    for heading in range(1, 4):
        move = TABLE[manner, heading]
        assert move.swept == {rotate(c, heading) for c in east.swept}
        assert move.end_delta == rotate(east.end_delta, heading)


def test_end_offsets_in_cells():
    assert end_offset(Manner.TURN_RIGHT_REVERSE) == ((-1, -1), 1)
    assert end_offset(Manner.LANE_RIGHT_REVERSE) == ((-2, -1), 0)


def test_triangle_area_criterion_equation_11():
    rect = body_corners(0.0, 0.0, 0.0, VehicleDims())
    assert point_in_rectangle((1.7, 0.4), rect)
    assert point_in_rectangle((-0.99, -0.49), rect)
    assert not point_in_rectangle((1.9, 0.0), rect)
    assert not point_in_rectangle((0.0, 0.6), rect)
