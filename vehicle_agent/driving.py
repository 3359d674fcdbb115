"""Where a forklift is at a sim time, from the trajectories it committed (pure; no I/O).

A forklift stands at rest at its pose until its next trajectory starts, then follows the
trajectory maneuver by maneuver, and stands at the goal after it ends. Within a maneuver the
progress is linear in time; the cells a maneuver sweeps are reserved for its whole window, so
any progress profile stays inside the reservation.

States are published at the instants k * period of one grid shared by every forklift (0.5 s
of sim time in fast mode, 0.1 s of wall time in real time), so a verifier can compare the
forklifts' poses at the very same instants. In fast mode a tick at t publishes the instants
before t only: a subtask decided at t may still start at t.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from fleet.layout import Layout
from fleet.maneuvers import Manner, world_pose
from fleet.protocol import VehicleState
from fleet.trajectory import Pose, Trajectory

FAST_STATE_PERIOD_S = 0.5  # sim seconds between two states in fast mode


@dataclass
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
        self.next_k = 0  # grid index of the next state to publish

    @property
    def pose(self) -> Pose:
        """Where the forklift will stand once every committed leg is driven."""
        return self.legs[-1].trajectory.goal if self.legs else self.rest_pose

    def add(self, trajectory: Trajectory, loaded: bool) -> None:
        self.legs.append(Leg(trajectory, loaded))

    def forget_before(self, t: float) -> None:
        """Drop legs that ended before t (their goal becomes the rest pose, their load what it
        carries); the last leg stays."""
        while len(self.legs) > 1 and self.legs[0].trajectory.t_end < t:
            leg = self.legs.pop(0)
            self.rest_pose, self.loaded = leg.trajectory.goal, leg.loaded

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

    def due(self, until: float, period: float, before: bool = False) -> list[float]:
        """The grid instants k * period up to `until` (with `before`, only those before it)
        not published yet, from t = 0 on; marks them published."""
        if not (math.isfinite(until) and math.isfinite(period) and period > 0):
            raise ValueError(f"no grid instants up to {until} every {period} s")
        last = math.floor(until / period)
        while (last + 1) * period <= until:  # floor of a rounded quotient can fall one short
            last += 1
        while last >= 0 and (last * period > until or (before and last * period == until)):
            last -= 1
        out = [k * period for k in range(self.next_k, last + 1)]
        self.next_k = max(self.next_k, last + 1)
        return out

    def _state(self, start: Pose, manner: Manner, s: float, speed: int, loaded: bool,
               label: str) -> VehicleState:
        x, y, theta = world_pose(start.cell, start.heading, manner, s, self.layout.cell_size)
        ox, oy = self.layout.origin
        return VehicleState(self.vehicle, str(start), speed, label, loaded, x + ox, y + oy,
                            theta)
