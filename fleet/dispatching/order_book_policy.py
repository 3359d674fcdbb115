"""Seed 002's dispatching as a policy: the order book has already decided each AGV's trip
(nearest idle AGV, nearest station, slot and pile: fleet/mission/orders.py), so the policy
only carries the trips out, the vehicles due first, lower id first."""

from __future__ import annotations

from collections.abc import Sequence

from fleet.dispatching.decision import (
    Decision,
    DispatchOutcome,
    FailedChoice,
    TargetsFor,
    VehicleView,
)


class OrderBookPolicy:
    def decide(self, vehicles: Sequence[VehicleView], failed: Sequence[int],
               targets_for: TargetsFor, remaining: dict[str, int]) -> DispatchOutcome:
        t = min(v.t_free for v in vehicles)
        due = sorted((v for v in vehicles if v.t_free == t), key=lambda v: v.vehicle)
        # One whose leg could not be settled just now goes after the others due with it.
        for view in sorted(due, key=lambda v: v.vehicle in failed):
            targets = targets_for(view)
            if targets and targets[0].kind is not None:
                trip = targets[0]
                return DispatchOutcome(Decision(view.vehicle, t, trip.kind, trip, False))
        return DispatchOutcome(None, [FailedChoice(v.vehicle, t, "no trip") for v in due])
