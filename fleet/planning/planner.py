"""Improved hybrid A* of seed 000 (Algorithm 2, Sections 4.1 to 4.4).

Nodes are (cell, heading, t_zero); each keeps the FixMovingTime end instants per speed level.
Children come from the eleven manners; Algorithm 3 decides their fate against the static map
and the reservations of the other vehicles: gamma = 1 (the end pose collides) closes the child
node, gamma = 2 (only the sweep between the poses collides) skips it. Collisions are checked
over the whole window the maneuver may occupy, from the earliest instant it may start to the
instant it ends at v_zero, so any speed profile later chosen along the path stays inside what
was checked. Waiting is the stop manner. A goal is reached only where the vehicle can then park
to infinity.

The search is deterministic: ties in f break on insertion order.
"""

from __future__ import annotations

import heapq
import math
from collections.abc import Callable, Collection, Sequence
from dataclasses import dataclass
from functools import cache
from typing import NamedTuple

import numpy as np

from fleet.params import ManeuverTimes, SearchParams, VehicleDims
from fleet.planning.blockage import Blockage, blockage, held_for_good, sidings
from fleet.planning.geometry import Cell
from fleet.planning.gridmap import GridMap
from fleet.planning.maneuvers import Kind, Manner, Move, move_table
from fleet.planning.pose_graph import MANNERS, Components, components, fitting, skeleton
from fleet.planning.reservations import ReservationView
from fleet.planning.trajectory import (
    FailureReason,
    PlanFailure,
    Pose,
    Step,
    Trajectory,
    merge_intervals,
)
from fleet.planning.velocity import INF, EndTimes, VelocityPlanner, fix_ending_levels, start_times

Key = tuple[int, int, int, float]


class _Edge(NamedTuple):
    manner: Manner
    kind: Kind
    direction: int
    x: int
    y: int
    heading: int
    end_cells: tuple[Cell, ...]
    body_cells: tuple[Cell, ...]  # start and intermediate cells
    kind_slot: int  # the kind's place in Kind: a search memoises child times by it


_KIND_SLOT = {kind: i for i, kind in enumerate(Kind)}
_TIMED_SLOTS = 2 * len(_KIND_SLOT)  # (kind, from rest)

# A move as the safe-interval relaxation sees it: end pose, the cells it sweeps, and its
# kind's shortest and longest durations.
_Move = tuple[int, int, int, tuple[Cell, ...], float, float]


@cache
def _candidate_edges(moves: tuple[Move, ...], x: int, y: int) -> tuple[_Edge, ...]:
    """Every move from (x, y) with absolute cells, whatever the map: planners for different
    fill states share these and only filter them by their own static map."""
    return tuple(_Edge(move.manner, move.manner.kind, move.manner.direction,
                       x + move.end_delta[0], y + move.end_delta[1], move.end_heading,
                       tuple((x + a, y + b) for a, b in sorted(move.end_cells)),
                       tuple((x + a, y + b) for a, b in sorted(move.start_cells
                                                               | move.middle_cells)),
                       _KIND_SLOT[move.manner.kind])
                 for move in moves)


@dataclass(slots=True)
class _Node:
    key: Key
    parent: _Node | None
    manner: Manner | None
    times: EndTimes
    last_dir: int  # direction of the last moving maneuver (0: none yet)
    turns: int
    lanes: int
    inversions: int
    g: float
    f: float


def heuristic(cell: Cell, heading: int, goal: Pose) -> float:
    """Equation (13): Manhattan distance in cells plus heading difference in quarter turns."""
    dh = abs(heading - goal.heading) % 4
    return abs(goal.cell[0] - cell[0]) + abs(goal.cell[1] - cell[1]) + min(dh, 4 - dh)


