"""The in-process reference engine: whole missions, checked apart from the engine."""

import sys
from pathlib import Path

import pytest

from fleet.engine import Engine, EngineOptions, lower_bound, run_mission
from fleet.layout import load_layout
from fleet.mission import Mission, MissionKind, Strategy
from fleet.record_io import digest

sys.path.insert(0, str(Path(__file__).parent))
from mission_check import mission_problems

SMALL = load_layout("small")


def options_for(strategy: Strategy) -> EngineOptions:
    if strategy is Strategy.ANN:
        from fleet.ann import load_scorer

        return EngineOptions(mlp=load_scorer(SMALL))
    return EngineOptions()


@pytest.mark.parametrize("kind", list(MissionKind))
@pytest.mark.parametrize("strategy", list(Strategy))
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
    with pytest.raises(ValueError, match="3 vehicles requested but layout small has 2"):
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
