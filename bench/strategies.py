"""The Table 4 experiment: the five strategies on fill and on empty, and a lower bound.

Every run is the in-process reference engine, so each number is deterministic; only the
planning wall time varies between machines.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

from fleet.dispatching.decision import Strategy
from fleet.dispatching.scorer import load_scorer
from fleet.mission.engine import EngineOptions, lower_bound, run_mission
from fleet.mission.spec import STACK_KINDS, Mission, MissionKind
from fleet.world.layout_file import load_layout

ORDER = (Strategy.ANN, Strategy.COMPREHENSIVE, Strategy.GREEDY, Strategy.TRAFFIC,
         Strategy.BALANCE)


def run(layout_name: str = "paper", missions: tuple[MissionKind, ...] = STACK_KINDS,
        weights: Path | None = None,
        progress: Callable[[str, int, int], None] | None = None) -> dict:
    layout = load_layout(layout_name)
    mlp = load_scorer(layout, weights)
    result: dict = {"layout": layout.name, "vehicles": len(layout.vehicle_starts),
                    "lower_bound_s": {}}
    for kind in missions:
        bound = lower_bound(layout, kind, len(layout.vehicle_starts), progress=(
            None if progress is None else
            lambda done, total, kind=kind: progress(f"{kind.value} lower bound", done, total)))
        result["lower_bound_s"][kind.value] = round(bound, 2)
        rows = {}
        for strategy in ORDER:
            label = f"{kind.value} {strategy.value}"

            def step(done: int, total: int, t: float, failures: int, label: str = label) -> None:
                if progress:
                    progress(label, done, total)

            options = EngineOptions(mlp=mlp if strategy is Strategy.ANN else None,
                                    progress=step)
            t0 = time.perf_counter()
            rec = run_mission(Mission(layout=layout_name, kind=kind, strategy=strategy),
                              options, layout)
            wall = time.perf_counter() - t0
            rows[strategy.value] = {
                "end_time_s": rec.end_time,
                "failures": rec.decision_failures,
                "wait_s": round(rec.total_wait_s, 2),
                "wall_s": round(wall, 2),
                "ratio_to_bound": round(rec.end_time / bound, 4),
                "stacks": len(rec.stacks_done),
            }
        result[kind.value] = rows
    return result


def table(result: dict) -> str:
    lines = [f"Table 4 style, layout {result['layout']}, {result['vehicles']} forklifts"]
    for kind in ("fill", "empty"):
        if kind not in result:
            continue
        bound = result["lower_bound_s"][kind]
        lines.append(f"\n{kind}: lower bound {bound:.2f} s")
        lines.append(f"  {'strategy':<14} {'end time s':>10} {'x bound':>8} {'failures':>8} "
                     f"{'waiting s':>9} {'wall s':>7}")
        for name, row in result[kind].items():
            lines.append(f"  {name:<14} {row['end_time_s']:>10.2f} "
                         f"{row['ratio_to_bound']:>8.3f} {row['failures']:>8} "
                         f"{row['wait_s']:>9.1f} {row['wall_s']:>7.1f}")
    return "\n".join(lines)
