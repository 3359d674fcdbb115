"""Seed 002's collisions on timed routes (fleet/planning/lane_schedule.py,
fleet/planning/lane_conflicts.py): found where two bodies would touch one cell at once,
named as the paper's three conditions, and settled by its rules with a wait in the right
schedule, the committed one's too."""

from __future__ import annotations

import itertools

import pytest

from fleet.planning.lane_conflicts import (
    Area,
    CollisionKind,
    first_collision,
    settle,
)
from fleet.planning.lane_schedule import timed
from fleet.world.lanes import collision_areas as areas
from fleet.world.layout_file import load_layout


@pytest.fixture(scope="module")
def cross():
    return load_layout("micro-cross")


@pytest.fixture(scope="module")
def paper002():
    return load_layout("paper002")


def row(y: int, xs) -> tuple:
    return tuple((x, y) for x in xs)


def col(x: int, ys) -> tuple:
    return tuple((x, y) for y in ys)


def apart(a, b) -> bool:
    """No cell touched by both at one time, recomputed from the reservations."""
    for p, q in itertools.product(a.intervals(), b.intervals()):
        if p.cell == q.cell and max(p.t0, q.t0) < min(p.t1, q.t1):
            return False
    return True


def test_the_sets_of_section_5_3(cross):
    cell_areas = areas(cross)
    assert cell_areas[(4, 4)] is Area.CROSSROAD and cell_areas[(5, 5)] is Area.CROSSROAD
    assert cell_areas[(4, 0)] is Area.T_CROSSROAD  # the T at the bottom channel
    assert cell_areas[(0, 0)] is Area.T_CROSSROAD  # a corner counts with the Ts
    assert cell_areas[(2, 4)] is Area.HORIZONTAL and cell_areas[(5, 2)] is Area.LONGITUDINAL
    assert cell_areas[(2, 2)] is Area.OFF_CHANNEL  # a slot


def test_horizontal_meeting_longitudinal_at_a_crossroad_waits_outside_it(cross):
    """Longitudinal priority (13): the AGV from the horizontal channel waits at the last node
    before the crossroad, whichever of the two planned last (the committed one is amended)."""
    north = timed(1, col(5, range(1, 8)), 0.0, 1.0)
    east = timed(2, row(4, range(2, 8)), 0.0, 1.0)
    collision = first_collision(east, north)
    assert collision.kind is CollisionKind.NODE and collision.cells == {(5, 4)}
    for new, committed in ((east, north), (north, east)):
        settled = settle(new, {committed.vehicle: committed}, areas(cross), now=0.0)
        assert settled.deadlock is None
        assert {w.vehicle for w in settled.waits} == {2}
        assert {east.cells[w.node] for w in settled.waits} == {(3, 4)}  # outside R
        after = settled.schedules[2]
        assert after.cells == east.cells and apart(after, north)
        assert 1 not in settled.schedules or settled.schedules[1] == north


def test_two_from_one_orientation_at_a_crossroad_the_later_to_clear_waits(cross):
    """(14): both from longitudinal channels, one going straight on and one turning into
    it; the one that would clear the node later waits before the crossroad."""
    north = timed(1, col(5, range(1, 9)), 0.0, 1.0)  # straight up the northbound lane
    south_then_east = timed(2, (*col(4, (7, 6, 5)), (4, 4), (5, 4), (6, 4), (7, 4)), 0.5, 1.0)
    settled = settle(south_then_east, {1: north}, areas(cross), now=0.0)
    assert settled.deadlock is None and settled.waits
    waiter = settled.waits[0]
    assert waiter.rule.startswith("R: later clears")
    assert apart(settled.schedules.get(1, north), settled.schedules.get(2, south_then_east))


def test_a_follower_keeps_a_cell_behind(paper002):
    """Two AGVs one behind the other on the eastbound bottom lane: the one behind waits at
    its start until the one ahead has left the cell it needs, then they drive in a file."""
    ahead = timed(1, row(0, range(4, 11)), 0.0, 1.0)
    behind = timed(2, row(0, range(3, 10)), 0.0, 1.0)
    settled = settle(behind, {1: ahead}, areas(paper002), now=0.0)
    assert settled.deadlock is None
    assert [(w.vehicle, w.node, w.seconds) for w in settled.waits] == [(2, 0, 1.0)]
    assert apart(settled.schedules[2], ahead)


def test_leaving_a_slot_onto_a_lane_in_use_waits_in_the_slot(paper002):
    """(17)-(18): an AGV coming out of a slot meets one driving along the channel; it waits
    where it is, under the shelf."""
    along = timed(1, row(1, range(8, 1, -1)), 0.0, 1.0)  # westbound row 1, past x = 5
    out = timed(2, ((5, 2), (5, 1), (4, 1), (3, 1)), 2.0, 1.0)  # s-5-2 onto row 1
    settled = settle(out, {1: along}, areas(paper002), now=0.0)
    assert settled.deadlock is None
    assert {(w.vehicle, w.node) for w in settled.waits} == {(2, 0)}
    assert settled.waits[0].rule == "channel: leaving N waits in N"
    assert apart(settled.schedules[2], along)


def test_a_swap_and_crossing_diagonals_are_named_as_such(cross):
    one = timed(1, ((2, 4), (3, 4)), 0.0, 1.0)
    other = timed(2, ((3, 4), (2, 4)), 0.0, 1.0)
    assert first_collision(one, other).kind is CollisionKind.SWAP
    ne = timed(1, ((4, 4), (5, 5)), 0.0, 1.0)
    nw = timed(2, ((5, 4), (4, 5)), 0.0, 1.0)
    assert first_collision(ne, nw).kind is CollisionKind.DIAGONAL
    ne = timed(1, ((4, 4), (5, 5), (5, 6)), 0.0, 1.0)  # on north after the diagonal
    later = timed(2, ((5, 4), (4, 5)), 2.4, 1.0)  # once the first has left the block
    assert first_collision(ne, later) is None


def test_a_wait_never_goes_into_a_schedule_past_the_node(cross):
    """At t = 3.5 the horizontal AGV has left (3, 4) already and cannot wait there: the
    longitudinal one, planning now, waits instead, before its own meeting node."""
    east = timed(2, row(4, range(2, 8)), 2.0, 1.0)
    north = timed(1, col(5, range(2, 8)), 3.5, 1.0)
    settled = settle(north, {2: east}, areas(cross), now=3.5)
    assert {w.vehicle for w in settled.waits} == {1}
    assert "the other had left" in settled.waits[0].rule
    assert apart(settled.schedules[1], east)


def test_a_goal_held_for_good_is_a_deadlock_left_to_the_caller(paper002):
    """Two routes ending on one cell, the first to stay there: no wait can settle it; the
    cap ends the scan and the collision is returned."""
    first = timed(1, row(0, range(4, 11)), 0.0, 1.0)
    second = timed(2, row(0, range(3, 11)), 0.0, 1.0)
    settled = settle(second, {1: first}, areas(paper002), now=0.0, limit=20)
    assert settled.deadlock is not None
    assert settled.deadlock.cells <= {(9, 0), (10, 0)}
