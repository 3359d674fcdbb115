"""Algorithm 1 with bounded enumeration: the dispatcher scores targets best bound first and
skips those that cannot win (fleet/dispatching/algorithm1.py, `_scored`), and the preliminary
A* fails at once for targets taken for good before it could reach them. Both must choose
exactly what scoring every target chooses, on a floor with many clusters and stations."""

from __future__ import annotations

import random

import pytest

from fleet.dispatching.algorithm1 import Algorithm1
from fleet.dispatching.decision import Strategy, Target, TaskKind, VehicleView
from fleet.dispatching.prelim import preliminary_astar, travel_floor
from fleet.planning.reservations import Interval, ReservationTable
from fleet.planning.trajectory import Pose
from fleet.world.generator import Shape, generate_layout

FLOOR = generate_layout(Shape(aisles=3, depth=8, lane_depth=2, vehicles=6))  # 12 clusters
STRATEGIES = (Strategy.GREEDY, Strategy.TRAFFIC, Strategy.BALANCE, Strategy.COMPREHENSIVE,
              Strategy.ANN)
ME, PARKER = 1, 9


class FixedMlp:
    def __init__(self, out: list[float]) -> None:
        self.out = out

    def __call__(self, u: list[float]) -> list[float]:
        return list(self.out)


def random_scene(rng: random.Random):
    """A random fill state, its targets (clusters' next stacks, and stations), other
    forklifts' reservations on the targets' cells and elsewhere, some parked for good."""
    filled: set = set()
    for cluster in FLOOR.clusters:
        stacks = FLOOR.cluster_stacks(cluster.name)
        filled |= {s.cell for s in stacks[:rng.randrange(len(stacks))]}
    clusters = []
    for cluster in FLOOR.clusters:
        left = [s for s in FLOOR.cluster_stacks(cluster.name) if s.cell not in filled]
        goals = FLOOR.unload_poses(left[0].cell, filled) if left else []
        if goals:
            clusters.append(Target(cluster.name, tuple(goals), left[0].cell, left[0].index,
                                   remaining=len(left), far=rng.random() < 0.3))
    stations = [Target(st.name, (st.dock,)) for st in FLOOR.stations]
    grid = FLOOR.grid_map(filled)
    free = [(x, y) for x in range(grid.cols) for y in range(grid.rows) if grid.free((x, y))]
    goal_cells = [g.cell for t in clusters + stations for g in t.goals]
    store = ReservationTable()
    t_i = 0.25 * rng.randrange(0, 160)
    taken: set = set()
    for _ in range(rng.randrange(0, 30)):
        cell = rng.choice(goal_cells if rng.random() < 0.6 else free)
        if cell in taken:
            continue
        taken.add(cell)
        if rng.random() < 0.4:  # parked for good, from before or after the decision
            store.park(PARKER + rng.randrange(3), [cell], t_i + 0.25 * rng.randrange(-40, 80))
        else:
            t0 = t_i + 0.25 * rng.randrange(0, 120)
            assert store.commit(7, [Interval(cell, t0, t0 + 0.25 * rng.randrange(1, 30))]).ok
    starts = [c for c in free if c not in taken]
    return filled, clusters, stations, store, t_i, starts


def algorithm(store, filled, strategy, every: bool, mlp=None) -> Algorithm1:
    grid = FLOOR.grid_map(filled)
    return Algorithm1(grid_for=lambda: grid, store=store, strategy=strategy,
                      cluster_names=tuple(c.name for c in FLOOR.clusters), mlp=mlp,
                      every_target=every)


@pytest.mark.parametrize("seed", range(4))
def test_bounded_scoring_decides_as_scoring_every_target(seed):
    rng = random.Random(300 + seed)
    scored = {True: 0, False: 0}
    for _ in range(40):
        filled, clusters, stations, store, t_i, starts = random_scene(rng)
        kind = rng.choice((TaskKind.DELIVER, TaskKind.RETURN))
        targets = clusters if kind is TaskKind.DELIVER else stations
        strategy = rng.choice(STRATEGIES)
        mlp = FixedMlp([rng.uniform(-250.0, 120.0) for _ in FLOOR.clusters])
        views = [VehicleView(ME + k, Pose(rng.choice(starts), rng.randrange(4)), t_i, kind,
                             None, None)
                 for k in range(rng.randrange(1, 4))]
        outcomes = {}
        for every in (True, False):
            alg = algorithm(store, filled, strategy, every, mlp)
            outcomes[every] = alg.decide(views, [], lambda _, t=targets: t,
                                         {t.name: t.remaining for t in clusters})
            d = outcomes[every].decision
            scored[every] += len(d.scores) if d is not None else 0
        exhaustive, bounded = outcomes[True], outcomes[False]
        assert bounded.failures == exhaustive.failures  # refusals name every target alike
        assert bounded.postponements == exhaustive.postponements
        if exhaustive.decision is None:
            assert bounded.decision is None
            continue
        e, b = exhaustive.decision, bounded.decision
        assert (b.vehicle, b.t_i, b.kind, b.target, b.postponed) == \
            (e.vehicle, e.t_i, e.kind, e.target, e.postponed)
        chosen = {s.target.name: s for s in e.scores}
        for s in b.scores:  # what was scored, scored alike
            assert s == chosen[s.target.name]
    assert scored[False] < scored[True] / 2  # and most targets were never scored


def test_a_target_taken_for_good_before_it_can_be_reached_fails_without_a_search():
    store = ReservationTable()
    start, dock = (2, 5), (9, 5)
    reach = 10.0 + travel_floor(start, [dock])  # 7 steps: 18.75 s at the soonest
    store.park(PARKER, [dock], reach - 0.25)
    grid = FLOOR.grid_map()
    result = preliminary_astar(grid, store, ME, start, 10.0, [dock])
    assert (result.found, result.expansions) == (False, 0)
    store = ReservationTable()
    store.park(PARKER, [dock], reach)  # free until the soonest arrival: a search is made
    result = preliminary_astar(grid, store, ME, start, 10.0, [dock])
    assert result.expansions > 0
