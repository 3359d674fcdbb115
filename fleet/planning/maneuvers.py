"""The eleven node-expansion manners of seed 000 (Section 4.1) and the cells each one sweeps.

A pose is a grid cell (the cell holding the rear-axle point P) plus one of four headings. With
2 m cells and the Table 3 body, the rear end (fork tips) lies on the border of P's cell and the
body covers P's cell and the one ahead of it: a forklift covers two cells.

Paths follow the kinematics of Section 2.2: straight moves are one cell long, a turn is a
quarter circle of radius one cell (the rear axle ends one cell ahead and one to the side), and a
lane change is two opposite arcs that shift the vehicle one cell sideways over two cells of
travel. Reverse manners are the forward ones driven backwards (Figure 8: "initial and final
body outlines are exchanged"). The swept cells are computed once, from densely sampled body
rectangles, for every manner and heading.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from enum import Enum
from functools import cache

from fleet.params import VehicleDims
from fleet.planning.geometry import Cell, body_corners, cells_swept, cells_under

HEADINGS = ("E", "N", "W", "S")  # heading index h means angle h * 90 degrees
STEPS: tuple[Cell, ...] = ((1, 0), (0, 1), (-1, 0), (0, -1))
SAMPLES = 360  # per maneuver: 0.25 degree of a turn, far finer than any sliver


class Kind(Enum):
    STOP = "stop"
    STRAIGHT = "straight"
    TURN = "turn"
    LANE = "lane"

    # Members are singletons compared by identity: hash them so (Enum's own hash is a call in
    # Python, and the planner's innermost loops look them up in dicts).
    __hash__ = object.__hash__


class Manner(Enum):
    """The eleven expansion manners: (kind, direction +1 forward / -1 reverse, side +1 left)."""

    STOP = ("stop", Kind.STOP, 0, 0)
    FORWARD = ("forward", Kind.STRAIGHT, 1, 0)
    REVERSE = ("reverse", Kind.STRAIGHT, -1, 0)
    TURN_LEFT = ("turn-left", Kind.TURN, 1, 1)
    TURN_RIGHT = ("turn-right", Kind.TURN, 1, -1)
    TURN_LEFT_REVERSE = ("turn-left-reverse", Kind.TURN, -1, 1)
    TURN_RIGHT_REVERSE = ("turn-right-reverse", Kind.TURN, -1, -1)
    LANE_LEFT = ("lane-left", Kind.LANE, 1, 1)
    LANE_RIGHT = ("lane-right", Kind.LANE, 1, -1)
    LANE_LEFT_REVERSE = ("lane-left-reverse", Kind.LANE, -1, 1)
    LANE_RIGHT_REVERSE = ("lane-right-reverse", Kind.LANE, -1, -1)

    # Members are singletons compared by identity: hash them so (Enum's own hash is a call in
    # Python, and the planner's innermost loops look them up in dicts).
    __hash__ = object.__hash__

    def __init__(self, label: str, kind: Kind, direction: int, side: int) -> None:
        self.label = label
        self.kind = kind
        self.direction = direction
        self.side = side

    @classmethod
    def from_label(cls, label: str) -> Manner:
        for manner in cls:
            if manner.label == label:
                return manner
        raise ValueError(f"unknown maneuver {label!r}")


LANE_ANGLE = 2 * math.atan(0.5)  # each arc of a lane change turns this much (53.13 degrees)
LANE_RADIUS = 1.25  # in cells: two arcs of this radius shift 1 cell over 2 cells of travel


def local_pose(manner: Manner, s: float) -> tuple[float, float, float]:
    """Pose at progress s in [0, 1] in the start frame, in cells: (ahead, left, heading change).
    Turning and lane changing in reverse steer to the side named, so the heading turns the
    other way."""
    d, side = manner.direction, manner.side
    if manner.kind is Kind.STOP:
        return 0.0, 0.0, 0.0
    if manner.kind is Kind.STRAIGHT:
        return d * s, 0.0, 0.0
    if manner.kind is Kind.TURN:
        phi = s * math.pi / 2
        return d * math.sin(phi), side * (1 - math.cos(phi)), d * side * phi
    # Lane change: an arc to the side, then the point-mirrored arc back to the old heading.
    if s <= 0.5:
        phi = 2 * s * LANE_ANGLE
        ahead = LANE_RADIUS * math.sin(phi)
        left = LANE_RADIUS * (1 - math.cos(phi))
    else:
        phi = 2 * (1 - s) * LANE_ANGLE
        ahead = 2 - LANE_RADIUS * math.sin(phi)
        left = 1 - LANE_RADIUS * (1 - math.cos(phi))
    return d * ahead, side * left, d * side * phi


@cache
def arc_length(manner: Manner) -> float:
    """Path length of a manner in cells (the rear-axle point's arc, finely sampled)."""
    points = [local_pose(manner, k / 200)[:2] for k in range(201)]
    return sum(math.dist(a, b) for a, b in itertools.pairwise(points))


def end_offset(manner: Manner) -> tuple[Cell, int]:
    """Cell offset (ahead, left) and heading change in quarter turns at the end of a manner."""
    ahead, left, dtheta = local_pose(manner, 1.0)
    return (round(ahead), round(left)), round(dtheta / (math.pi / 2))


def rotate(offset: Cell, heading: int) -> Cell:
    """Rotate a (ahead, left) offset given for heading E to the given heading."""
    a, b = offset
    for _ in range(heading % 4):
        a, b = -b, a
    return a, b


def world_pose(cell: Cell, heading: int, manner: Manner, s: float,
               cell_size: float) -> tuple[float, float, float]:
    """World pose (x, y, theta) at progress s of a manner started at cell/heading; cell (0, 0)
    is centred at the origin of this frame."""
    ahead, left, dtheta = local_pose(manner, s)
    theta0 = heading * math.pi / 2
    c, sn = math.cos(theta0), math.sin(theta0)
    x = cell[0] * cell_size + (ahead * c - left * sn) * cell_size
    y = cell[1] * cell_size + (ahead * sn + left * c) * cell_size
    return x, y, theta0 + dtheta


@dataclass(frozen=True)
class Move:
    """One manner applied at one heading, with cells as offsets from the start cell.

    start_cells / end_cells: the body at the start and end pose; middle_cells: everything else
    the body sweeps in between (Algorithm 3's intermediate grids); swept = all three."""

    manner: Manner
    heading: int
    end_delta: Cell
    end_heading: int
    start_cells: frozenset[Cell]
    middle_cells: frozenset[Cell]
    end_cells: frozenset[Cell]

    @property
    def swept(self) -> frozenset[Cell]:
        return self.start_cells | self.middle_cells | self.end_cells


def pose_cells(cell: Cell, heading: int, dims: VehicleDims, cell_size: float) -> frozenset[Cell]:
    """Cells the body covers at rest."""
    x, y = cell[0] * cell_size, cell[1] * cell_size
    return frozenset(cells_under(body_corners(x, y, heading * math.pi / 2, dims), cell_size))


@cache
def move_table(dims: VehicleDims = VehicleDims(), cell_size: float = 2.0) -> dict[
        tuple[Manner, int], Move]:
    """Every (manner, heading) move, precomputed once per body and cell size. The sweep is
    sampled for heading E and rotated to the others (the grid is symmetric under quarter
    turns)."""
    table = {}
    for manner in Manner:
        (ahead, left), quarter_turns = end_offset(manner)
        poses = [world_pose((0, 0), 0, manner, i / SAMPLES, cell_size)
                 for i in range(SAMPLES + 1)]
        swept_east = cells_swept(poses, dims, cell_size)
        start_east = pose_cells((0, 0), 0, dims, cell_size)
        end_east = frozenset((ahead + a, left + b) for a, b in
                             (rotate(c, quarter_turns) for c in start_east))
        for heading in range(4):
            def turned(cells: frozenset[Cell], h: int = heading) -> frozenset[Cell]:
                return frozenset(rotate(c, h) for c in cells)

            start, end = turned(start_east), turned(end_east)
            table[manner, heading] = Move(manner, heading, rotate((ahead, left), heading),
                                          (heading + quarter_turns) % 4, start,
                                          turned(frozenset(swept_east)) - start - end, end)
    return table


def body_cells_at_rest(cell: Cell, heading: int) -> tuple[Cell, Cell]:
    """The two cells of a forklift at rest on the default grid: P's cell and the one ahead."""
    step = STEPS[heading]
    return cell, (cell[0] + step[0], cell[1] + step[1])


def fork_target(cell: Cell, heading: int) -> Cell:
    """The cell the forks point at (directly behind P's cell)."""
    step = STEPS[heading]
    return cell[0] - step[0], cell[1] - step[1]
