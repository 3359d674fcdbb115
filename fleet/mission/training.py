"""Training cycles of the MLP correction (seed 000, Section 3.3 and Figure 6).

Cycle 1 fills the warehouse with the comprehensive strategy and records, for every scored
delivery, the MLP input U and the target of Equation (6); the networks are then fitted with
Levenberg-Marquardt. Every further cycle fills the warehouse with the ANN strategy using the
networks so far, records the targets of Equation (10), and refits on all samples gathered.

The result is the networks of the last fit, on every sample of every cycle: a rule fixed before
any mission judges them. Keeping the cycle whose mission ended soonest would choose the
networks by the very result they are then judged on (issue 24: cycle 2 of one training filled
in 1972.5 s, cycle 3 in 2619.75 s); `fleet bench strategies` reports the ANN strategy over
several training seeds instead.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from fleet.dispatching.algorithm1 import ScoredDecision, mlp_inputs
from fleet.dispatching.decision import Strategy, TaskKind
from fleet.dispatching.mlp import ClusterMLPs
from fleet.errors import UserError
from fleet.mission.engine import EngineOptions, Planned, run_mission
from fleet.mission.spec import Mission, MissionKind
from fleet.params import DispatchParams
from fleet.world.layout import Layout

Sample = tuple[tuple[float, ...], int, float]  # MLP input U, cluster, target


class SampleCollector:
    """Hears every planned decision of one mission (EngineOptions.planned) and keeps, for
    every delivery, the training target of Equation (6) (Equation (10) under the ANN
    strategy) of each cluster it scored."""

    def __init__(self, layout: Layout, strategy: Strategy,
                 params: DispatchParams | None = None) -> None:
        self.clusters = tuple(c.name for c in layout.clusters)
        self.strategy = strategy
        self.params = params or DispatchParams()
        self.trip_times: list[float] = []  # every committed subtask's, so far
        self.samples: list[Sample] = []

    def planned(self, planned: Planned) -> None:
        decision, traj = planned.decision, planned.trajectory
        if decision.kind is TaskKind.DELIVER and isinstance(decision, ScoredDecision):
            self._collect(planned, decision)
        if traj is not None:
            self.trip_times.append(traj.t_end - decision.t_i)

    def _collect(self, planned: Planned, decision: ScoredDecision) -> None:
        p = self.params
        traj = planned.trajectory
        u = tuple(mlp_inputs(self.clusters, planned.fleet, planned.remaining))
        mean_trip = sum(self.trip_times) / len(self.trip_times) if self.trip_times else 0.0
        for score in decision.scores:
            base = score.value - p.C1 * score.target.remaining if \
                self.strategy is Strategy.ANN else score.J0
            if score.target.name == decision.target.name:
                if traj is None:
                    target = p.C5
                else:
                    norm = p.C7 if score.target.far else p.C8
                    target = base - p.C6 * (traj.t_end - decision.t_i - mean_trip + norm)
            else:
                target = base
            self.samples.append((u, self.clusters.index(score.target.name), target))


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
    samples: list[Sample] = []
    reports = []
    for cycle in range(1, cycles + 1):
        strategy = Strategy.COMPREHENSIVE if cycle == 1 else Strategy.ANN

        def step(done: int, total: int, t: float, failures: int, cycle: int = cycle) -> None:
            if progress:
                progress(cycle, cycles, done, total)

        mission = Mission(layout=layout.name, kind=MissionKind.FILL, strategy=strategy,
                          seed=seed)
        collector = SampleCollector(layout, strategy)
        options = EngineOptions(mlp=mlps if cycle > 1 else None, score_every_target=True,
                                progress=step, planned=collector.planned)
        record = run_mission(mission, options, layout)
        samples.extend(collector.samples)
        fits = mlps.fit(samples, lm_steps)
        first = [r.initial for r in fits.values() if r.losses]
        last = [r.losses[-1] for r in fits.values() if r.losses]
        reports.append(CycleReport(cycle, strategy.value, record.end_time,
                                   record.decision_failures, len(samples),
                                   sum(first) / max(len(first), 1),
                                   sum(last) / max(len(last), 1)))
    return mlps, reports
