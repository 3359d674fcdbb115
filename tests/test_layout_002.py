"""Seed 002's lane layouts: the shipped maps' inventory (seed pack note A.2.2), allowed moves,
keep-right, the drawing and reachability checks, and fleet show / check / run on them."""

import re
from collections import Counter
from importlib import resources

import pytest

from fleet.cli import main
from fleet.world.lane_reachability import lane_problems
from fleet.world.lanes import allowed_moves, diagonal_moves, doors, step
from fleet.world.layout import DIRECTIONS, LayoutError
from fleet.world.layout_file import load_layout, parse_layout

PAPER002 = load_layout("paper002")
LEFT_OF = {"E": "N", "N": "W", "W": "S", "S": "E"}  # y up: a quarter turn anticlockwise
OPPOSITE = {"E": "W", "W": "E", "N": "S", "S": "N"}


def source(name: str) -> str:
    return resources.files("fleet.world.layouts").joinpath(f"{name}.toml").read_text()


def without_drawing(text: str) -> str:
    return re.sub(r'drawing = """.*?"""\n', "", text, flags=re.S)


@pytest.mark.parametrize(("name", "cols", "slots", "junctions"), [
    ("paper002", 36, 378, {"crossroad": 12, "t": 16, "corner": 4}),
    ("paper002-406", 39, 406, {"crossroad": 18, "t": 12, "corner": 2}),
    ("paper002-uni", 36, 378, {"crossroad": 12, "t": 16, "corner": 4}),
])
def test_shipped_002_layouts_have_the_notes_counts(name, cols, slots, junctions):
    layout = load_layout(name)
    assert (layout.cols, layout.rows) == (cols, 31)
    assert len(layout.slots) == slots == len(layout.shelves)
    assert len(layout.packing) == 30 and len(layout.piles) == 33
    assert Counter(j.kind for j in layout.junctions) == junctions
    assert {p.cell for p in layout.packing} == {(0, y) for y in range(30)}
    assert {p.cell for p in layout.piles} == {(x, 30) for x in range(3, 36)}
    assert all(p.dwell == 10.0 for p in layout.packing)
    assert layout.vehicle.kind == "agv"
    assert lane_problems(layout) == []


def test_paper002_inventory_of_lane_cells():
    junction_cells = {c for j in PAPER002.junctions for c in j.cells}
    lane_cells = set(PAPER002.lane_directions) - junction_cells
    horizontal = {c for c in lane_cells if PAPER002.lane_directions[c] <= {"E", "W"}}
    assert len(junction_cells) == 48 + 64 + 16
    assert (len(horizontal), len(lane_cells - horizontal)) == (432, 112)  # |H|, |L|
    assert PAPER002.shelves["s-3-7"].cell == (3, 7)


def test_micro_layouts_check():
    for name, kinds in (("micro-cross", {"crossroad": 1, "t": 4, "corner": 4}),
                        ("micro-t", {"t": 2, "corner": 4}),
                        ("micro-channel", {"corner": 4})):
        layout = load_layout(name)
        assert Counter(j.kind for j in layout.junctions) == kinds
        assert layout.slots and lane_problems(layout) == []


def test_allowed_moves_on_a_lane_cell_a_crossroad_and_a_t():
    assert allowed_moves(PAPER002, (5, 4)) == {"E"}  # h2's lower lane
    assert allowed_moves(PAPER002, (5, 5)) == {"W"}
    assert allowed_moves(PAPER002, (12, 10)) == {"S"}  # V1's left lane
    # The crossroad of V1 and h2: each cell keeps its two lanes' directions.
    assert allowed_moves(PAPER002, (12, 4)) == {"E", "S"}
    assert allowed_moves(PAPER002, (13, 4)) == {"E", "N"}
    assert allowed_moves(PAPER002, (12, 5)) == {"W", "S"}
    assert allowed_moves(PAPER002, (13, 5)) == {"W", "N"}
    # The T of V0 and h2 at the left edge: west leads onto a packing station, not a lane.
    assert allowed_moves(PAPER002, (1, 5)) == {"S"}
    assert allowed_moves(PAPER002, (1, 4)) == {"E", "S"}
    assert allowed_moves(PAPER002, (3, 3)) == frozenset()  # a slot
    assert diagonal_moves(PAPER002, (12, 5)) == {"SE"}  # a left turn cut inside the junction
    assert diagonal_moves(PAPER002, (5, 4)) == frozenset()  # no turning off a plain lane


