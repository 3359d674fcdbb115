"""Improved hybrid A* on synthetic grids: soundness (brute-force checker), determinism, and
clean failures."""

import random
import sys
from pathlib import Path

import pytest

from fleet.params import SearchParams, VehicleDims
from fleet.planning.gridmap import GridMap
from fleet.planning.maneuvers import body_cells_at_rest
from fleet.planning.planner import HybridAStar, PlannerCache
from fleet.planning.reservations import Interval, ReservationTable
from fleet.planning.trajectory import FailureReason, PlanFailure, Pose, Trajectory

sys.path.insert(0, str(Path(__file__).parent))
from brute_force import check_trajectory


def others_of(table, vehicle):
    return [(r.vehicle, r.cell, r.t0, r.t1) for r in table.reservations() if r.vehicle != vehicle]


def free_pose(rng, grid, taken):
    while True:
        pose = Pose((rng.randrange(grid.cols), rng.randrange(grid.rows)), rng.randrange(4))
        cells = body_cells_at_rest(pose.cell, pose.heading)
        if grid.all_free(cells) and not taken & set(cells):
            return pose


@pytest.mark.parametrize("seed", range(12))
def test_random_fleets_never_overlap(seed):
    rng = random.Random(seed)
    blocked = frozenset((rng.randrange(14), rng.randrange(10)) for _ in range(18))
    grid = GridMap(14, 10, blocked)
    planner = HybridAStar(grid)
    table = ReservationTable()
    starts, taken = {}, set()
    for v in range(1, 5):
        starts[v] = free_pose(rng, grid, taken)
        taken |= set(body_cells_at_rest(starts[v].cell, starts[v].heading))
        assert table.park(v, body_cells_at_rest(starts[v].cell, starts[v].heading), 0.0).ok
    found = 0
    for v in range(1, 5):
        goal = free_pose(rng, grid, taken)
        result = planner.plan(v, starts[v], rng.choice([0.0, 3.0, 7.5]), [goal], table)
        if isinstance(result, Trajectory):
            found += 1
            assert check_trajectory(result, others_of(table, v), grid) == []
            assert result.goal == goal
            assert table.commit(v, result.intervals, release_from=result.t_start).ok
            taken |= set(body_cells_at_rest(goal.cell, goal.heading))
        else:
            assert result.reason in FailureReason
    assert found >= 1


def test_waits_for_a_crossing_vehicle():
    grid = GridMap(12, 3, frozenset((c, r) for c in range(12) for r in (0, 2) if c != 6))
    planner = HybridAStar(grid)
    table = ReservationTable()
    from fleet.planning.reservations import Interval
    # Vehicle 2 drives north through the corridor's crossing column 6 over t in [0, 30).
    crossing = [((6, 0), 0, 30), ((6, 1), 0, 30), ((6, 2), 0, 30)]
    assert table.commit(2, [Interval(c, a, b) for c, a, b in crossing]).ok
    result = planner.plan(1, Pose((1, 1), 0), 0.0, [Pose((9, 1), 0)], table)
    assert isinstance(result, Trajectory)
    assert check_trajectory(result, others_of(table, 1), grid) == []
    entering = [s for s in result.steps if (6, 1) in s.cells]
    assert min(s.t0 for s in entering) >= 30
    assert any(s.manner.label == "stop" for s in result.steps)


def test_same_inputs_same_trajectory():
    grid = GridMap(14, 10, frozenset({(5, y) for y in range(2, 10)}))
    table = ReservationTable()
    table.park(2, [(8, 3), (8, 4)], 0.0)
    a = HybridAStar(grid).plan(1, Pose((1, 1), 1), 0.0, [Pose((11, 8), 3)], table)
    b = HybridAStar(grid).plan(1, Pose((1, 1), 1), 0.0, [Pose((11, 8), 3)], table)
    assert isinstance(a, Trajectory) and a == b


def test_start_blocked_by_another_vehicle():
    grid = GridMap(8, 8, frozenset())
    table = ReservationTable()
    table.park(2, [(3, 3)], 0.0)
    result = HybridAStar(grid).plan(1, Pose((3, 2), 1), 5.0, [Pose((6, 6), 0)], table)
    assert isinstance(result, PlanFailure) and result.reason is FailureReason.START_BLOCKED
    assert "vehicle 2" in result.detail


def test_goal_parked_on_forever_fails_at_once():
    grid = GridMap(8, 8, frozenset())
    table = ReservationTable()
    table.park(2, [(6, 6)], 0.0)
    result = HybridAStar(grid).plan(1, Pose((1, 1), 0), 0.0, [Pose((6, 5), 1)], table)
    assert isinstance(result, PlanFailure) and result.reason is FailureReason.GOAL_BLOCKED
    assert result.expansions == 0


