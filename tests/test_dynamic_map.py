"""Seed 002's per-AGV dynamic map in literal mode (fleet/planning/dynamic_map.py): which lane
cells Algorithms 1, 2 and 3-x close for hand-worked (start, end) pairs, errata E1-E7 included;
the A* over the open cells; and, on seeded samples of the pairs the paper plans, whether a
route exists and keeps right by the layout's lanes. docs/planning-002.md has the counts."""

from collections import Counter
from dataclasses import dataclass
from functools import cache
from itertools import pairwise

import pytest

from fleet.analysis.lane_rules import lane_violations
from fleet.planning import dynamic_map as dm
from fleet.world.layout_file import load_layout

PAPER002 = load_layout("paper002")
LANES = PAPER002.lane_directions
SPANS = [x for n in (1, 2, 3) for x in range(3 + 11 * (n - 1), 12 + 11 * (n - 1))]


def closed(start, end, **options):
    return dm.closed_lane_cells(PAPER002, start, end, **options)


def closed_in_row(start, end, row, **options):
    return sorted(x for x, y in closed(start, end, **options) if y == row)


def closed_in_column(start, end, col, **options):
    return sorted(y for x, y in closed(start, end, **options) if x == col)


# -- levels, blocks, geometry ---------------------------------------------------------------

def test_levels_and_blocks_are_the_sub_areas_of_the_layout():
    # paper002's shelf area a-m-n holds exactly the slots of level m and block n
    for slot in PAPER002.slots:
        assert slot.area == "a-{}-{}".format(*dm.sub_area(slot.cell))
    assert dm.sub_area((0, 0)) == (1, 0) and dm.sub_area((0, 29)) == (8, 0)
    assert dm.sub_area((0, 6)) == (2, 0) and dm.sub_area((0, 7)) == (3, 0)  # m(y), E6
    assert dm.sub_area((13, 30)) == (8, 1) and dm.sub_area((14, 30)) == (8, 2)  # piles
    assert dm.sub_area((35, 30)) == (8, 3)


@pytest.mark.parametrize("name", ["paper002-406", "paper002-uni", "hall"])
def test_other_geometries_are_refused(name):
    with pytest.raises(ValueError, match="not paper002-shaped"):
        dm.literal_open_cells(load_layout(name), (3, 2), (0, 0))


def test_start_and_end_must_be_places():
    with pytest.raises(ValueError, match="no slot, packing station or pile"):
        dm.literal_open_cells(PAPER002, (3, 1), (0, 0))


# -- Algorithm 1 and 2 by hand ----------------------------------------------------------------

def test_algorithm_1_start_below_h3_to_a_station_on_its_level():
    # start (5, 7): level 3 (below h3, rows 8-9), block 1; end p8 (0, 7): level 3, so no 3-x.
    start, end = (5, 7), (0, 7)
    # line 16: the eastbound row 8 left of x1; line 17: the westbound row 9 right of x1, but
    # the junction cells of V1, V2 (line 18) and of V3 (E3) reopened
    assert closed_in_row(start, end, 8) == [3, 4]
    assert closed_in_row(start, end, 9) == [x for x in SPANS if x > 5]
    # line 14: the northbound lanes in the double-row below h3 (rows 6-7), all four channels
    for col in (2, 13, 24, 35):
        assert {6, 7} <= set(closed_in_column(start, end, col))
    # line 15: the southbound lanes in the double-row above (rows 10-11), V1..V3 only
    for col in (12, 23, 34):
        assert closed_in_column(start, end, col) == [10, 11]
    # Algorithm 2, n2 = 0: column 2 above the station but its channel rows, column 1 below
    assert closed_in_column(start, end, 1) == list(range(7))
    assert closed_in_column(start, end, 2) == [6, 7, 10, 11, 14, 15, 18, 19, 22, 23, 26, 27]


def test_algorithm_2_end_above_h1_from_a_station():
    # start p15 (0, 14): n1 = 0; end (20, 2): level 1 (above h1), block 2.
    start, end = (0, 14), (20, 2)
    # Algorithm 2 line 8: the westbound row 1 left of x2, junctions reopened (line 10)
    assert closed_in_row(start, end, 1) == [x for x in SPANS if x < 20]
    # line 9: the eastbound row 0 right of x2 (its junctions are not reopened)
    assert closed_in_row(start, end, 0) == list(range(21, 36))
    # line 7: the northbound lanes of the double-row above h1 (rows 2-3); Algorithm 3-4 adds
    # those of the double-rows up to the station's level (rows 6-7, 10-11)
    for col in (13, 24, 35):
        assert [y for y in closed_in_column(start, end, col) if y > 0] == [2, 3, 6, 7, 10, 11]
    # Algorithm 1, n1 = 0: column 1 above the station, column 2 below it but channel rows
    assert closed_in_column(start, end, 1) == list(range(15, 30))
    assert set(closed_in_column(start, end, 2)) == {2, 3, 6, 7, 10, 11}
    # Algorithm 3-4 (bottom right, n1 = 0): h2, h3 lose their westbound row along the shelves
    # (the end's own h1 is Algorithm 2's), and the double-rows below them their northbound
    # lanes; h4, the station's own level, too (i runs to m1)
    for row in (5, 9, 13):
        assert closed_in_row(start, end, row) == SPANS
    assert closed_in_row(start, end, 17) == [1]  # only column 1, above the station


