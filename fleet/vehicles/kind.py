"""What a vehicle kind is: the interface the rest of the fleet sees.

A kind answers three questions for the vehicles of a layout:

- its motion model: which cells its body covers at rest, where it works a cell from, and where
  it is (world pose, speed, the step in progress) at an instant of a step it committed;
- its planner: a search per static map (one per fill state of the warehouse);
- its conflict policy: what a planned leg commits to the shared reservation store.

Seed 000's forklift (`fleet.vehicles.forklift`) plans against everyone's space-time
reservations and commits the whole trajectory at once. The next kinds fit the same interface:
seed 002's 1-cell AGV with 8-direction moves plans on space only and then delays conflicting
steps (its policy inserts waits into the trajectory it commits, and may later amend another
vehicle's); seed 004's lifting AGV, which passes under shelves, keys its planners by load as
well as fill state, and tracks reactively, locking cells while it drives, which needs a
step-level executor beside today's whole-leg one.

Steps are named by their labels (what the wire and the records carry), so the analysis asks a
kind about a label without knowing its manners.
"""

from __future__ import annotations

from collections.abc import Callable, Collection, Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import ClassVar, Protocol

from fleet.planning.blockage import Blockage
from fleet.planning.geometry import Cell
from fleet.planning.gridmap import GridMap
from fleet.planning.lane_conflicts import Area
from fleet.planning.lane_route import LaneGraph
from fleet.planning.reservations import (
    Amendment,
    Interval,
    ReservationView,
    ReservationWriter,
    TimedRoute,
    WriteResult,
)
from fleet.planning.trajectory import PlanFailure, Pose, Step, Trajectory


@dataclass(frozen=True)
class Outline:
    """The body's rectangle about the vehicle's reference point, in metres: what the safety
    verifier re-derives covered cells from, with its own geometry."""

    front: float
    rear: float
    width: float


@dataclass(frozen=True)
class Placement:
    """Where a vehicle is at one instant, as its state stream says it."""

    pose: Pose  # at rest: its pose; moving: the pose the step in progress started from
    x: float  # metres, in the grid's frame (cell (0, 0) centred at the origin)
    y: float
    theta: float  # radians
    speed: int  # the speed level driven (0 at rest and while waiting)
    step: str  # the label of the step in progress ("" at rest)


@dataclass(frozen=True)
class AmendedLeg:
    """Another vehicle's committed leg, postponed by a commit: what the store changes, and
    what that vehicle drives instead."""

    amendment: Amendment
    trajectory: Trajectory


@dataclass(frozen=True)
class Commitment:
    """What one planned leg asks of the reservation store, all or nothing: the vehicle's
    holdings from `release_from` on become `intervals` (with the route in time they come
    from, where the kind shares one); it then drives `trajectory`. `amends` postpone other
    vehicles' legs in the same step (seed 002's collision rules)."""

    trajectory: Trajectory
    intervals: tuple[Interval, ...]
    release_from: float
    amends: tuple[AmendedLeg, ...] = ()
    route: TimedRoute | None = None

    def write(self, store: ReservationWriter) -> WriteResult:
        """Ask the store for it (all or nothing)."""
        return store.commit(self.trajectory.vehicle, self.intervals, self.release_from,
                            tuple(a.amendment for a in self.amends), route=self.route)


