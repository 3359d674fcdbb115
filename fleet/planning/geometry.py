"""Plane geometry of the vehicle body on the square grid (pure functions)."""

from __future__ import annotations

import math
from collections.abc import Iterable

from fleet.params import VehicleDims

Cell = tuple[int, int]
Point = tuple[float, float]

# Overlap smaller than this (metres) is touching, not entering: a body whose edge lies on a
# cell border does not occupy the neighbouring cell.
TOUCH = 1e-9


def body_corners(x: float, y: float, theta: float, dims: VehicleDims) -> list[Point]:
    """Corners A, B, C, D of the body rectangle for rear-axle point (x, y) and heading theta."""
    c, s = math.cos(theta), math.sin(theta)
    b = dims.width / 2
    corners = []
    for lon, lat in ((dims.front, b), (-dims.rear, b), (-dims.rear, -b), (dims.front, -b)):
        corners.append((x + lon * c - lat * s, y + lon * s + lat * c))
    return corners


def _triangle_area(p: Point, q: Point, r: Point) -> float:
    return abs((q[0] - p[0]) * (r[1] - p[1]) - (r[0] - p[0]) * (q[1] - p[1])) / 2


def point_in_rectangle(point: Point, rect: list[Point]) -> bool:
    """Equation (11) of seed 000: Q lies inside ABCD iff the four triangles QAB..QDA add up to
    no more than the rectangle's area."""
    a, b, c, d = rect
    rect_area = _triangle_area(a, b, c) + _triangle_area(a, c, d)
    total = sum(_triangle_area(point, p, q) for p, q in ((a, b), (b, c), (c, d), (d, a)))
    return total <= rect_area * (1 + 1e-12)


def rect_overlaps_square(rect: list[Point], x0: float, y0: float, side: float) -> bool:
    """Separating-axis test between a rotated rectangle and an axis-aligned square,
    counting only a penetration deeper than TOUCH."""
    xs = [p[0] for p in rect]
    ys = [p[1] for p in rect]
    if min(xs) >= x0 + side - TOUCH or max(xs) <= x0 + TOUCH:
        return False
    if min(ys) >= y0 + side - TOUCH or max(ys) <= y0 + TOUCH:
        return False
    square = [(x0, y0), (x0 + side, y0), (x0 + side, y0 + side), (x0, y0 + side)]
    for i in range(2):
        ex, ey = rect[i + 1][0] - rect[i][0], rect[i + 1][1] - rect[i][1]
        norm = math.hypot(ex, ey)
        ax, ay = -ey / norm, ex / norm
        r = [ax * p[0] + ay * p[1] for p in rect]
        q = [ax * p[0] + ay * p[1] for p in square]
        if min(r) >= max(q) - TOUCH or max(r) <= min(q) + TOUCH:
            return False
    return True


def cells_under(rect: list[Point], cell_size: float) -> set[Cell]:
    """Cells (column, row) whose interior the rectangle enters; cell (0, 0) is centred at the
    origin."""
    xs = [p[0] for p in rect]
    ys = [p[1] for p in rect]
    half = cell_size / 2
    c0 = math.floor((min(xs) + half) / cell_size)
    c1 = math.floor((max(xs) + half) / cell_size)
    r0 = math.floor((min(ys) + half) / cell_size)
    r1 = math.floor((max(ys) + half) / cell_size)
    found = set()
    for i in range(c0, c1 + 1):
        for j in range(r0, r1 + 1):
            if rect_overlaps_square(rect, i * cell_size - half, j * cell_size - half, cell_size):
                found.add((i, j))
    return found


def cells_swept(poses: Iterable[tuple[float, float, float]], dims: VehicleDims,
                cell_size: float) -> set[Cell]:
    """Union of the cells under the body at each sampled pose."""
    swept: set[Cell] = set()
    for x, y, theta in poses:
        swept |= cells_under(body_corners(x, y, theta, dims), cell_size)
    return swept