def test_walled_in_goal_has_no_path():
    wall = {(c, 5) for c in range(10)}
    grid = GridMap(10, 10, frozenset(wall))
    result = HybridAStar(grid).plan(1, Pose((1, 1), 0), 0.0, [Pose((4, 7), 0)],
                                    ReservationTable())
    assert isinstance(result, PlanFailure) and result.reason is FailureReason.NO_PATH


def test_iteration_cap_is_reported():
    grid = GridMap(30, 30, frozenset({(15, y) for y in range(1, 30)}))
    planner = HybridAStar(grid, params=SearchParams(iter_search=20))
    result = planner.plan(1, Pose((1, 28), 0), 0.0, [Pose((28, 28), 0)], ReservationTable())
    assert isinstance(result, PlanFailure) and result.reason is FailureReason.ITERATION_CAP
    assert result.expansions == 20


def test_start_equals_goal_parks_in_place():
    grid = GridMap(6, 6, frozenset())
    result = HybridAStar(grid).plan(1, Pose((2, 2), 1), 4.0, [Pose((2, 2), 1)],
                                    ReservationTable())
    assert isinstance(result, Trajectory) and result.steps == ()
    assert {iv.cell for iv in result.intervals} == {(2, 2), (2, 3)}


def test_brute_force_checker_catches_a_missing_sweep_cell():
    grid = GridMap(10, 10, frozenset())
    table = ReservationTable()
    result = HybridAStar(grid).plan(1, Pose((2, 2), 1), 0.0, [Pose((6, 5), 0)], table)
    assert isinstance(result, Trajectory)
    assert check_trajectory(result, [], grid) == []
    turn = next(s for s in result.steps if s.manner.kind.value == "turn")
    sliver = sorted(turn.cells - {c for s in result.steps if s is not turn for c in s.cells})
    assert sliver, "a turn sweeps a cell no other step does (the notch cell)"
    broken = type(result)(result.vehicle, result.start, result.goal, result.t_start,
                          result.steps, tuple(iv for iv in result.intervals
                                              if iv.cell != sliver[0]), result.expansions)
    problems = check_trajectory(broken, [], grid)
    assert any("outside its reservation" in p for p in problems)


def corridor():
    """A 12 x 3 map whose middle row is the only way through."""
    return GridMap(12, 3, frozenset((c, r) for c in range(12) for r in (0, 2)))


def test_vehicle_parked_across_the_only_way_fails_fast():
    table = ReservationTable()
    table.park(2, [(6, 1)], 0.0)
    result = HybridAStar(corridor()).plan(1, Pose((1, 1), 0), 0.0, [Pose((9, 1), 0)], table)
    assert isinstance(result, PlanFailure) and result.reason is FailureReason.NO_PATH
    assert result.expansions == SearchParams().relaxation_check_at
    assert "close every way to the goal in time" in result.detail


def test_a_way_open_only_after_another_closes_for_good_fails_fast():
    """(6, 1) is held until t = 50 s, and (8, 1), further on, is taken for good from t = 30
    s: each alone could be waited out or outrun, together they close the corridor. Seeing
    that needs the times of both (a safe-interval relaxation); with the hold ending at t = 10
    s the way is open and the search finds it."""
    for hold_until, found in ((50.0, False), (10.0, True)):
        table = ReservationTable()
        table.commit(2, [Interval((6, 1), 0.0, hold_until)])
        table.park(3, [(8, 1)], 30.0)
        result = HybridAStar(corridor()).plan(1, Pose((1, 1), 0), 0.0, [Pose((10, 1), 0)],
                                              table)
        assert isinstance(result, Trajectory) is found
        if not found:
            assert result.reason is FailureReason.NO_PATH
            assert result.expansions == SearchParams().relaxation_check_at


@pytest.mark.parametrize("seed", range(4))
def test_the_relaxation_never_refuses_a_query_the_search_solves(seed):
    """Seeded random maps, fleets and start times: wherever the search (without the check)
    finds a trajectory, the safe-interval relaxation says the goal is reachable; and it
    refuses some of the others (it is not a check that never says no)."""
    rng = random.Random(seed)
    solved = refused = 0
    for _ in range(60):
        blocked = frozenset((rng.randrange(14), rng.randrange(10)) for _ in range(14))
        grid = GridMap(14, 10, blocked)
        planner = HybridAStar(grid, params=SearchParams(relaxation_check_at=10**9,
                                                        iter_search=3000))
        table, taken = ReservationTable(), set()
        poses = {}
        for v in (1, 2, 3, 4):
            poses[v] = free_pose(rng, grid, taken)
            taken |= set(body_cells_at_rest(poses[v].cell, poses[v].heading))
            table.park(v, body_cells_at_rest(poses[v].cell, poses[v].heading), 0.0)
        for v in (2, 3, 4):  # the others drive first, each to a random free pose
            goal = free_pose(rng, grid, taken)
            other = planner.plan(v, poses[v], rng.choice([0.0, 2.0, 5.0]), [goal], table)
            if isinstance(other, Trajectory):
                table.commit(v, other.intervals, release_from=other.t_start)
        goal = free_pose(rng, grid, set())
        t0 = rng.choice([0.0, 3.0, 8.0])
        result = planner.plan(1, poses[1], t0, [goal], table)
        reachable = planner._intervals_reachable(1, poses[1], t0, {(goal.cell, goal.heading)},
                                                 table)
        if isinstance(result, Trajectory):
            solved += 1
            assert reachable, (seed, poses, goal, t0)
        refused += not reachable
    assert solved > 20 and refused > 0


