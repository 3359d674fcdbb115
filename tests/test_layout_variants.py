"""`paper-cut` and `paper-firewall`: other readings of seed 000's warehouse than `paper`
(docs/layouts.md, "Variants of paper"). Each differs from paper only where its reading says,
loads with six clusters and passes the layout check."""

import re
from importlib import resources

import pytest

from fleet.planning.trajectory import Pose
from fleet.world.layout_file import load_layout, parse_layout
from fleet.world.reachability import reachability_problems

PAPER = load_layout("paper")
CUT = load_layout("paper-cut")
FIREWALL = load_layout("paper-firewall")

CUT_STACKS = {(5, 6): 11, (6, 6): 17, (7, 6): 23}  # s3's stacks in the passage, by index
FIREWALL_ENDS = {(3, 7), (3, 4)}  # paper's notches at the firewalls' ends
MOVED_NOTCHES = {"s1": (2, 7), "s2": (2, 4)}  # where the variant's notches went


def source(name: str) -> str:
    return resources.files("fleet.world.layouts").joinpath(f"{name}.toml").read_text()


def edited(name: str, *changes: tuple[str, str]) -> str:
    """A shipped layout's text with some edits, without its drawing (the loader draws it)."""
    text = source(name)
    for old, new in changes:
        assert old in text
        text = text.replace(old, new)
    return re.sub(r'drawing = """.*?"""\n', "", text, flags=re.S)


def stack_cells(layout) -> dict:
    return {s.cell: (s.cluster, s.index) for s in layout.stacks}


def firewall_cells(layout) -> set:
    return {c for o in layout.obstacles if o.kind == "firewall" for c in o.cells}


def passage(layout, name: str) -> frozenset:
    return next(p.cells for p in layout.passages if p.name == name)


def route_open(layout, filled) -> bool:
    """Can a forklift in the passage between s1 and s2 reach p1's dock with `filled` full?"""
    planner = layout.vehicle_kind.planner(layout.grid_map(filled))
    left = Pose.parse("1,5,E")
    return planner.component(left) == planner.component(layout.station("p1").dock)


@pytest.mark.parametrize(("layout", "counts"), [
    (CUT, {"s1": 15, "s2": 15, "s3": 23, "s4": 20, "s5": 33, "s6": 33}),
    (FIREWALL, {"s1": 14, "s2": 14, "s3": 20, "s4": 20, "s5": 33, "s6": 33}),
])
def test_variants_are_paper_sized_with_six_clusters(layout, counts):
    # Not paper's 136: paper-cut adds three stacks to s3 (139), paper-firewall gives one lane
    # mouth of s1 and of s2 to a notch (134); docs/layouts.md says why.
    assert (layout.cols, layout.rows, layout.cell_size) == (PAPER.cols, PAPER.rows, 2.0)
    assert layout.origin == PAPER.origin
    assert [c.name for c in layout.clusters] == ["s1", "s2", "s3", "s4", "s5", "s6"]
    assert {c: len(layout.cluster_stacks(c)) for c in counts} == counts
    assert len(layout.stacks) == sum(counts.values()) == {CUT: 139, FIREWALL: 134}[layout]
    assert layout.stations == PAPER.stations
    assert layout.vehicle_starts == PAPER.vehicle_starts
    assert layout.vehicle == PAPER.vehicle


@pytest.mark.parametrize("name", ["paper-cut", "paper-firewall"])
def test_variants_pass_the_layout_check(name):
    assert reachability_problems(load_layout(name)) == []


# -- paper-cut ------------------------------------------------------------------------------

def test_cut_stacks_stand_in_the_passage_that_is_free_in_paper():
    cut = stack_cells(CUT)
    for cell, index in CUT_STACKS.items():
        assert cut[cell] == ("s3", index)
        assert cell not in stack_cells(PAPER) and cell in passage(PAPER, "horizontal")
        assert cell not in passage(CUT, "horizontal")
    assert CUT.cluster_stacks("s3")[-1].cell == (7, 6)  # the seed's "23rd stack" of s3
    # Nothing else moves: the same cells hold the same clusters' stacks.
    assert {c: k for c, (k, _) in cut.items() if c not in CUT_STACKS} == {
        c: k for c, (k, _) in stack_cells(PAPER).items()}
    assert CUT.obstacles == PAPER.obstacles
    assert [c.notches for c in CUT.clusters] == [c.notches for c in PAPER.clusters]


