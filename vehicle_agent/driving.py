"""Where a forklift is at a sim time, from the trajectories it committed (pure; no I/O).

A forklift stands at rest at its pose until its next trajectory starts, then follows the
trajectory maneuver by maneuver, and stands at the goal after it ends. Within a maneuver the
progress is linear in time; the cells a maneuver sweeps are reserved for its whole window, so
any progress profile stays inside the reservation.
"""

from __future__ import annotations

from dataclasses import dataclass

from fleet.layout import Layout
from fleet.maneuvers import Manner, world_pose
from fleet.protocol import VehicleState
from fleet.trajectory import Pose, Trajectory


@dataclass(frozen=True)
class Leg:
    trajectory: Trajectory
    loaded: bool


class Drive:
    def __init__(self, vehicle: int, pose: Pose, layout: Layout) -> None:
        self.vehicle = vehicle
        self.layout = layout
        self.rest_pose = pose  # where the forklift stands when no leg covers t
        self.legs: list[Leg] = []
        self.loaded = False

    @property
    def pose(self) -> Pose:
        """Where the forklift will stand once every committed leg is driven."""
        return self.legs[-1].trajectory.goal if self.legs else self.rest_pose

    def add(self, trajectory: Trajectory, loaded: bool) -> None:
        self.legs.append(Leg(trajectory, loaded))

    def forget_before(self, t: float) -> None:
        """Drop legs that ended before t (their goal becomes the rest pose)."""
        while self.legs and self.legs[0].trajectory.t_end < t and len(self.legs) > 1:
            self.rest_pose = self.legs.pop(0).trajectory.goal

    def state_at(self, t: float) -> VehicleState:
        pose, loaded = self.rest_pose, self.loaded
        for leg in self.legs:
            traj = leg.trajectory
            if t < traj.t_start:
                break
            loaded = leg.loaded
            if t >= traj.t_end:
                pose = traj.goal
                continue
            for step in traj.steps:
                if step.t0 <= t < step.t1:
                    s = (t - step.t0) / (step.t1 - step.t0)
                    speed = int(max(step.v0, step.v1)) if step.manner is not Manner.STOP else 0
                    return self._state(step.start, step.manner, s, speed, loaded,
                                       step.manner.label)
        return self._state(pose, Manner.STOP, 0.0, 0, loaded, "")

    def maneuver_starts(self, after: float, until: float) -> list[float]:
        """Instants in (after, until] at which a maneuver starts or a leg ends (fast mode
        publishes the state at each)."""
        out = []
        for leg in self.legs:
            for step in leg.trajectory.steps:
                if after < step.t0 <= until:
                    out.append(step.t0)
            if after < leg.trajectory.t_end <= until:
                out.append(leg.trajectory.t_end)
        return sorted(set(out))

    def _state(self, start: Pose, manner: Manner, s: float, speed: int, loaded: bool,
               label: str) -> VehicleState:
        x, y, theta = world_pose(start.cell, start.heading, manner, s, self.layout.cell_size)
        ox, oy = self.layout.origin
        return VehicleState(self.vehicle, str(start), speed, label, loaded, x + ox, y + oy,
                            theta)
