"""Seed 002's unit AGV as a vehicle kind: one cell, moves to the eight neighbours at one
constant speed (d = 1 or 1.4 cells), routes on the lanes planned on space only
(`fleet.planning.lane_route`), then timed and settled against the other AGVs' routes in time
by the collision rules of Section 5 (`fleet.planning.lane_conflicts`).

The conflict policy is where the paper's coordination happens: the leg's timed route is
checked against every route the store holds, and each collision is settled by inserting a
wait, into this AGV's route or into one already committed. The commit then carries the
postponed routes as amendments, all or nothing (docs/protocol.md, "Amending").

The body is a square of 0.7 cells about the cell centre: turned 45 degrees on a diagonal it
would still stay inside the 2 x 2 block the move holds, but it is not turned at all. The seed
gives no turning time, and a square turned by quarter turns covers what it covered, so the AGV
is drawn and checked without a heading: every pose says E (docs/agv-002.md, "The AGV").
"""

from __future__ import annotations

import math
from collections.abc import Callable, Collection, Mapping, Sequence
from dataclasses import dataclass
from typing import ClassVar

from fleet.params import VehicleDims
from fleet.planning.blockage import Blockage, held_for_good
from fleet.planning.geometry import Cell
from fleet.planning.gridmap import GridMap
from fleet.planning.lane_conflicts import Area, settle
from fleet.planning.lane_route import DIAGONAL, LaneRoutes, move_length
from fleet.planning.lane_schedule import Schedule, as_route, from_route, timed
from fleet.planning.reservations import INF, Amendment, ReservationTable, ReservationView
from fleet.planning.trajectory import (
    FailureReason,
    LaneMove,
    PlanFailure,
    Pose,
    Step,
    Trajectory,
)
from fleet.planning.velocity import Speed
from fleet.vehicles.kind import AmendedLeg, Commitment, Outline, Placement, Site

SPEED_CELLS_PER_S = 1.0  # the seed's "constant velocity v" (note A.3: 1 m/s on 1 m cells)
BODY_CELLS = 0.7  # side of the square body, in cells
EAST = 0  # the one heading an AGV's pose says


def schedule_steps(schedule: Schedule) -> tuple[Step, ...]:
    """A schedule as the steps its AGV drives: a wait where it stands a while (not at the
    end: there it parks), a move or a diagonal to each next node, touching the cells the
    schedule holds for it."""
    steps = []
    cells, arrivals = schedule.cells, schedule.arrivals
    for m, cell in enumerate(cells[:-1]):
        here = Pose(cell, EAST)
        if schedule.dwells[m] > 0:
            steps.append(Step(LaneMove.WAIT, here, here, arrivals[m], schedule.departure(m),
                              Speed.ZERO, Speed.ZERO, frozenset({cell})))
        nxt = cells[m + 1]
        move = LaneMove.DIAGONAL if move_length(cell, nxt) == DIAGONAL else LaneMove.MOVE
        block = frozenset({cell, nxt, (cell[0], nxt[1]), (nxt[0], cell[1])})
        steps.append(Step(move, here, Pose(nxt, EAST), schedule.departure(m), arrivals[m + 1],
                          Speed.MID, Speed.MID, block))
    return tuple(steps)


def leg_of(schedule: Schedule, expansions: int = 0) -> Trajectory:
    """The schedule as a committed leg: its steps, and its cells held as it touches them,
    the last one for good."""
    return Trajectory(schedule.vehicle, Pose(schedule.cells[0], EAST),
                      Pose(schedule.cells[-1], EAST), schedule.arrivals[0],
                      schedule_steps(schedule), schedule.intervals(), expansions)


def schedule_of(leg: Trajectory, seconds_per_cell: float) -> Schedule:
    """The schedule a leg drives (`leg_of` undone), parked for good at its end."""
    cells, arrivals, dwells = [leg.start.cell], [leg.t_start], [0.0]
    for step in leg.steps:
        if step.manner is LaneMove.WAIT:
            dwells[-1] += step.t1 - step.t0
        else:
            cells.append(step.end.cell)
            arrivals.append(step.t1)
            dwells.append(0.0)
    dwells[-1] = INF
    return Schedule(leg.vehicle, tuple(cells), tuple(arrivals), tuple(dwells),
                    seconds_per_cell)


def closed(store: ReservationView, vehicle: int, cell: Cell, t_start: float) -> bool:
    """Whether a zone (no vehicle) holds the cell at some time from t_start on."""
    owner = store.conflict(vehicle, cell, t_start, INF)
    return owner is not None and owner < 1


def standing(store: ReservationView, vehicle: int, t_start: float) -> Callable[[Cell], bool]:
    """Which cells a route from t_start must keep off: those something holds for good
    (another vehicle standing there: no rule settles with one that never leaves) or a
    closed zone holds from then on. In a run without faults no lane cell is either."""
    memo: dict[Cell, bool] = {}

    def blocked(cell: Cell) -> bool:
        if cell not in memo:
            memo[cell] = held_for_good(store, vehicle, cell) is not None or \
                closed(store, vehicle, cell, t_start)
        return memo[cell]

    return blocked


