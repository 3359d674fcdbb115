"""Who stands in a vehicle's way, and where it could step aside: two searches over a planner's
static pose graph that look only at what is held for good (parked to infinity).

A plan fails for two kinds of reason: the way is busy for a while (waiting or postponing will
do), or the way is closed for good by vehicles parked to infinity, which only move when they
are told to. `blockage` tells the second kind apart and names the vehicles: a 0-1 search in
which a move over a cell parked on for good by a movable vehicle costs 1 and any other move 0,
so the way found crosses as few parked vehicles as can be. `sidings` finds the nearest poses a
vehicle can reach over cells nobody holds for good and that keep off another's way.

Both ignore time and the speed profile (what the reservation table holds for a while): they
answer "who must move", not "when can I go".
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Collection, Iterable, Sequence
from dataclasses import dataclass

from fleet.planning.geometry import Cell
from fleet.planning.maneuvers import Kind
from fleet.planning.reservations import ReservationView
from fleet.planning.trajectory import Pose

_NEVER_FREED = 1e300  # an instant after every finite reservation: what holds there holds for good

PoseKey = tuple[int, int, int]
EdgesOf = Callable[[int, int, int], Iterable]  # a planner's statically valid moves from a pose


@dataclass(frozen=True)
class Blockage:
    """The way to a goal crossing the fewest cells held for good: the vehicles holding them
    (none: the way is only busy for a while) and every cell the way sweeps."""

    goal: Pose
    blockers: frozenset[int]
    cells: frozenset[Cell]


def held_for_good(store: ReservationView, vehicle: int, cell: Cell) -> int | None:
    """Who holds `cell` to infinity (another vehicle, the goods or a zone), or None."""
    return store.conflict(vehicle, cell, _NEVER_FREED, float("inf"))


def blockage(edges_of: EdgesOf, rest_cells: Callable[[Pose], Sequence[Cell]], vehicle: int,
             start: Pose, goals: Collection[Pose], store: ReservationView,
             movable: Callable[[int], bool], shortest: bool = False) -> Blockage | None:
    """The way from `start` to any goal that crosses the fewest cells held for good by
    vehicles that can move (`movable`), or with `shortest` the way of fewest moves whoever
    stands on it; cells held for good by anything else are walls. None: no way at all, even
    with every movable vehicle gone."""
    owners: dict[Cell, int | None] = {}

    def cost(cells: Iterable[Cell]) -> int | None:
        """0 free, 1 held by a movable vehicle, None a wall."""
        worst = 0
        for c in cells:
            if c not in owners:
                owners[c] = held_for_good(store, vehicle, c)
            owner = owners[c]
            if owner is None:
                continue
            if owner <= 0 or not movable(owner):
                return None
            worst = 1
        return worst

    goal_keys = {(g.cell[0], g.cell[1], g.heading): g for g in goals}
    first = (start.cell[0], start.cell[1], start.heading)
    best: dict[PoseKey, int] = {first: 0}
    came: dict[PoseKey, tuple[PoseKey, tuple[Cell, ...]]] = {}
    queue: deque[tuple[int, PoseKey]] = deque([(0, first)])
    while queue:
        d, key = queue.popleft()
        if d > best[key]:
            continue
        if key in goal_keys:
            goal = goal_keys[key]
            at_goal = cost(rest_cells(goal))
            if at_goal is not None:
                return _way(came, key, goal, rest_cells(goal), owners)
        for edge in edges_of(*key):
            if edge.kind is Kind.STOP:
                continue
            cells = (*edge.body_cells, *edge.end_cells)
            c = cost(cells)
            if c is None:
                continue
            nxt = (edge.x, edge.y, edge.heading)
            c = 1 if shortest else c
            if d + c < best.get(nxt, 1 << 30):
                best[nxt] = d + c
                came[nxt] = (key, cells)
                (queue.appendleft if c == 0 else queue.append)((d + c, nxt))
    return None


def _way(came: dict[PoseKey, tuple[PoseKey, tuple[Cell, ...]]], key: PoseKey, goal: Pose,
         goal_cells: Sequence[Cell], owners: dict[Cell, int | None]) -> Blockage:
    cells: set[Cell] = set(goal_cells)
    while key in came:
        key, swept = came[key]
        cells.update(swept)
    blockers = frozenset(o for c in cells if (o := owners.get(c)) is not None and o > 0)
    return Blockage(goal, blockers, frozenset(cells))


def sidings(edges_of: EdgesOf, rest_cells: Callable[[Pose], Sequence[Cell]], vehicle: int,
            start: Pose, store: ReservationView, avoid: Collection[Cell],
            limit: int) -> list[Pose]:
    """The nearest poses (fewest moves first) `vehicle` can reach from `start` over cells
    nobody holds for good, where it could park for good without standing on `avoid`: at most
    `limit` of them."""
    def free(cells: Iterable[Cell]) -> bool:
        return all(held_for_good(store, vehicle, c) is None for c in cells)

    first = (start.cell[0], start.cell[1], start.heading)
    seen = {first}
    queue = deque([first])
    found: list[Pose] = []
    while queue and len(found) < limit:
        key = queue.popleft()
        pose = Pose((key[0], key[1]), key[2])
        cells = rest_cells(pose)
        if key != first and not set(cells) & set(avoid) and free(cells):
            found.append(pose)
        for edge in edges_of(*key):
            nxt = (edge.x, edge.y, edge.heading)
            if edge.kind is Kind.STOP or nxt in seen:
                continue
            if free((*edge.body_cells, *edge.end_cells)):
                seen.add(nxt)
                queue.append(nxt)
    return found
