"""The paper's typical subtasks on `paper`: from a station to a stack of each cluster and back,
with the other three forklifts' trajectories in the table, each checked by the brute-force
checker (which shares no code with the planner's collision detection)."""

import sys
from pathlib import Path

import pytest

from fleet.planning.maneuvers import body_cells_at_rest
from fleet.planning.planner import HybridAStar
from fleet.planning.reservations import ReservationTable
from fleet.planning.trajectory import FailureReason, PlanFailure, Trajectory
from fleet.world.layout_file import load_layout

sys.path.insert(0, str(Path(__file__).parent))
from brute_force import check_trajectory

PAPER = load_layout("paper")
CLUSTERS = [c.name for c in PAPER.clusters]


def half_filled() -> set:
    """Each cluster's first half filled, in fill order."""
    filled = set()
    for name in CLUSTERS:
        stacks = PAPER.cluster_stacks(name)
        filled |= {s.cell for s in stacks[: len(stacks) // 2]}
    return filled


def next_stack(name: str):
    stacks = PAPER.cluster_stacks(name)
    return stacks[len(stacks) // 2]


def others_of(table, vehicle):
    return [(r.vehicle, r.cell, r.t0, r.t1) for r in table.reservations() if r.vehicle != vehicle]


@pytest.mark.parametrize("station", range(4))
@pytest.mark.parametrize("cluster", CLUSTERS)
def test_station_to_cluster_and_back(station, cluster):
    filled = half_filled()
    planner = HybridAStar(PAPER.grid_map(filled), PAPER.vehicle.dims)
    table = ReservationTable()
    docks = [s.dock for s in PAPER.stations]
    for k, dock in enumerate(docks, start=1):
        assert table.park(k, body_cells_at_rest(dock.cell, dock.heading), 0.0).ok
    me = station + 1
    # The other three leave their stations for stacks in other clusters first.
    others = [k for k in range(1, 5) if k != me]
    for n, k in enumerate(others):
        target = next_stack(CLUSTERS[(CLUSTERS.index(cluster) + 1 + n) % len(CLUSTERS)])
        goals = PAPER.unload_poses(target.cell, filled)
        result = planner.plan(k, docks[k - 1], 0.0, goals, table)
        assert isinstance(result, Trajectory), result
        assert table.commit(k, result.intervals, release_from=0.0).ok
        filled = filled | {target.cell}  # its goods arrive there
    planner = HybridAStar(PAPER.grid_map(filled), PAPER.vehicle.dims)
    stack = next_stack(cluster)
    out = planner.plan(me, docks[station], 0.0, PAPER.unload_poses(stack.cell, filled), table)
    assert isinstance(out, Trajectory), out
    assert check_trajectory(out, others_of(table, me), PAPER.grid_map(filled)) == []
    assert table.commit(me, out.intervals, release_from=0.0).ok
    t_back = out.t_end + 5.0  # t_unload
    back = planner.plan(me, out.goal, t_back, [docks[station]], table)
    assert isinstance(back, Trajectory), back
    assert back.goal == docks[station] and back.t_start == t_back
    assert check_trajectory(back, others_of(table, me), PAPER.grid_map(filled)) == []


def test_goal_on_a_filled_stack_is_blocked():
    filled = {s.cell for s in PAPER.stacks}
    planner = HybridAStar(PAPER.grid_map(filled), PAPER.vehicle.dims)
    deep = PAPER.cluster_stacks("s3")[0]
    goals = PAPER.unload_poses(deep.cell)  # poses of the empty warehouse, now on full stacks
    result = planner.plan(1, PAPER.stations[0].dock, 0.0, goals, ReservationTable())
    assert isinstance(result, PlanFailure) and result.reason is FailureReason.GOAL_BLOCKED
    assert result.expansions == 0


def test_a_walled_in_pocket_has_no_path():
    # s3's first lane is full except a pocket of three cells sealed by its mouth stack.
    pocket = {(4, 10), (4, 9), (4, 8)}
    filled = {s.cell for s in PAPER.stacks} - pocket
    planner = HybridAStar(PAPER.grid_map(filled), PAPER.vehicle.dims)
    goals = PAPER.unload_poses((4, 10), filled)
    assert [str(g) for g in goals] == ["4,9,S"]
    result = planner.plan(1, PAPER.stations[0].dock, 0.0, goals, ReservationTable())
    assert isinstance(result, PlanFailure) and result.reason is FailureReason.NO_PATH
    assert "no goal pose can be reached" in result.detail
