"""Seed 002's A* on the lanes (fleet/planning/lane_route.py): costs recomputed from the cells
(Equations 2-4), routes that stay on the lanes, the same route for the same query, and the
bidirectional warehouse never slower than the unidirectional one on any pair."""

from __future__ import annotations

import heapq
import itertools
import random

import pytest
from test_lane_rules import BOTTOM_T, CROSSROAD, T_TURNS

from fleet.analysis.lane_rules import lane_violations
from fleet.planning.lane_route import Heuristic, LaneRoutes
from fleet.world.lanes import lane_graph
from fleet.world.layout_file import load_layout

LANE_LAYOUTS = ("paper002", "paper002-uni", "paper002-406", "micro-cross", "micro-t",
                "micro-channel")


def place_cells(layout) -> list:
    return [p.cell for p in (*layout.slots, *layout.packing, *layout.piles)]


def pairs(layout, count: int, seed: int) -> list:
    rng = random.Random(seed)
    cells = place_cells(layout)
    return [tuple(rng.sample(cells, 2)) for _ in range(count)]


def recomputed_g(cells, speed: float = 1.0) -> float:
    """Equation (2) from the cells alone: d = 1 straight, 1.4 diagonal, each move to one of
    the eight neighbours."""
    g = 0.0
    for (x0, y0), (x1, y1) in itertools.pairwise(cells):
        dx, dy = abs(x1 - x0), abs(y1 - y0)
        assert max(dx, dy) == 1, f"{(x0, y0)} -> {(x1, y1)} is no move to a neighbour"
        g += (1.4 if dx and dy else 1.0) / speed
    return g


@pytest.fixture(scope="module")
def paper002():
    return load_layout("paper002")


@pytest.fixture(scope="module")
def uni():
    return load_layout("paper002-uni")


def test_g_is_the_sum_of_d_over_v_and_only_the_ends_are_off_the_lanes(paper002, uni):
    for layout in (paper002, uni):
        routes = LaneRoutes(lane_graph(layout), speed_mps=0.5)
        lanes = layout.lane_directions
        for start, goal in pairs(layout, 200, seed=2):
            route = routes.route(start, goal)
            assert route is not None, (layout.name, start, goal)
            assert route.cells[0] == start and route.cells[-1] == goal
            assert route.cost_s == pytest.approx(recomputed_g(route.cells, speed=0.5))
            inner = route.cells[1:-1]
            off = [c for c in inner if c not in lanes]
            # the unidirectional baseline crosses an access cell next to either end only
            assert all(c in layout.access_cells for c in off)
            assert all(c in (route.cells[1], route.cells[-2]) for c in off)


@pytest.mark.parametrize("name", LANE_LAYOUTS)
def test_every_route_keeps_the_lane_rules_as_the_independent_oracle_reads_them(name):
    """A-RHR-1 on planned routes: fleet/analysis/lane_rules.py, written apart from the
    planner, finds no violation on any of 500 seeded place-to-place routes."""
    layout = load_layout(name)
    routes = LaneRoutes(lane_graph(layout))
    for start, goal in pairs(layout, 500, seed=7):
        route = routes.route(start, goal)
        assert lane_violations(layout, route.cells) == [], (start, goal)


@pytest.mark.parametrize("layout,table", [("micro-cross", CROSSROAD), ("micro-t", T_TURNS),
                                          ("micro-cross", BOTTOM_T)],
                         ids=["crossroad", "left T", "bottom T"])
def test_every_turn_through_a_junction(layout, table):
    """A-RHR-3: between the ends of each hand-written turn (tests/test_lane_rules.py), the
    route is legal and no dearer than the cheapest written; straight on and right turns
    are those very cells, and lefts and U-turns cut across the junction by one diagonal
    (3.4 and 4.4 cell-times where the orthogonal way takes 4 and 5)."""
    layout = load_layout(layout)
    routes = LaneRoutes(lane_graph(layout))
    by_ends: dict[tuple, list] = {}
    for name, cells in table.items():
        by_ends.setdefault((cells[0], cells[-1]), []).append((recomputed_g(cells), name, cells))
    for (start, goal), written in by_ends.items():
        cost, name, cells = min(written)
        route = routes.route(start, goal)
        assert lane_violations(layout, route.cells) == [], name
        assert route.cost_s <= cost + 1e-9, name
        diagonals = sum(d == 1.4 for d in route.distances())
        if "straight" in name or "right" in name:
            assert list(route.cells) == cells, name
        elif "U-turn" in name:
            assert diagonals == 1 and route.cost_s == pytest.approx(4.4), name
        else:
            assert diagonals == 1, name


