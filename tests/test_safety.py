"""The independent safety verifier (fleet/analysis/safety.py) on its own: its footprint agrees
with the
planner's geometry, its table replay with the reservation table's rules, and it shares no
code with either."""

import dataclasses
import math
import subprocess
import sys

from hypothesis import given, settings
from hypothesis import strategies as st

from fleet.analysis.safety import (
    TOLERANCE_M,
    Body,
    Held,
    Sample,
    covered_cells,
    double_bookings,
    on_goods,
    outside_reservation,
    overlaps,
    placed,
    replay,
    shrunk_cells,
)
from fleet.params import VehicleDims
from fleet.planning.geometry import body_corners, cells_under

DIMS = VehicleDims()
BODY = Body(DIMS.front, DIMS.rear, DIMS.width, 2.0, (0.0, 0.0))
INF = math.inf
MAX_SPEED = 4.0  # seed 000's forklift: one cell in 0.5 s
REACH = math.hypot(DIMS.front, DIMS.width / 2)


@settings(max_examples=400, deadline=None)
@given(st.floats(-20, 20), st.floats(-20, 20), st.floats(-math.pi, math.pi))
def test_the_footprint_is_the_planners_up_to_the_touch_tolerance(x, y, theta):
    mine = covered_cells(BODY, x, y, theta)
    theirs = cells_under(body_corners(x, y, theta, DIMS), 2.0)
    assert mine <= theirs  # the verifier only forgives touching
    # What it forgives, the body enters by less than the tolerance: shrunk by it, the
    # planner's own geometry no longer finds it there.
    shrunk = dataclasses.replace(DIMS, front_overhang=DIMS.front_overhang - 2 * TOLERANCE_M,
                                 rear_overhang=DIMS.rear_overhang - 2 * TOLERANCE_M,
                                 width=DIMS.width - 4 * TOLERANCE_M)
    assert theirs - mine <= theirs - cells_under(body_corners(x, y, theta, shrunk), 2.0)


def test_a_body_at_rest_covers_its_two_cells_at_any_heading():
    for heading, ahead in enumerate(((1, 0), (0, 1), (-1, 0), (0, -1))):
        cells = covered_cells(BODY, 4.0, 6.0, heading * math.pi / 2)
        assert cells == {(2, 3), (2 + ahead[0], 3 + ahead[1])}


def test_replay_follows_the_tables_rules():
    held = replay([
        ("commit", 1, [(0, 0, 0.0, INF), (1, 0, 0.0, INF)], None),  # parked
        ("commit", 1, [(0, 0, 5.0, 7.0), (0, 1, 6.0, 9.0), (0, 2, 8.0, INF)], 5.0),  # drives
        ("commit", 2, [(3, 3, 0.0, INF)], None),
        ("release", 2, [], 4.0),
    ])
    assert sorted(held, key=lambda h: (h.vehicle, h.cell, h.t0)) == [
        Held(1, (0, 0), 0.0, 5.0), Held(1, (0, 0), 5.0, 7.0), Held(1, (0, 1), 6.0, 9.0),
        Held(1, (0, 2), 8.0, INF), Held(1, (1, 0), 0.0, 5.0), Held(2, (3, 3), 0.0, 4.0)]


def test_double_bookings_are_found_and_back_to_back_is_not_one():
    held = [Held(1, (0, 0), 0.0, 5.0), Held(2, (0, 0), 5.0, 9.0), Held(3, (0, 0), 8.0, 10.0),
            Held(1, (4, 4), 0.0, INF), Held(1, (4, 4), 3.0, 6.0)]  # one owner twice: fine
    (found,) = double_bookings(held)
    assert (found.cell, found.vehicles, found.t0, found.t1) == ((0, 0), (2, 3), 8.0, 9.0)


