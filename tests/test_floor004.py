"""Seed 004's floor, traffic rules, grid values and improved A* (seed pack note B.2-B.4):
`paper004` is the note's reconstruction cell for cell, its rule graphs connect what the work
needs, the expansion filters and the direction code are the seed's Equations (3) and (4), the
heap and the list open sets return the same paths, and the turning cost cuts turns without
lengthening routes."""

from __future__ import annotations

import dataclasses
import itertools
import random
from collections import Counter
from pathlib import Path

import pytest

from fleet.cli import main
from fleet.errors import UserError
from fleet.planning.astar004 import Costs, plan
from fleet.planning.rules004 import (
    STEP,
    Direction,
    Kind,
    Occupancy,
    Task,
    allowed,
    direction_code,
    plannable,
    value,
)
from fleet.world.floor004 import CLASSES, Floor004Shape, build, class_of, paper004
from fleet.world.floor004_check import floor_problems
from fleet.world.layout import LayoutError
from fleet.world.layout_file import layout_source, load_layout, parse_layout

FLOOR = paper004()
DRAWING = Path(__file__).parent / "data" / "paper004.txt"


def test_paper004_is_the_notes_drawing_cell_for_cell():
    """The note draws the floor it reconstructs (B.2.2); the generated one is that floor."""
    assert FLOOR.drawing() == DRAWING.read_text().rstrip("\n")


def test_paper004_has_the_seeds_elements_in_the_seeds_numbers():
    assert (FLOOR.width, FLOOR.height) == (100, 50)
    blocks = Counter(s.block for s in FLOOR.slots)
    assert len(FLOOR.slots) == 1920 and len(blocks) == 192 and set(blocks.values()) == {10}
    assert len(FLOOR.goods) == 18 and {g.split("-")[0] for g in FLOOR.goods} == set(CLASSES)
    per_goods = {g: len({s.block for s in slots}) for g, slots in FLOOR.goods.items()}
    assert set(per_goods.values()) <= {10, 11}
    assert len(FLOOR.stations) == 8
    assert all(len(s.waiting) == 3 and len(s.route) == 9 for s in FLOOR.stations)
    assert len(FLOOR.piles) == 20 and {x for x, _ in FLOOR.piles} == {0, 99}
    assert len(set(FLOOR.parking)) == len(FLOOR.parking) >= 48
    assert all(y < FLOOR.shape.aisle_rows[0] for _, y in FLOOR.parking)


def test_hotter_goods_lie_nearer_the_stations_than_every_colder_band():
    deepest = {c: max(s.xy[1] for s in FLOOR.slots if s.goods.startswith(c)) for c in CLASSES}
    shallowest = {c: min(s.xy[1] for s in FLOOR.slots if s.goods.startswith(c))
                  for c in CLASSES}
    for hot, cold in itertools.pairwise(CLASSES):
        assert shallowest[hot] > deepest[cold], (hot, cold)
    assert [class_of(k, 12) for k in range(12)] == [5, 5, 4, 4, 3, 3, 2, 2, 1, 1, 0, 0]


def test_every_slot_lies_beside_a_one_cell_aisle():
    for slot in FLOOR.slots:
        x, y = slot.xy
        assert FLOOR.kind((x, y - 1)) is Kind.FLOOR or FLOOR.kind((x, y + 1)) is Kind.FLOOR
    for y in FLOOR.shape.aisle_rows[1:-1]:  # between two double rows: one cell wide
        assert FLOOR.kind((4, y - 1)) is Kind.SLOT and FLOOR.kind((4, y + 1)) is Kind.SLOT


def test_shapes_that_cannot_be_built_are_refused_naming_the_number():
    with pytest.raises(UserError, match="piles_per_side"):
        build(Floor004Shape(piles_per_side=12))
    with pytest.raises(UserError, match="parking_rows must be 2 or more"):
        build(Floor004Shape(parking_rows=1))
    with pytest.raises(UserError, match="8 stations 12 columns apart"):
        build(Floor004Shape(blocks_across=4))
    small = build(Floor004Shape(blocks_across=4, double_rows=6, stations=2, piles_per_side=3))
    assert len(small.slots) == 4 * 6 * 10 and len(small.piles) == 6


# -- the layout file ---------------------------------------------------------------------------

def test_the_layout_paper004_is_the_generated_floor():
    layout = load_layout("paper004")
    assert layout.floor == FLOOR and layout.render_drawing() == FLOOR.drawing()
    assert layout.vehicle.kind == "lifting-agv" and (layout.cols, layout.rows) == (100, 50)