def test_algorithm_3_1_top_left_closes_the_middle_levels():
    # start (30, 3): level 2, block 3; end (5, 22): level 6, block 1 -> 3-1 with i = 3, 4, 5
    start, end = (30, 3), (5, 22)
    for row in (8, 12, 16):  # the eastbound rows of h3..h5 along the shelves
        assert closed_in_row(start, end, row) == SPANS
    for row in (9, 13, 17):  # their westbound rows stay
        assert closed_in_row(start, end, row) == []
    for col in (12, 23, 34):  # the southbound lanes of the double-rows from above h2 to below
        # h6 (Algorithms 1 and 2 close the outer two), not of the channels between
        assert closed_in_column(start, end, col) == [6, 7, 10, 11, 14, 15, 18, 19]
    assert closed_in_column(start, end, 1) == []  # V0's southbound lane: k starts at 1


# -- the errata ----------------------------------------------------------------------------

def test_e1_the_raw_period_closes_shelves_and_the_wrong_lanes():
    start, end = (5, 7), (0, 7)
    patched = closed(start, end)
    raw = closed(start, end, unpatched=True)
    # k(L + 1) + 2 = 12 for k = 1: the raw listing closes V1's southbound lane where it means
    # the northbound one, and 22, 32 are shelf columns (nothing to close)
    assert (13, 6) in patched and (13, 6) not in raw
    assert (12, 6) in raw and (12, 6) not in patched
    # the raw reopening k(L + 1) + 1 .. + 2 is columns 11-12 and 21-22: V2's junction cells in
    # row 9 stay closed, and a lane cell off the junction is reopened
    assert (24, 9) in raw and (24, 9) not in patched
    assert (11, 9) not in raw and (11, 9) in patched


def test_e3_reopens_the_right_edge_junctions():
    start, end = (5, 7), (0, 7)
    assert {(34, 9), (35, 9)} <= closed(start, end, errata=dm.ERRATA - {"E3"})
    assert not {(34, 9), (35, 9)} & closed(start, end)


def test_e4_keeps_the_end_column_open_on_one_channel():
    # both below h2 (row 3), the end left of the start: Algorithm 1 closes row 4 left of x1,
    # which covers x2, so the end could only be reached across the westbound row 5
    start, end = (9, 3), (5, 3)
    assert (5, 4) in closed(start, end, errata=dm.ERRATA - {"E4"})
    assert (5, 4) not in closed(start, end)
    # the end right of the start: Algorithm 2 closes row 5 left of x2, covering x1, so a start
    # above the channel could not step out at all
    assert (5, 5) in closed((5, 6), (9, 3), errata=dm.ERRATA - {"E4"})
    assert dm.literal_route(PAPER002, (5, 6), (9, 3), errata=dm.ERRATA - {"E4"}) is None
    assert dm.literal_route(PAPER002, (5, 6), (9, 3)) is not None


def test_e5_same_block_closes_the_wrong_vertical_lanes_between():
    start, end = (5, 3), (6, 15)  # block 1, level 2 up to level 5: no 3-x applies
    for col in (12, 23, 34):  # Algorithms 1 and 2 close rows 6-7 and 14-15, E5 those between
        assert closed_in_column(start, end, col, errata=dm.ERRATA - {"E5"}) == [6, 7, 14, 15]
        assert closed_in_column(start, end, col) == [6, 7, 10, 11, 14, 15]
    assert closed_in_row(start, end, 8) == closed_in_row(start, end, 9) == []


def test_e7_start_and_end_are_open():
    cells = dm.literal_open_cells(PAPER002, (5, 7), (0, 7))
    assert {(5, 7), (0, 7)} <= cells
    assert not {s.cell for s in PAPER002.slots} - {(5, 7)} & cells
    raw = dm.literal_open_cells(PAPER002, (5, 7), (0, 7), errata=dm.READINGS - {"E7"})
    assert (5, 7) not in raw
    assert dm.literal_route(PAPER002, (5, 7), (0, 7), errata=dm.READINGS - {"E7"}) is None


# -- the A* --------------------------------------------------------------------------------

def test_route_cost_is_the_sum_of_d_over_v():
    route = dm.literal_route(PAPER002, (30, 3), (5, 22))
    cells = list(route.cells)
    d = [1.4 if a[0] != b[0] and a[1] != b[1] else 1.0 for a, b in pairwise(cells)]
    assert route.cost_s == pytest.approx(sum(d))
    faster = dm.literal_route(PAPER002, (30, 3), (5, 22), speed=2.0)
    assert faster.cells == route.cells and faster.cost_s == pytest.approx(route.cost_s / 2)
    assert cells[0] == (30, 3) and cells[-1] == (5, 22)
    open_cells = dm.literal_open_cells(PAPER002, (30, 3), (5, 22))
    for a, b in pairwise(cells):  # one step each, on open cells, no closed corner cut
        assert max(abs(a[0] - b[0]), abs(a[1] - b[1])) == 1
        assert {a, b, (a[0], b[1]), (b[0], a[1])} <= open_cells


