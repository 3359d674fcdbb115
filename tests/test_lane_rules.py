"""The lane oracle (fleet/analysis/lane_rules.py) against routes written by hand from the
layout drawings (docs/layouts.md; seed pack note A.4.2, A.7 A-RHR-3): every turn through a
crossroad and a T is legal, and each way of breaking the rules is named by its rule.

Cells are (column, row), row 0 the drawing's bottom line. The pieces used, read off the
drawings:

micro-cross, the crossroad X at columns 4-5, rows 4-5: h2-east is row 4 (>), h2-west row 5
(<), v1-south column 4 (v), v1-north column 5 (^); slots at columns 2-3 and 6-7 of rows 2-3
and 6-7, the ones of rows 3 and 6 entered from the channel between them (rows 4-5).

micro-t, the T at columns 1-2, rows 4-5 (left edge): h2-east row 4 starts at column 1,
h2-west row 5 ends there, v0-south column 1, v0-north column 2; packing stations p1..p10 at
column 0 (p6 at (0, 5)), entered from column 1; piles on row 10 entered from row 9 (h3-west).
"""

from __future__ import annotations

import ast
import dataclasses
import subprocess
import sys
from pathlib import Path

import pytest

from fleet.analysis.lane_rules import LaneViolation, lane_violations
from fleet.world.layout import Lane
from fleet.world.layout_file import load_layout

ROOT = Path(__file__).resolve().parent.parent
CROSS = load_layout("micro-cross")
T = load_layout("micro-t")
UNI = load_layout("paper002-uni")


def rules(layout, cells):
    return [(v.index, v.rule) for v in lane_violations(layout, cells)]


# A-RHR-3 on the crossroad: from each approach left, right, straight and the U-turn.
CROSSROAD = {
    "from west, straight": [(3, 4), (4, 4), (5, 4), (6, 4)],
    "from west, right": [(3, 4), (4, 4), (4, 3)],
    "from west, left": [(3, 4), (4, 4), (5, 4), (5, 5), (5, 6)],
    "from west, left cutting inside": [(3, 4), (4, 4), (5, 5), (5, 6)],
    "from west, U-turn via the westbound lane": [(3, 4), (4, 4), (5, 4), (5, 5), (4, 5), (3, 5)],
    "from east, straight": [(6, 5), (5, 5), (4, 5), (3, 5)],
    "from east, right": [(6, 5), (5, 5), (5, 6)],
    "from east, left": [(6, 5), (5, 5), (4, 5), (4, 4), (4, 3)],
    "from east, left cutting inside": [(6, 5), (5, 5), (4, 4), (4, 3)],
    "from east, U-turn": [(6, 5), (5, 5), (4, 5), (4, 4), (5, 4), (6, 4)],
    "from south, straight": [(5, 3), (5, 4), (5, 5), (5, 6)],
    "from south, right": [(5, 3), (5, 4), (6, 4)],
    "from south, left": [(5, 3), (5, 4), (5, 5), (4, 5), (3, 5)],
    "from south, left cutting inside": [(5, 3), (5, 4), (4, 5), (3, 5)],
    "from south, U-turn": [(5, 3), (5, 4), (5, 5), (4, 5), (4, 4), (4, 3)],
    "from north, straight": [(4, 6), (4, 5), (4, 4), (4, 3)],
    "from north, right": [(4, 6), (4, 5), (3, 5)],
    "from north, left": [(4, 6), (4, 5), (4, 4), (5, 4), (6, 4)],
    "from north, left cutting inside": [(4, 6), (4, 5), (5, 4), (6, 4)],
    "from north, U-turn": [(4, 6), (4, 5), (4, 4), (5, 4), (5, 5), (5, 6)],
}

