"""Brute-force trajectory checker for tests, written apart from the planner.

It shares no collision code with fleet: it re-derives each maneuver's path from the start and
end poses (a straight line, a quarter circle, or two opposite arcs), fills the body rectangle
with sample points, and maps every point to its cell. Every cell a point lands in must be
reserved by the vehicle for the whole step; the final cells must be reserved to infinity; no
reserved interval may overlap another vehicle's; and every step's duration must be one of
Table 1's links.
"""

from __future__ import annotations

import functools
import math
from types import SimpleNamespace

CELL = 2.0
FRONT, REAR, HALF_WIDTH = 1.8, 1.0, 0.5
DIRS = {0: (1, 0), 1: (0, 1), 2: (-1, 0), 3: (0, -1)}
T = {"T1": 4, "T2": 2, "T3": 1.25, "T4": 0.75, "T5": 0.5, "T6": 8, "T7": 5, "T8": 3, "T9": 12,
     "T10": 8, "T11": 5, "T12": 1}
DURATIONS = {  # (kind, v0, v1) -> seconds, Table 1
    ("straight", 0, 0): T["T1"], ("straight", 0, 1): T["T2"], ("straight", 1, 0): T["T2"],
    ("straight", 1, 1): T["T3"], ("straight", 1, 2): T["T4"], ("straight", 2, 1): T["T4"],
    ("straight", 2, 2): T["T5"], ("turn", 0, 0): T["T6"], ("turn", 0, 1): T["T7"],
    ("turn", 1, 0): T["T7"], ("turn", 1, 1): T["T8"], ("lane", 0, 0): T["T9"],
    ("lane", 0, 1): T["T10"], ("lane", 1, 0): T["T10"], ("lane", 1, 1): T["T11"],
    ("stop", 0, 0): T["T12"],
}


def body_points(x, y, theta, spacing=0.02, inset=1e-7):
    """Points along the body outline, a hair inside it. The body (2.8 m x 1 m) is never inside
    one 2 m cell and never covers one, so it enters exactly the cells its outline enters."""
    c, s = math.cos(theta), math.sin(theta)
    lo, hi = -REAR + inset, FRONT - inset
    w = HALF_WIDTH - inset
    outline = []
    n_lon = round((hi - lo) / spacing)
    n_lat = round(2 * w / spacing)
    for i in range(n_lon + 1):
        lon = lo + (hi - lo) * i / n_lon
        outline += [(lon, w), (lon, -w)]
    for j in range(n_lat + 1):
        lat = -w + 2 * w * j / n_lat
        outline += [(lo, lat), (hi, lat)]
    for lon, lat in outline:
        yield x + lon * c - lat * s, y + lon * s + lat * c


def point_cell(px, py):
    return math.floor(px / CELL + 0.5), math.floor(py / CELL + 0.5)


def path(start, end, kind, samples=120):
    """Poses (x, y, theta) along a step, from its start and end poses alone."""
    (sx, sy), sh = start.cell, start.heading
    ex, ey = end.cell
    x0, y0, x1, y1 = sx * CELL, sy * CELL, ex * CELL, ey * CELL
    th0 = sh * math.pi / 2
    fx, fy = math.cos(th0), math.sin(th0)
    ahead = (x1 - x0) * fx + (y1 - y0) * fy
    left = -(x1 - x0) * fy + (y1 - y0) * fx
    out = []
    for k in range(samples + 1):
        u = k / samples
        if kind in ("stop", "straight"):
            a, b, dth = ahead * u, 0.0, 0.0
        elif kind == "turn":
            r = abs(ahead)  # quarter circle: |ahead| = |left| = one cell
            phi = u * math.pi / 2
            a = math.copysign(r * math.sin(phi), ahead)
            b = math.copysign(r * (1 - math.cos(phi)), left)
            dth = math.copysign(phi, ahead * left)
        else:  # lane change: two arcs of equal radius and angle, mirrored at the midpoint
            half_a, half_b = abs(ahead) / 2, abs(left) / 2
            alpha = 2 * math.atan2(half_b, half_a)
            r = half_a / math.sin(alpha)
            if u <= 0.5:
                phi = 2 * u * alpha
                a0, b0 = r * math.sin(phi), r * (1 - math.cos(phi))
            else:
                phi = 2 * (1 - u) * alpha
                a0, b0 = abs(ahead) - r * math.sin(phi), abs(left) - r * (1 - math.cos(phi))
            a, b = math.copysign(a0, ahead), math.copysign(b0, left)
            dth = math.copysign(phi, ahead * left)
        out.append((x0 + a * fx - b * fy, y0 + a * fy + b * fx, th0 + dth))
    return out


def cells_visited(start, end, kind):
    (sx, sy), (ex, ey) = start.cell, end.cell
    return {(sx + a, sy + b) for a, b in _cells_from_origin(start.heading, ex - sx, ey - sy,
                                                             kind)}


@functools.cache
def _cells_from_origin(heading, dx, dy, kind):
    """The sweep of a step that starts at cell (0, 0); a step elsewhere is this one moved by
    whole cells (cells are 2 m and the sample points sit 1e-7 m inside the body, far above
    float rounding), so whole missions are checked in seconds."""
    start = SimpleNamespace(cell=(0, 0), heading=heading)
    end = SimpleNamespace(cell=(dx, dy))
    cells = set()
    for x, y, th in path(start, end, kind):
        for px, py in body_points(x, y, th):
            cells.add(point_cell(px, py))
    return frozenset(cells)


def holds(intervals, cell, t0, t1):
    """The trajectory's own intervals cover [t0, t1) on the cell."""
    return any(iv.cell == cell and iv.t0 <= t0 and t1 <= iv.t1 for iv in intervals)


def check_trajectory(traj, others, grid=None):
    """Return a list of problems (empty when the trajectory is sound).

    others: iterable of (vehicle, cell, t0, t1) reservations of other vehicles."""
    problems = []
    t = traj.t_start
    for i, step in enumerate(traj.steps):
        kind = step.manner.kind.value
        if step.t0 != t:
            problems.append(f"step {i} starts at {step.t0}, previous ended at {t}")
        t = step.t1
        expected = DURATIONS.get((kind, int(step.v0), int(step.v1)))
        if expected is None or step.t1 - step.t0 != expected:
            problems.append(f"step {i} {kind} {int(step.v0)}->{int(step.v1)} lasts "
                            f"{step.t1 - step.t0}, Table 1 says {expected}")
        for cell in cells_visited(step.start, step.end, kind):
            if grid is not None and not grid.free(cell):
                problems.append(f"step {i} enters blocked cell {cell}")
            if not holds(traj.intervals, cell, step.t0, step.t1):
                problems.append(f"step {i} ({kind}) enters {cell} outside its reservation")
        if i + 1 < len(traj.steps) and traj.steps[i + 1].start != step.end:
            problems.append(f"step {i + 1} does not start where step {i} ended")
    final = traj.steps[-1].end if traj.steps else traj.start
    for px, py in body_points(final.cell[0] * CELL, final.cell[1] * CELL,
                              final.heading * math.pi / 2):
        cell = point_cell(px, py)
        if not holds(traj.intervals, cell, traj.t_end, math.inf):
            problems.append(f"parked cell {cell} not reserved to infinity")
            break
    for iv in traj.intervals:
        for vehicle, cell, t0, t1 in others:
            if vehicle != traj.vehicle and cell == iv.cell and iv.t0 < t1 and t0 < iv.t1:
                problems.append(f"{iv} overlaps vehicle {vehicle} on {cell} [{t0}, {t1})")
    return problems
