"""Seed 002's battery, as pure logic: state of charge, where AGVs start, and when one goes to
charge (seed pack note A.3 and A.4.7).

GIVEN (Section 2): "The AGV is obligated to return to the designated charging area once its
battery level falls below 20%", and (Section 2.2) the N_op AGVs "with the highest power
capacity continue operations ... the remaining AGVs should return to the charging station
upon task completion". Everything numeric besides the 20 % is a CHOICE of the notes and a
field of `BatteryParams`:

- SOC is a percentage, 0..100.
- Driving drains `drain_per_s` (100 % per 14 400 s); standing (under a shelf, at a packing
  station, waiting) drains nothing.
- A pile charges `charge_per_s` (100 % per 3 600 s) up to 100 %; the AGV rejoins at 100 %.
- AGV i (1-based) of n starts on pile c_k, k = ceil((i - 1/2) * piles / n).

The decision itself (`goes_to_charge`) is taken at a task completion only, never while a
shelf is carried. Which pile, and the queue when all are busy, is the order book's
(fleet.mission.orders), because piles are shared state.
"""

from __future__ import annotations

import math
import random
from collections.abc import Sequence
from dataclasses import dataclass

from fleet.planning.geometry import Cell
from fleet.wire.protocol import MissionInfo
from fleet.world.layout import Layout, Pile

FULL = 100.0


def _check_soc(what: str, soc: float) -> None:
    if not 0.0 <= soc <= FULL:
        raise ValueError(f"{what} must be a state of charge between 0 and 100 %, not {soc!r}")


@dataclass(frozen=True)
class BatteryParams:
    """The battery model's numbers (seed pack note A.3; only `threshold` is the seed's)."""

    drain_per_s: float = FULL / 14_400.0  # % per second of driving (CHOICE: 4 h of driving)
    charge_per_s: float = FULL / 3_600.0  # % per second on a pile (CHOICE: 1 h from empty)
    threshold: float = 20.0  # GIVEN: below it, the AGV goes to charge at its task completion
    n_op: int | None = None  # AGVs kept operational (CHOICE: None is all n, the plain rule)

    def __post_init__(self) -> None:
        if not self.drain_per_s >= 0.0:
            raise ValueError(f"battery drain rate must be 0 or more % per second of driving, "
                             f"not {self.drain_per_s!r}")
        if not self.charge_per_s > 0.0:
            raise ValueError(f"battery charge rate must be more than 0 % per second (an AGV "
                             f"must be able to rejoin), not {self.charge_per_s!r}")
        _check_soc("the charging threshold", self.threshold)
        if self.n_op is not None and self.n_op < 1:
            raise ValueError(f"n_op (AGVs kept operational) must be at least 1, not "
                             f"{self.n_op!r}")

    def operational(self, n: int) -> int:
        """N_op for a fleet of n AGVs."""
        if self.n_op is not None and self.n_op > n:
            raise ValueError(f"n_op (AGVs kept operational) is {self.n_op} but the fleet has "
                             f"only {n} AGVs")
        return n if self.n_op is None else self.n_op

    def after_driving(self, soc: float, seconds: float) -> float:
        """SOC after `seconds` of driving, floored at 0 (`ran_flat` says whether it was hit)."""
        if seconds < 0:
            raise ValueError(f"driving time must be 0 or more seconds, not {seconds!r}")
        return max(0.0, soc - self.drain_per_s * seconds)

    def ran_flat(self, soc: float, seconds: float) -> bool:
        """Whether `seconds` of driving from `soc` would take more than the battery holds."""
        return soc - self.drain_per_s * seconds < 0.0

    def after_charging(self, soc: float, seconds: float) -> float:
        if seconds < 0:
            raise ValueError(f"charging time must be 0 or more seconds, not {seconds!r}")
        return min(FULL, soc + self.charge_per_s * seconds)

    def time_to_full(self, soc: float) -> float:
        return (FULL - soc) / self.charge_per_s


BATTERY_KEYS = {
    "start": "each AGV's charge at the start, % (LOW..HIGH: drawn with the seed; default 100)",
    "below": "it goes to charge below this %, at a task's end (default 20, the seed's)",
    "n_op": "AGVs kept operational by staggered charging (default: all)",
    "drive_hours": "hours of driving from full to empty (default 4)",
    "charge_hours": "hours on a pile from empty to full (default 1)",
}