class LanePlanner:
    """The paper's A* on the lanes, on space only: the route is timed from the start and
    left for the conflict policy to settle. Other AGVs are no obstacles, save one that
    stands for good (down, or halted and not moving yet): the route goes round it, as round
    a closed zone (`standing`)."""

    def __init__(self, routes: LaneRoutes) -> None:
        self.routes = routes

    def plan(self, vehicle: int, start: Pose, t_start: float, goals: Sequence[Pose],
             store: ReservationView) -> Trajectory | PlanFailure:
        best, expansions = None, 0
        blocked = standing(store, vehicle, t_start)
        for cell in dict.fromkeys(g.cell for g in goals):  # each goal cell once, in order
            if closed(store, vehicle, cell, t_start):
                continue
            route = self.routes.route(start.cell, cell, blocked)
            if route is None:
                continue
            expansions += route.expansions
            if best is None or route.cost_s < best.cost_s:
                best = route
        if best is None:
            return PlanFailure(FailureReason.NO_PATH, f"no lane route from {start.cell} to "
                               f"{', '.join(str(g.cell) for g in goals)} round what stands "
                               f"for good and closed zones", expansions)
        return leg_of(timed(vehicle, best.cells, t_start, self.routes.seconds_per_cell),
                      expansions)

    # Other AGVs are no obstacles on the lanes (they are settled in time), and every place is
    # connected (`fleet layout check`): the deadlock-breaking questions have plain answers,
    # save who stands for good in the way.
    def component(self, pose: Pose) -> int | None:
        return 0

    def blockage(self, vehicle: int, start: Pose, goals: Sequence[Pose],
                 store: ReservationView, movable: Callable[[int], bool],
                 shortest: bool = False) -> Blockage | None:
        """The route to a goal past what cannot move (vehicles that are down, what is no
        vehicle), and the vehicles that can but stand for good on it (its blockers); None
        when what cannot move walls every goal off (a zone for a while walls nothing)."""
        memo: dict[Cell, int | None] = {}

        def holder(cell: Cell) -> int | None:
            if cell not in memo:
                memo[cell] = held_for_good(store, vehicle, cell)
            return memo[cell]

        def wall(cell: Cell) -> bool:
            owner = holder(cell)
            return owner is not None and not (owner > 0 and movable(owner))

        for goal in goals:
            if wall(goal.cell):
                continue
            route = self.routes.route(start.cell, goal.cell, wall)
            if route is not None:
                cells = frozenset(route.cells)
                blockers = {o for c in cells if c != start.cell and (o := holder(c)) is not None}
                return Blockage(goal, frozenset(blockers), cells)
        return None

    def rest_cells(self, pose: Pose) -> list[Cell]:
        return [pose.cell]

    def exit_cells(self, pose: Pose) -> frozenset[Cell]:
        return frozenset({pose.cell})

    def exit_blockers(self, vehicle: int, pose: Pose, store: ReservationView,
                      also_held: Collection[Cell] = ()) -> frozenset[int] | None:
        return frozenset()

    def sidings(self, vehicle: int, start: Pose, store: ReservationView,
                avoid: Collection[Cell], limit: int) -> list[Pose]:
        return []


