"""Seed 004's floor, traffic rules, grid values and improved A* (seed pack note B.2-B.4):
`paper004` is the note's reconstruction cell for cell, its rule graphs connect what the work
needs, the expansion filters and the direction code are the seed's Equations (3) and (4), the
heap and the list open sets return the same paths, and the turning cost cuts turns without
lengthening routes."""

from __future__ import annotations

import itertools
import random
from collections import Counter
from pathlib import Path

import pytest

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
    with pytest.raises(UserError, match="8 stations 12 columns apart"):
        build(Floor004Shape(blocks_across=4))
    small = build(Floor004Shape(blocks_across=4, double_rows=6, stations=2, piles_per_side=3))
    assert len(small.slots) == 4 * 6 * 10 and len(small.piles) == 6


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


def rule_graph(task: Task, cells: set) -> dict:
    return {c: [(c[0] + STEP[d][0], c[1] + STEP[d][1]) for d in allowed(FLOOR.grid, task, c)
                if (c[0] + STEP[d][0], c[1] + STEP[d][1]) in cells] for c in cells}


def reached(edges: dict, start) -> set:
    seen, todo = {start}, [start]
    while todo:
        for n in edges[todo.pop()]:
            if n not in seen:
                seen.add(n)
                todo.append(n)
    return seen


def strongly_connected(edges: dict) -> bool:
    back: dict = {c: [] for c in edges}
    for c, ns in edges.items():
        for n in ns:
            back[n].append(c)
    first = next(iter(edges))
    return reached(edges, first) == set(edges) == reached(back, first)


def test_empty_agvs_reach_every_floor_cell_and_slot_from_every_other_under_the_rules():
    cells = {c for c, k in FLOOR.kinds.items() if k in (Kind.FLOOR, Kind.SLOT)} - \
        set(FLOOR.piles)
    assert strongly_connected(rule_graph(Task.FETCH, cells))


def test_loaded_agvs_connect_every_slot_with_every_station_under_the_rules():
    """On the floor (slots are not driven loaded) the loaded rule graph is one strongly
    connected piece, holding every entrance and exit point; every slot is left into it and
    entered from it along the rules."""
    floor = {c for c, k in FLOOR.kinds.items() if k is Kind.FLOOR} - set(FLOOR.piles)
    edges = rule_graph(Task.DELIVER, floor)
    assert strongly_connected(edges)
    assert {s.entrance for s in FLOOR.stations} | {s.exit_point for s in FLOOR.stations} <= floor
    for slot in FLOOR.slots:
        x, y = slot.xy
        around = [((x + dx, y + dy), d) for d, (dx, dy) in STEP.items()]
        assert any(n in floor for n, _ in around), slot
        assert any(n in floor and opposite(d) in allowed(FLOOR.grid, Task.RETURN, n)
                   for n, d in around), slot


def opposite(d: Direction) -> Direction:
    return {Direction.UP: Direction.DOWN, Direction.DOWN: Direction.UP,
            Direction.LEFT: Direction.RIGHT, Direction.RIGHT: Direction.LEFT}[d]


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
    start, goal = (20, 3), (30, 3)  # along a horizontal aisle
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


def test_every_move_planned_keeps_its_tasks_rules():
    rng = random.Random(4)
    floor = [c for c, k in FLOOR.kinds.items() if k is Kind.FLOOR and c not in FLOOR.piles]
    for _ in range(40):
        slot = rng.choice(FLOOR.slots).xy
        for task, a, b, home in ((Task.FETCH, rng.choice(floor), slot, None),
                                 (Task.DELIVER, slot, rng.choice(FLOOR.stations).entrance, slot),
                                 (Task.RETURN, rng.choice(FLOOR.stations).exit_point, slot,
                                  slot)):
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
    floor = [c for c, k in FLOOR.kinds.items() if k is Kind.FLOOR and c not in FLOOR.piles]
    for _ in range(60):
        slot = rng.choice(FLOOR.slots).xy
        for task, a, b, home in ((Task.FETCH, rng.choice(floor), slot, None),
                                 (Task.DELIVER, slot, rng.choice(FLOOR.stations).entrance, slot),
                                 (Task.CHARGE, slot, rng.choice(FLOOR.piles), None)):
            heading = rng.choice(list(Direction))
            costs = Costs(heat=2.0, t_value={rng.choice(floor): 1.0 for _ in range(50)})
            by_heap = plan(FLOOR.grid, task, a, b, heading, costs, heap=True, home=home)
            by_list = plan(FLOOR.grid, task, a, b, heading, costs, heap=False, home=home)
            assert by_heap == by_list, (task, a, b)


def test_the_turning_cost_cuts_turns_and_keeps_route_lengths():
    """Over random fetches on an empty floor (the note's B-TURN-1 setting) the turning cost
    never lengthens a route and removes many of its turns; `fleet bench` will report the
    share."""
    rng = random.Random(1)
    floor = [c for c, k in FLOOR.kinds.items() if k is Kind.FLOOR and c not in FLOOR.piles]
    turns = {0.0: 0, 1.0: 0}
    for _ in range(120):
        a, b = rng.choice(floor), rng.choice(FLOOR.slots).xy
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
