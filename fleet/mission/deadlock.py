"""The wait-for graph: which vehicles cannot go on until others move, and which of them never
will unless told to.

Each vehicle whose way is closed for good waits for the vehicles parked in it (its `Wait`, from
its planner's `blockage`). A vehicle moves by itself when it has work it can be offered and its
way is only busy for a while. Vehicles that have no such way (idle ones, the walled-in, and
waiting ones all of whose blockers are stuck as well) are stuck together: the greatest such
set holds every cycle of waits and every chain that ends at an idle vehicle. Postponing never
frees them; a vehicle among them must be moved aside (fleet/mission/step_aside.py). Frozen
vehicles (down, cut off) are no vertex: their cells are walls the blockage search goes around.
Pure functions over plain data, whatever the vehicle kind.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from enum import Enum

from fleet.planning.blockage import Blockage


class WaitKind(Enum):
    CYCLE = "cycle"  # vehicles waiting for each other
    IDLE = "idle"  # a chain of waits ending at one that will not move by itself (idle, walled)
    WALLED = "walled"  # no way at all but through goods, zones or frozen vehicles


@dataclass(frozen=True)
class Wait:
    """A vehicle's way to where its next subtask may end, as the table stood at `revision`:
    None when goods, zones or frozen vehicles close every way."""

    vehicle: int
    blockage: Blockage | None
    revision: int
    shortest: bool = False  # the way of fewest moves, not the way past fewest vehicles

    @property
    def blockers(self) -> frozenset[int]:
        return self.blockage.blockers if self.blockage is not None else frozenset()


@dataclass(frozen=True)
class Deadlock:
    """A waiting vehicle that stuck vehicles wall in, and the chain of waits from it."""

    waiting: int
    kind: WaitKind
    chain: tuple[int, ...]  # waiting -> a blocker -> its blocker ... (a cycle repeats its head)


def stuck(waits: Mapping[int, Wait], idle: Iterable[int]) -> frozenset[int]:
    """The greatest set of vehicles none of which moves unless another in it does: the idle
    ones, the walled-in, and every waiting one whose blockers are all in the set. A vehicle
    without a wait (not tried yet) or with an empty one (its way is only busy) moves by
    itself."""
    members = set(idle) | {v for v, w in waits.items() if w.blockage is None or w.blockers}
    while True:
        leaving = {v for v in members if v in waits and waits[v].blockers
                   and not waits[v].blockers <= members}
        if not leaving:
            return frozenset(members)
        members -= leaving


def deadlocks(waits: Mapping[int, Wait], idle: Iterable[int],
              priority: Mapping[int, float]) -> list[Deadlock]:
    """The waiting vehicles that are stuck, highest priority first (`priority`: lower sorts
    first, e.g. the instant each began to wait, so the longest waiting is served first and
    none starves), each with the chain of waits that holds it."""
    idle = frozenset(idle)
    members = stuck(waits, idle)
    found = []
    for v in sorted((v for v in members if v in waits), key=lambda v: (priority.get(v, 0), v)):
        if waits[v].blockage is None:
            found.append(Deadlock(v, WaitKind.WALLED, (v,)))
            continue
        chain = _chain(v, waits, idle)
        kind = WaitKind.CYCLE if chain[-1] in chain[:-1] else WaitKind.IDLE
        found.append(Deadlock(v, kind, chain))
    return found


def _chain(start: int, waits: Mapping[int, Wait], idle: frozenset[int]) -> tuple[int, ...]:
    """Follow the lowest-numbered blocker from `start` until an idle or walled-in vehicle, or
    until a vehicle repeats (a cycle)."""
    chain = [start]
    while True:
        here = chain[-1]
        if here in idle or here not in waits or not waits[here].blockers:
            return tuple(chain)
        nxt = min(waits[here].blockers)
        chain.append(nxt)
        if nxt in chain[:-1]:
            return tuple(chain)