# The T on micro-t's left edge: approaches from the east (row 5), the north (column 1) and
# the south (column 2); exits east (row 4), south (column 1), north (column 2), and the
# station p6 west of row 5.
T_TURNS = {
    "from east, left (south)": [(3, 5), (2, 5), (1, 5), (1, 4), (1, 3)],
    "from east, left cutting inside": [(3, 5), (2, 5), (1, 4), (1, 3)],
    "from east, right (north)": [(3, 5), (2, 5), (2, 6)],
    "from east, straight into station p6": [(3, 5), (2, 5), (1, 5), (0, 5)],
    "from east, U-turn": [(3, 5), (2, 5), (1, 5), (1, 4), (2, 4), (3, 4)],
    "from north, straight": [(1, 6), (1, 5), (1, 4), (1, 3)],
    "from north, left (east)": [(1, 6), (1, 5), (1, 4), (2, 4), (3, 4)],
    "from north, right into station p6": [(1, 6), (1, 5), (0, 5)],
    "from north, U-turn": [(1, 6), (1, 5), (1, 4), (2, 4), (2, 5), (2, 6)],
    "from south, straight": [(2, 3), (2, 4), (2, 5), (2, 6)],
    "from south, right (east)": [(2, 3), (2, 4), (3, 4)],
    "from south, left (west, then south)": [(2, 3), (2, 4), (2, 5), (1, 5), (1, 4), (1, 3)],
    "from south, left cutting inside": [(2, 3), (2, 4), (1, 5), (1, 4), (1, 3)],
}

# micro-t's T-crossroad at the bottom middle does not exist (its channels are at the edges),
# so the T with a stem is micro-cross's bottom one: columns 4-5, rows 0-1, stem going up.
BOTTOM_T = {
    "from west, straight": [(3, 0), (4, 0), (5, 0), (6, 0)],
    "from west, left": [(3, 0), (4, 0), (5, 0), (5, 1), (5, 2)],
    "from west, U-turn": [(3, 0), (4, 0), (5, 0), (5, 1), (4, 1), (3, 1)],
    "from east, straight": [(6, 1), (5, 1), (4, 1), (3, 1)],
    "from east, right": [(6, 1), (5, 1), (5, 2)],
    "from east, U-turn": [(6, 1), (5, 1), (4, 1), (4, 0), (5, 0), (6, 0)],
    "from north, left": [(4, 2), (4, 1), (4, 0), (5, 0), (6, 0)],
    "from north, right": [(4, 2), (4, 1), (3, 1)],
    "from north, U-turn": [(4, 2), (4, 1), (4, 0), (5, 0), (5, 1), (5, 2)],
}


@pytest.mark.parametrize("name", CROSSROAD)
def test_every_turn_through_the_crossroad_is_legal(name):
    assert lane_violations(CROSS, CROSSROAD[name]) == []


@pytest.mark.parametrize("name", T_TURNS)
def test_every_turn_through_the_t_is_legal(name):
    assert lane_violations(T, T_TURNS[name]) == []


@pytest.mark.parametrize("name", BOTTOM_T)
def test_every_turn_through_the_bottom_t_is_legal(name):
    assert lane_violations(CROSS, BOTTOM_T[name]) == []