@pytest.mark.parametrize(("change", "named"), [
    (("blocks_across = 16", "blocks_across = 15"), "bounds: the map is 100 x 50 cells, but the "
                                                   "floor of [floor004] is 94 x 50"),
    (("piles_per_side = 10", "piles_per_side = 12"), "floor004: piles_per_side must be 0..11"),
    (("stations = 8", "stations = 8\nqueue = 4"), "floor004: unknown key 'queue'"),
    (("stations = 8", "stations = 'eight'"), "floor004: 'stations' must be a int"),
    (('kind = "lifting-agv"', 'kind = "agv"'), "vehicle: a seed-004 floor is driven by "
                                               "lifting-agv vehicles, not agv"),
    (("C..........", "C.....R...."), "drawing: row 6 from the top differs from the floor at "
                                     "column 6: 'R' drawn, '.' generated"),
    (("[bounds]", "[[pile]]\nname = 'x'\n\n[bounds]"), "pile: a seed-004 floor is generated "
                                                       "from [floor004]; it takes no [[pile]]"),
])
def test_a_floor_file_that_disagrees_with_itself_is_refused_naming_what(change, named):
    text = layout_source("paper004").replace(*change, 1)
    with pytest.raises(LayoutError) as refused:
        parse_layout(text, "f.toml")
    assert str(refused.value).startswith(f"f.toml: {named}"), str(refused.value)


def test_the_floor_is_shown_and_checked(capsys):
    assert main(["layout", "show", "paper004"]) == 0
    out = capsys.readouterr().out
    assert FLOOR.drawing() in out and "1920 in 192 blocks" in out and "stations 8" in out
    assert main(["layout", "check", "paper004"]) == 0
    assert "paper004: ok: 1920 slots, 18 goods, 8 stations, 20 piles" in capsys.readouterr().out


def test_fleet_plan_answers_one_query_on_the_floor_with_the_tasks_rules(capsys):
    assert main(["plan", "--layout", "paper004", "--from", "s-40-26", "--to", "station-3"]) == 0
    head, cells, summary = capsys.readouterr().out.splitlines()
    assert head.startswith("M2 (deliver) s-40-26 (40, 26) -> station-3 (30, 4)")
    assert cells.split()[0] == "40,26" and cells.split()[-1] == "30,4"
    assert "0 under shelves" in summary
    assert main(["plan", "--layout", "paper004", "--from", "2,48", "--to", "s-40-26",
                 "--turn-cost", "0", "--list-open"]) == 0
    assert capsys.readouterr().out.startswith("M1 (fetch) 2,48")
    assert main(["plan", "--layout", "paper004", "--from", "0,0", "--to", "s-40-26"]) == 2
    assert "cell (0, 0) of paper004 is wall" in capsys.readouterr().err
    # aisle row 46 (from the bottom; the seed's row 3) runs left: relaxed, straight right
    assert main(["plan", "--layout", "paper004", "--from", "3,46", "--to", "9,46",
                 "--relaxed"]) == 0
    head, cells, summary = capsys.readouterr().out.splitlines()
    assert head.endswith("rules lifted") and summary.startswith("6 cells")
    assert main(["plan", "--layout", "paper004", "--from", "s-40-26", "--to", "station-3",
                 "--relaxed"]) == 2
    assert "only an empty AGV plans without the rules" in capsys.readouterr().err


# -- the rules --------------------------------------------------------------------------------

def test_the_direction_code_is_the_seeds():
    """Equation (3)'s dx + 3|dx| + dy + 2|dy| with y down: up 1, left 2, down 3, right 4."""
    assert {d: direction_code(*STEP[d]) for d in Direction} == {
        Direction.UP: 1, Direction.LEFT: 2, Direction.DOWN: 3, Direction.RIGHT: 4}


def test_grid_values_follow_kind_and_occupancy():
    assert [value(Kind.FLOOR, o) for o in Occupancy] == [0, 1, 5]
    assert [value(Kind.SLOT, o) for o in Occupancy] == [3, 4, 6]
    assert value(Kind.LANE) == 7 and value(Kind.LANE, Occupancy.MOVING) == 8
    assert value(Kind.STRUCTURE) == 2
    assert [v for v in range(10) if plannable(Task.FETCH, v)] == [0, 1, 3, 4]
    assert [v for v in range(10) if plannable(Task.RETURN, v)] == [0, 1, 5]


def test_the_rules_let_every_part_of_the_work_be_done():
    """Under the rules, empty AGVs reach every floor cell and slot from every other; loaded
    AGVs every station from every slot and back; every pile is reached and left (B-MAP-2)."""
    assert floor_problems(FLOOR) == []


def test_a_floor_without_piles_is_named_so():
    assert floor_problems(build(Floor004Shape(piles_per_side=0))) == [
        "the floor has no charging pile"]


U, L, D, R = Direction.UP, Direction.LEFT, Direction.DOWN, Direction.RIGHT