def optimal_cost(routes: LaneRoutes, start, goal) -> float:
    """Dijkstra over the same moves: the least g any route has."""
    best = {start: 0.0}
    heap = [(0.0, start)]
    ways_in = routes.graph.ways_in.get(goal, {})
    while heap:
        g, cell = heapq.heappop(heap)
        if cell == goal:
            return g
        if g > best[cell]:
            continue
        for edge in routes.moves_from(cell, start, ways_in):
            cost = g + edge.d * routes.seconds_per_cell
            if cost < best.get(edge.to, float("inf")):
                best[edge.to] = cost
                heapq.heappush(heap, (cost, edge.to))
    return float("inf")


def test_the_paper_heuristic_may_cost_a_little_and_octile_is_optimal(paper002):
    """h = Manhattan / v is not admissible with 1.4-cell diagonals (the paper's; the note
    A.4.3): routes may be slightly longer than the least, never much; the octile option
    finds the least every time."""
    manhattan = LaneRoutes(lane_graph(paper002))
    octile = LaneRoutes(lane_graph(paper002), heuristic=Heuristic.OCTILE)
    excess = []
    for start, goal in pairs(paper002, 150, seed=3):
        least = optimal_cost(manhattan, start, goal)
        assert octile.route(start, goal).cost_s == pytest.approx(least)
        cost = manhattan.route(start, goal).cost_s
        assert cost >= least - 1e-9
        excess.append(cost / least - 1)
    assert max(excess) < 0.05


def test_manhattan_search_expands_fewer_nodes_than_octile(paper002):
    """The heuristic is used: the greedier paper heuristic takes fewer nodes from the open
    list than the admissible one, over the same queries."""
    manhattan = LaneRoutes(lane_graph(paper002))
    octile = LaneRoutes(lane_graph(paper002), heuristic=Heuristic.OCTILE)
    queries = pairs(paper002, 100, seed=4)
    assert (sum(manhattan.route(*q).expansions for q in queries)
            < sum(octile.route(*q).expansions for q in queries))


def test_the_same_query_gives_the_same_route(paper002):
    first, second = LaneRoutes(lane_graph(paper002)), LaneRoutes(lane_graph(paper002))
    for start, goal in pairs(paper002, 50, seed=5):
        assert first.route(start, goal) == first.route(start, goal) == second.route(start, goal)


def test_leaving_a_slot_may_cross_to_the_far_lane_in_its_own_column_only(paper002):
    """s-3-2 lies above the bottom channel (row 1 runs west, row 0 east): a route east
    leaves it straight across onto the eastbound lane; a route west stays on row 1."""
    routes = LaneRoutes(lane_graph(paper002))
    east = routes.route((3, 2), (33, 2))
    assert east.cells[:3] == ((3, 2), (3, 1), (3, 0)) and east.cells[3] == (4, 0)
    west = routes.route((3, 2), (0, 1))  # packing station p2 at the left wall
    assert west.cells[:3] == ((3, 2), (3, 1), (2, 1))


def test_the_bidirectional_warehouse_is_never_slower_than_the_unidirectional(paper002, uni):
    """Every move of paper002-uni is a move of paper002, so the least route between any two
    places is never longer there; over a sample it is shorter on average by a lot."""
    bi = LaneRoutes(lane_graph(paper002), heuristic=Heuristic.OCTILE)
    one_way = LaneRoutes(lane_graph(uni), heuristic=Heuristic.OCTILE)
    ratios = []
    for start, goal in pairs(paper002, 200, seed=6):
        b, u = bi.route(start, goal).cost_s, one_way.route(start, goal).cost_s
        assert b <= u + 1e-9
        ratios.append(b / u)
    assert sum(ratios) / len(ratios) < 0.75  # 0.61 on this sample


def test_bad_queries_name_what_is_wrong(paper002):
    routes = LaneRoutes(lane_graph(paper002))
    with pytest.raises(ValueError, match=r"start \(0, 30\) is neither on a lane"):
        routes.route((0, 30), (3, 2))  # the wall in the top left corner
    with pytest.raises(ValueError, match="has no lanes"):
        lane_graph(load_layout("small"))
    with pytest.raises(ValueError, match="speed must be positive"):
        LaneRoutes(lane_graph(paper002), speed_mps=0.0)