def test_keep_right_on_every_lane_cell_of_paper002():
    junction_cells = {c for j in PAPER002.junctions for c in j.cells}
    lanes = PAPER002.lane_directions
    for cell, directions in lanes.items():
        if cell in junction_cells:
            continue
        (d,) = directions
        left, right = step(cell, LEFT_OF[d]), step(cell, OPPOSITE[LEFT_OF[d]])
        assert lanes.get(left, frozenset()) & {OPPOSITE[d]} or left in junction_cells, cell
        assert OPPOSITE[d] not in lanes.get(right, frozenset()), cell


def test_slot_doors_cross_the_channel_in_its_column():
    assert doors(PAPER002, PAPER002.shelves["s-3-3"]) == {(3, 4), (3, 5)}
    uni = load_layout("paper002-uni")
    assert doors(uni, uni.shelves["s-3-3"]) == {(3, 5)}  # across the access cell (3, 4)
    assert set(DIRECTIONS) == {"E", "N", "W", "S"}


def test_a_lane_drawn_against_its_data_is_named():
    text = source("micro-channel")
    text = text.replace("LL>>>>LL\nv^", "LL><>>LL\nv^", 1)
    with pytest.raises(LayoutError, match=r"drawing: cell \(3, 4\) shows '<' but the data "
                                          r"makes it lane h2-east \('>'\)"):
        parse_layout(text, "t")


def test_a_lane_that_is_not_straight_or_overlaps_is_named():
    text = without_drawing(source("micro-channel"))
    bent = text.replace('cells = "0,0..7,0"', 'cells = ["0,0..6,0", "7,1"]', 1)
    with pytest.raises(LayoutError, match="lane h1-east: runs E, so its cells must lie in one "
                                          "row"):
        parse_layout(bent, "t")
    over = text.replace('cells = "7,1..0,1"', 'cells = "7,0..0,0"', 1)
    with pytest.raises(LayoutError, match=r"lane h1-west overlaps lane h1-east at cell"):
        parse_layout(over, "t")


def cut_channel() -> str:
    """micro-channel with its bottom channel's lanes shortened off both vertical channels:
    no lane leads in or out, so its four slots are cut off from the four above."""
    text = without_drawing(source("micro-channel"))
    return (text.replace('cells = "0,0..7,0"', 'cells = "2,0..5,0"', 1)
            .replace('cells = "7,1..0,1"', 'cells = "5,1..2,1"', 1))


def test_a_lane_set_that_cuts_a_slot_off_fails_check_naming_it():
    problems = [str(p) for p in lane_problems(parse_layout(cut_channel(), "t"))]
    assert problems[0] == "slot s-2-2: cannot be reached from slot s-2-3 along the lanes"
    # the four slots cut off, then the four above, which are cut off from them
    assert len(problems) == 8
    assert problems[4] == "slot s-2-3: cannot be reached from slot s-2-2 along the lanes"


def test_a_slot_with_no_lane_beside_it_is_named():
    text = without_drawing(source("micro-channel")).replace(
        'access = ["N", "S"]', 'access = ["E"]', 1)
    with pytest.raises(LayoutError, match=r"slot s-2-2: no lane or access cell beside it on "
                                          r"its access sides \(E\)"):
        parse_layout(text, "t")


def test_lane_elements_need_lanes_and_a_lane_kind():
    text = without_drawing(source("micro-channel"))
    with pytest.raises(LayoutError, match="vehicle: kind 'forklift' does not drive lanes"):
        parse_layout(text.replace('vehicle = { kind = "agv" }', ""), "t")
    no_lanes = re.sub(r"\[\[lane\]\]\n(.*\n){3}", "", text)
    with pytest.raises(LayoutError, match="shelf_area: shelf areas, packing stations, piles "
                                          "and access cells belong to a lane layout"):
        parse_layout(no_lanes, "t")


def test_layout_show_and_check_paper002(capsys):
    assert main(["layout", "show", "paper002"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("###CCCC") and "PTT>>>>>>>>>XX" in out
    assert "h2-east > (1, 4)..(35, 4)" in out
    assert "junctions 32: 12 crossroads (X), 16 T-crossroads (T), 4 corners (L)" in out
    assert "shelves  378 in 24 shelf areas" in out and "dwell 10 s" in out
    assert "piles 33" in out
    assert main(["layout", "check", "paper002"]) == 0
    assert "every slot, station and pile can be reached" in capsys.readouterr().out


def test_layout_check_names_the_cut_off_slot(tmp_path, capsys):
    path = tmp_path / "cut.toml"
    path.write_text(cut_channel())
    assert main(["layout", "check", str(path)]) == 1
    err = capsys.readouterr().err.splitlines()
    assert err[0] == f"{path}: slot s-2-2: cannot be reached from slot s-2-3 along the lanes"
    assert err[-1] == f"{path}: 8 problem(s)"
