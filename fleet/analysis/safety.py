"""The safety verifier: from what was recorded, did two vehicles ever share a cell at the same
time, and did any vehicle stand outside its own reservation?

Deliberately independent of the code it checks: it imports neither the planner nor the
reservation table nor the geometry they share, nor the vehicle kinds. It replays the recorded
table changes itself, and recomputes the cells under a vehicle's body from its recorded pose
(x, y, theta) and the numbers of the body's outline with its own separating-axis test.
Vehicles publish their states on one grid of instants, so two vehicles are compared at the
very same instants; and between them: each vehicle's pose is interpolated between two of its
states, its body shrunk by how far the interpolation may be off (docs/metrics.md), and two
shrunk bodies on one cell are an overlap too.
"""

from __future__ import annotations

import bisect
import itertools
import math
from collections import defaultdict
from dataclasses import dataclass
from functools import lru_cache

Cell = tuple[int, int]
# A body entering a cell by less than this (metres) touches it, not occupies it: recorded
# poses are rounded floats, and a body flush with a cell border must not count as inside.
TOLERANCE_M = 1e-6


@dataclass(frozen=True)
class Body:
    """A vehicle's rectangle about its reference point (its kind's outline: for seed 000's
    forklift the rear-axle point; a square 1-cell body has front = rear = width / 2), and the
    grid it stands on."""

    front: float
    rear: float
    width: float
    cell_size: float
    origin: tuple[float, float]  # world position of the centre of cell (0, 0)


@dataclass(frozen=True)
class Sample:
    vehicle: int
    t: float
    x: float
    y: float
    theta: float


@dataclass(frozen=True)
class Held:
    """A cell a vehicle held over [t0, t1) once every recorded change is applied."""

    vehicle: int
    cell: Cell
    t0: float
    t1: float


@dataclass(frozen=True)
class Overlap:
    t: float
    vehicles: tuple[int, int]
    cells: tuple[Cell, ...]
    between: bool = False  # at an instant where one of them has no state: interpolated


@dataclass(frozen=True)
class Outside:
    t: float
    vehicle: int
    cells: tuple[Cell, ...]  # cells under the body that the vehicle did not hold at t


@dataclass(frozen=True)
class DoubleBooking:
    cell: Cell
    vehicles: tuple[int, int]
    t0: float
    t1: float


def replay(changes: list[tuple]) -> list[Held]:
    """Apply (op, vehicle, intervals, release_from[, release_cells]) changes in order: a
    release (or a commit with release_from) gives up the vehicle's cells (those listed, if
    any are) from that instant on; a commit adds."""
    held: dict[int, list[Held]] = defaultdict(list)
    for op, vehicle, intervals, release_from, *rest in changes:
        only = {tuple(c) for c in rest[0]} if rest and rest[0] is not None else None
        if release_from is not None:
            kept = []
            for h in held[vehicle]:
                if (only is not None and h.cell not in only) or h.t1 <= release_from:
                    kept.append(h)  # not asked, or over by then: as it was
                elif h.t0 < release_from:
                    kept.append(Held(vehicle, h.cell, h.t0, min(h.t1, release_from)))
            held[vehicle] = kept
        if op == "commit":
            held[vehicle] += [Held(vehicle, (c, r), t0, t1) for c, r, t0, t1 in intervals
                              if t1 > t0]
    return [h for hs in held.values() for h in hs]


def corners(body: Body, x: float, y: float, theta: float) -> list[tuple[float, float]]:
    """The body's four corners at (x, y, theta)."""
    c, s = math.cos(theta), math.sin(theta)
    half = body.width / 2
    return [(x + lon * c - lat * s, y + lon * s + lat * c)
            for lon, lat in ((body.front, half), (-body.rear, half), (-body.rear, -half),
                             (body.front, -half))]


