"""Whether each stack the dispatcher announced done was physically served: the forklift the
announcement names stood still, with its forks at the stack, for the whole handling time
before the instant announced; and whether each cluster's stacks were taken up in its order.

The dispatcher announces a stack when it commits the delivery, with the instant the handling
will end; only the forklifts' recorded states say whether it happened. Where they are (the
grid pose each stood still on at each recorded instant) comes from fleet.analysis.motion;
where its forks reach from a pose is the vehicle kind's `handled_cell`.

The order is that of the deliveries' decisions, each taking up the first stack of its cluster
not yet taken up: two forklifts serving one cluster at once may finish its stacks in another
order (docs/metrics.md).
"""

from __future__ import annotations

import bisect
import itertools
from collections import Counter, defaultdict
from collections.abc import Callable
from dataclasses import dataclass

from fleet.analysis.safety import Cell
from fleet.planning.trajectory import Pose


@dataclass(frozen=True)
class Announced:
    """A stack the dispatcher announced done (dispatch/stack), not reopened after."""

    cluster: str
    index: int
    vehicle: int
    t: float  # when its handling ends

    @property
    def stack(self) -> str:
        return f"{self.cluster}#{self.index}"


@dataclass(frozen=True)
class Standing:
    """Where a vehicle was at one recorded instant, as far as handling goes."""

    vehicle: int
    t: float
    pose: Pose | None  # the grid pose it stood still on; None: moving, or off every pose


@dataclass(frozen=True)
class NotServed:
    """An announced stack the recording shows was not served as announced."""

    stack: str
    vehicle: int
    t: float  # when the dispatcher said its handling would end
    why: str


@dataclass(frozen=True)
class OutOfOrder:
    """A delivery decided for a stack while its cluster's order put another first."""

    cluster: str
    taken: int  # the stack the delivery was decided for
    t: float  # when that delivery set out
    first: int  # the stack its cluster's order put first then, not yet taken up


@dataclass(frozen=True)
class Delivery:
    """A delivery the dispatcher decided (a subtask to a stack), setting out at t."""

    cluster: str
    index: int
    t: float


@dataclass(frozen=True)
class Service:
    """An announced stack, and what the states say of it."""

    announced: Announced
    served: bool  # physically confirmed (or taken on the dispatcher's word: `unverified`)
    unverified: str  # why its forklift's states over the handling are not known ("": known)
    why: str  # why it was not served ("": it was)


def services(announced: list[Announced], cells: dict[tuple[str, int], Cell],
             where: list[Standing], handling: float, max_gap: float,
             handled_cell: Callable[[Pose], Cell],
             unknown: Callable[[int, float, float], str]) -> list[Service]:
    """Each announcement judged on the recorded states: its forklift at rest, forks at the
    stack, at every recorded instant of [t - handling, t), with no two of them (nor the
    span's ends) more than `max_gap` apart. `unknown(vehicle, t0, t1)` says why the
    forklift's states over [t0, t1) are not known (not recorded, silent), or "": those
    announcements are believed, as unverified."""
    by_vehicle: dict[int, list[Standing]] = defaultdict(list)
    for s in sorted(where, key=lambda s: s.t):
        by_vehicle[s.vehicle].append(s)
    instants = {v: [s.t for s in ss] for v, ss in by_vehicle.items()}
    out = []
    for a in announced:
        t0, t1 = a.t - handling, a.t
        reason = unknown(a.vehicle, t0, t1)
        if reason:
            out.append(Service(a, True, reason, ""))
            continue
        own, times = by_vehicle.get(a.vehicle, []), instants.get(a.vehicle, [])
        seen = own[bisect.bisect_left(times, t0):bisect.bisect_left(times, t1)]
        why = _not_at(a, cells[a.cluster, a.index], seen, handled_cell) or \
            _not_covered(t0, t1, seen, times, max_gap)
        out.append(Service(a, not why, "", why))
    return out


def _not_at(a: Announced, cell: Cell, seen: list[Standing],
            handled_cell: Callable[[Pose], Cell]) -> str:
    for s in seen:
        if s.pose is None:
            return f"forklift {a.vehicle} was moving at t={s.t:.2f} s"
        reached = handled_cell(s.pose)
        if reached != cell:
            return (f"forklift {a.vehicle} stood at {s.pose} at t={s.t:.2f} s, its forks at "
                    f"{reached}, not at the stack's {cell}")
    return ""


def _not_covered(t0: float, t1: float, seen: list[Standing], times: list[float],
                 max_gap: float) -> str:
    marks = [t0, *(s.t for s in seen), t1]
    for a, b in itertools.pairwise(marks):
        if b - a > max_gap:
            last = times[-1] if times else None
            if last is None or last <= a:
                return ("the recording has no state of its forklift after "
                        + ("the start" if last is None else f"t={last:.2f} s"))
            return f"no state of its forklift from t={a:.2f} to {b:.2f} s"
    return ""


def out_of_order(stacks: dict[str, list[int]], order: Callable[[int], int],
                 decided: list[Delivery], reopened: list[tuple[str, int]]) -> list[OutOfOrder]:
    """Each delivery, of those `decided` (in the order they were decided), for a stack while
    another came first in its cluster's `order` (of the stack indices in `stacks`): the
    clusters' queues replayed, each decision taking up the first stack not yet taken up. A
    stack reopened (its delivery cut short) goes back; as when it did among the decisions
    is not recorded, its next delivery is in order, and so are the others meanwhile. A stack
    no recorded decision took up was taken up when nobody can tell: it is in no queue."""
    taken_up = {(d.cluster, d.index) for d in decided}
    queues = {c: sorted((i for i in indices if (c, i) in taken_up), key=order)
              for c, indices in stacks.items()}
    back = Counter(reopened)
    found = []
    for d in decided:
        queue = queues.get(d.cluster)
        if queue is None or d.index not in queue:
            if back[d.cluster, d.index] > 0:  # delivered again after a reopening
                back[d.cluster, d.index] -= 1
            continue  # else taken up twice: a stack done twice, judged as such
        if queue[0] != d.index and not any(back[d.cluster, i] for i in stacks[d.cluster]):
            found.append(OutOfOrder(d.cluster, d.index, d.t, queue[0]))
        queue.remove(d.index)
    return found