# Each illegal variant, with the violations it must give: (index of the move, rule).
WW, CL, TP, PA = "wrong-way", "crossing-lane", "through-place", "place-access"
ILLEGAL = [
    # driving against a lane
    (CROSS, "west on h2-east", [(6, 4), (5, 4), (4, 4), (3, 4)], [(0, WW), (1, WW), (2, WW)]),
    (CROSS, "north up v1-south", [(4, 3), (4, 4), (4, 5), (4, 6)], [(0, WW), (1, WW), (2, WW)]),
    (CROSS, "U-turn the wrong way round", [(3, 4), (4, 4), (4, 5), (3, 5)], [(1, WW)]),
    (CROSS, "left turn begun before the X", [(3, 4), (4, 5), (3, 5)], [(0, WW)]),
    (T, "west on h2-east into the T", [(3, 4), (2, 4), (1, 4)], [(0, WW), (1, WW)]),
    (T, "from the south, west on h2-east", [(2, 3), (2, 4), (1, 4), (1, 3)], [(1, WW)]),
    # turning mid-lane: in a two-lane channel that is a sidestep across the other lane
    (CROSS, "U-turn in the middle of h2", [(2, 4), (2, 5), (1, 5)], [(0, CL)]),
    (CROSS, "diagonal U-turn mid-h2", [(1, 4), (2, 4), (3, 5), (2, 5)], [(1, CL)]),
    (T, "U-turn in the middle of v0", [(2, 2), (1, 2), (1, 1)], [(0, CL)]),
    # cutting a corner past a slot
    (CROSS, "right turn past slot s-3-3", [(3, 4), (4, 3), (4, 2)], [(0, "corner-cut")]),
    (CROSS, "right turn past slot s-3-6", [(4, 7), (4, 6), (3, 5)], [(1, "corner-cut")]),
    (T, "right turn past slot s-3-3", [(2, 2), (2, 3), (3, 4)], [(1, "corner-cut")]),
    # passing through a slot or a station
    (CROSS, "through slots s-2-2, s-2-3", [(2, 1), (2, 2), (2, 3), (2, 4)], [(0, TP), (1, TP)]),
    (CROSS, "in and out of s-2-3 on the way", [(1, 4), (2, 4), (2, 3), (2, 4), (3, 4)], [(1, TP)]),
    (T, "through station p6", [(1, 6), (1, 5), (0, 5), (0, 4), (1, 4)], [(1, TP), (2, TP)]),
    # crossing the opposite lane away from the start's and end's columns
    (CROSS, "from s-2-3, a column on", [(2, 3), (2, 4), (3, 4), (3, 5), (2, 5)], [(2, CL)]),
    (CROSS, "to s-3-6 early", [(1, 4), (2, 4), (2, 5), (3, 5), (3, 6)], [(1, CL), (2, WW)]),
    (CROSS, "to s-2-6, a column late", [(3, 4), (3, 5), (2, 5), (2, 6)], [(0, CL)]),
    (T, "leaving p4, across v0 a row down", [(0, 3), (1, 3), (1, 2), (2, 2)], [(2, CL)]),
    # places entered or left other than from their access cells, cells off the lanes, jumps
    (CROSS, "into slot s-2-2 from the side", [(1, 1), (1, 2), (2, 2)], [(1, PA)]),
    (CROSS, "into slot s-2-3 from the far side", [(2, 1), (2, 2), (2, 3)], [(0, TP), (1, PA)]),
    (CROSS, "out of slot s-3-3 diagonally", [(3, 3), (4, 4), (5, 4)], [(0, PA)]),
    (T, "into station p5 from p6", [(1, 6), (1, 5), (0, 5), (0, 4)], [(1, TP), (2, PA)]),
    (T, "off the map east of the right T", [(7, 4), (8, 4), (9, 4)], [(1, "off-lanes")]),
    (T, "onto the wall beside the piles", [(2, 8), (2, 9), (2, 10)], [(1, "off-lanes")]),
    (CROSS, "a jump along h2-east", [(2, 4), (4, 4), (5, 4)], [(0, "not-adjacent")]),
]


@pytest.mark.parametrize(
    "layout, cells, expected",
    [(layout, cells, expected) for layout, _, cells, expected in ILLEGAL],
    ids=[name for _, name, _, _ in ILLEGAL],
)
def test_each_illegal_variant_gives_its_rule(layout, cells, expected):
    assert rules(layout, cells) == expected


def test_a_violation_names_its_move_and_cells():
    (violation,) = lane_violations(CROSS, [(2, 4), (2, 5), (1, 5)])
    assert violation == LaneViolation(
        index=0, move=((2, 4), (2, 5)), rule="crossing-lane", detail=violation.detail
    )
    assert "(2, 4)" in violation.detail and "h2-east" in violation.detail
    assert "h2-west" in violation.detail


def test_a_repeated_cell_is_a_wait_and_indices_stay_the_routes():
    # waiting on the slot, on the near lane and at the end changes nothing
    route = [(2, 3), (2, 3), (2, 4), (2, 4), (2, 5), (2, 6), (2, 6)]
    assert lane_violations(CROSS, route) == []
    # a violation after waits is reported at its index in the route as given
    assert rules(CROSS, [(3, 4), (3, 4), (3, 4), (3, 5)]) == [(2, "crossing-lane")]
    assert lane_violations(CROSS, [(3, 4)]) == lane_violations(CROSS, []) == []


