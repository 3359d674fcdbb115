"""Seed 002's collisions: found on timed routes (Section 5.2), and settled by its priority
rules (Section 5.3) with a wait inserted into one AGV's schedule.

**Detection.** The paper predicts collisions from arrival times: two AGVs at one node within
a window δ (Equations 5-6), swapping along one edge (7-9), or crossing diagonals of one
2 x 2 block (10-11). It leaves δ open. Here two schedules collide when their bodies touch a
common cell at a common time (`lane_schedule.Touch`), which is the note's conservative
choice of δ = 2 cell-times (A.4.5) at every angle, and exactly what the reservation store can
keep apart. The kind of a collision (node, swap or diagonal) is named from the two moves, as
the paper's three conditions name it.

**Rules**, by the sets of Section 5.3 (R crossroad cells, T T-crossroad and corner cells, N
slots, stations, piles and access cells, H and L horizontal and longitudinal lane cells
outside junctions), for two AGVs meeting at nodes α and β:

- both in R, one coming from H and the other from L (12, 13): longitudinal priority, the one
  from H waits outside the crossroad;
- both in R from the same orientation (12, 14), or both in T from L (15, 16): the one with the
  later τ_{α+1} waits at its last node before the junction;
- both in T, one from H (15, not 16; the paper is silent): longitudinal priority, as in R;
- both on channels, one coming out of N (17, 18): that one waits where it is, in N (also
  when its way out crosses the near lane and they meet on the far one);
- otherwise (both on channels, and every other case): the later τ_{α+1} waits at α-1.

Ties in τ go to the higher vehicle id waiting. A wait lasts until the other has stopped
touching the contested cells; the scan then runs again (a new collision may follow), up to
`MAX_RESOLUTIONS` per change (the note's K = 100). A wait goes into the schedule of whichever
AGV the rule names, the other one's too (the store amends it): unless that AGV has already
left the node it would wait at, and then the other one waits instead. When neither can, or
the cap is reached, it is a deadlock, which the caller settles (A.4.6's fallback).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from enum import Enum

from fleet.planning.geometry import Cell
from fleet.planning.lane_schedule import Schedule, Touch

MAX_RESOLUTIONS = 100


class Area(Enum):
    """Section 5.3's sets of cells (`fleet.world.lanes.collision_areas` sorts a layout's)."""

    CROSSROAD = "R"
    T_CROSSROAD = "T"
    OFF_CHANNEL = "N"
    HORIZONTAL = "H"
    LONGITUDINAL = "L"


class CollisionKind(Enum):
    NODE = "node"  # Equations (5)-(6)
    SWAP = "swap"  # (7)-(9)
    DIAGONAL = "diagonal"  # (10)-(11)


@dataclass(frozen=True)
class Collision:
    """Vehicles `a` and `b` would touch `cells` at once from `t` on; α and β index the
    nodes of their routes where they meet (for a swap or crossing diagonals, the node each
    move starts from)."""

    a: int
    b: int
    alpha: int
    beta: int
    kind: CollisionKind
    t: float
    cells: frozenset[Cell]


@dataclass(frozen=True)
class WaitOrder:
    """A wait a rule puts into one schedule: `vehicle` stands `seconds` more at `node`."""

    vehicle: int
    node: int
    seconds: float
    rule: str  # which rule of Section 5.3 named it
    collision: Collision


def first_collision(a: Schedule, b: Schedule) -> Collision | None:
    """The earliest instant the two bodies would touch a common cell, named."""
    pair = _first_touching(a, b)
    return None if pair is None else _named(a, b, *pair)


def _first_touching(a: Schedule, b: Schedule) -> tuple[Touch, Touch] | None:
    """The first touches of the two that share a cell at one time. Each schedule's touches
    follow one another in time, so one sweep over both finds it."""
    if a.touched.isdisjoint(b.touched):
        return None  # never near each other (most pairs of a large fleet)
    ta, tb = a.touches(), b.touches()
    i = j = 0
    while i < len(ta) and j < len(tb):
        x, y = ta[i], tb[j]
        if max(x.t0, y.t0) < min(x.t1, y.t1) and x.cells & y.cells:
            return x, y
        if x.t1 <= y.t1:
            i += 1
        else:
            j += 1
    return None


def _named(a: Schedule, b: Schedule, x: Touch, y: Touch) -> Collision:
    shared = x.cells & y.cells
    t = max(x.t0, y.t0)
    if x.moving and y.moving:
        a0, a1 = a.cells[x.node], a.cells[x.node + 1]
        b0, b1 = b.cells[y.node], b.cells[y.node + 1]
        if a0 == b1 and a1 == b0:
            return Collision(a.vehicle, b.vehicle, x.node, y.node, CollisionKind.SWAP, t,
                             shared)
        diagonal = a0[0] != a1[0] and a0[1] != a1[1] and b0[0] != b1[0] and b0[1] != b1[1]
        if diagonal and (a0[0] + a1[0], a0[1] + a1[1]) == (b0[0] + b1[0], b0[1] + b1[1]):
            return Collision(a.vehicle, b.vehicle, x.node, y.node, CollisionKind.DIAGONAL, t,
                             shared)
    return Collision(a.vehicle, b.vehicle, _node_at(a, x, shared), _node_at(b, y, shared),
                     CollisionKind.NODE, t, shared)


def _node_at(s: Schedule, touch: Touch, shared: frozenset[Cell]) -> int:
    """The node of the route where the contested cell lies: the one it stands on, the one
    a move leads to, or (a cell only a diagonal's corner sweeps) the one it leads to."""
    if touch.moving and s.cells[touch.node] in shared and s.cells[touch.node + 1] not in shared:
        return touch.node
    return touch.node + 1 if touch.moving else touch.node


def who_waits(c: Collision, a: Schedule, b: Schedule, cell_areas: Mapping[Cell, Area]
              ) -> tuple[int, int, str]:
    """The rule of Section 5.3 for collision `c`: (vehicle, node it waits at, rule)."""

    def area(s: Schedule, node: int) -> Area | None:
        return cell_areas.get(s.cells[max(node, 0)])

    def later(x: Schedule, i: int, y: Schedule, j: int) -> bool:
        """Whether x clears its collision node after y does (it is the one to wait)."""
        tx = x.arrivals[min(i + 1, len(x.cells) - 1)]
        ty = y.arrivals[min(j + 1, len(y.cells) - 1)]
        return (tx, x.vehicle) > (ty, y.vehicle)

    def outside(s: Schedule, node: int, junction: Area) -> int:
        """The last node before `node` that is not in the junction."""
        k = node - 1
        while k > 0 and area(s, k) is junction:
            k -= 1
        return max(k, 0)

    def by_time(rule: str, junction: Area | None = None) -> tuple[int, int, str]:
        s, i = (a, c.alpha) if later(a, c.alpha, b, c.beta) else (b, c.beta)
        node = outside(s, i, junction) if junction else max(i - 1, 0)
        return s.vehicle, node, rule

    def came_out(s: Schedule, node: int) -> int | None:
        """The N node `s` comes straight out of to reach `node`: the one before it, or the
        one before that when the way out crosses the near lane (N cell, access cell, far
        lane in one line: one move out of N for lane_route, its access cell passed)."""
        if node >= 1 and area(s, node - 1) is Area.OFF_CHANNEL:
            return node - 1
        if node >= 2 and area(s, node - 2) is Area.OFF_CHANNEL:
            (x0, y0), (x1, y1), (x2, y2) = s.cells[node - 2:node + 1]
            if (x1 - x0, y1 - y0) == (x2 - x1, y2 - y1):
                return node - 2
        return None

    here_a, here_b = area(a, c.alpha), area(b, c.beta)
    h, v = Area.HORIZONTAL, Area.LONGITUDINAL
    for junction in (Area.CROSSROAD, Area.T_CROSSROAD):
        if here_a is junction and here_b is junction:
            # Where each came from: the paper looks two nodes back (C_{α-2}), past the 2 x 2
            # junction for one going straight; one turning inside it is two back still in
            # it, so this looks back to the last node outside.
            came_a = area(a, outside(a, c.alpha, junction))
            came_b = area(b, outside(b, c.beta, junction))
            if {came_a, came_b} == {h, v}:  # (13): longitudinal priority
                s, i = (a, c.alpha) if came_a is h else (b, c.beta)
                return s.vehicle, outside(s, i, junction), f"{junction.value}: horizontal waits"
            if came_a is came_b and came_a in (h, v):  # (14), (16)
                return by_time(f"{junction.value}: later clears, waits", junction)
    channels = (h, v)
    if here_a in channels and here_b in channels:  # (17)
        out_a, out_b = came_out(a, c.alpha), came_out(b, c.beta)
        if (out_a is None) != (out_b is None):  # (18): the one leaving N waits in N
            s, k = (a, out_a) if out_a is not None else (b, out_b)
            return s.vehicle, k, "channel: leaving N waits in N"
    return by_time("later clears, waits")


@dataclass(frozen=True)
class Settled:
    """The schedules a change leaves (every one it changed), the waits that made them, and
    whether a deadlock is left for the caller (with the collision it could not settle)."""

    schedules: dict[int, Schedule]
    waits: tuple[WaitOrder, ...]
    deadlock: Collision | None = None


def settle(own: Schedule, others: Mapping[int, Schedule], cell_areas: Mapping[Cell, Area],
           now: float, limit: int = MAX_RESOLUTIONS) -> Settled:
    """Settle every collision of `own` (a new or changed schedule) with `others` (already
    apart from one another), earliest first, by the rules."""
    current = {**others, own.vehicle: own}
    changed = [own.vehicle]
    waits: list[WaitOrder] = []
    collision = None
    for _ in range(limit):
        collision = _earliest(current, changed)
        if collision is None:
            return Settled({v: current[v] for v in changed}, tuple(waits))
        order = _order(collision, current, cell_areas, now)
        if order is None:
            break
        current[order.vehicle] = current[order.vehicle].waited(order.node, order.seconds)
        if order.vehicle not in changed:
            changed.append(order.vehicle)
        waits.append(order)
    return Settled({v: current[v] for v in changed}, tuple(waits), collision)


def _earliest(current: Mapping[int, Schedule], changed: list[int]) -> Collision | None:
    found = []
    for v in changed:
        for w, other in sorted(current.items()):
            if w != v and (w not in changed or w > v):
                c = first_collision(current[v], other)
                if c is not None:
                    found.append(c)
    return min(found, key=lambda c: (c.t, c.a, c.b), default=None)


def _order(c: Collision, current: Mapping[int, Schedule], cell_areas: Mapping[Cell, Area],
           now: float) -> WaitOrder | None:
    """The wait the rule names, or the other's when the named one cannot wait there (it
    left that node already, or waiting there would not keep it off the cells)."""
    a, b = current[c.a], current[c.b]
    vehicle, node, rule = who_waits(c, a, b, cell_areas)
    first = _wait(c, current, vehicle, node, rule, now)
    if first is not None:
        return first
    other = c.b if vehicle == c.a else c.a
    cells = current[other].cells
    at = (c.beta if other == c.b else c.alpha) - 1
    while at > 0 and cell_areas.get(cells[at]) in (Area.CROSSROAD, Area.T_CROSSROAD):
        at -= 1  # it waits before the junction, not inside it
    return _wait(c, current, other, max(at, 0), rule + "; the other had left, so this one",
                 now)


def _wait(c: Collision, current: Mapping[int, Schedule], vehicle: int, node: int,
          rule: str, now: float) -> WaitOrder | None:
    """`vehicle` waits at `node` until the other stops touching the cell they share; None
    when it cannot: it has left that node, the shared touch comes no later (waiting there
    does not move it), or the other never leaves."""
    s = current[vehicle]
    if s.departure(node) < now:
        return None
    mine, theirs = _first_touching(s, current[c.b if vehicle == c.a else c.a])
    shifted = (mine.moving and mine.node >= node) or (not mine.moving and mine.node > node)
    seconds = theirs.t1 - mine.t0
    if not shifted or seconds == float("inf"):
        return None
    return WaitOrder(vehicle, node, seconds, rule, c)
