"""The in-process reference engine: whole missions, checked apart from the engine."""

import sys
from pathlib import Path

import pytest

from fleet.dispatching.decision import STACK_STRATEGIES, Strategy, TaskKind
from fleet.errors import UserError
from fleet.mission.engine import Engine, EngineOptions, run_mission
from fleet.mission.lower_bound import lower_bound
from fleet.mission.record import digest
from fleet.mission.spec import STACK_KINDS, Mission, MissionKind
from fleet.world.layout_file import load_layout

sys.path.insert(0, str(Path(__file__).parent))
from mission_check import mission_problems

SMALL = load_layout("small")


def options_for(strategy: Strategy) -> EngineOptions:
    if strategy is Strategy.ANN:
        from fleet.dispatching.scorer import load_scorer

        return EngineOptions(mlp=load_scorer(SMALL))
    return EngineOptions()


@pytest.mark.parametrize("kind", STACK_KINDS)
@pytest.mark.parametrize("strategy", STACK_STRATEGIES)
def test_every_strategy_completes_safely_on_small(kind, strategy):
    rec = run_mission(Mission(layout="small", kind=kind, strategy=strategy),
                      options_for(strategy), SMALL)
    assert mission_problems(rec, SMALL) == []
    assert len(rec.stacks_done) == 24
    assert rec.end_time >= lower_bound(SMALL, kind, 2)


def test_same_mission_same_record_bit_for_bit():
    a = run_mission(Mission(layout="small", strategy=Strategy.ANN), options_for(Strategy.ANN))
    b = run_mission(Mission(layout="small", strategy=Strategy.ANN), options_for(Strategy.ANN))
    assert digest(a) == digest(b)
    c = run_mission(Mission(layout="small", strategy=Strategy.GREEDY))
    assert digest(c) != digest(a)


def test_fill_order_is_kept_within_each_cluster():
    rec = run_mission(Mission(layout="small", strategy=Strategy.BALANCE))
    for name in ("a", "b"):
        assert [i for c, i, _ in rec.stacks_done if c == name] == list(range(1, 13))
    empty = run_mission(Mission(layout="small", kind=MissionKind.EMPTY,
                                strategy=Strategy.BALANCE))
    assert [i for c, i, _ in empty.stacks_done if c == "a"] == list(range(12, 0, -1))


def test_balance_alternates_clusters_and_greedy_does_not_have_to():
    rec = run_mission(Mission(layout="small", strategy=Strategy.BALANCE))
    done = [c for c, _, _ in rec.stacks_done]
    # G_d decides: the cluster with more stacks left is chosen, so they never drift apart by
    # more than the fleet size.
    for k in range(1, len(done) + 1):
        assert abs(done[:k].count("a") - done[:k].count("b")) <= 2


def test_fleet_size_and_start_errors():
    with pytest.raises(UserError, match="3 vehicles requested but layout small has 2"):
        Engine(Mission(layout="small", vehicles=3))
    rec = run_mission(Mission(layout="small", vehicles=1, strategy=Strategy.GREEDY))
    assert {s.vehicle for s in rec.subtasks} == {1}
    assert len(rec.stacks_done) == 24


def test_the_mission_checker_catches_overlaps_and_repeats():
    import dataclasses

    rec = run_mission(Mission(layout="small", strategy=Strategy.GREEDY))
    copy = dataclasses.replace(rec.subtasks[5], vehicle=1 if rec.subtasks[5].vehicle == 2 else 2)
    rec.subtasks.insert(6, copy)
    rec.stacks_done.append(rec.stacks_done[0])
    problems = mission_problems(rec, SMALL)
    assert any("both hold" in p for p in problems)
    assert any("done 2 times" in p for p in problems)


def test_a_fleet_parked_around_a_crossing_breaks_its_cycle_and_gets_home():
    """Seen in a real-time fault run: four forklifts parked after their last deliveries
    around the passages' crossing, each sent back to a station its neighbour's parking
    closes. The wait-for graph finds the cycle within a few decisions and sends one forklift
    aside (before, only the last-resort rule got them out, after 300 failures in a row)."""
    from fleet.mission.pickup import Recovered
    from fleet.planning.trajectory import Pose

    layout = load_layout("paper")
    mission = Mission("paper", MissionKind.FILL, Strategy.ANN, 4, 0)
    poses = {1: "8,7,E", 2: "7,5,N", 3: "11,6,S", 4: "8,8,E"}
    everything_done = Recovered(
        tuple((s.cluster, s.index, 100.0) for s in layout.stacks), (),
        {v: Pose.parse(p) for v, p in poses.items()}, dict.fromkeys(poses, 200.0),
        dict.fromkeys(poses, False), {}, 200.0)
    record = Engine(mission, EngineOptions(unstick_after=10_000), layout,
                    recovered=everything_done).run()
    assert [(d.kind, d.moved) for d in record.deadlocks] == [("cycle", 4)]
    assert record.deadlocks[0].chain[0] == record.deadlocks[0].chain[-1]
    homes = {s.vehicle: s.target for s in record.subtasks if s.kind is not TaskKind.ASIDE}
    assert sorted(homes) == [1, 2, 3, 4]
    assert set(homes.values()) <= {st.name for st in layout.stations}
    assert record.decision_failures < 20
    assert mission_problems(record, layout) == []
