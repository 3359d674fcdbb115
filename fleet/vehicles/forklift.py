"""Seed 000's forklift as a vehicle kind: the eleven manners of `fleet.planning.maneuvers`, the
improved hybrid A* of `fleet.planning.planner`, and reservations ahead of time.

A forklift covers two cells at rest (its rear-axle point's cell and the one ahead), works a
cell with its forks from the cell behind, and moves along each manner with progress linear in
time: the cells a manner sweeps are reserved for its whole window, so any progress profile
stays inside the reservation.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from fleet.params import ManeuverTimes, VehicleDims
from fleet.planning.geometry import Cell
from fleet.planning.gridmap import GridMap
from fleet.planning.maneuvers import (
    STEPS,
    Manner,
    arc_length,
    body_cells_at_rest,
    fork_target,
    world_pose,
)
from fleet.planning.planner import HybridAStar, PlannerCache
from fleet.planning.reservations import ReservationView
from fleet.planning.trajectory import PlanFailure, Pose, Step, Trajectory
from fleet.vehicles.kind import Commitment, ConflictPolicy, Outline, Placement, Site


class ReserveWholeTrajectory:
    """Plan against every other vehicle's space-time reservations, then commit the whole
    trajectory as planned, the vehicle's parking released from its start: conflict-free by
    construction, and only the vehicle being planned is ever delayed."""

    def commitment(self, trajectory: Trajectory, view: ReservationView
                   ) -> Commitment | PlanFailure:
        return Commitment(trajectory, trajectory.intervals, trajectory.t_start)


@dataclass(frozen=True)
class Forklift:
    dims: VehicleDims = VehicleDims()
    cell_size: float = 2.0
    name: ClassVar[str] = "forklift"
    noun: ClassVar[str] = "forklift"

    @property
    def outline(self) -> Outline:
        return Outline(self.dims.front, self.dims.rear, self.dims.width)

    @property
    def max_speed_mps(self) -> float:
        # One straight cell at v_high (Table 1's T5); a turn's outer corner or a lane change
        # moves a point at most 1.6 m/s.
        return self.cell_size / ManeuverTimes().T5

    def body_cells_at_rest(self, pose: Pose) -> tuple[Cell, ...]:
        return body_cells_at_rest(pose.cell, pose.heading)

    def handling_poses(self, cell: Cell) -> tuple[Pose, ...]:
        """The four poses whose forks point at `cell` (E, N, W, S)."""
        return tuple(Pose((cell[0] + dx, cell[1] + dy), heading)
                     for heading, (dx, dy) in enumerate(STEPS))

    def handled_cell(self, pose: Pose) -> Cell:
        return fork_target(pose.cell, pose.heading)

    def at_rest(self, pose: Pose) -> Placement:
        x, y, theta = world_pose(pose.cell, pose.heading, Manner.STOP, 0.0, self.cell_size)
        return Placement(pose, x, y, theta, 0, "")

    def on_step(self, step: Step, t: float) -> Placement:
        s = (t - step.t0) / (step.t1 - step.t0)
        x, y, theta = world_pose(step.start.cell, step.start.heading, step.manner, s,
                                 self.cell_size)
        speed = int(max(step.v0, step.v1)) if step.manner is not Manner.STOP else 0
        return Placement(step.start, x, y, theta, speed, step.manner.label)

    def is_wait(self, step: str) -> bool:
        return step == Manner.STOP.label

    def path_length_m(self, step: str) -> float:
        return arc_length(Manner.from_label(step)) * self.cell_size

    def planner(self, grid: GridMap) -> HybridAStar:
        return HybridAStar(grid, self.dims)

    def planners(self, layout: Site) -> ForkliftPlanners:
        return ForkliftPlanners(layout.grid_map, self.dims)


class ForkliftPlanners(PlannerCache):
    """A hybrid A* per fill state, and legs committed whole."""

    policy: ClassVar[ConflictPolicy] = ReserveWholeTrajectory()