@pytest.mark.parametrize(("task", "xy", "home", "expected"), [
    # empty AGVs: the row's and the column's rule everywhere (B.4.1)
    (Task.FETCH, (20, 3), None, {L, U}),  # odd row left, even plain column up
    (Task.FETCH, (20, 4), None, {R, U}),  # under a shelf too: even row right
    (Task.FETCH, (7, 4), None, {R, D}),  # aisle column 1 (from the left) runs down
    (Task.FETCH, (13, 9), None, {L, U}),  # aisle column 2 runs up
    (Task.FETCH, (1, 9), None, {L, U}),  # the approach column is aisle column 0
    (Task.FETCH, (98, 10), None, {R, D}),  # aisle column 17
    # loaded AGVs: the aisle's own way, free across it; both at crossings and in the open
    (Task.DELIVER, (20, 3), None, {L, U, D}),
    (Task.RETURN, (7, 4), None, {D, L, R}),
    (Task.DELIVER, (7, 3), None, {L, D}),
    (Task.DELIVER, (20, 42), None, {R, U}),
    (Task.RETURN, (20, 4), (20, 4), set(Direction)),  # its own slot
    # piles are left outward; charging AGVs turn toward the piles beside them
    (Task.FETCH, (0, 6), None, {R}), (Task.CHARGE, (99, 6), None, {L}),
    (Task.CHARGE, (1, 6), None, {L, U}), (Task.CHARGE, (98, 9), None, {R, D}),
])
def test_the_rule_table_is_the_notes(task, xy, home, expected):
    """D_M(x, y) as the note reconstructs Table 3, cell by cell (y down: row 3 is the first
    aisle, x = 7 the first aisle column after the approach column x = 1)."""
    assert allowed(FLOOR.grid, task, xy, home) == expected


def test_a_floor_whose_rules_cut_something_off_names_it():
    """Walls put round one block cut its slots off; the check names each of them."""
    block = [s for s in FLOOR.slots if s.block == (0, 5)]
    around = {(x, y) for s in block for x in range(s.xy[0] - 1, s.xy[0] + 2)
              for y in range(s.xy[1] - 1, s.xy[1] + 2)
              if FLOOR.kind((x, y)) is Kind.FLOOR}
    walled = dict(FLOOR.kinds) | {c: Kind.WALL for c in around}
    broken = dataclasses.replace(FLOOR, kinds=walled)
    broken.__dict__.pop("grid", None)  # the grid is derived from the kinds
    problems = floor_problems(broken)
    assert {s.name for s in block} <= {p.split()[1] for p in problems if p.startswith("slot")}
    assert not any("station" in p for p in problems)


def test_piles_are_reached_to_charge_and_left_only_outward():
    for x, y in FLOOR.piles:
        assert allowed(FLOOR.grid, Task.CHARGE, (x, y)) == {Direction.RIGHT if x == 0 else
                                                       Direction.LEFT}
        assert plan(FLOOR.grid, Task.CHARGE, FLOOR.parking[0], (x, y)) is not None
        back = plan(FLOOR.grid, Task.FETCH, (x, y), FLOOR.slots[0].xy)
        assert back is not None and back.cells[1][0] in (1, 98)


# -- the improved A* --------------------------------------------------------------------------

def moving(at: dict):
    """A grid with these cells' occupancy, the rest free."""
    return lambda xy: value(FLOOR.kind(xy), at.get(xy, Occupancy.FREE))


def test_an_empty_agv_drives_under_shelves_and_a_loaded_one_does_not():
    a, b = (2, 4), (6, 5)  # corners of the first block (black goods)
    empty = plan(FLOOR.grid, Task.FETCH, a, b)
    assert empty is not None and any(FLOOR.kind(c) is Kind.SLOT for c in empty.cells[1:-1])
    loaded = plan(FLOOR.grid, Task.RETURN, FLOOR.stations[0].exit_point, b, home=b)
    assert loaded is not None
    assert [c for c in loaded.cells if FLOOR.kind(c) is Kind.SLOT] == [b]