def test_cut_narrows_the_route_of_s1_and_s2_to_one_lane_but_never_closes_it():
    everything = {s.cell for s in CUT.stacks}
    between = [(x, y) for x in range(5, 8) for y in (5, 6)]
    assert [c for c in between if CUT.grid_map(everything).free(c)] == [(5, 5), (6, 5), (7, 5)]
    assert all(PAPER.grid_map({s.cell for s in PAPER.stacks}).free(c) for c in between)
    assert route_open(CUT, everything)


def test_an_s4_stack_across_from_s3s_would_close_the_route():
    # Why s3 cuts alone: one stack of s4 in row 5 leaves no way past, and the check says so.
    closed = parse_layout(edited("paper-cut", ('"7,0..7,4"]', '"7,0..7,4", "6,5"]'),
                                 ('"0,5..17,5"', '"0,5..5,5", "7,5..17,5"')), "t")
    assert stack_cells(closed)[(6, 5)] == ("s4", 21)
    assert not route_open(closed, {s.cell for s in closed.stacks})
    problems = [str(p) for p in reachability_problems(closed)]
    assert any(p.startswith("cluster s1 stack") for p in problems)


def test_cut_drawing():
    assert CUT.render_drawing().split("\n")[4:8] == [
        "111n3333::n5555555",
        ":::::333::::::::::",
        "::::::::::::::::::",
        "222n4444::n6666666"]


# -- paper-firewall -------------------------------------------------------------------------

def test_firewalls_reach_the_passage_where_paper_keeps_notches():
    assert firewall_cells(FIREWALL) == firewall_cells(PAPER) | FIREWALL_ENDS
    assert {c for k in PAPER.clusters for c in k.notches} >= FIREWALL_ENDS
    everything = {s.cell for s in PAPER.stacks}
    assert all(PAPER.grid_map(everything).free(c) for c in FIREWALL_ENDS)
    assert not any(FIREWALL.grid_map().free(c) for c in FIREWALL_ENDS)
    for x, y in FIREWALL_ENDS:  # each firewall now touches the horizontal passage
        assert (x, 6 if y == 7 else 5) in passage(FIREWALL, "horizontal")


def test_firewall_moves_the_notches_onto_a_lane_mouth_of_s1_and_s2():
    paper, variant = stack_cells(PAPER), stack_cells(FIREWALL)
    for cluster, cell in MOVED_NOTCHES.items():
        assert FIREWALL.cluster(cluster).notches == {cell}
        assert paper[cell][0] == cluster and cell not in variant
    assert {c: k for c, (k, _) in variant.items()} == {
        c: k for c, (k, _) in paper.items() if c not in MOVED_NOTCHES.values()}
    assert passage(FIREWALL, "horizontal") == passage(PAPER, "horizontal")


def test_firewall_reading_without_the_moved_notch_fails_the_check():
    # All 15 cells of s1 (and of s2) stacks, as in paper, with the firewall to the passage.
    full = parse_layout(edited("paper-firewall", ('"2,11..2,8"]', '"2,11..2,7"]'),
                               ('"2,0..2,3"]', '"2,0..2,4"]'), ('notches = ["2,7"]', ""),
                               ('notches = ["2,4"]', "")), "t")
    assert len(full.stacks) == 136
    problems = [str(p) for p in reachability_problems(full)]
    assert any(p.startswith("cluster s1 stack") for p in problems)
    assert any(p.startswith("cluster s2 stack") for p in problems)


def test_firewall_drawing():
    assert FIREWALL.render_drawing().split("\n")[4:8] == [
        "11n#3333::n5555555",
        "::::::::::::::::::",
        "::::::::::::::::::",
        "22n#4444::n6666666"]
