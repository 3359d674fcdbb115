"""Whether each vehicle's recorded states are physically possible: between two of its states
no point of its body moved faster than its kind's maximum speed, and a state that says the
vehicle stands still puts it exactly on a grid pose (its reference point on a cell's centre,
its heading one of the four), the pose the state names.

Like the safety verifier, it re-derives everything from the recorded (x, y, theta) with its
own geometry (fleet.analysis.safety's body corners) and takes from the vehicle kind only
numbers: its outline and its maximum speed.
"""

from __future__ import annotations

import math
from collections import defaultdict
from collections.abc import Callable
from dataclasses import dataclass

from fleet.analysis.safety import Body, Cell, corners
from fleet.planning.trajectory import Pose
from fleet.wire.protocol import VehicleState

# Recorded poses are floats computed from grid numbers: a vehicle this close to a grid pose
# stands on it, and a move this much longer than its speed allows is rounding.
POSITION_TOLERANCE_M = 1e-6
HEADING_TOLERANCE_RAD = 1e-9
QUARTER = math.pi / 2


@dataclass(frozen=True)
class Impossible:
    """A state that no vehicle of the kind can be in, after the one before it."""

    vehicle: int
    t: float
    why: str


def grid_pose(body: Body, x: float, y: float, theta: float) -> Pose | None:
    """The grid pose a vehicle at (x, y, theta) stands exactly on (None: it stands on none)."""
    ox, oy = body.origin
    col, row = (x - ox) / body.cell_size, (y - oy) / body.cell_size
    heading = theta / QUARTER
    cell: Cell = (round(col), round(row))
    if abs(col - cell[0]) * body.cell_size > POSITION_TOLERANCE_M or \
            abs(row - cell[1]) * body.cell_size > POSITION_TOLERANCE_M or \
            abs(heading - round(heading)) * QUARTER > HEADING_TOLERANCE_RAD:
        return None
    return Pose(cell, round(heading) % 4)


def at_rest(state: VehicleState, is_wait: Callable[[str], bool]) -> bool:
    """Whether the state says the vehicle stands still: between maneuvers, or waiting in one."""
    return state.maneuver == "" or is_wait(state.maneuver)


def points(body: Body, m: VehicleState) -> list[tuple[float, float]]:
    """The body's reference point and corners: no point of it moves farther than these."""
    return [(m.x, m.y), *corners(body, m.x, m.y, m.theta)]


def impossible_states(states: list[tuple[float, VehicleState]], body: Body, max_speed: float,
                      is_wait: Callable[[str], bool]) -> list[Impossible]:
    """Every state that is not physically possible: standing still off a grid pose (or on
    another than it names, or at a speed level above 0), or reached from the vehicle's
    previous state faster than `max_speed` (m/s, any point of the body) allows."""
    by_vehicle: dict[int, list[tuple[float, VehicleState]]] = defaultdict(list)
    for t, m in states:
        by_vehicle[m.vehicle].append((t, m))
    found = []
    for vehicle, own in sorted(by_vehicle.items()):
        own.sort(key=lambda tm: tm[0])
        before: tuple[float, list[tuple[float, float]]] | None = None
        for t, m in own:
            now = (t, points(body, m))
            why = _standing_wrong(body, m, is_wait) or \
                (_too_fast(before, now, max_speed) if before else "")
            if why:
                found.append(Impossible(vehicle, t, why))
            before = now
    return found


def _standing_wrong(body: Body, m: VehicleState, is_wait: Callable[[str], bool]) -> str:
    if not at_rest(m, is_wait):
        return ""
    pose = grid_pose(body, m.x, m.y, m.theta)
    if pose is None:
        return (f"stands still off every grid pose, at ({m.x:.3f}, {m.y:.3f}) heading "
                f"{math.degrees(m.theta):.1f} deg")
    said = Pose.parse(m.pose)
    if said != pose:
        return f"stands still on {pose} but says {said}"
    if m.speed != 0:
        return f"stands still at speed level {m.speed}"
    return ""


def _too_fast(before: tuple[float, list[tuple[float, float]]],
              now: tuple[float, list[tuple[float, float]]], max_speed: float) -> str:
    (t0, a), (t1, b) = before, now
    moved = max(math.dist(p, q) for p, q in zip(a, b, strict=True))
    if moved <= max_speed * (t1 - t0) + POSITION_TOLERANCE_M:
        return ""
    if t1 == t0:
        return f"two states at one instant, {moved:.3f} m apart"
    return (f"moved {moved:.3f} m in {t1 - t0:.3f} s ({moved / (t1 - t0):.2f} m/s; at most "
            f"{max_speed:.2f})")
