"""A restarted dispatcher picks a mission up: the state the engine starts from, from the
goods the reservation service holds and what each forklift's agent says it committed
(dispatcher/pickup.py asks them; docs/faults.md)."""

from __future__ import annotations

from dataclasses import dataclass

from fleet.dispatching.decision import TaskKind
from fleet.mission.work import MissionWork
from fleet.planning.maneuvers import fork_target
from fleet.planning.reservations import Interval
from fleet.planning.trajectory import Pose, Trajectory


@dataclass(frozen=True)
class HeldLeg:
    """One forklift as its agent holds it (a VehicleStatus, decoded)."""

    vehicle: int
    pose: Pose  # where it stands once everything committed is driven
    leg: Trajectory | None  # its last committed leg
    loaded: bool
    kind: str  # what the leg was for: "deliver", "return", "aside", or "" (none, or cut short)
    down: bool


@dataclass(frozen=True)
class Recovered:
    """A mission picked up mid-way: what the engine starts from."""

    done: tuple[tuple[str, int, float], ...]  # stacks done: cluster, index, t_done
    undelivered: tuple[tuple[str, int, float, int], ...]  # committed, goods not reserved yet
    poses: dict[int, Pose]
    t_free: dict[int, float]
    delivers_next: dict[int, bool]
    legs: dict[int, Trajectory]
    t: float  # the clock's last instant: nothing is decided before it


def recovered_state(stacks, goods: list[Interval], held: list[HeldLeg], t: float,
                    work: MissionWork) -> Recovered:
    """`stacks`: the layout's (cluster, index, cell); `goods`: the store's GOODS reservations,
    which say the stacks done (`work.done_at`). A forklift whose last leg is a committed
    delivery arrives whatever happened to the dispatcher: its stack is done, and if its
    goods are not reserved yet (the dispatcher died in between) they are to be."""
    by_cell = {cell: (cluster, index) for cluster, index, cell in stacks}
    done_at = {iv.cell: work.done_at(iv) for iv in goods if iv.cell in by_cell}
    done = [(*by_cell[c], t_done) for c, t_done in done_at.items() if t_done is not None]
    undelivered = []
    poses, t_free, delivers_next, legs = {}, {}, {}, {}
    for h in held:
        poses[h.vehicle] = h.pose
        end = h.leg.t_end if h.leg else 0.0
        if h.leg is None:  # never moved: ready when the mission's first subtask is
            delivers_next[h.vehicle], end, handling = True, work.ready_at, 0.0
        elif h.kind == "deliver":
            delivers_next[h.vehicle], handling = False, work.handling(TaskKind.DELIVER)
            stack = fork_target(h.pose.cell, h.pose.heading)
            if stack in by_cell and done_at.get(stack) is None:
                undelivered.append((*by_cell[stack], end, h.vehicle))
        elif h.kind == "return":
            delivers_next[h.vehicle], handling = True, work.handling(TaskKind.RETURN)
        else:  # cut short, or sent aside: goods on board or not, a delivery next or not
            delivers_next[h.vehicle] = h.loaded == work.loaded(TaskKind.DELIVER)
            handling = 0.0
        t_free[h.vehicle] = max(end + handling, t)
        if h.leg is not None:
            legs[h.vehicle] = h.leg
    return Recovered(tuple(sorted(done, key=lambda d: d[2])), tuple(undelivered), poses,
                     t_free, delivers_next, legs, t)
