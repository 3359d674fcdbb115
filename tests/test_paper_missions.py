"""All five strategies fill and empty the paper warehouse, checked apart from the engine:
no two forklifts ever hold one cell at once, every trajectory covers its swept cells, every
stack is done exactly once, every forklift ends parked. ANN and traffic-jam removal are
checked in test_runtime.py, where the same in-process run is also the reference the
multi-process run must equal (one run of each, not two)."""

import functools
import sys
from pathlib import Path

import pytest

from fleet.dispatching.decision import STACK_STRATEGIES, Strategy
from fleet.dispatching.scorer import load_scorer
from fleet.mission.engine import EngineOptions, run_mission
from fleet.mission.lower_bound import lower_bound
from fleet.mission.spec import STACK_KINDS, Mission, MissionKind
from fleet.world.layout_file import load_layout

sys.path.insert(0, str(Path(__file__).parent))
from mission_check import mission_problems

PAPER = load_layout("paper")


CHECKED_IN_RUNTIME = (Strategy.ANN, Strategy.TRAFFIC)


@functools.cache
def bound(kind: MissionKind) -> float:
    return lower_bound(PAPER, kind, 4)


def check_paper_mission(rec) -> None:
    assert mission_problems(rec, PAPER) == []
    assert len(rec.stacks_done) == 136
    assert rec.end_time >= bound(rec.mission.kind)


@pytest.mark.parametrize("kind", STACK_KINDS)
@pytest.mark.parametrize("strategy", [s for s in STACK_STRATEGIES if s not in CHECKED_IN_RUNTIME])
def test_strategy_completes_on_paper(kind, strategy):
    mlp = load_scorer(PAPER) if strategy is Strategy.ANN else None
    check_paper_mission(run_mission(Mission(kind=kind, strategy=strategy),
                                    EngineOptions(mlp=mlp), PAPER))