@lru_cache(maxsize=65536)
def covered_cells(body: Body, x: float, y: float, theta: float) -> frozenset[Cell]:
    """Cells whose interior the body at (x, y, theta) enters."""
    c, s = math.cos(theta), math.sin(theta)
    ox, oy = body.origin
    size = body.cell_size
    around = corners(body, x, y, theta)
    xs = [p[0] - ox + size / 2 for p in around]  # cell (i, j) spans [i, i+1) * size here
    ys = [p[1] - oy + size / 2 for p in around]
    local = list(zip(xs, ys, strict=True))
    axes = [(c, s), (-s, c)]  # the body's own axes; the grid's are tested by the box bounds
    found = set()
    for i in range(math.floor(min(xs) / size), math.floor(max(xs) / size) + 1):
        for j in range(math.floor(min(ys) / size), math.floor(max(ys) / size) + 1):
            x0, y0 = i * size, j * size
            if min(xs) >= x0 + size - TOLERANCE_M or max(xs) <= x0 + TOLERANCE_M:
                continue
            if min(ys) >= y0 + size - TOLERANCE_M or max(ys) <= y0 + TOLERANCE_M:
                continue
            square = [(x0, y0), (x0 + size, y0), (x0, y0 + size), (x0 + size, y0 + size)]
            if all(_projections_overlap(ax, local, square) for ax in axes):
                found.add((i, j))
    return frozenset(found)


def _projections_overlap(axis: tuple[float, float], a: list, b: list) -> bool:
    pa = [axis[0] * p[0] + axis[1] * p[1] for p in a]
    pb = [axis[0] * p[0] + axis[1] * p[1] for p in b]
    return min(pa) < max(pb) - TOLERANCE_M and max(pa) > min(pb) + TOLERANCE_M


# Between two consecutive instants of the fleet's states, the poses are also compared here
# (fractions of the way): in the middle the interpolation is least sure, at the quarters less.
BETWEEN = (0.25, 0.5, 0.75)


@dataclass(frozen=True)
class Placed:
    """Where a vehicle's body is at an instant: recorded (`off` 0), or interpolated between
    two of its states, each point of it at most `off` metres from where it really was."""

    x: float
    y: float
    theta: float
    off: float
    still: tuple[float, ...] = ()  # interpolated between two states at one pose: their instants


def overlaps(samples: list[Sample], body: Body, max_speed: float,
             max_gap: float) -> list[Overlap]:
    """Every instant at which two vehicles' bodies were on a common cell: at each instant
    some vehicle has a state, and between two consecutive such instants. A vehicle without a
    state at the instant is placed by interpolating between its states around it (at most
    `max_gap` apart; farther apart, it is not placed), its body shrunk by `placed`'s bound."""
    tracks = _tracks(samples)
    instants = sorted({s.t for s in samples})
    checks = sorted(instants + [a + f * (b - a) for a, b in itertools.pairwise(instants)
                                for f in BETWEEN])
    reach = math.hypot(max(body.front, body.rear), body.width / 2)
    near = 2 * reach + body.cell_size * math.sqrt(2)  # farther apart, no cell in common
    found = []
    for t in checks:
        at = [(v, p) for v, track in tracks.items()
              if (p := placed(track, t, max_speed, max_gap, reach)) is not None]
        for k, (a, pa) in enumerate(at):
            for b, pb in at[k + 1:]:
                if set(pa.still) & set(pb.still) or \
                        math.hypot(pa.x - pb.x, pa.y - pb.y) > near:
                    continue  # both standing still where they were compared at one instant
                common = shrunk_cells(body, pa) & shrunk_cells(body, pb)
                if common:
                    found.append(Overlap(t, (min(a, b), max(a, b)), tuple(sorted(common)),
                                         bool(pa.off or pb.off)))
    return found


def _tracks(samples: list[Sample]) -> dict[int, tuple[list[float], list[Sample]]]:
    """Each vehicle's samples in time order (one per instant), with their instants."""
    by_vehicle: dict[int, dict[float, Sample]] = defaultdict(dict)
    for s in samples:
        by_vehicle[s.vehicle].setdefault(s.t, s)
    return {v: (sorted(own), [own[t] for t in sorted(own)])
            for v, own in sorted(by_vehicle.items())}


