"""The dispatch-policy seam: the interface the engine decides through, and the registry that
gives a mission the policy its strategy names.

A policy sees the vehicles that have something left to do and asks the mission's work state
(fleet/mission/work.py) where each may go; it answers with one decision (which vehicle, from
which instant, to which target) or none, and each choice it made on the way that came to
nothing. It keeps no state of the mission between calls: the engine owns that, so the
in-process run and the dispatcher process (which builds its engine the same way) decide the
same. Seed 000's Algorithm 1 with its five strategies is the first policy; another (seeds
002 and 004: nearest pair, round robin) is a class with `decide` and an entry in POLICIES
for the strategies that name it.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Protocol

from fleet.dispatching.algorithm1 import Algorithm1, MlpFn
from fleet.dispatching.decision import (
    STACK_STRATEGIES,
    DispatchOutcome,
    Strategy,
    TargetsFor,
    VehicleView,
)
from fleet.dispatching.order_book_policy import OrderBookPolicy
from fleet.params import LOOKAHEAD_S, DispatchParams
from fleet.planning.gridmap import GridMap
from fleet.planning.reservations import ReservationView
from fleet.world.layout import Layout


class DispatchPolicy(Protocol):
    def decide(self, vehicles: Sequence[VehicleView], failed: Sequence[int],
               targets_for: TargetsFor, remaining: dict[str, int]) -> DispatchOutcome:
        """The next decision for one of `vehicles` (those with work left), with the targets
        `targets_for` offers each and the work `remaining` per group of targets (per
        cluster); `failed` are the vehicles whose decided trajectory could not be planned
        since the last success, in order. None in the outcome: no solid decision; each
        choice that came to nothing is one of the outcome's failures (at least one when
        there is no decision), and the engine announces each."""


@dataclass(frozen=True)
class PolicySetup:
    """What a policy is built from, once per mission."""

    strategy: Strategy
    layout: Layout
    store: ReservationView  # the reservation table as the dispatcher sees it
    grid_for: Callable[[], GridMap]  # the static map as the work state leaves it now
    params: DispatchParams = field(default_factory=DispatchParams)
    mlp: MlpFn | None = None  # the trained scorer, for a strategy that uses one
    every_target: bool = False  # score every target, even those that cannot win (training)
    lookahead: float = LOOKAHEAD_S  # Algorithm 1's (the mission's)


def algorithm1(setup: PolicySetup) -> Algorithm1:
    return Algorithm1(grid_for=setup.grid_for, store=setup.store, strategy=setup.strategy,
                      params=setup.params,
                      cluster_names=tuple(c.name for c in setup.layout.clusters),
                      mlp=setup.mlp, every_target=setup.every_target,
                      lookahead=setup.lookahead)


def order_book(setup: PolicySetup) -> DispatchPolicy:
    return OrderBookPolicy()


POLICIES: dict[Strategy, Callable[[PolicySetup], DispatchPolicy]] = {
    **{strategy: algorithm1 for strategy in STACK_STRATEGIES}, Strategy.NEAREST: order_book}


def dispatch_policy(setup: PolicySetup) -> DispatchPolicy:
    """The policy the mission's strategy names."""
    return POLICIES[setup.strategy](setup)