# Doors: leaving a slot onto the near lane and straight across onto the far lane.
def test_leaving_a_slot_onto_the_near_or_the_far_lane_is_legal():
    assert lane_violations(CROSS, [(2, 3), (2, 4), (3, 4)]) == []  # near lane, east
    assert lane_violations(CROSS, [(2, 3), (2, 4), (2, 5), (1, 5)]) == []  # far lane, west
    assert lane_violations(CROSS, [(3, 6), (3, 5), (2, 5)]) == []  # near lane, west
    assert lane_violations(CROSS, [(3, 6), (3, 5), (3, 4), (4, 4)]) == []  # far lane, east
    # and the mirror: arriving across the channel into the end slot
    assert lane_violations(CROSS, [(1, 4), (2, 4), (2, 5), (2, 6)]) == []
    assert lane_violations(CROSS, [(3, 5), (2, 5), (2, 4), (2, 3)]) == []
    # straight across the channel from slot to slot
    assert lane_violations(CROSS, [(2, 3), (2, 4), (2, 5), (2, 6)]) == []


def test_leaving_a_station_or_a_pile_across_the_channel_is_legal():
    assert lane_violations(T, [(0, 2), (1, 2), (2, 2), (2, 3)]) == []  # p3 onto v0-north
    assert lane_violations(T, [(0, 2), (1, 2), (1, 1)]) == []  # p3 onto v0-south
    assert lane_violations(T, [(2, 8), (2, 9), (1, 9), (0, 9)]) == []  # into p10
    assert lane_violations(T, [(3, 10), (3, 9), (3, 8), (4, 8)]) == []  # pile c1 across h3
    assert lane_violations(T, [(2, 8), (3, 8), (3, 9), (3, 10)]) == []  # into c1 across h3


def test_crossing_the_channel_elsewhere_is_not():
    # from the near lane when the route does not start on the slot
    assert rules(CROSS, [(2, 4), (2, 5), (1, 5)]) == [(0, "crossing-lane")]
    # diagonally across right after leaving: only the straight step is exempt
    assert rules(CROSS, [(2, 3), (2, 4), (3, 5), (2, 5)]) == [(1, "crossing-lane")]
    # across a vertical channel a row away from the station's
    assert rules(T, [(0, 3), (1, 3), (1, 2), (2, 2), (2, 3)]) == [(2, "crossing-lane")]
    # across, then on across into the far slot row is passing through it
    assert rules(CROSS, [(2, 3), (2, 4), (2, 5), (2, 6), (2, 7)]) == [
        (2, "through-place"),
        (3, "place-access"),
    ]
    # a wait between leaving and crossing does not break the door
    assert lane_violations(CROSS, [(2, 3), (2, 4), (2, 4), (2, 5), (1, 5)]) == []


def test_a_lane_ending_beside_another_is_no_junction():
    # micro-channel with v1-north stopping at row 3: (7, 3) leads north onto (7, 4), which
    # is then only on h2-east, so going on north there turns where no junction is.
    base = load_layout("micro-channel")
    lanes = tuple(
        Lane("v1-north", "N", ((7, 0), (7, 1), (7, 2), (7, 3)))
        if lane.name == "v1-north"
        else lane
        for lane in base.lanes
    )
    cut = dataclasses.replace(base, lanes=lanes)
    assert rules(cut, [(7, 2), (7, 3), (7, 4)]) == [(1, "turn-off-junction")]
    assert rules(base, [(7, 2), (7, 3), (7, 4), (7, 5)]) == []