def test_a_station_route_leaves_and_enters_through_the_access_cells():
    cells = dm.literal_route(PAPER002, (0, 14), (20, 2)).cells
    assert cells[1] == (1, 14) and cells[-2] == (20, 1)


# -- sweeps over the pairs the paper plans ---------------------------------------------------------

STATIONS = [(0, 0), (0, 29)]  # p1 and p30: the corners of V0
PILES = [(3, 30), (13, 30)]  # c1, and c11 over V1's northbound lane


@cache
def sample_pairs():
    slots = [s.cell for s in PAPER002.slots]
    pairs = [(s, p) for p in STATIONS + PILES for s in slots]
    pairs += [(p, s) for p in STATIONS + PILES for s in slots]
    return pairs + dm.sample_slot_pairs(PAPER002, 300, seed=2002)


@dataclass(frozen=True)
class Checked:
    """A pair planned on its literal map and judged by the lane oracle
    (fleet/analysis/lane_rules.py)."""

    start: tuple
    end: tuple
    route: tuple | None
    violations: tuple

    @property
    def ok(self) -> bool:
        return self.route is not None and not self.violations


@cache
def sweep(unpatched):
    results = []
    for start, end in sample_pairs():
        found = dm.literal_route(PAPER002, start, end, unpatched=unpatched)
        cells = None if found is None else found.cells
        results.append(Checked(start, end, cells, () if cells is None else
                               tuple(lane_violations(PAPER002, cells))))
    return results


def wrong_way_moves(result):
    return [v.move for v in result.violations if v.rule not in ("place-access", "corner-cut")]


def test_patched_literal_map_always_has_a_route():
    results = sweep(False)
    assert len(results) == 4 * 2 * 378 + 300
    assert all(r.route is not None for r in results)
    for r in results:  # no place but the ends is driven over, every place through its access
        assert not any(v.rule in ("place-access", "through-place", "off-lanes", "access-cell")
                       for v in r.violations)


def test_patched_literal_routes_keep_right_but_at_junctions_and_the_ends():
    """Finding: the literal map closes only whole lane stretches, so a junction cell (open for
    both of its lanes) and the start's and end's own columns (open in both lanes: Algorithms
    1, 2 and E4) can be crossed the wrong way by the direction-blind A*. Every wrong-way move
    of the sample is of one of these kinds, or of a same-block pair (E5 leaves the middle
    horizontal lanes open both ways). And the start and end cells, open on the map (E7), let
    a diagonal cut the corner past them, which the lane oracle does not allow."""
    results = sweep(False)
    bad = [r for r in results if not r.ok]
    kinds = Counter()
    for r in bad:
        for v in r.violations:
            if v.rule != "corner-cut":
                continue
            (ax, ay), (bx, by) = v.move
            assert {(ax, by), (bx, ay)} & {r.start, r.end}, (r.start, r.end, v)
            kinds["corner past the start or end"] += 1
        for a, b in wrong_way_moves(r):
            own_rows = {4 * (dm.level(c) - 1) + j for c in (r.start, r.end) for j in (0, 1)}
            if len(LANES[a]) == 2 or len(LANES[b]) == 2:
                kinds["junction"] += 1
            elif {a[1], b[1]} <= own_rows:
                kinds["own channel"] += 1
            else:
                assert dm.block(r.start) == dm.block(r.end), (r.start, r.end, a, b)
                kinds["same block, middle"] += 1
    assert bad and kinds["junction"] > 0
    assert len(bad) < len(results) / 4  # most routes keep right
    print(f"patched: {len(results)} pairs, {len(results) - len(bad)} compliant, {dict(kinds)}")


def test_literal_route_at_a_junction_goes_the_wrong_way():
    # slot (3, 3) (below h2, beside V0) to p1: the A* steps west from (3, 4) onto (2, 4), the
    # eastbound lane's junction cell, which no line of Algorithms 1-3 closes
    cells = dm.literal_route(PAPER002, (3, 3), (0, 0)).cells
    assert cells[:3] == ((3, 3), (3, 4), (2, 4))
    assert ((3, 4), (2, 4), "wrong-way") in [
        (*v.move, v.rule) for v in lane_violations(PAPER002, cells)]


def test_unpatched_indices_fail_more_pairs():
    """Finding: with the listings' raw indices (no E1, E3, E4, E5) some pairs have no route at
    all and many more drive a lane the wrong way, away from junctions too."""
    patched, raw = sweep(False), sweep(True)
    no_route = [(r.start, r.end) for r in raw if r.route is None]
    failing = [(r.start, r.end) for r in raw if not r.ok]
    assert no_route
    assert len(failing) > 2 * sum(not r.ok for r in patched)
    print(f"unpatched: {len(raw)} pairs, {len(failing)} failing, {len(no_route)} without route")
