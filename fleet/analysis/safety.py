"""The safety verifier: from what was recorded, did two vehicles ever share a cell at the same
time, and did any vehicle stand outside its own reservation?

Deliberately independent of the code it checks: it imports neither the planner nor the
reservation table nor the geometry they share, nor the vehicle kinds. It replays the recorded
table changes itself, and recomputes the cells under a vehicle's body from its recorded pose
(x, y, theta) and the numbers of the body's outline with its own separating-axis test.
Vehicles publish their states on one grid of instants, so two vehicles are compared at the
very same instants.
"""

from __future__ import annotations

import bisect
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
                if only is not None and h.cell not in only:
                    kept.append(h)
                elif h.t0 < release_from:
                    kept.append(Held(vehicle, h.cell, h.t0, min(h.t1, release_from)))
            held[vehicle] = kept
        if op == "commit":
            held[vehicle] += [Held(vehicle, (c, r), t0, t1) for c, r, t0, t1 in intervals
                              if t1 > t0]
    return [h for hs in held.values() for h in hs]


@lru_cache(maxsize=65536)
def covered_cells(body: Body, x: float, y: float, theta: float) -> frozenset[Cell]:
    """Cells whose interior the body at (x, y, theta) enters."""
    c, s = math.cos(theta), math.sin(theta)
    half = body.width / 2
    corners = [(x + lon * c - lat * s, y + lon * s + lat * c)
               for lon, lat in ((body.front, half), (-body.rear, half), (-body.rear, -half),
                                (body.front, -half))]
    ox, oy = body.origin
    size = body.cell_size
    xs = [p[0] - ox + size / 2 for p in corners]  # cell (i, j) spans [i, i+1) * size here
    ys = [p[1] - oy + size / 2 for p in corners]
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


def overlaps(samples: list[Sample], body: Body) -> list[Overlap]:
    """Every instant at which two vehicles' bodies were on a common cell."""
    by_time: dict[float, list[Sample]] = defaultdict(list)
    for s in samples:
        by_time[s.t].append(s)
    found = []
    for t in sorted(by_time):
        at = by_time[t]
        cells = [(s.vehicle, covered_cells(body, s.x, s.y, s.theta)) for s in at]
        for k, (a, ca) in enumerate(cells):
            for b, cb in cells[k + 1:]:
                if a != b and ca & cb:
                    found.append(Overlap(t, (min(a, b), max(a, b)), tuple(sorted(ca & cb))))
    return found


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
