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


@dataclass
class Leg:
    trajectory: Trajectory
    loaded: bool
    sent: int = 0  # events (maneuver starts, then the arrival) already published in fast mode

    def events(self) -> list[float]:
        return [s.t0 for s in self.trajectory.steps] + [self.trajectory.t_end]


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

    def forget_before(self, t: float, published: bool = True) -> None:
        """Drop legs that ended before t (their goal becomes the rest pose); the last leg
        stays. With `published`, only legs whose every state fast mode has published."""
        while (len(self.legs) > 1 and self.legs[0].trajectory.t_end < t
               and (not published or self.legs[0].sent == len(self.legs[0].events()))):
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

    def due(self, until: float) -> list[float]:
        """Instants up to `until` whose state fast mode has not published yet: each maneuver
        start and each arrival, once (a leg committed at the very instant of the last tick
        still gets its first state). Marks them published."""
        out = []
        for leg in self.legs:
            events = leg.events()
            while leg.sent < len(events) and events[leg.sent] <= until:
                out.append(events[leg.sent])
                leg.sent += 1
        return sorted(set(out))

    def _state(self, start: Pose, manner: Manner, s: float, speed: int, loaded: bool,
               label: str) -> VehicleState:
        x, y, theta = world_pose(start.cell, start.heading, manner, s, self.layout.cell_size)
        ox, oy = self.layout.origin
        return VehicleState(self.vehicle, str(start), speed, label, loaded, x + ox, y + oy,
                            theta)