# paper002-uni: one lane a channel, the dropped lane beside a slot row an access cell.
def test_a_slot_is_entered_and_left_across_its_access_cell():
    # slot s-3-2 above row 0 (h1-east), its access cell (3, 1)
    assert lane_violations(UNI, [(2, 0), (3, 0), (3, 1), (3, 2)]) == []
    assert lane_violations(UNI, [(3, 2), (3, 1), (3, 0), (4, 0)]) == []
    # slot s-3-3 below row 5 (h2-west), its access cell (3, 4)
    assert lane_violations(UNI, [(4, 5), (3, 5), (3, 4), (3, 3)]) == []
    assert lane_violations(UNI, [(3, 3), (3, 4), (3, 5), (2, 5)]) == []
    # a vehicle stopped on the access cell, leaving or arriving
    assert lane_violations(UNI, [(3, 1), (3, 0), (4, 0)]) == []
    assert lane_violations(UNI, [(2, 0), (3, 0), (3, 1)]) == []


def test_driving_along_or_across_access_cells_is_not():
    assert rules(UNI, [(3, 2), (3, 1), (4, 1), (4, 0)]) == [
        (1, "access-cell"),
        (2, "access-cell"),
    ]
    assert rules(UNI, [(3, 2), (3, 1), (4, 0)]) == [(1, "access-cell")]  # diagonally off it
    # onto an access cell that leads to no end: across the slot rows
    assert rules(UNI, [(3, 0), (3, 1), (3, 2), (3, 3), (3, 4), (3, 5)]) == [
        (0, "access-cell"),
        (1, "through-place"),
        (2, "through-place"),
        (4, "access-cell"),
    ]
    # the other floor of the dropped lanes is no lane at all
    assert rules(UNI, [(0, 3), (1, 3), (2, 3)]) == [(1, "off-lanes")]


def test_every_door_of_paper002_is_legal_and_only_from_its_place():
    """Each slot, station and pile left onto its access cell and on straight across, and
    entered the same way: all legal. The same crossing without the place at the route's end
    is a sidestep across the channel, where the two cells are plain lane cells."""
    layout = load_layout("paper002")
    lanes = {cell for lane in layout.lanes for cell in lane.cells}
    junction = {cell for j in layout.junctions for cell in j.cells}
    places = [*layout.slots, *layout.packing, *layout.piles]
    far_doors = sidesteps = 0
    for place in places:
        for near in place.access:
            step = (near[0] - place.cell[0], near[1] - place.cell[1])
            far = (near[0] + step[0], near[1] + step[1])
            assert lane_violations(layout, [place.cell, near]) == [], place.name
            assert lane_violations(layout, [near, place.cell]) == [], place.name
            assert far in lanes, place.name  # every place sits by a two-lane channel
            far_doors += 1
            assert lane_violations(layout, [place.cell, near, far]) == [], place.name
            assert lane_violations(layout, [far, near, place.cell]) == [], place.name
            if near not in junction and far not in junction:
                sidesteps += 1
                assert rules(layout, [near, far]) == [(0, "crossing-lane")], place.name
                assert rules(layout, [far, near]) == [(0, "crossing-lane")], place.name
    assert far_doors == len(places) == 378 + 30 + 33
    assert sidesteps == 378 + 14 + 27  # slots; stations by shelf rows; piles off V0-V3


def test_the_oracle_shares_no_code_with_the_planner():
    """It imports nothing of the project at run time (the layout only as a type), so neither
    fleet.world.lanes nor lane_reachability nor any planner module."""
    path = ROOT / "fleet" / "analysis" / "lane_rules.py"
    imported = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom):
            imported.add(node.module)
        elif isinstance(node, ast.Import):
            imported.update(alias.name for alias in node.names)
    assert {m for m in imported if m.startswith("fleet")} == {"fleet.world.layout"}
    program = "import sys, fleet.analysis.lane_rules; print(*sorted(sys.modules))"
    loaded = subprocess.run(
        [sys.executable, "-c", program], capture_output=True, text=True, check=True, cwd=ROOT
    ).stdout.split()
    project = sorted(m for m in loaded if m.startswith("fleet"))
    assert project == ["fleet", "fleet.analysis", "fleet.analysis.lane_rules"]
