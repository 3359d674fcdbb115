"""Seed 004's heat cost (Section 2, Equation 6; seed pack note B.4.7): the traffic of a history
run counted per cell, T = k1 Q_pass + k2 Q_wait + k3 Q_block + k4 Q_load, scaled to a
T_value in 0..1 that the improved A* adds to G (`Costs.heat` times it).

What each Q counts is the note's CHOICE: Q_pass the entries into the cell, Q_wait the
conflict episodes an AGV began waiting there, Q_block the waits that turned stagnant there,
Q_load the lifts and drops. Q_pass and Q_load stand for conflicts that may happen, Q_wait
and Q_block for conflicts that did (GIVEN)."""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterable
from dataclasses import dataclass, field

from fleet.mission.orders004 import Mission004, generate_orders
from fleet.mission.tracking004 import Event, Met, Moved, Paused, Stagnant
from fleet.planning.rules004 import XY
from fleet.world.floor004 import Floor004

W_HEAT = 2.0  # w_heat of the seed's runs with the heat cost
HISTORY_SEED = 1000  # the history run of order seed s draws the orders of seed s + 1000


@dataclass(frozen=True)
class HeatWeights:
    k_pass: float = 0.1
    k_wait: float = 1.0
    k_block: float = 2.0
    k_load: float = 0.5


@dataclass(frozen=True)
class HeatCounts:
    passes: Counter[XY] = field(default_factory=Counter)
    waits: Counter[XY] = field(default_factory=Counter)
    blocks: Counter[XY] = field(default_factory=Counter)
    loads: Counter[XY] = field(default_factory=Counter)

    def heat(self, w: HeatWeights = HeatWeights()) -> dict[XY, float]:
        """Equation (6): T per cell that saw any traffic."""
        cells = set(self.passes) | set(self.waits) | set(self.blocks) | set(self.loads)
        return {c: w.k_pass * self.passes[c] + w.k_wait * self.waits[c] +
                w.k_block * self.blocks[c] + w.k_load * self.loads[c] for c in sorted(cells)}


def heat_counts(events: Iterable[Event]) -> HeatCounts:
    counts = HeatCounts()
    for e in events:
        if isinstance(e, Moved):
            counts.passes[e.to] += 1
        elif isinstance(e, Met):
            counts.waits[e.at] += 1
        elif isinstance(e, Stagnant):
            counts.blocks[e.at] += 1
        elif isinstance(e, Paused) and e.label in ("lift", "drop"):
            counts.loads[e.at] += 1
    return counts


def t_values(heat: dict[XY, float]) -> dict[XY, float]:
    """T scaled to 0..1 by the hottest cell (T_min is 0: a cell nobody used)."""
    top = max(heat.values(), default=0.0)
    return {c: t / top for c, t in heat.items()} if top > 0 else {}


def history_heat(floor: Floor004, vehicles: int, orders: int, seed: int) -> dict[XY, float]:
    """T_value from the history run of a mission (heat off, the orders of seed + 1000): the
    seed's protocol of a run with the heat cost."""
    history = Mission004(floor, vehicles, generate_orders(floor, orders, seed + HISTORY_SEED))
    return t_values(heat_counts(history.run().events).heat())
