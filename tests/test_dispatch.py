"""Dispatcher core: rank, Algorithm 1's altered and backup states with constructed blockages,
and what each strategy maximises."""

from fleet.dispatching.algorithm1 import Algorithm1, mlp_inputs, rank
from fleet.dispatching.decision import (
    STACK_STRATEGIES,
    FailedChoice,
    Strategy,
    Target,
    TaskKind,
    VehicleView,
)
from fleet.dispatching.policy import PolicySetup, dispatch_policy
from fleet.planning.gridmap import GridMap
from fleet.planning.reservations import ReservationTable
from fleet.planning.trajectory import Pose
from fleet.world.layout_file import load_layout

# A 12 x 5 floor split by a wall at column 6 except for a one-cell gap at row 2.
WALL = frozenset((6, r) for r in range(5) if r != 2)
GRID = GridMap(12, 5, WALL)


def view(vehicle, cell, t_free=0.0, task=TaskKind.DELIVER):
    return VehicleView(vehicle, Pose(cell, 0), t_free, task, None, None)


def dispatcher(store, strategy=Strategy.COMPREHENSIVE, names=("east",)):
    return Algorithm1(grid_for=lambda: GRID, store=store, strategy=strategy,
                      cluster_names=names)


def east_target(view):
    return [Target("east", (Pose((10, 2), 0),), (11, 2), 1, remaining=5)]


def test_rank_orders_by_free_time_and_puts_failed_vehicles_last():
    views = [view(1, (0, 0), 30.0), view(2, (0, 1), 10.0), view(3, (0, 2), 20.0)]
    assert rank(views) == [2, 3, 1]
    assert rank(views, failed=[2]) == [3, 1, 2]
    assert rank(views, failed=[3, 2]) == [1, 3, 2]


def test_rank_leaves_out_vehicles_free_beyond_the_lookahead():
    """Ours, not the seed's: a forklift free more than `lookahead` after the earliest is not
    decided for yet, failed or not; one just at the bound still is."""
    views = [view(1, (0, 0), 100.0), view(2, (0, 1), 140.0), view(3, (0, 2), 140.25)]
    assert rank(views, lookahead=40.0) == [1, 2]
    assert rank(views, failed=[1, 3], lookahead=40.0) == [2, 1]


def test_a_vehicle_far_ahead_is_not_chosen_while_the_earliest_cannot_be_dispatched():
    """Vehicle 1 is walled in; vehicle 2, free 60 s later, could go east. Beyond the lookahead
    (40 s) vehicle 2 is not chosen: the backup state postpones vehicle 1 instead (its ten
    choices: at 0 s, then nine times Δt_i later), and the clock moves on towards vehicle 2's
    instant. Within the lookahead, vehicle 2 is chosen."""
    store = ReservationTable()
    store.park(3, [(6, 2)], 0.0)
    store.park(4, [(0, 1), (1, 1), (2, 1), (0, 3), (1, 3), (2, 3), (3, 2)], 0.0)
    views = [view(1, (1, 2), t_free=0.0), view(2, (8, 2), t_free=60.0)]
    outcome = dispatcher(store).decide(views, [], east_target, {"east": 5})
    assert outcome.decision is None and outcome.postponements == {1: 90.0}
    assert {f.vehicle for f in outcome.failures} == {1}
    views = [view(1, (1, 2), t_free=30.0), view(2, (8, 2), t_free=60.0)]
    outcome = dispatcher(store).decide(views, [], east_target, {"east": 5})
    assert outcome.decision is not None and outcome.decision.vehicle == 2


def test_altered_state_when_the_first_vehicle_is_blocked():
    store = ReservationTable()
    store.park(3, [(6, 2)], 0.0)  # a broken-down forklift in the gap, for good
    views = [view(1, (1, 2), t_free=0.0), view(2, (8, 2), t_free=5.0)]
    outcome = dispatcher(store).decide(views, [], east_target, {"east": 5})
    assert outcome.decision is not None
    assert outcome.decision.vehicle == 2 and outcome.decision.t_i == 5.0
    # vehicle 1 was selected first and could not be dispatched: the way east is shut
    assert outcome.failures == [FailedChoice(1, 0.0, "no preliminary path to east")]
    assert not outcome.decision.postponed


def test_backup_state_postpones_by_dt_when_every_vehicle_is_blocked():
    store = ReservationTable()
    store.park(3, [(6, 2)], 0.0)
    views = [view(1, (1, 2), t_free=0.0), view(2, (2, 3), t_free=5.0)]
    outcome = dispatcher(store).decide(views, [], east_target, {"east": 5})
    assert outcome.decision is None
    assert len(outcome.failures) == 10  # iter_dispatch, each choice with its instant
    assert [(f.vehicle, f.t_i) for f in outcome.failures[:4]] == \
        [(1, 0.0), (2, 5.0), (1, 10.0), (2, 15.0)]
    # two fresh selections, then eight postponements of 10 s, the longest-waiting first
    assert outcome.postponements == {1: 40.0, 2: 45.0}


def test_postponement_lets_a_temporary_blockage_clear():
    store = ReservationTable()
    from fleet.planning.reservations import Interval

    # The gap is held until t = 35 s: waiting inside the preliminary search cannot bridge that
    # within iter_pre, but postponing the decision can.
    store.commit(3, [Interval((6, 2), 0.0, 35.0)])
    views = [view(1, (1, 2), t_free=0.0)]
    outcome = dispatcher(store).decide(views, [1], east_target, {"east": 5})
    assert outcome.decision is not None and outcome.decision.postponed
    assert outcome.decision.t_i >= 10.0
    assert outcome.failures


def test_strategies_maximise_their_own_term():
    store = ReservationTable()
    near = Target("near", (Pose((3, 2), 0),), (4, 2), 1, remaining=2)
    far = Target("far", (Pose((10, 2), 0),), (11, 2), 1, remaining=9)
    v = view(1, (1, 2))
    picks = {}
    for strategy in (Strategy.GREEDY, Strategy.BALANCE, Strategy.TRAFFIC,
                     Strategy.COMPREHENSIVE):
        d = dispatcher(store, strategy, ("near", "far"))
        picks[strategy] = d.decide([v], [], lambda _: [near, far], {}).decision.target.name
    assert picks[Strategy.GREEDY] == "near"  # shortest preliminary travel time
    assert picks[Strategy.TRAFFIC] == "near"
    assert picks[Strategy.BALANCE] == "far"  # most stacks left
    assert picks[Strategy.COMPREHENSIVE] == "far"  # C1 * G_d outweighs the travel time


def test_mlp_inputs_follow_equation_7():
    views = [VehicleView(1, Pose((0, 0), 0), 0, TaskKind.RETURN, "a", TaskKind.DELIVER),
             VehicleView(2, Pose((0, 1), 0), 0, TaskKind.DELIVER, "b", TaskKind.RETURN),
             VehicleView(3, Pose((0, 2), 0), 0, TaskKind.DELIVER, None, None)]
    assert mlp_inputs(("a", "b", "c"), views, {"a": 4, "b": 7, "c": 9}) == [4.0, -7.0, 0.0]


def test_every_strategy_names_seed_000s_algorithm_1_with_itself():
    layout = load_layout("small")
    for strategy in STACK_STRATEGIES:
        policy = dispatch_policy(PolicySetup(strategy, layout, ReservationTable(),
                                             lambda: GRID))
        assert isinstance(policy, Algorithm1)
        assert (policy.strategy, policy.cluster_names) == (strategy, ("a", "b"))
