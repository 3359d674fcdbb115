"""Training cycles of the MLP correction (seed 000, Section 3.3 and Figure 6).

Cycle 1 fills the warehouse with the comprehensive strategy and records, for every scored
delivery, the MLP input U and the target of Equation (6); the networks are then fitted with
Levenberg-Marquardt. Every further cycle fills the warehouse with the ANN strategy using the
networks so far, records the targets of Equation (10), and refits on all samples gathered.

The result is the set of networks that gave the shortest end time in an ANN cycle (the last
fit when there was no ANN cycle): each refit fits the samples better, but the mission is the
judge of whether its choices are better.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from fleet.dispatching.mlp import ClusterMLPs
from fleet.errors import UserError
from fleet.mission.engine import EngineOptions, run_mission
from fleet.mission.spec import Mission, MissionKind, Strategy
from fleet.world.layout import Layout


@dataclass(frozen=True)
class CycleReport:
    cycle: int
    strategy: str  # what filled the warehouse in this cycle
    end_time: float
    decision_failures: int
    samples: int
    loss_before: float  # mean over clusters of the loss before LM (standardised units)
    loss_after: float


def train(layout: Layout, cycles: int, seed: int, lm_steps: int = 50,
          progress: Callable[[int, int, int, int], None] | None = None,
          ) -> tuple[ClusterMLPs, list[CycleReport]]:
    """`cycles` warehouse-filling cycles; progress(cycle, cycles, stacks done, stacks)."""
    if cycles < 1:
        raise UserError("--cycles must be at least 1")
    names = tuple(c.name for c in layout.clusters)
    biggest = max(len(layout.cluster_stacks(n)) for n in names)
    mlps = ClusterMLPs.fresh(names, biggest, seed, layout.name)
    samples: list[tuple[tuple[float, ...], int, float]] = []
    reports = []
    best: tuple[float, dict] | None = None  # (end time, networks used) of the best ANN cycle
    for cycle in range(1, cycles + 1):
        strategy = Strategy.COMPREHENSIVE if cycle == 1 else Strategy.ANN

        def step(done: int, total: int, t: float, failures: int, cycle: int = cycle) -> None:
            if progress:
                progress(cycle, cycles, done, total)

        mission = Mission(layout=layout.name, kind=MissionKind.FILL, strategy=strategy,
                          seed=seed)
        options = EngineOptions(mlp=mlps if cycle > 1 else None, collect_training=True,
                                progress=step)
        used = mlps.to_json()
        record = run_mission(mission, options, layout)
        if cycle > 1 and (best is None or record.end_time < best[0]):
            best = (record.end_time, used)
        samples.extend(record.training_samples)
        fits = mlps.fit(samples, lm_steps)
        first = [r.initial for r in fits.values() if r.losses]
        last = [r.losses[-1] for r in fits.values() if r.losses]
        reports.append(CycleReport(cycle, strategy.value, record.end_time,
                                   record.decision_failures, len(samples),
                                   sum(first) / max(len(first), 1),
                                   sum(last) / max(len(last), 1)))
    if best is not None:
        chosen = ClusterMLPs.from_json(best[1], "training")
        chosen.trained_on = mlps.trained_on
        return chosen, reports
    return mlps, reports
