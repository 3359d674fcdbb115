"""Breaking a deadlock: a stuck vehicle in the waiting one's way is sent aside.

The first blocker that can reach a siding off the waiting vehicle's way (Open-RMF's responsive
wait: an idle or waiting vehicle in another's way moves) is sent there. When none of them can
(the way past fewest vehicles ends in a dead end whose vehicles could only leave past the
waiting one), its ways to each of its other goals are tried in turn. A blocker that cannot
move because it is itself walled in inherits the waiting vehicle's priority and has its own
blockers sent aside first (PIBT's priority inheritance), a few levels deep. Each move is a
subtask like any other: planned against the reservation table and committed before it is
driven, so the safety contract is the same. Sidings keep off `keep_clear` (the docks and the
stacks still to do) while any other siding is reachable.
"""

from __future__ import annotations

from collections.abc import Callable, Collection, Iterable, Mapping
from dataclasses import dataclass

from fleet.mission.deadlock import Deadlock, Wait
from fleet.planning.blockage import Blockage
from fleet.planning.geometry import Cell
from fleet.planning.reservations import ReservationView
from fleet.planning.trajectory import Pose, Trajectory
from fleet.vehicles.kind import Planner

SIDINGS_OFFERED = 8  # the nearest few: the planner picks the quickest to reach among them
INHERITANCE_DEPTH = 3

# Plan and commit a move of `vehicle` to any of the poses (None: it cannot go now).
MoveAside = Callable[[int, tuple[Pose, ...]], Trajectory | None]


@dataclass(frozen=True)
class SentAside:
    vehicle: int  # the one that moved
    trajectory: Trajectory
    for_vehicle: int  # whose way it opens (the waiting one, or a blocker that inherited)


def break_deadlock(deadlock: Deadlock, waits: Mapping[int, Wait], planner: Planner,
                   store: ReservationView, poses: Mapping[int, Pose],
                   keep_clear: Collection[Cell], move: MoveAside,
                   other_ways: Callable[[], Iterable[Blockage]] = tuple) -> SentAside | None:
    """Open the waiting vehicle's way by sending one vehicle aside; None if none can go.
    `other_ways`: the waiting vehicle's ways to each of its goals, asked for only when its
    own way cannot be opened."""

    def open_way(waiting: int, way: Blockage | None, avoid: frozenset[Cell],
                 visited: frozenset[int], depth: int) -> SentAside | None:
        if way is None:
            return None
        avoid = avoid | way.cells
        for blocker in sorted(way.blockers - visited):
            sent = send_aside(blocker, waiting, avoid, visited | {blocker}, depth)
            if sent is not None:
                return sent
        return None

    def send_aside(vehicle: int, for_vehicle: int, avoid: frozenset[Cell],
                   visited: frozenset[int], depth: int) -> SentAside | None:
        pose = poses[vehicle]
        sidings = (planner.sidings(vehicle, pose, store, avoid | set(keep_clear),
                                   SIDINGS_OFFERED)
                   or planner.sidings(vehicle, pose, store, avoid, SIDINGS_OFFERED))
        if sidings:
            trajectory = move(vehicle, tuple(sidings))
            if trajectory is not None:
                return SentAside(vehicle, trajectory, for_vehicle)
        if depth > 0 and vehicle in waits:  # walled in itself: it inherits the priority
            return open_way(vehicle, waits[vehicle].blockage, avoid, visited, depth - 1)
        return None

    own = waits[deadlock.waiting].blockage
    start = frozenset({deadlock.waiting})
    sent = open_way(deadlock.waiting, own, frozenset(), start, INHERITANCE_DEPTH)
    if sent is None and own is not None:
        for way in other_ways():
            if way.blockers and way != own:
                sent = open_way(deadlock.waiting, way, frozenset(), start, INHERITANCE_DEPTH)
                if sent is not None:
                    break
    return sent
