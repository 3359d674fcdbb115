"""Layout files: the shipped layouts, the structural checks, reachability, the generator."""

import re

import pytest

from fleet.planning.maneuvers import fork_target
from fleet.world.generator import Shape, generate_layout, generate_toml
from fleet.world.layout import LayoutError
from fleet.world.layout_file import load_layout, parse_layout
from fleet.world.reachability import check_layout, reachability_problems

SMALL = load_layout("small")


def small_source() -> str:
    from importlib import resources

    return resources.files("fleet.world.layouts").joinpath("small.toml").read_text()


def edited(old: str, new: str, drawing: bool = False) -> str:
    """The small layout with one edit; the drawing is dropped unless kept on purpose."""
    text = small_source()
    assert old in text
    text = text.replace(old, new)
    if not drawing:
        text = re.sub(r'drawing = """.*?"""\n', "", text, flags=re.S)
    return text


def test_paper_is_the_seed_warehouse():
    paper = load_layout("paper")
    assert (paper.cols, paper.rows, paper.cell_size) == (18, 12, 2.0)
    assert paper.cell_center((0, 0)) == (-17.0, -11.0)
    assert paper.cell_center((17, 11)) == (17.0, 11.0)
    assert len(paper.stacks) == 136
    assert [c.name for c in paper.clusters] == ["s1", "s2", "s3", "s4", "s5", "s6"]
    assert sorted(o.kind for o in paper.obstacles).count("firewall") == 2
    assert [s.name for s in paper.stations] == ["p1", "p2", "p3", "p4"]
    assert len(paper.vehicle_starts) == 4 and paper.vehicle.kind == "forklift"
    for station in paper.stations:
        assert fork_target(station.dock.cell, station.dock.heading) == station.cell


def test_shipped_layouts_are_reachable_in_fill_order():
    for name in ("paper", "small"):
        assert reachability_problems(load_layout(name)) == []


def test_fill_order_numbers_stacks_from_the_first_corner():
    stacks = SMALL.cluster_stacks("a")
    assert [s.cell for s in stacks[:4]] == [(0, 7), (0, 6), (0, 5), (1, 7)]
    assert [s.index for s in stacks] == list(range(1, 13))


def test_drawing_that_disagrees_names_the_cell():
    text = small_source().replace("aaaaPP##\n", "aaa.PP##\n", 1)
    with pytest.raises(LayoutError, match=r"cell \(3, 7\) shows '\.' but the data makes it "
                                          r"cluster a stack 10"):
        parse_layout(text, "t")


def test_drawing_with_a_missing_row():
    text = small_source().replace("aaaa::..\n", "", 1)
    with pytest.raises(LayoutError, match="drawing: has 7 rows, the map has 8"):
        parse_layout(text, "t")


def test_overlapping_clusters_are_named():
    text = edited('fill = ["0,0..0,2"', 'fill = ["0,5..0,5", "0,0..0,2"')
    with pytest.raises(LayoutError, match=r"cluster b stack 1 overlaps cluster a stack 3 "
                                          r"at cell \(0, 5\)"):
        parse_layout(text, "t")


def test_station_off_the_map():
    text = edited('cell = "5,7"', 'cell = "5,8"')
    with pytest.raises(LayoutError, match=r"station p2: cell \(5, 8\) is off the 8 x 8 map"):
        parse_layout(text, "t")


def test_dock_must_point_at_its_station():
    text = edited('dock = "5,6,S"', 'dock = "6,5,S"')
    with pytest.raises(LayoutError, match=r"station p2: dock 6,5,S works cell \(6, 6\), "
                                          r"not the station \(5, 7\)"):
        parse_layout(text, "t")


def test_unknown_key_and_bad_type():
    with pytest.raises(LayoutError, match="cluster a: unknown key 'colour'"):
        parse_layout(edited('name = "a"\n', 'name = "a"\ncolour = "red"\n'), "t")
    with pytest.raises(LayoutError, match="layout: 'cell_size' must be a float"):
        parse_layout(edited("cell_size = 2.0", 'cell_size = "2"'), "t")


def test_bounds_must_be_whole_cells():
    with pytest.raises(LayoutError, match="bounds: x span 15 m is not a whole number"):
        parse_layout(edited("x = [0.0, 16.0]", "x = [0.0, 15.0]"), "t")


def test_start_on_a_stack_is_refused():
    with pytest.raises(LayoutError, match="start 2: pose 3,6,S stands on cluster a stack"):
        parse_layout(edited('starts = ["4,6,S", "5,6,S"]', 'starts = ["4,6,S", "3,6,S"]'), "t")


def test_stack_walled_in_by_the_fill_order_is_named():
    # Filling cluster a's front row first walls in the rows behind it.
    text = edited('fill = ["0,7..0,5", "1,7..1,5", "2,7..2,5", "3,7..3,5"]',
                  'fill = ["0,5..3,5", "3,6..0,6", "0,7..3,7"]')
    layout = parse_layout(text, "t")
    problems = reachability_problems(layout)
    assert [str(p) for p in problems[:2]] == [
        "cluster a stack 6 at (2, 6): no unload pose connects to a station dock (there and "
        "back, with the stack filled) once the stacks before it are filled",
        "cluster a stack 7 at (1, 6): no free pose can point its forks at it once the "
        "stacks before it are filled"]
    with pytest.raises(LayoutError, match=r"cluster a stack 6 at \(2, 6\).*\(and \d+ more\)"):
        check_layout(layout)


def test_start_cut_off_from_every_dock():
    text = edited('starts = ["4,6,S", "5,6,S"]', 'starts = ["4,6,S", "7,0,N"]')
    text = text.replace('cells = ["6,7..7,7"]', 'cells = ["6,7..7,7", "6,0..6,2", "7,2"]')
    problems = reachability_problems(parse_layout(text, "t"))
    assert [str(p) for p in problems] == ["start 2 (7,0,N): cannot reach any station dock"]


def test_vehicles_that_pass_under_shelves():
    under = parse_layout(edited("[bounds]", "[vehicle]\npasses_under_shelves = true\n\n[bounds]"),
                         "t")
    assert under.vehicle.passes_under_shelves
    full = {s.cell for s in under.stacks}
    assert not under.grid_map(full, under_shelves=True).blocked & full
    assert full <= under.grid_map(full).blocked


def test_generator_round_trips_and_is_reachable():
    shape = Shape(aisles=1, depth=4, lane_depth=3, vehicles=2)
    layout = generate_layout(shape)
    assert (layout.cols, layout.rows) == (shape.cols, shape.rows)
    assert len(layout.stacks) == 4 * 4 * 3
    assert layout.drawing.count("\n") == layout.rows - 1
    assert reachability_problems(layout) == []
    assert parse_layout(generate_toml(shape), "again") == layout


def test_generator_scales_past_a_hundred_vehicles():
    layout = generate_layout(Shape(aisles=12, depth=20, vehicles=120))
    assert len(layout.vehicle_starts) == 120
    assert len(layout.stacks) == 4 * 12 * 20 * 5
    cells = [c for p in layout.vehicle_starts for c in (p.cell,)]
    assert len(set(cells)) == 120


def test_generator_refuses_more_vehicles_than_slots():
    from fleet.errors import UserError

    with pytest.raises(UserError, match="--vehicles must be between 1 and 6"):
        generate_layout(Shape(aisles=1, depth=8, vehicles=7))
