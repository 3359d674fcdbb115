"""Seed 002's batteries as the recording shows them: each AGV's state of charge, from its
published states, judged against the numbers the mission message gives (the rates and the
threshold), with this module's own arithmetic (nothing of the order book or the drive).

- **Bounds.** The charge stays within 0..100 %.
- **Where it rises.** Only on a charging pile: between two states of which one stands on a
  pile, and no faster than the charge rate.
- **Where it falls.** Only while driving (the AGV's centre moved between the two states),
  and no faster than the drain rate.
- **The 20 % rule** (GIVEN, Section 2: "obligated to return to the designated charging area
  once its battery level falls below 20%", decided at a task's end). An AGV that puts a shelf
  down below the threshold goes to a pile next: the next place (slot, packing station or
  pile) it stops at is a pile, if it stops anywhere again. The charge at the drop lies
  between the two states around it; only a drop below the threshold on both sides is judged.
"""

from __future__ import annotations

import itertools
from collections import defaultdict
from collections.abc import Iterable
from dataclasses import dataclass, field

Cell = tuple[int, int]
EPS = 1e-6  # % (the states carry the charge to 6 decimals)


@dataclass(frozen=True)
class Charge:
    """One state, as the battery checks read it."""

    vehicle: int
    t: float
    soc: float
    cell: Cell | None  # the cell holding the centre (None on an edge)
    moved: bool  # the centre moved since the state before
    loaded: bool


@dataclass(frozen=True)
class BatteryFault:
    t: float
    vehicle: int
    why: str


@dataclass
class BatteryVerdict:
    lowest: float = 100.0  # the lowest charge any AGV had
    charged: int = 0  # times a charge began to rise
    faults: list[BatteryFault] = field(default_factory=list)

    @property
    def passed(self) -> bool:
        return not self.faults


def battery_verdict(states: Iterable[Charge], piles: set[Cell], places: set[Cell],
                    drain_per_s: float, charge_per_s: float, below: float) -> BatteryVerdict:
    """The batteries' verdict (this module's docstring); `places` are every slot, packing
    station and pile cell."""
    by_vehicle: dict[int, list[Charge]] = defaultdict(list)
    for s in states:
        by_vehicle[s.vehicle].append(s)
    verdict = BatteryVerdict()
    for vehicle, seen in sorted(by_vehicle.items()):
        seen.sort(key=lambda s: s.t)
        verdict.lowest = min(verdict.lowest, *(s.soc for s in seen))
        verdict.faults += [BatteryFault(s.t, vehicle, f"charge {s.soc:g} % is outside 0..100 %")
                           for s in seen if not 0.0 <= s.soc <= 100.0]
        rising = False
        for k, (a, b) in enumerate(itertools.pairwise(seen)):
            dt, change = b.t - a.t, b.soc - a.soc
            if change > EPS:
                if not (a.cell in piles or b.cell in piles):
                    verdict.faults.append(BatteryFault(b.t, vehicle, f"charge rose {change:g} % "
                                                       f"off a pile"))
                elif change > charge_per_s * dt + EPS:
                    verdict.faults.append(BatteryFault(b.t, vehicle, f"charge rose {change:g} % "
                                                       f"in {dt:g} s, faster than its rate"))
                verdict.charged += not rising
            elif change < -EPS:
                if not b.moved:
                    verdict.faults.append(BatteryFault(b.t, vehicle, f"charge fell "
                                                       f"{-change:g} % standing still"))
                elif -change > drain_per_s * dt + EPS:
                    verdict.faults.append(BatteryFault(b.t, vehicle, f"charge fell {-change:g} "
                                                       f"% in {dt:g} s, faster than its rate"))
            rising = change > EPS
            if a.loaded and not b.loaded and a.soc < below and b.soc < below:
                verdict.faults += _went_to_charge(seen[k + 1:], piles, places, below)
    return verdict


def _went_to_charge(after: list[Charge], piles: set[Cell], places: set[Cell],
                    below: float) -> list[BatteryFault]:
    """Nothing, if the next place the AGV stops at after a drop is a pile (or it stops at no
    other place); else the fault."""
    drop = after[0]
    for s in after[1:]:
        if not s.moved and s.cell in places and s.cell != drop.cell:
            if s.cell in piles:
                return []
            return [BatteryFault(drop.t, drop.vehicle, f"put a shelf down at {drop.soc:g} %, "
                                 f"below {below:g} %, then stopped at {s.cell}, not a pile")]
    return []