class HybridAStar:
    """One planner per map (and body); `plan` answers one query."""

    def __init__(self, grid: GridMap, dims: VehicleDims = VehicleDims(),
                 times: ManeuverTimes = ManeuverTimes(),
                 params: SearchParams = SearchParams()) -> None:
        self.grid = grid
        self.params = params
        self.velocity = VelocityPlanner(times)
        self.move_of = move_table(dims, grid.cell_size)
        self.moves = [tuple(self.move_of[m, h] for m in Manner) for h in range(4)]
        self._graph = skeleton(dims, grid.cell_size, grid.cols, grid.rows)
        self._fits: np.ndarray | None = None  # which moves fit on this map (pose_graph)
        self._edges: dict[tuple[int, int, int], list[_Edge]] = {}
        self._moves: dict[tuple[int, int, int], list[_Move]] = {}  # the relaxation's
        self._components: Components | None = None
        self._shortest: dict[Kind, float] = {}  # each kind's shortest speed link
        self._longest: dict[Kind, float] = {}  # ... and longest
        for (kind, _, _), dt in self.velocity.links.items():
            self._shortest[kind] = min(dt, self._shortest.get(kind, INF))
            self._longest[kind] = max(dt, self._longest.get(kind, 0.0))
        # The fewest seconds any maneuver takes per cell it moves the vehicle (Manhattan): no
        # vehicle closes a distance of d cells in less than d times this.
        self._seconds_per_cell = min(
            self._shortest[move.manner.kind] / (abs(move.end_delta[0]) + abs(move.end_delta[1]))
            for move in self.move_of.values() if move.end_delta != (0, 0))

    def component(self, pose: Pose) -> int | None:
        """Connected component of the pose in the static pose graph (moves are reversible,
        so reachability is symmetric); None for a pose on a blocked cell."""
        if self._components is None:
            self._components = components(self._graph, self._fitting())
        return self._components.of(self._graph, pose.cell, pose.heading)

    def _fitting(self) -> np.ndarray:
        if self._fits is None:
            self._fits = fitting(self._graph, self.grid.blocked)
        return self._fits

    def edges(self, x: int, y: int, heading: int) -> list[_Edge]:
        """The statically valid moves from a pose, with absolute cells (cached per map):
        Algorithm 3, lines 4-7 and 15-18, static collisions always fail (gamma 1: the end
        pose hits the static map; 2: only the sweep does)."""
        found = self._edges.get((x, y, heading))
        if found is None:
            candidates = _candidate_edges(self.moves[heading], x, y)
            if 0 <= x < self.grid.cols and 0 <= y < self.grid.rows:
                first = self._graph.move(x, y, heading)
                fit = self._fitting()[first:first + len(MANNERS)].tolist()
            else:  # off the map: no table, the cells themselves
                fit = [self.grid.all_free((x + a, y + b) for a, b in
                                          (*move.end_cells, *move.middle_cells))
                       for move in self.moves[heading]]
            found = [edge for edge, ok in zip(candidates, fit, strict=True) if ok]
            self._edges[x, y, heading] = found
        return found

    def plan(self, vehicle: int, start: Pose, t_start: float, goals: list[Pose] | tuple[Pose, ...],
             store: ReservationView) -> Trajectory | PlanFailure:
        """Plan from `start` at rest at `t_start` to any of `goals` (arriving at rest)."""
        table = self.moves
        start_cells = [(start.cell[0] + a, start.cell[1] + b)
                       for a, b in table[start.heading][0].start_cells]
        if not self.grid.all_free(start_cells):
            return PlanFailure(FailureReason.START_BLOCKED,
                               f"start pose {start} lies on a blocked cell", 0)
        t_probe = math.nextafter(t_start, INF)
        for c in start_cells:
            other = store.conflict(vehicle, c, t_start, t_probe)
            if other is not None:
                return PlanFailure(FailureReason.START_BLOCKED,
                                   f"start cell {c} is held by vehicle {other} at t={t_start}", 0)

        goals = list(dict.fromkeys(goals))
        reachable_goals = [g for g in goals if self._goal_can_park(vehicle, g, store)]
        if not reachable_goals:
            return PlanFailure(FailureReason.GOAL_BLOCKED,
                               "every goal pose is static-blocked or parked on by another "
                               "vehicle: " + ", ".join(str(g) for g in goals), 0)
        here = self.component(start)
        reachable_goals = [g for g in reachable_goals if self.component(g) == here]
        if not reachable_goals:
            return PlanFailure(FailureReason.NO_PATH,
                               f"no goal pose can be reached from {start} on the static map", 0)
        goal_set = {(g.cell, g.heading) for g in reachable_goals}

        def h(cell: Cell, heading: int) -> float:
            return min(heuristic(cell, heading, g) for g in reachable_goals)

        root = _Node((start.cell[0], start.cell[1], start.heading, t_start), None, None,
                     start_times(t_start), 0, 0, 0, 0, 0.0, 0.0)
        if (start.cell, start.heading) in goal_set:
            return self._build(vehicle, start, root, 0)
        root.f = self.params.C11 * h(start.cell, start.heading)

        C11, p = self.params.C11, self.params
        open_heap: list[tuple[float, int, _Node]] = [(root.f, 0, root)]
        best_f: dict[Key, float] = {root.key: root.f}
        closed: set[Key] = set()
        counter = 1
        expansions = 0
        h_cache: dict[tuple[int, int, int], float] = {}
        # Each cell's holds by others that end after t_start, read once a search: every
        # instant the search asks about is from t_start on.
        holds: dict[Cell, list[tuple[float, float]]] = {}

        def held(cells: tuple[Cell, ...], t0: float, t1: float) -> bool:
            """Whether another vehicle holds any of the cells somewhere in [t0, t1)."""
            for c in cells:
                line = holds.get(c)
                if line is None:
                    line = holds[c] = store.busy(vehicle, c, t_start)
                for s, e in line:
                    if s >= t1:
                        break
                    if e > t0:
                        return True
            return False

        child_window = self.velocity.child_window
        stop, turn, lane = Manner.STOP, Kind.TURN, Kind.LANE  # locals: the hot loop reads them
        p_turn, p_lane, p_inv = p.p_turn, p.p_lane, p.p_inv
        # Many nodes end at the same instants (the same maneuvers in another order or place):
        # their children's times are computed once a search.
        windows: dict[tuple[tuple[float, float, float], int],
                      tuple[EndTimes, float, float, float]] = {}
        while open_heap:
            f, _, node = heapq.heappop(open_heap)
            if node.key in closed or best_f.get(node.key) != f:
                continue  # stale heap entry
            closed.add(node.key)
            expansions += 1
            if expansions == p.relaxation_check_at and not self._intervals_reachable(
                    vehicle, start, t_start, goal_set, store):
                return PlanFailure(FailureReason.NO_PATH,
                                   "other vehicles' reservations close every way to the goal "
                                   "in time (a safe-interval relaxation, checked after "
                                   f"{expansions} expansions)", expansions)
            if expansions > p.iter_search:
                return PlanFailure(FailureReason.ITERATION_CAP,
                                   f"no path within iter_search={p.iter_search} expansions",
                                   expansions - 1)
            x, y, heading, _ = node.key
            last_dir, parent_times = node.last_dir, node.times
            # The child times depend only on the edge's kind and whether it starts from
            # rest: a few values an expansion, each computed once.
            timed: list[tuple[EndTimes, float, float, float] | None] = [None] * _TIMED_SLOTS
            for edge in self.edges(x, y, heading):
                manner, kind, d, ex, ey, eh, end_cells, body_cells, kind_slot = edge
                reverses = d != 0 and last_dir != 0 and d != last_dir
                from_rest = manner is stop or reverses
                slot = 2 * kind_slot + from_rest
                known = timed[slot]
                if known is None:
                    memo = (parent_times.at, slot)
                    known = windows.get(memo)
                    if known is None:
                        known = windows[memo] = child_window(parent_times, kind, from_rest)
                    timed[slot] = known
                times, tz, t_from, t_to = known
                key = (ex, ey, eh, tz)
                if key in closed:
                    continue
                if held(end_cells, t_from, t_to):
                    closed.add(key)  # gamma = 1
                    continue
                if held(body_cells, t_from, t_to):
                    continue  # gamma = 2
                at_goal = ((ex, ey), eh) in goal_set
                if at_goal and held(end_cells, tz, INF):
                    closed.add(key)  # cannot park here at this time
                    continue
                turns = node.turns + (kind is turn)
                lanes = node.lanes + (kind is lane)
                inversions = node.inversions + reverses
                g = tz - t_start + p_turn * turns + p_lane * lanes + p_inv * inversions
                hc = h_cache.get((ex, ey, eh))
                if hc is None:
                    hc = h_cache[ex, ey, eh] = h((ex, ey), eh)
                fc = g + C11 * hc
                previous = best_f.get(key)
                if previous is not None and previous <= fc:
                    continue
                child = _Node(key, node, manner, times, d or last_dir, turns, lanes,
                              inversions, g, fc)
                if at_goal:
                    return self._build(vehicle, start, child, expansions)
                best_f[key] = fc
                heapq.heappush(open_heap, (fc, counter, child))
                counter += 1
        return PlanFailure(FailureReason.NO_PATH,
                           f"open list exhausted after {expansions} expansions", expansions)

    def _intervals_reachable(self, vehicle: int, start: Pose, t_start: float,
                             goal_set: set[tuple[Cell, int]], store: ReservationView) -> bool:
        """Whether any goal can be reached in a safe-interval relaxation (in the spirit of
        SIPP) of the search: a pose may be stood on only while no other vehicle holds its
        cells, within one of its safe intervals; a maneuver leaves within that interval, at
        the earliest instant from which every cell it sweeps stays free for its kind's
        shortest duration, and arrives between its shortest and its longest duration after
        leaving, within a safe interval of the next pose; a goal is arrived at in an
        interval that never ends. A real trajectory is such a sequence (it stands on each
        pose at instants the search checked free, a wait holds the pose throughout, and each
        maneuver takes one of its kind's link durations, its sweep free all along), except
        that it may leave later than the earliest instant, which only delays it; so False
        proves that no trajectory exists."""
        busy_of: dict[Cell, list[tuple[float, float]]] = {}
        safe_of: dict[tuple[int, int, int], list[tuple[float, float]]] = {}

        def busy(c: Cell) -> list[tuple[float, float]]:
            line = busy_of.get(c)
            if line is None:
                line = busy_of[c] = store.busy(vehicle, c, t_start)
            return line

        def safe(x: int, y: int, heading: int) -> list[tuple[float, float]]:
            """The pose's safe intervals [start, end], closed (touching holds are allowed)."""
            found = safe_of.get((x, y, heading))
            if found is None:
                held = sorted(iv for a, b in self.moves[heading][0].start_cells
                              for iv in busy((x + a, y + b)))
                found, free_from = [], -INF
                for t0, t1 in held:
                    if t0 > free_from:
                        found.append((free_from, t0))
                    free_from = max(free_from, t1)
                if free_from < INF:
                    found.append((free_from, INF))
                safe_of[x, y, heading] = found
            return found

        def departure(swept: tuple[Cell, ...], t: float, duration: float, leave_by: float
                      ) -> float:
            """The earliest instant from `t` on (INF: none by `leave_by`) at which every cell
            the edge sweeps stays free for `duration`."""
            moved = True
            while moved:
                moved = False
                for c in swept:
                    line = busy_of.get(c)
                    if line is None:
                        line = busy_of[c] = store.busy(vehicle, c, t_start)
                    for t0, t1 in line:
                        if t0 >= t + duration:
                            break
                        if t1 > t:
                            t, moved = t1, True
                            if t > leave_by:
                                return INF
            return t

        x0, y0, h0 = start.cell[0], start.cell[1], start.heading
        first = next((i for i, (s, e) in enumerate(safe(x0, y0, h0)) if s <= t_start <= e),
                     None)
        if first is None:
            return True  # the start itself is held: the search says so, not this test
        # Goal first (A*, by arrival plus the soonest the goal could follow): any order of
        # the states finds the same set reachable, this one reaches a goal far sooner.
        goal_cells = {cell for cell, _ in goal_set}
        rate = self._seconds_per_cell

        def soonest(x: int, y: int) -> float:
            return rate * min(abs(x - gx) + abs(y - gy) for gx, gy in goal_cells)

        best = {(x0, y0, h0, first): t_start}
        heap = [(t_start + soonest(x0, y0), t_start, x0, y0, h0, first)]
        while heap:
            _, t, x, y, heading, i = heapq.heappop(heap)
            if best[x, y, heading, i] < t:
                continue
            leave_by = safe_of[x, y, heading][i][1]
            if ((x, y), heading) in goal_set and leave_by == INF:
                return True
            for ex, ey, eh, swept, duration, slowest in self._moves_from(x, y, heading):
                leave = departure(swept, t, duration, leave_by)
                if leave == INF:
                    continue
                earliest, latest = leave + duration, leave_by + slowest
                for j, (s, e) in enumerate(safe(ex, ey, eh)):
                    if s > latest:
                        break
                    arrive = max(earliest, s)
                    if arrive > e or arrive > latest:
                        continue
                    key = (ex, ey, eh, j)
                    if arrive < best.get(key, INF):
                        best[key] = arrive
                        heapq.heappush(heap, (arrive + soonest(ex, ey), arrive, *key))
        return False

    def _moves_from(self, x: int, y: int, heading: int) -> list[_Move]:
        """The relaxation's view of the statically valid moves from a pose (waits left out:
        waiting is free within an interval), cached per map."""
        found = self._moves.get((x, y, heading))
        if found is None:
            found = self._moves[x, y, heading] = [
                (edge.x, edge.y, edge.heading, (*edge.body_cells, *edge.end_cells),
                 self._shortest[edge.kind], self._longest[edge.kind])
                for edge in self.edges(x, y, heading) if edge.kind is not Kind.STOP]
        return found

    def earliest_arrivals(self, start: Pose, t_start: float = 0.0,
                          usable_until: Callable[[Cell], float] | None = None,
                          stop_at: Collection[tuple[Cell, int]] = (),
                          ) -> dict[tuple[int, int, int], float]:
        """A relaxation that can only say too soon: the earliest arrival at each pose (x, y,
        heading) over the static pose graph with every maneuver at its shortest duration, a
        cell usable until `usable_until` says (default: for ever). No trajectory arrives
        sooner, since a real one departs no earlier and moves no faster. Stops once a pose of
        `stop_at` is settled."""
        shortest = self._shortest
        best = {(start.cell[0], start.cell[1], start.heading): t_start}
        settled: dict[tuple[int, int, int], float] = {}
        heap = [(t_start, start.cell[0], start.cell[1], start.heading)]
        while heap:
            t, x, y, heading = heapq.heappop(heap)
            if best[x, y, heading] < t:
                continue
            settled[x, y, heading] = t
            if ((x, y), heading) in stop_at:
                break
            for edge in self.edges(x, y, heading):
                if edge.kind is Kind.STOP:
                    continue
                t_end = t + shortest[edge.kind]
                if usable_until is not None and any(
                        usable_until(c) < t_end for c in edge.end_cells + edge.body_cells):
                    continue
                key = (edge.x, edge.y, edge.heading)
                if t_end < best.get(key, INF):
                    best[key] = t_end
                    heapq.heappush(heap, (t_end, *key))
        return settled

    def rest_cells(self, pose: Pose) -> list[Cell]:
        """The cells the body covers at rest at `pose`."""
        return [(pose.cell[0] + a, pose.cell[1] + b)
                for a, b in self.moves[pose.heading][0].start_cells]

    def blockage(self, vehicle: int, start: Pose, goals: Sequence[Pose],
                 store: ReservationView, movable: Callable[[int], bool],
                 shortest: bool = False) -> Blockage | None:
        """Who stands for good in the way to the goals (fleet/planning/blockage.py)."""
        return blockage(self.edges, self.rest_cells, vehicle, start, goals, store, movable,
                        shortest)

    def sidings(self, vehicle: int, start: Pose, store: ReservationView,
                avoid: Collection[Cell], limit: int) -> list[Pose]:
        """The nearest poses to step aside to, off `avoid` (fleet/planning/blockage.py)."""
        return sidings(self.edges, self.rest_cells, vehicle, start, store, avoid, limit)

    def _goal_can_park(self, vehicle: int, goal: Pose, store: ReservationView) -> bool:
        cells = [(goal.cell[0] + a, goal.cell[1] + b)
                 for a, b in self.moves[goal.heading][0].start_cells]
        if not self.grid.all_free(cells):
            return False
        # Someone parked there for good can never be waited out.
        return all(held_for_good(store, vehicle, c) is None for c in cells)

    def exit_cells(self, pose: Pose) -> frozenset[Cell]:
        """Every cell a move out of `pose` sweeps."""
        return frozenset(c for edge in self.edges(*pose.cell, pose.heading)
                         if edge.kind is not Kind.STOP
                         for c in (*edge.body_cells, *edge.end_cells))

    def exit_blockers(self, vehicle: int, pose: Pose, store: ReservationView,
                      also_held: Collection[Cell] = ()) -> frozenset[int] | None:
        """Who holds for good the cells of every move out of `pose` (with `also_held` held
        too): empty when some move leads out, None when goods or zones close every move."""
        blockers: set[int] = set()
        for edge in self.edges(*pose.cell, pose.heading):
            if edge.kind is Kind.STOP:
                continue
            cells = (*edge.body_cells, *edge.end_cells)
            owners = {held_for_good(store, vehicle, c) for c in cells} - {None}
            if not owners and not set(cells) & set(also_held):
                return frozenset()
            blockers |= {o for o in owners if o is not None}
        return frozenset(o for o in blockers if o > 0) if blockers else None

    def _build(self, vehicle: int, start: Pose, goal_node: _Node,
               expansions: int) -> Trajectory:
        chain = []
        node: _Node | None = goal_node
        while node is not None and node.parent is not None:
            chain.append(node)
            node = node.parent
        chain.reverse()
        levels = fix_ending_levels([n.times for n in chain])
        steps = []
        for node, level in zip(chain, levels, strict=True):
            parent = node.parent
            assert parent is not None and node.manner is not None
            v0 = node.times.start_level[level]
            assert v0 is not None
            move = self.move_of[node.manner, parent.key[2]]
            px, py = parent.key[0], parent.key[1]
            cells = frozenset((px + a, py + b) for a, b in move.swept)
            steps.append(Step(node.manner, Pose((px, py), parent.key[2]),
                              Pose((node.key[0], node.key[1]), node.key[2]),
                              parent.times.at[v0], node.times.at[level], v0, level, cells))
        goal = Pose((goal_node.key[0], goal_node.key[1]), goal_node.key[2])
        t_end = steps[-1].t1 if steps else goal_node.key[3]
        goal_cells = [(goal.cell[0] + a, goal.cell[1] + b)
                      for a, b in self.moves[goal.heading][0].start_cells]
        pieces = [(c, s.t0, s.t1) for s in steps for c in s.cells]
        pieces += [(c, t_end, INF) for c in goal_cells]
        return Trajectory(vehicle, start, goal, steps[0].t0 if steps else t_end, tuple(steps),
                          merge_intervals(pieces), expansions)


class PlannerCache:
    """One planner per fill state of a layout (its static map), the most recent few kept: a
    mission asks for the current state and the next few candidates, and building a planner
    (map + reachability) costs far more than a search."""

    def __init__(self, grid_for, dims: VehicleDims, size: int = 16) -> None:
        self.grid_for = grid_for  # filled cells -> GridMap
        self.dims = dims
        self.size = size
        self._planners: dict[frozenset[Cell], HybridAStar] = {}  # least recently used first

    def get(self, filled: frozenset[Cell]) -> HybridAStar:
        planner = self._planners.pop(filled, None)
        if planner is None:
            planner = HybridAStar(self.grid_for(filled), self.dims)
            if len(self._planners) >= self.size:
                del self._planners[next(iter(self._planners))]
        self._planners[filled] = planner
        return planner
