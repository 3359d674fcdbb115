"""Seed 000's dispatch policy (Section 3, Algorithm 1): pure functions over a fleet view.

Which vehicle plans next (`rank`, SelectInitialState / SelectAlteredState / SelectBackupState),
where it goes (the scores of Equations 3, 4 and 9 from the time-expanded preliminary A*), and
how decision failures are counted. The engine (in-process or distributed) owns the state and
calls `Algorithm1.decide` (the DispatchPolicy interface, fleet/dispatching/policy.py) whenever
a vehicle must be given its next subtask.

Reading of the seed where it is ambiguous (docs/dispatching.md says more):
- I_d is printed as (t_find - t_i) [+ C5 for s1, s2]; with C2 > 0 that would make the greedy
  strategy (argmax I_d) pick the farthest cluster. We use I_d = -(t_find - t_i) [+ C5 for the
  far clusters], so that less travel time scores higher, as the text intends.
- S_r must be positive to accept a return (Algorithm 1, line 24); with I_r = -(t_find - t_i) it
  never is, so S_r = C3 + I_r when the preliminary search succeeds and 0 otherwise.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

from fleet.dispatching.decision import (
    Decision,
    DispatchOutcome,
    FailedChoice,
    Strategy,
    Target,
    TaskKind,
    VehicleView,
)
from fleet.dispatching.prelim import cover_time, preliminary_astar, travel_floor
from fleet.params import LOOKAHEAD_S, DispatchParams
from fleet.planning.gridmap import GridMap
from fleet.planning.reservations import ReservationView


@dataclass(frozen=True)
class Score:
    target: Target
    found: bool
    t_find: float
    cover: float
    I: float  # noqa: E741 - the seed's name
    J0: float
    S0: float
    J_hat: float
    value: float  # what the strategy maximises


@dataclass(frozen=True)
class ScoredDecision(Decision):
    """A decision with the scores of every target it was chosen among (what the MLP's
    training learns from, fleet/mission/training.py)."""

    scores: tuple[Score, ...]


# A refusal names this many targets, then how many more.
NAMED_TARGETS = 3


def refusal(scores: Sequence[Score]) -> str:
    """Why no target was accepted, briefly: those the preliminary A* did not reach, and the
    best of those it did, whose score was not positive."""
    if not scores:
        return "no target offered"
    unreached = [s.target.name for s in scores if not s.found]
    found = [s for s in scores if s.found]
    parts = [f"no preliminary path to {_names(unreached)}"] if unreached else []
    if found:
        best = max(found, key=lambda s: s.value)
        parts.append(f"best {best.target.name} scored {best.value:.2f}, not above 0")
    return "; ".join(parts)


def _names(names: Sequence[str]) -> str:
    """"a, b, c and 2 more"."""
    shown = ", ".join(names[:NAMED_TARGETS])
    return shown + (f" and {len(names) - NAMED_TARGETS} more" if len(names) > NAMED_TARGETS
                    else "")


def rank(vehicles: Sequence[VehicleView], failed: Sequence[int] = (),
         lookahead: float = math.inf) -> list[int]:
    """Vehicles by the end of their last trajectory; vehicles whose last decision failed to be
    planned go last, in the order they failed. Those free more than `lookahead` after the
    earliest are left out: one decided for far ahead of the rest holds its way all the time in
    between, and the others then plan around a wall of its commitments (docs/dispatching.md)."""
    soonest = min((v.t_free for v in vehicles), default=0.0)
    order = [v.vehicle for v in sorted(vehicles, key=lambda v: (v.t_free, v.vehicle))
             if v.t_free <= soonest + lookahead]
    late = [v for v in failed if v in order]
    return [v for v in order if v not in late] + late


MlpFn = Callable[[list[float]], list[float]]


def mlp_inputs(cluster_names: Sequence[str], vehicles: Sequence[VehicleView],
               remaining: dict[str, int]) -> list[float]:
    """Equation (7): u_d = G_d if a delivery is linked to cluster d, -G_d for a return or
    both, 0 if none."""
    linked: dict[str, set[TaskKind]] = {}
    for v in vehicles:
        if v.linked_cluster is not None and v.linked_kind is not None:
            linked.setdefault(v.linked_cluster, set()).add(v.linked_kind)
    u = []
    for name in cluster_names:
        kinds = linked.get(name, set())
        g = remaining.get(name, 0)
        u.append(0.0 if not kinds else float(g) if kinds == {TaskKind.DELIVER} else -float(g))
    return u


@dataclass
class Algorithm1:
    """Scores targets and runs Algorithm 1 for one decision at a time."""

    grid_for: Callable[[], GridMap]
    store: ReservationView
    strategy: Strategy
    params: DispatchParams = field(default_factory=DispatchParams)
    cluster_names: tuple[str, ...] = ()
    mlp: MlpFn | None = None

    # Score every target, as Algorithm 1 enumerates them (what training learns from); when
    # False, targets are scored best bound first and those that cannot win are skipped.
    every_target: bool = False
    # Forklifts free more than this after the earliest are not decided for (`rank`).
    lookahead: float = LOOKAHEAD_S

    def score_clusters(self, vehicle: VehicleView, t_i: float, targets: Sequence[Target],
                       u: list[float]) -> list[Score]:
        """Equations (3) and (9) for every cluster with work left."""
        return self._scored(vehicle, t_i, targets, u, TaskKind.DELIVER, every=True)

    def score_stations(self, vehicle: VehicleView, t_i: float,
                       targets: Sequence[Target]) -> list[Score]:
        """Equation (4), shifted by C3 so that a found station scores above zero."""
        return self._scored(vehicle, t_i, targets, [], TaskKind.RETURN, every=True)

    def _scored(self, vehicle: VehicleView, t_i: float, targets: Sequence[Target],
                u: list[float], kind: TaskKind, every: bool) -> list[Score]:
        """The targets' scores in their order; unless `every`, only of those that could still
        win: targets go best bound first (`_bound`: what the score would be with the shortest
        travel the preliminary A* can find), and once the best score so far is accepted and
        above the next bound, the rest are skipped. The choice is the same as with every
        target scored (the skipped ones score below it); a refusal scores them all."""
        grid = self.grid_for()
        ann = kind is TaskKind.DELIVER and self.mlp is not None and \
            self.strategy is Strategy.ANN
        j_hat = self.mlp(u) if ann else None
        jh = [j_hat[self.cluster_names.index(t.name)] if j_hat is not None else 0.0
              for t in targets]

        def score(k: int) -> Score:
            if kind is TaskKind.DELIVER:
                return self._cluster_score(grid, vehicle, t_i, targets[k], ann, jh[k])
            return self._station_score(grid, vehicle, t_i, targets[k])

        if every or not self._bounds_hold():
            return [score(k) for k in range(len(targets))]
        bounds = [self._bound(vehicle, t, kind, ann, jh[k]) for k, t in enumerate(targets)]
        done: dict[int, Score] = {}
        best: Score | None = None
        for k in sorted(range(len(targets)), key=lambda k: -bounds[k]):
            if best is not None and bounds[k] < best.value and self._acceptable(best, kind):
                break
            done[k] = score(k)
            if done[k].found and (best is None or done[k].value > best.value):
                best = done[k]
        return [done[k] for k in sorted(done)]

    def _bounds_hold(self) -> bool:
        """Whether a score can only fall as travel and cover grow (the weights' signs)."""
        p = self.params
        return p.C2 >= 0 and p.cover_weight >= 0 and (
            self.strategy is not Strategy.ANN or p.C9 >= 0)

    def _bound(self, vehicle: VehicleView, target: Target, kind: TaskKind, ann: bool,
               jh: float) -> float:
        """The most the target can score if found: its score with no cover and the travel
        `travel_floor` gives (no preliminary trajectory is shorter)."""
        p = self.params
        travel = travel_floor(vehicle.pose.cell, [g.cell for g in target.goals])
        if kind is TaskKind.RETURN:
            return p.C3 - travel
        i_d = -travel + (p.C5 if target.far else 0.0)
        return self._cluster_value(target, i_d, p.C2 * i_d + p.C3, ann, jh)

    def _cluster_value(self, target: Target, i_d: float, j0: float, ann: bool,
                       jh: float) -> float:
        """What the strategy maximises (Equations 3 and 9)."""
        p = self.params
        s0 = p.C1 * target.remaining + j0
        return {
            Strategy.GREEDY: i_d,
            Strategy.TRAFFIC: j0,
            Strategy.BALANCE: float(target.remaining),
            Strategy.COMPREHENSIVE: s0,
            Strategy.ANN: p.C1 * target.remaining + p.C9 * j0 + p.C10 * jh if ann else s0,
        }[self.strategy]

    def _cluster_score(self, grid: GridMap, vehicle: VehicleView, t_i: float,
                       target: Target, ann: bool, jh: float) -> Score:
        p = self.params
        cells = [g.cell for g in target.goals]
        pre = preliminary_astar(grid, self.store, vehicle.vehicle, vehicle.pose.cell, t_i,
                                cells, p.iter_pre)
        if pre.found:
            cover = cover_time(self.store, vehicle.vehicle, cells, pre.t_find, p.dt_entry)
            travel = pre.t_find - t_i
            i_d = -travel + (p.C5 if target.far else 0.0)
            j0 = -p.cover_weight * cover + p.C2 * i_d + p.C3
        else:
            cover, i_d, j0 = 0.0, -float(p.iter_pre), p.C4
        s0 = p.C1 * target.remaining + j0
        return Score(target, pre.found, pre.t_find, cover, i_d, j0, s0, jh if ann else 0.0,
                     self._cluster_value(target, i_d, j0, ann, jh))

    def _station_score(self, grid: GridMap, vehicle: VehicleView, t_i: float,
                       target: Target) -> Score:
        p = self.params
        cells = [g.cell for g in target.goals]
        pre = preliminary_astar(grid, self.store, vehicle.vehicle, vehicle.pose.cell, t_i,
                                cells, p.iter_pre)
        i_r = -(pre.t_find - t_i) if pre.found else 0.0
        s_r = p.C3 + i_r if pre.found else 0.0
        return Score(target, pre.found, pre.t_find, 0.0, i_r, s_r, s_r, 0.0, s_r)

    def _acceptable(self, best: Score, kind: TaskKind) -> bool:
        """Whether the best found score makes the decision solid (Algorithm 1, lines 16 and
        24): positive for a return and for the scored strategies."""
        if kind is TaskKind.RETURN or self.strategy in (Strategy.COMPREHENSIVE, Strategy.ANN):
            return best.value > 0  # S_r, S_d,0, or Equation 9's S_d
        return True

    def accepted(self, scores: Sequence[Score], kind: TaskKind) -> Score | None:
        """The best target, if the decision is solid: a found preliminary trajectory and, for
        the scored strategies, a positive score (Algorithm 1, lines 16 and 24)."""
        found = [s for s in scores if s.found]
        if not found:
            return None
        best = max(found, key=lambda s: s.value)  # first of equals: targets are ordered
        return best if self._acceptable(best, kind) else None

    def decide(self, vehicles: Sequence[VehicleView], failed: Sequence[int],
               targets_for: Callable[[VehicleView], list[Target]],
               remaining: dict[str, int]) -> DispatchOutcome:
        """Algorithm 1: select the vehicle and its goal, re-selecting on failure.

        `failed` lists the vehicles whose decided trajectory could not be planned since the
        last success (the engine's `fail` flag, kept across calls so that two failing vehicles
        cannot starve the others). When every vehicle has failed, the backup state postpones
        the one that has waited longest by dt_i and tries it again at the later instant."""
        by_id = {v.vehicle: v for v in vehicles}
        order = rank(vehicles, failed, self.lookahead)
        selected: set[int] = set(failed)
        failures: list[FailedChoice] = []
        postponements: dict[int, float] = {}
        u = mlp_inputs(self.cluster_names, vehicles, remaining)
        for _ in range(self.params.iter_dispatch):
            postponed = False
            fresh = [v for v in order if v not in selected]
            if fresh:
                current = fresh[0]  # SelectInitialState, then SelectAlteredState
            else:
                current = min(order, key=lambda v: (postponements.get(v, by_id[v].t_free), v))
                postponed = True  # SelectBackupState: postpone by dt_i
                base = postponements.get(current, by_id[current].t_free)
                postponements[current] = base + self.params.dt_postpone
            selected.add(current)
            view = by_id[current]
            t_i = postponements.get(current, view.t_free)
            targets = targets_for(view)
            scores = self._scored(view, t_i, targets, u, view.next_task, self.every_target)
            best = self.accepted(scores, view.next_task)
            if best is not None:
                return DispatchOutcome(ScoredDecision(current, t_i, view.next_task,
                                                      best.target, postponed, tuple(scores)),
                                       failures, postponements)
            failures.append(FailedChoice(current, t_i, refusal(scores)))
        return DispatchOutcome(None, failures, postponements)