def test_deadline_check_lets_through_a_vehicle_that_parks_later():
    table = ReservationTable()
    table.park(2, [(6, 1)], 40.0)  # parks across the corridor only from t = 40 s
    planner = HybridAStar(corridor(), params=SearchParams(relaxation_check_at=1))
    result = planner.plan(1, Pose((1, 1), 0), 0.0, [Pose((9, 1), 0)], table)
    assert isinstance(result, Trajectory)
    assert check_trajectory(result, others_of(table, 1), corridor()) == []
    late = planner.plan(1, Pose((1, 1), 0), 39.0, [Pose((9, 1), 0)], table)
    assert isinstance(late, PlanFailure) and late.reason is FailureReason.NO_PATH
    assert late.expansions == 1


def components_by_search(planner: HybridAStar) -> set[frozenset]:
    """Reference: the pose graph's components found by plain graph search from every free
    pose, following statically free moves (the planner's own sweep test is brute-forced in
    test_maneuvers)."""
    grid = planner.grid
    free = {((x, y), h) for x in range(grid.cols) for y in range(grid.rows) for h in range(4)
            if grid.all_free((x + a, y + b) for a, b in planner.moves[h][0].start_cells)}
    seen, parts = set(), set()
    for seed in sorted(free):
        if seed in seen:
            continue
        part, todo = {seed}, [seed]
        while todo:
            (x, y), h = todo.pop()
            for move in planner.moves[h][1:]:
                if not grid.all_free((x + a, y + b) for a, b in move.swept):
                    continue
                nxt = ((x + move.end_delta[0], y + move.end_delta[1]), move.end_heading)
                if nxt not in part:
                    part.add(nxt)
                    todo.append(nxt)
        seen |= part
        parts.add(frozenset(part))
    return parts


@pytest.mark.parametrize("seed", range(6))
def test_components_match_a_plain_graph_search(seed):
    rng = random.Random(seed)
    blocked = frozenset((rng.randrange(12), rng.randrange(9)) for _ in range(rng.randrange(30)))
    planner = HybridAStar(GridMap(12, 9, blocked))
    labels: dict[int, set] = {}
    for x in range(12):
        for y in range(9):
            for h in range(4):
                label = planner.component(Pose((x, y), h))
                if label is not None:
                    labels.setdefault(label, set()).add(((x, y), h))
    assert {frozenset(p) for p in labels.values()} == components_by_search(planner)


@pytest.mark.parametrize("seed", range(4))
def test_the_moves_that_fit_are_those_whose_cells_are_free(seed):
    """The moves from each pose, on and just off the map, are those whose end and swept
    cells the grid says are free (pose_graph lays them out once per map size)."""
    rng = random.Random(seed)
    blocked = frozenset((rng.randrange(12), rng.randrange(9)) for _ in range(rng.randrange(30)))
    planner = HybridAStar(GridMap(12, 9, blocked))
    for x in range(-2, 14):
        for y in range(-2, 11):
            for h in range(4):
                fits = [move.manner for move in planner.moves[h] if planner.grid.all_free(
                    (x + a, y + b) for a, b in (*move.end_cells, *move.middle_cells))]
                assert [e.manner for e in planner.edges(x, y, h)] == fits, (x, y, h)


def test_planner_cache_keeps_the_most_recently_used():
    built = []

    def grid_for(filled):
        built.append(filled)
        return GridMap(6, 6, filled)

    cache = PlannerCache(grid_for, VehicleDims(), size=2)
    a, b, c = frozenset({(0, 0)}), frozenset({(1, 1)}), frozenset({(2, 2)})
    first = cache.get(a)
    cache.get(b)
    assert cache.get(a) is first  # a is now the most recent
    cache.get(c)  # evicts b
    assert cache.get(a) is first
    cache.get(b)
    assert built == [a, b, c, b]