class SettleByRules:
    """Settle a leg's timed route against every route the store holds, by Section 5.3's
    rules: waits go into this leg or into legs already committed (amendments)."""

    def __init__(self, areas: Mapping[Cell, Area], seconds_per_cell: float) -> None:
        self.areas = areas
        self.seconds_per_cell = seconds_per_cell

    def commitment(self, trajectory: Trajectory, view: ReservationView
                   ) -> Commitment | PlanFailure:
        own = schedule_of(trajectory, self.seconds_per_cell)
        others = self.routes(trajectory.vehicle, view)
        settled = settle(own, others, self.areas, trajectory.t_start)
        if settled.deadlock is not None:
            c = settled.deadlock
            return PlanFailure(FailureReason.DEADLOCK, f"the collision rules cannot settle "
                               f"vehicles {c.a} and {c.b} meeting at {sorted(c.cells)} "
                               f"(t={c.t:.2f} s, {c.kind.value})", trajectory.expansions)
        mine = settled.schedules[own.vehicle]
        held = self._held(mine, others, view)
        if held is not None:
            return PlanFailure(FailureReason.NO_PATH, held, trajectory.expansions)
        amends = []
        for vehicle, schedule in sorted(settled.schedules.items()):
            if vehicle == own.vehicle:
                continue
            before = others[vehicle]
            node = next(m for m, (a, b) in enumerate(zip(before.dwells, schedule.dwells,
                                                         strict=True)) if a != b)
            release_from = before.departure(node)
            # A wait at the last node of a route that was already parked there never happens:
            # settle only postpones what follows a node, and a parked AGV has nothing after.
            intervals = tuple(iv for iv in schedule.intervals() if iv.t1 > release_from)
            amendment = Amendment(vehicle, release_from, intervals, as_route(schedule))
            amends.append(AmendedLeg(amendment, leg_of(schedule)))
        leg = leg_of(mine, trajectory.expansions)
        return Commitment(leg, leg.intervals, trajectory.t_start, tuple(amends),
                          as_route(mine))

    @staticmethod
    def _held(mine: Schedule, others: Mapping[int, Schedule], view: ReservationView
              ) -> str | None:
        """Why the settled leg still cannot be committed: a cell it touches is held by what
        the rules do not settle with (a vehicle frozen mid-move, a closed zone), which only
        waiting for it to go ends; None when nothing such is in the way."""
        for iv in mine.intervals():
            other = view.conflict(mine.vehicle, iv.cell, iv.t0, iv.t1)
            if other is not None and other not in others:
                who = f"vehicle {other}" if other > 0 else "a closed zone"
                return (f"cell {iv.cell} is held by {who}, which the collision rules cannot "
                        f"settle with, over [{iv.t0:.2f}, {iv.t1:.2f})")
        return None

    def routes(self, vehicle: int, view: ReservationView) -> dict[int, Schedule]:
        """Every other vehicle's route in time, as the store holds it; one without a route
        (parked at the start, or frozen) stands on each cell it holds while it holds it."""
        if not isinstance(view, ReservationTable):
            raise TypeError("seed 002's AGVs settle against a reservation table's routes")
        found = {}
        for other in view.vehicles():
            if other == vehicle or other < 1:
                continue
            route = view.route(other)
            if route is not None:
                found[other] = from_route(other, route, self.seconds_per_cell)
                continue
            held = view.reservations(other)
            if len(held) == 1:
                r = held[0]
                found[other] = Schedule(other, (r.cell,), (r.t0,), (r.t1 - r.t0,),
                                        self.seconds_per_cell)
            # Several cells and no route: a vehicle frozen mid-move; the store's own check
            # of the commit keeps this leg off its cells.
        return found


class LanePlanners:
    """One lane planner for the whole warehouse (shelves in their slots block no lane), and
    the rules that settle its legs."""

    def __init__(self, layout: Site, speed_cells_per_s: float) -> None:
        routes = LaneRoutes(layout.lane_graph, speed_cells_per_s * layout.cell_size)
        self.planner = LanePlanner(routes)
        self.policy = SettleByRules(layout.cell_areas, routes.seconds_per_cell)

    def get(self, filled: frozenset[Cell]) -> LanePlanner:
        return self.planner


@dataclass(frozen=True)
class Agv:
    dims: VehicleDims = VehicleDims()  # a forklift's; the AGV's body is BODY_CELLS square
    cell_size: float = 1.0
    name: ClassVar[str] = "agv"
    noun: ClassVar[str] = "AGV"

    @property
    def seconds_per_cell(self) -> float:
        return 1.0 / SPEED_CELLS_PER_S

    @property
    def outline(self) -> Outline:
        half = BODY_CELLS * self.cell_size / 2
        return Outline(half, half, BODY_CELLS * self.cell_size)

    @property
    def max_speed_mps(self) -> float:
        # A diagonal move drives sqrt(2) cells in the paper's 1.4 cell-times.
        return math.sqrt(2) / DIAGONAL * SPEED_CELLS_PER_S * self.cell_size

    def body_cells_at_rest(self, pose: Pose) -> tuple[Cell, ...]:
        return (pose.cell,)

    def handling_poses(self, cell: Cell) -> tuple[Pose, ...]:
        """It drives under the shelf (onto the station, the pile) and works it from there."""
        return (Pose(cell, EAST),)

    def handled_cell(self, pose: Pose) -> Cell:
        return pose.cell

    def at_rest(self, pose: Pose) -> Placement:
        x, y = (c * self.cell_size for c in pose.cell)
        return Placement(pose, x, y, 0.0, 0, "")

    def on_step(self, step: Step, t: float) -> Placement:
        s = (t - step.t0) / (step.t1 - step.t0)
        (c0, r0), (c1, r1) = step.start.cell, step.end.cell
        x, y = ((a + s * (b - a)) * self.cell_size for a, b in ((c0, c1), (r0, r1)))
        moving = step.manner is not LaneMove.WAIT
        return Placement(step.start, x, y, 0.0, int(moving), step.manner.label)

    def is_wait(self, step: str) -> bool:
        return step == LaneMove.WAIT.label

    def path_length_m(self, step: str) -> float:
        lengths = {LaneMove.MOVE.label: 1.0, LaneMove.DIAGONAL.label: math.sqrt(2),
                   LaneMove.WAIT.label: 0.0}
        return lengths[step] * self.cell_size

    def planner(self, grid: GridMap) -> LanePlanner:
        raise TypeError("an AGV plans on a layout's lanes, not on a grid: use planners(layout)")

    def planners(self, layout: Site) -> LanePlanners:
        return LanePlanners(layout, SPEED_CELLS_PER_S)