class Planner(Protocol):
    """A search on one static map."""

    def plan(self, vehicle: int, start: Pose, t_start: float, goals: Sequence[Pose],
             store: ReservationView) -> Trajectory | PlanFailure:
        """From `start` at rest at `t_start` to any of `goals`, at rest."""
        ...

    def component(self, pose: Pose) -> int | None:
        """The pose's connected component on the static map (None: on a blocked cell)."""
        ...

    def blockage(self, vehicle: int, start: Pose, goals: Sequence[Pose],
                 store: ReservationView, movable: Callable[[int], bool],
                 shortest: bool = False) -> Blockage | None:
        """The way to any goal crossing the fewest cells held for good by movable vehicles
        (with `shortest`, the way of fewest moves), and who holds them (None: walled in by
        goods, zones or vehicles that cannot move)."""
        ...

    def rest_cells(self, pose: Pose) -> list[Cell]:
        """The cells the body covers at rest at `pose` (on this planner's map)."""
        ...

    def exit_cells(self, pose: Pose) -> frozenset[Cell]:
        """Every cell a move out of `pose` sweeps."""
        ...

    def exit_blockers(self, vehicle: int, pose: Pose, store: ReservationView,
                      also_held: Collection[Cell] = ()) -> frozenset[int] | None:
        """Who holds the cells of every move out of `pose` for good (with `also_held` held
        too): empty when a move leads out, None when goods or zones close every move."""
        ...

    def sidings(self, vehicle: int, start: Pose, store: ReservationView,
                avoid: Collection[Cell], limit: int) -> list[Pose]:
        """The nearest poses the vehicle can step aside to and park at, off `avoid`."""
        ...


class ConflictPolicy(Protocol):
    """How a kind keeps its vehicles apart: what a planned leg commits, given the table as
    the planner saw it."""

    def commitment(self, trajectory: Trajectory, view: ReservationView
                   ) -> Commitment | PlanFailure:
        """What to commit, or why nothing can be (seed 002: a collision the rules cannot
        settle)."""
        ...


class Site(Protocol):
    """The warehouse a kind's planners are built for, as they read it: the world wing's
    `Layout` is one (this wing sits below it, since a layout is checked with its kind)."""

    name: str
    cell_size: float

    def grid_map(self, filled: Iterable[Cell] = (), under_shelves: bool = False) -> GridMap:
        """The drivable grid with these stacks filled (forklifts)."""
        ...

    @property
    def lane_graph(self) -> LaneGraph:
        """Its lanes' moves for the route search (seed 002's AGVs)."""
        ...

    @property
    def cell_areas(self) -> Mapping[Cell, Area]:
        """Each lane cell's set of Section 5.3 (seed 002's collision rules)."""
        ...


class Planners(Protocol):
    """Planners by fill state (the stacks holding goods), built on demand, and the conflict
    policy their legs are committed by, for one warehouse."""

    @property
    def policy(self) -> ConflictPolicy: ...

    def get(self, filled: frozenset[Cell]) -> Planner: ...


class VehicleKind(Protocol):
    name: ClassVar[str]  # what a layout's [vehicle] kind says
    noun: ClassVar[str]  # what a user calls one ("forklift", "AGV")

    @property
    def outline(self) -> Outline: ...

    @property
    def max_speed_mps(self) -> float:
        """The fastest any point of its body moves, in metres per second: the analysis bounds
        a vehicle's motion between two of its recorded states by it."""
        ...

    # -- the motion model ----------------------------------------------------------------------
    def body_cells_at_rest(self, pose: Pose) -> tuple[Cell, ...]:
        """The cells the body covers standing at `pose` (what parking reserves)."""
        ...

    def handling_poses(self, cell: Cell) -> tuple[Pose, ...]:
        """The poses from which the vehicle loads or unloads at `cell`, whatever is free."""
        ...

    def handled_cell(self, pose: Pose) -> Cell:
        """The cell a vehicle standing at `pose` loads or unloads."""
        ...

    def at_rest(self, pose: Pose) -> Placement: ...

    def on_step(self, step: Step, t: float) -> Placement:
        """Where the vehicle is at t in [step.t0, step.t1) of a step it committed."""
        ...

    def is_wait(self, step: str) -> bool:
        """Whether the step so labelled stands still (waiting for another vehicle)."""
        ...

    def path_length_m(self, step: str) -> float:
        """How far the step so labelled drives its reference point, in metres."""
        ...

    # -- the planner ---------------------------------------------------------------------------
    def planner(self, grid: GridMap) -> Planner: ...

    def planners(self, layout: Site) -> Planners:
        """Planners for the fill states of one warehouse, and its conflict policy."""
        ...
