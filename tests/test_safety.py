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
    outside_reservation,
    overlaps,
    replay,
)
from fleet.params import VehicleDims
from fleet.planning.geometry import body_corners, cells_under

DIMS = VehicleDims()
BODY = Body(DIMS.front, DIMS.rear, DIMS.width, 2.0, (0.0, 0.0))
INF = math.inf


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


def test_overlaps_and_excursions_at_shared_instants():
    a = Sample(1, 2.0, 4.0, 6.0, 0.0)  # cells (2, 3), (3, 3)
    b = Sample(2, 2.0, 8.0, 6.0, math.pi)  # cells (4, 3), (3, 3)
    far = Sample(2, 2.5, 8.0, 6.0, math.pi)  # another instant: not compared with a
    (o,) = overlaps([a, b, far], BODY)
    assert (o.t, o.vehicles, o.cells) == (2.0, (1, 2), ((3, 3),))
    held = [Held(1, (2, 3), 0.0, INF), Held(1, (3, 3), 0.0, 2.0)]  # (3, 3) given up at 2.0
    (out,) = outside_reservation([a], held, BODY)
    assert (out.t, out.vehicle, out.cells) == (2.0, 1, ((3, 3),))


def test_the_verifier_imports_neither_planner_nor_table_nor_their_geometry():
    code = ("import sys, fleet.analysis.safety; print(sorted(m for m in sys.modules "
            "if m.startswith(('fleet.', 'reservation', 'vehicle_agent'))))")
    loaded = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                            check=True).stdout
    assert loaded.strip() == "['fleet.analysis', 'fleet.analysis.safety']"  # and its wing