def test_a_body_on_a_stack_while_goods_stand_on_it_is_found():
    """Goods on stack (3, 3) over [0, 5) (an empty mission: there until claimed) and on
    (9, 9) from 4 on (a fill): a body covering (3, 3) at 2 s is on goods, at 5 s it is not
    (claimed); covering (9, 9) at 2 s it is not (not filled yet)."""
    goods = {(3, 3): [(0.0, 5.0)], (9, 9): [(4.0, INF)]}
    on = Sample(1, 2.0, 4.0, 6.0, 0.0)  # cells (2, 3), (3, 3)
    after = Sample(1, 5.0, 4.0, 6.0, 0.0)
    early = Sample(2, 2.0, 18.0, 18.0, math.pi)  # cells (9, 9), (8, 9)
    (found,) = on_goods([on, after, early], goods, BODY)
    assert (found.t, found.vehicle, found.cells) == (2.0, 1, ((3, 3),))


def test_overlaps_and_excursions_at_shared_instants():
    a = Sample(1, 2.0, 4.0, 6.0, 0.0)  # cells (2, 3), (3, 3)
    b = Sample(2, 2.0, 8.0, 6.0, math.pi)  # cells (4, 3), (3, 3)
    far = Sample(2, 2.5, 8.0, 6.0, math.pi)  # another instant, and a has no state then
    (o,) = overlaps([a, b, far], BODY, MAX_SPEED, 0.75)
    assert (o.t, o.vehicles, o.cells, o.between) == (2.0, (1, 2), ((3, 3),), False)
    held = [Held(1, (2, 3), 0.0, INF), Held(1, (3, 3), 0.0, 2.0)]  # (3, 3) given up at 2.0
    (out,) = outside_reservation([a], held, BODY)
    assert (out.t, out.vehicle, out.cells) == (2.0, 1, ((3, 3),))


def test_two_bodies_never_seen_at_one_instant_are_compared_between_their_states():
    """Forklift 2's states fall between forklift 1's: where both stood still on the same
    cells, the interpolated bodies meet."""
    one = [Sample(1, t, 4.0, 6.0, 0.0) for t in (0.0, 0.5, 1.0)]
    two = [Sample(2, t, 4.0, 6.0, 0.0) for t in (0.25, 0.75)]
    found = overlaps(one + two, BODY, MAX_SPEED, 0.75)
    assert found and all(o.between and o.vehicles == (1, 2) for o in found)
    assert {c for o in found for c in o.cells} <= {(2, 3), (3, 3)}
    assert not overlaps(one + [Sample(2, t, 12.0, 6.0, 0.0) for t in (0.25, 0.75)], BODY,
                        MAX_SPEED, 0.75)


@settings(max_examples=300, deadline=None)
@given(x=st.floats(-10, 10), y=st.floats(-10, 10), theta=st.floats(-math.pi, math.pi),
       v0=st.floats(-4, 4), dv=st.floats(-1, 1), spin=st.floats(-0.5, 0.5),
       switch=st.floats(0, 0.5), when=st.floats(0.001, 0.499))
def test_an_interpolated_body_shrunk_by_its_bound_lies_inside_the_real_one(
        x, y, theta, v0, dv, spin, switch, when):
    """The tolerance between instants (docs/metrics.md): a forklift driving straight at one
    speed, then at another (velocity changing by at most its maximum speed), and turning
    at a steady rate: between two states 0.5 s apart, the cells of its interpolated body
    shrunk by the bound are cells its real body enters."""
    v1 = max(-MAX_SPEED, min(MAX_SPEED, v0 + dv * 2.5))

    def real(t: float) -> Sample:
        ahead = v0 * min(t, switch) + v1 * max(0.0, t - switch)
        heading = theta + spin * t
        return Sample(1, t, x + ahead * math.cos(theta), y + ahead * math.sin(theta), heading)

    pose = placed(([0.0, 0.5], [real(0.0), real(0.5)]), when, MAX_SPEED, 0.75, REACH)
    truth = real(when)
    assert shrunk_cells(BODY, pose) <= covered_cells(BODY, truth.x, truth.y, truth.theta)


def test_the_verifier_imports_neither_planner_nor_table_nor_their_geometry():
    code = ("import sys, fleet.analysis.safety; print(sorted(m for m in sys.modules "
            "if m.startswith(('fleet.', 'reservation', 'vehicle_agent'))))")
    loaded = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                            check=True).stdout
    assert loaded.strip() == "['fleet.analysis', 'fleet.analysis.safety']"  # and its wing