def test_the_filters_keep_stagnant_and_moving_agvs_as_the_seed_says():
    """Empty AGVs avoid stagnant cells (5, 6) but plan through moving ones (1, 4); loaded AGVs
    plan through a stagnant floor cell (5: it will have cleared) but not a 6."""
    start, goal = (20, 3), (30, 3)  # along aisle row 3, which runs left: round by row 2
    straight = plan(FLOOR.grid, Task.FETCH, start, goal)
    middle = straight.cells[5]
    for occupancy, through in ((Occupancy.MOVING, True), (Occupancy.STAGNANT, False)):
        path = plan(FLOOR.grid, Task.FETCH, start, goal, values=moving({middle: occupancy}))
        assert (middle in path.cells) is through, occupancy
    home = FLOOR.slots[0].xy
    route = plan(FLOOR.grid, Task.DELIVER, home, FLOOR.stations[0].entrance, home=home)
    on_floor = next(c for c in route.cells[2:-1] if FLOOR.kind(c) is Kind.FLOOR)
    stuck = plan(FLOOR.grid, Task.DELIVER, home, FLOOR.stations[0].entrance, home=home,
                 values=moving({on_floor: Occupancy.STAGNANT}))
    assert on_floor in stuck.cells
    slot_ahead = plan(FLOOR.grid, Task.FETCH, (2, 4), (6, 5))
    under = next(c for c in slot_ahead.cells[1:-1] if FLOOR.kind(c) is Kind.SLOT)
    for occupancy, through in ((Occupancy.MOVING, True), (Occupancy.STAGNANT, False)):
        path = plan(FLOOR.grid, Task.FETCH, (2, 4), (6, 5), values=moving({under: occupancy}))
        assert (under in path.cells) is through, occupancy


FREE = sorted(c for c, k in FLOOR.kinds.items() if k is Kind.FLOOR and c not in FLOOR.piles)


def random_queries(rng: random.Random, n: int) -> list[tuple]:
    """n seeded queries of each task type: (task, start, goal, home slot)."""
    out = []
    for _ in range(n):
        slot = rng.choice(FLOOR.slots).xy
        out += [(Task.FETCH, rng.choice(FREE), slot, None),
                (Task.DELIVER, slot, rng.choice(FLOOR.stations).entrance, slot),
                (Task.RETURN, rng.choice(FLOOR.stations).exit_point, slot, slot),
                (Task.CHARGE, slot, rng.choice(FLOOR.piles), None)]
    return out


def test_every_move_planned_keeps_its_tasks_rules():
    for task, a, b, home in random_queries(random.Random(4), 40):
        path = plan(FLOOR.grid, task, a, b, home=home)
        for c, n in itertools.pairwise(path.cells):
            code = direction_code(n[0] - c[0], n[1] - c[1])
            assert Direction(code) in allowed(FLOOR.grid, task, c, home), (task, c, n)


def test_the_search_stops_when_the_goal_enters_the_open_list():
    """Along a straight free aisle every cell before the goal is expanded once, the goal
    never: the search ends when the goal is opened, not when it is taken (step 5)."""
    path = plan(FLOOR.grid, Task.FETCH, (8, 3), (2, 3), heading=Direction.LEFT)
    assert path.cells == tuple((x, 3) for x in range(8, 1, -1))
    assert path.expansions == path.length


def test_the_heap_and_the_list_return_the_same_paths():
    rng = random.Random(7)
    for task, a, b, home in random_queries(rng, 45):
        heading = rng.choice(list(Direction))
        costs = Costs(heat=2.0, t_value={rng.choice(FREE): 1.0 for _ in range(50)})
        by_heap = plan(FLOOR.grid, task, a, b, heading, costs, heap=True, home=home)
        by_list = plan(FLOOR.grid, task, a, b, heading, costs, heap=False, home=home)
        assert by_heap == by_list, (task, a, b)


def test_the_turning_cost_cuts_turns_and_keeps_route_lengths():
    """Over random fetches on an empty floor (the note's B-TURN-1 setting) the turning cost
    never lengthens a route and removes many of its turns; `fleet bench` will report the
    share."""
    rng = random.Random(1)
    turns = {0.0: 0, 1.0: 0}
    for _ in range(120):
        a, b = rng.choice(FREE), rng.choice(FLOOR.slots).xy
        without, with_ = (plan(FLOOR.grid, Task.FETCH, a, b, costs=Costs(turn=w)) for w in (0, 1))
        assert with_.length <= without.length
        turns[0.0] += without.turns()
        turns[1.0] += with_.turns()
    assert turns[1.0] < 0.8 * turns[0.0], turns


def test_relaxed_planning_lifts_the_rules_for_empty_agvs_only():
    """A fetch the rules send the long way round goes straight once they are lifted (the
    seed's answer to deadlock 4); a loaded AGV keeps them."""
    a, b = (9, 3), (3, 3)  # aisle row 3 runs left: from b to a is against it
    ruled = plan(FLOOR.grid, Task.FETCH, b, a)
    relaxed = plan(FLOOR.grid, Task.FETCH, b, a, relaxed=True)
    assert relaxed.length == 6 < ruled.length
    loaded_ruled = plan(FLOOR.grid, Task.DELIVER, b, a)
    assert plan(FLOOR.grid, Task.DELIVER, b, a, relaxed=True) == loaded_ruled