def placed(track: tuple[list[float], list[Sample]], t: float, max_speed: float,
           max_gap: float, reach: float) -> Placed | None:
    """The vehicle at t: its state at t, or interpolated between its states around t. A
    point's interpolated place is off by at most max_speed * a * b / (a + b) (a, b: the
    time from the state before and to the state after; a point whose velocity changes by at
    most max_speed over the interval), and the body turned to the interpolated heading puts a
    point at most reach * (1 - cos(dtheta / 2)) off the straight line between its places."""
    times, own = track
    k = bisect.bisect_left(times, t)
    if k < len(times) and times[k] == t:
        s = own[k]
        return Placed(s.x, s.y, s.theta, 0.0)
    if k == 0 or k == len(times) or times[k] - times[k - 1] > max_gap:
        return None
    s0, s1 = own[k - 1], own[k]
    a, b = t - s0.t, s1.t - t
    f = a / (a + b)
    turn = math.remainder(s1.theta - s0.theta, 2 * math.pi)
    off = max_speed * a * b / (a + b) + reach * (1 - math.cos(turn / 2))
    still = (s0.t, s1.t) if (s0.x, s0.y, s0.theta) == (s1.x, s1.y, s1.theta) else ()
    return Placed(s0.x + f * (s1.x - s0.x), s0.y + f * (s1.y - s0.y), s0.theta + f * turn,
                  off, still)


def shrunk_cells(body: Body, p: Placed) -> frozenset[Cell]:
    """The cells the body enters at p, shrunk by how far p may be off: the real body holds
    the shrunk one (nothing, once the bound is half its width)."""
    if p.off == 0:
        return covered_cells(body, p.x, p.y, p.theta)
    if min(body.front + body.rear, body.width) <= 2 * p.off:
        return frozenset()
    shrunk = Body(body.front - p.off, body.rear - p.off, body.width - 2 * p.off,
                  body.cell_size, body.origin)
    return covered_cells(shrunk, p.x, p.y, p.theta)


def outside_reservation(samples: list[Sample], held: list[Held], body: Body) -> list[Outside]:
    """Every recorded instant at which a vehicle's body covered a cell it did not hold."""
    windows: dict[tuple[int, Cell], list[tuple[float, float]]] = defaultdict(list)
    for h in held:
        windows[h.vehicle, h.cell].append((h.t0, h.t1))
    for spans in windows.values():
        spans.sort()
    found = []
    for s in samples:
        missing = [cell for cell in covered_cells(body, s.x, s.y, s.theta)
                   if not _holds(windows.get((s.vehicle, cell), []), s.t)]
        if missing:
            found.append(Outside(s.t, s.vehicle, tuple(sorted(missing))))
    return found


def on_goods(samples: list[Sample], goods: dict[Cell, list[tuple[float, float]]],
             body: Body) -> list[Outside]:
    """Every recorded instant at which a vehicle's body covered a stack cell while goods
    stood on it (`goods`: each stack's spans with goods, from the mission's own account of
    its stacks, not from the table): a plan must never drive through goods, and the table
    alone cannot say so where goods are not held in it."""
    spans = {cell: sorted(s) for cell, s in goods.items()}
    found = []
    for s in samples:
        on = [cell for cell in covered_cells(body, s.x, s.y, s.theta)
              if _holds(spans.get(cell, []), s.t)]
        if on:
            found.append(Outside(s.t, s.vehicle, tuple(sorted(on))))
    return found


def _holds(spans: list[tuple[float, float]], t: float) -> bool:
    started = bisect.bisect_right(spans, (t, math.inf))  # spans[:started] start at or before t
    return any(t < t1 for _, t1 in spans[:started])


def double_bookings(held: list[Held]) -> list[DoubleBooking]:
    """Cells two owners held over overlapping times (the table must never allow it)."""
    by_cell: dict[Cell, list[Held]] = defaultdict(list)
    for h in held:
        by_cell[h.cell].append(h)
    found = []
    for cell, hs in by_cell.items():
        hs.sort(key=lambda h: h.t0)
        for k, a in enumerate(hs):
            for b in hs[k + 1:]:
                if b.t0 >= a.t1:
                    break
                if a.vehicle != b.vehicle:
                    found.append(DoubleBooking(cell, (a.vehicle, b.vehicle), b.t0,
                                               min(a.t1, b.t1)))
    return found
