"""Where a vehicle is at a sim time, from the trajectories it committed (pure; no I/O).

A vehicle stands at rest at its pose until its next trajectory starts, then follows the
trajectory step by step, and stands at the goal after it ends; where it is within a step is
its kind's motion model (fleet.vehicles).

States are published at the instants k * period of one grid shared by every vehicle (0.5 s
of sim time in fast mode, 0.1 s of wall time in real time), so a verifier can compare the
vehicles' poses at the very same instants. In fast mode a tick at t publishes the instants
before t only: a subtask decided at t may still start at t.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from fleet.mission.battery import Battery
from fleet.mission.drive_log import AddLeg, AmendLeg, CutAt, DriveOrder, ResumeAt, StopAt
from fleet.mission.spec import ClockMode
from fleet.planning.geometry import Cell
from fleet.planning.trajectory import Pose, Step, Trajectory
from fleet.vehicles.kind import Placement
from fleet.wire.protocol import VehicleState
from fleet.world.layout import Layout

FAST_STATE_PERIOD_S = 0.5  # sim seconds between two states in fast mode
REALTIME_STATE_PERIOD_S = 0.1  # wall seconds between two states in real time (10 Hz)


def replayed(vehicle: int, start: Pose, layout: Layout, battery: Battery | None,
             log: list[DriveOrder]) -> tuple[Drive, list[tuple[float, float]]]:
    """The vehicle driven as its agent was told (a `DriveLog` entry's orders, in order), and
    the windows it was down in (it says nothing then)."""
    drive = Drive(vehicle, start, layout, battery)
    silent: list[tuple[float, float]] = []
    for order in log:
        match order:
            case AddLeg(trajectory, loaded, after):
                drive.add(trajectory, loaded, after)
            case AmendLeg(trajectory):
                drive.amend(trajectory)
            case CutAt(t):
                drive.cut(t)
            case StopAt(t):
                drive.stop(t)
                silent.append((t, math.inf))
            case ResumeAt(t):
                drive.resume(t)
                silent[-1] = (silent[-1][0], t)
    return drive, silent


def states_until(t_end: float) -> float:
    """Where the states of a mission that ended at t_end stop (exclusive): past the first
    instant of the fast grid at or after t_end, so the recording shows every vehicle as the
    mission leaves it (an AGV's last shelf put down at t_end). No tolerance: an end a
    rounding error past a grid instant must still be seen from the next one."""
    k = math.ceil(t_end / FAST_STATE_PERIOD_S)
    return (k + 1) * FAST_STATE_PERIOD_S


def state_period(mode: str, speed: float) -> float:
    """Sim seconds between two states: the fast grid, or 10 Hz of wall time but never coarser
    than the fast grid, so the recording's safety check sees as much at any speed. `mode` is a
    ClockMode, or a recording's clock ("inprocess" runs on the fast grid)."""
    if mode != ClockMode.REALTIME:
        return FAST_STATE_PERIOD_S
    return min(speed * REALTIME_STATE_PERIOD_S, FAST_STATE_PERIOD_S)


@dataclass
class Leg:
    trajectory: Trajectory
    loaded: bool
    after: bool | None = None  # loaded once arrived (None: as on the leg)
    # A vehicle that went down stands still over [pause_from, pause_to) part-way through
    # its step, then completes it: the leg runs that much later.
    pause_from: float = math.inf
    pause_to: float = math.inf

    @property
    def carries_after(self) -> bool:
        return self.loaded if self.after is None else self.after

    @property
    def t_end(self) -> float:
        if self.pause_from >= self.trajectory.t_end:
            return self.trajectory.t_end
        return self.trajectory.t_end + (self.pause_to - self.pause_from)

    def local(self, t: float) -> float:
        """The trajectory's own time at t (time stands still while paused)."""
        if t < self.pause_from:
            return t
        return self.pause_from if t < self.pause_to else t - (self.pause_to - self.pause_from)


class Drive:
    def __init__(self, vehicle: int, pose: Pose, layout: Layout,
                 battery: Battery | None = None) -> None:
        self.vehicle = vehicle
        self.layout = layout
        self.vehicle_kind = layout.vehicle_kind
        self.rest_pose = pose  # where the vehicle stands when no leg covers t
        self.legs: list[Leg] = []
        self.loaded = False
        self.next_k = 0  # grid index of the next state to publish
        self.battery = battery
        # The charge known at an instant; later ones are worked out from the legs since.
        self.charged_at = (0.0, battery.start_soc if battery is not None else 0.0)

    @property
    def pose(self) -> Pose:
        """Where the vehicle will stand once every committed leg is driven."""
        return self.legs[-1].trajectory.goal if self.legs else self.rest_pose

    def add(self, trajectory: Trajectory, loaded: bool, after: bool | None = None) -> None:
        self.legs.append(Leg(trajectory, loaded, after))

    def amend(self, trajectory: Trajectory) -> None:
        """The last leg is postponed: drive `trajectory` instead (the same start, the same
        steps up to the first wait put in)."""
        last = self.legs[-1]
        if last.trajectory.t_start != trajectory.t_start:
            raise ValueError(f"vehicle {self.vehicle}: the amended leg from "
                             f"t={trajectory.t_start} is not its last, from "
                             f"t={last.trajectory.t_start}")
        self.legs[-1] = Leg(trajectory, last.loaded, last.after)

    def cut(self, t: float) -> None:
        """Drive nothing committed after the step in progress at t (legs not started by t go;
        the one in progress ends with that step)."""
        kept = []
        for leg in self.legs:
            if leg.trajectory.t_start >= t:
                continue
            steps = tuple(s for s in leg.trajectory.steps if s.t0 < leg.local(t))
            if steps and len(steps) < len(leg.trajectory.steps):
                traj = leg.trajectory
                leg = Leg(Trajectory(traj.vehicle, traj.start, steps[-1].end, traj.t_start,
                                     steps, (), traj.expansions), leg.loaded,
                          None, leg.pause_from, leg.pause_to)
            kept.append(leg)
        self.legs = kept

    def stop(self, t: float) -> None:
        """Stand still from t where the vehicle is (it is down), until `resume`."""
        self.cut(t)
        if self.legs and self.legs[-1].t_end > t:
            self.legs[-1].pause_from, self.legs[-1].pause_to = t, math.inf

    def resume(self, t: float) -> None:
        """Move again from t: the step stopped part-way is completed first."""
        for leg in self.legs:
            if leg.pause_to == math.inf and leg.pause_from <= t:
                leg.pause_to = t

    def restart(self, rest: Pose, loaded: bool, step: Step | None, t_stop: float,
                t_resume: float, soc: float | None = None) -> None:
        """Become what the dispatcher says (a restarted agent knows nothing of itself): at
        rest at `rest`, or stopped part-way through `step` since t_stop, moving from
        t_resume, with the battery at `soc` at t_stop (None: as its own legs had it). States
        before t_resume are not published again."""
        if self.battery is not None and t_stop >= self.charged_at[0]:
            self.charged_at = (t_stop, self.soc_at(t_stop) if soc is None else soc)
        self.legs = []
        self.rest_pose, self.loaded = rest, loaded
        if step is not None:
            self.rest_pose = step.start
            traj = Trajectory(self.vehicle, step.start, step.end, step.t0, (step,), (), 0)
            self.legs = [Leg(traj, loaded, None, t_stop, t_resume)]

    def skip_to(self, t: float, period: float) -> None:
        """Publish no state for instants before t (the vehicle was down: nothing was said)."""
        self.next_k = max(self.next_k, math.ceil(t / period - 1e-9))

    def forget_before(self, t: float) -> None:
        """Drop legs that ended before t (their goal becomes the rest pose, their load what it
        carries, the charge at their end known); the last leg stays."""
        while len(self.legs) > 1 and self.legs[0].t_end < t:
            end = self.legs[0].t_end
            if self.battery is not None and end > self.charged_at[0]:
                self.charged_at = (end, self.soc_at(end))
            leg = self.legs.pop(0)
            self.rest_pose, self.loaded = leg.trajectory.goal, leg.carries_after

    def soc_at(self, t: float) -> float:
        """The battery's state of charge at t (from the last instant it is known at on): it
        drains while the vehicle moves and charges while it is parked on a pile."""
        assert self.battery is not None
        params, piles = self.battery.params, self.battery.piles
        t_known, soc = self.charged_at
        for t0, t1, doing, cell in self._spans(t_known, t):
            if doing == "moving":
                soc = params.after_driving(soc, t1 - t0)
            elif doing == "parked" and cell in piles:
                soc = params.after_charging(soc, t1 - t0)
        return soc

    def _spans(self, t0: float, t1: float) -> list[tuple[float, float, str, Cell]]:
        """[t0, t1) cut into spans moving, standing (inside a leg) and parked (between
        legs), in time order, with the cell each starts on."""
        out: list[tuple[float, float, str, Cell]] = []

        def add(a: float, b: float, doing: str, cell: Cell) -> None:
            a, b = max(a, t0), min(b, t1)
            if b > a:
                out.append((a, b, doing, cell))

        cursor, pose = t0, self.rest_pose
        for leg in self.legs:
            traj = leg.trajectory
            add(cursor, traj.t_start, "parked", pose.cell)
            if traj.t_start >= t1:
                return out  # the legs after t1 do not count
            if leg.t_end <= t0:
                cursor, pose = max(cursor, leg.t_end), traj.goal
                continue  # over before t0
            for step in traj.steps:
                doing = "standing" if self.vehicle_kind.is_wait(step.manner.label) else \
                    "moving"
                if step.t0 < leg.pause_from < step.t1:  # down part-way through the step
                    add(step.t0, leg.pause_from, doing, step.start.cell)
                    add(leg.pause_from, leg.pause_to, "standing", step.start.cell)
                    add(leg.pause_to, step.t1 + leg.pause_to - leg.pause_from, doing,
                        step.start.cell)
                else:
                    shift = 0.0 if step.t1 <= leg.pause_from else leg.pause_to - leg.pause_from
                    add(step.t0 + shift, step.t1 + shift, doing, step.start.cell)
            cursor, pose = max(cursor, leg.t_end), traj.goal
        add(cursor, math.inf, "parked", pose.cell)
        return out

    def state_at(self, t: float) -> VehicleState:
        pose, loaded = self.rest_pose, self.loaded
        for leg in self.legs:
            traj = leg.trajectory
            if t < traj.t_start:
                break
            loaded = leg.loaded
            if t >= leg.t_end:
                pose, loaded = traj.goal, leg.carries_after
                continue
            tau = leg.local(t)
            for step in traj.steps:
                if step.t0 <= tau < step.t1:
                    return self._state(self.vehicle_kind.on_step(step, tau), loaded, t)
        return self._state(self.vehicle_kind.at_rest(pose), loaded, t)

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

    def _state(self, at: Placement, loaded: bool, t: float) -> VehicleState:
        ox, oy = self.layout.origin
        soc = None if self.battery is None else round(self.soc_at(t), 6)
        return VehicleState(self.vehicle, str(at.pose), at.speed, at.step, loaded, at.x + ox,
                            at.y + oy, at.theta, soc)
