"""One forklift as the engine keeps it: where it will stand, when it is free, what it does
next, and the time it spent (the wire's VehicleState is what its agent says instead)."""

from __future__ import annotations

from dataclasses import dataclass

from fleet.dispatching.decision import TaskKind, VehicleView
from fleet.planning.trajectory import Pose, Trajectory


@dataclass
class VehicleSlot:
    vehicle: int
    pose: Pose
    t_free: float
    next_task: TaskKind
    linked_cluster: str | None = None
    linked_kind: TaskKind | None = None
    busy_s: float = 0.0  # driving (maneuvers other than stop)
    wait_s: float = 0.0  # stop maneuvers and postponements
    # Postponed since its last subtask: waiting once a subtask follows; a forklift postponed
    # after its last one stood idle, as its recording shows.
    postponed_s: float = 0.0
    t_still: float = 0.0  # from when it stands at `pose`, driven and handled (t_free may be later)

    def view(self) -> VehicleView:
        return VehicleView(self.vehicle, self.pose, self.t_free, self.next_task,
                           self.linked_cluster, self.linked_kind)

    def wait_until(self, t: float) -> None:
        """Free only from t on (a pacer's or a postponement's later instant): waiting, if a
        subtask follows."""
        self.postponed_s += t - self.t_free
        self.t_free = t

    def amended(self, delay: float, t_done: float) -> None:
        """Its committed leg was postponed by `delay` seconds of waiting: done at t_done."""
        self.wait_s += delay
        self.t_free = self.t_still = t_done

    def step_aside(self, traj: Trajectory, waited: float) -> None:
        """Sent out of another's way, standing still since before traj.t_start (perhaps
        postponed beyond): it stands at the siding from the arrival on, with the same subtask
        next (and the goods it carried)."""
        self.busy_s += traj.t_end - traj.t_start - waited
        self.wait_s += waited + self.postponed_s - max(0.0, self.t_free - traj.t_start)
        self.postponed_s = 0.0  # (postponed beyond the start no longer)
        self.pose = traj.goal
        self.t_free = self.t_still = traj.t_end

    def drive(self, kind: TaskKind, target: str, traj: Trajectory, t_done: float,
              waited: float, next_task: TaskKind) -> None:
        """A subtask committed (`waited`: the seconds of its steps that wait in place): it
        stands at the goal from t_done on, and does `next_task` next."""
        self.busy_s += traj.t_end - traj.t_start - waited
        self.wait_s += waited + self.postponed_s
        self.postponed_s = 0.0
        self.pose = traj.goal
        self.t_free = self.t_still = t_done
        self.next_task = next_task
        if kind is TaskKind.DELIVER:
            self.linked_cluster, self.linked_kind = target, TaskKind.DELIVER
        else:
            self.linked_kind = TaskKind.RETURN if self.linked_cluster else None