def parse_battery(text: str) -> tuple[tuple[float, float], BatteryParams]:
    """`start=15..40,below=20,n_op=6,drive_hours=4,charge_hours=1` (any of them, in any
    order): the start charge range and the battery's numbers; ValueError naming what is
    wrong."""
    given: dict[str, str] = {}
    for item in filter(None, (part.strip() for part in text.split(","))):
        key, sep, value = item.partition("=")
        key = key.strip().replace("-", "_")
        if not sep or key not in BATTERY_KEYS:
            raise ValueError(f"{item!r} is not KEY=VALUE with KEY one of "
                             f"{', '.join(BATTERY_KEYS)}")
        if key in given:
            raise ValueError(f"{key} is given twice")
        given[key] = value.strip()
    low_text, _, high_text = given.get("start", "100").partition("..")
    low = _number("start", low_text)
    high = _number("start", high_text) if high_text else low
    start_charges(low, high, 1, 0)  # checks the range
    hours = {key: _number(key, given.get(key, default))
             for key, default in (("drive_hours", "4"), ("charge_hours", "1"))}
    for key, value in hours.items():
        if value <= 0:
            raise ValueError(f"{key}={given[key]} must be more than 0")
    n_op = None
    if "n_op" in given:
        try:
            n_op = int(given["n_op"])
        except ValueError:
            raise ValueError(f"n_op={given['n_op']!r} is not a whole number") from None
    params = BatteryParams(FULL / (3600.0 * hours["drive_hours"]),
                           FULL / (3600.0 * hours["charge_hours"]),
                           _number("below", given.get("below", "20")), n_op)
    return (low, high), params


def _number(key: str, text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise ValueError(f"{key}={text!r} is not a number") from None
    if not math.isfinite(value):
        raise ValueError(f"{key}={text!r} is not a finite number")
    return value


def start_charges(low: float, high: float, n: int, seed: int) -> tuple[float, ...]:
    """Each AGV's SOC at the start: `low` for all when `high` is the same, else drawn
    uniformly in [low, high] with the mission's seed (the note's A-BAT-1 draws 15..40 %)."""
    _check_soc("the start charge", low)
    _check_soc("the start charge", high)
    if low > high:
        raise ValueError(f"the start charge {low:g}..{high:g} % runs backwards")
    if low == high:
        return (float(low),) * n
    rng = random.Random(f"battery {seed}")  # apart from the orders' draw
    return tuple(round(rng.uniform(low, high), 6) for _ in range(n))


@dataclass(frozen=True)
class Battery:
    """One AGV's battery as it drives (fleet.mission.driving): it drains while the AGV
    moves, and charges while the AGV is parked on a pile (between legs: a wait inside a leg
    is no docking), never above 100 %."""

    params: BatteryParams
    start_soc: float
    piles: frozenset[Cell]


def battery_of(info: MissionInfo, vehicle: int, layout: Layout) -> Battery | None:
    """The battery a mission gives the vehicle (None: the mission models none)."""
    if not 1 <= vehicle <= len(info.soc_start):
        return None
    params = BatteryParams(info.drain_per_s, info.charge_per_s, info.charge_below)
    return Battery(params, info.soc_start[vehicle - 1], frozenset(p.cell for p in layout.piles))


def start_piles(layout: Layout, n: int) -> tuple[Pile, ...]:
    """Where the n AGVs start (CHOICE, note A.3): AGV i (1-based) on pile c_k with
    k = ceil((i - 1/2) * piles / n), the piles in the layout's order. The piles are spread
    evenly and distinct because piles / n >= 1."""
    piles = len(layout.piles)
    if n < 1:
        raise ValueError(f"the fleet needs at least 1 AGV, not {n!r}")
    if n > piles:
        raise ValueError(f"{n} AGVs cannot start on the {piles} charging piles of layout "
                         f"{layout.name}: more AGVs than piles")
    # ceil((2i - 1) * piles / 2n) in integers
    return tuple(layout.piles[-(-(2 * i - 1) * piles // (2 * n)) - 1] for i in range(1, n + 1))


def goes_to_charge(params: BatteryParams, agv: int, soc: float,
                   operational: Sequence[tuple[int, float]], n: int) -> str | None:
    """Why AGV `agv`, having just completed a task at `soc`, goes to charge: "threshold" (below
    20 %), "staggered" (not among the N_op highest-SOC operational AGVs), or None (it stays
    operational).

    `operational` is every AGV not charging, heading to a pile or waiting for one, as
    (id, SOC) pairs, this one included. CHOICES (note A.4.7 leaves them open):

    - The ranking is over the operational AGVs only, by SOC high to low, ties by lower id
      first. So the staggered rule alone never leaves fewer than N_op operational: at most
      n - N_op charge at once unless the 20 % rule sends more.
    - An AGV at 100 % is never sent by the staggered rule: a pile would give it nothing.
    """
    if soc < params.threshold:
        return "threshold"
    n_op = params.operational(n)
    if len(operational) <= n_op or soc >= FULL:
        return None
    ranked = sorted(operational, key=lambda pair: (-pair[1], pair[0]))
    rank = next(i for i, (a, _) in enumerate(ranked) if a == agv)
    return "staggered" if rank >= n_op else None
