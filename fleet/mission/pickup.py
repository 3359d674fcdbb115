"""A restarted dispatcher picks a mission up: the state the engine starts from, from the
goods the reservation service holds (an order mission: from the book its journal replays)
and what each vehicle's agent says it committed (dispatcher/pickup.py asks them;
docs/faults.md)."""

from __future__ import annotations

from dataclasses import dataclass, field

from fleet.dispatching.decision import Decision, TaskKind
from fleet.errors import UserError
from fleet.mission.halt_log import Halted
from fleet.mission.order_work import OrderWork
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
    halted: Halted | None = None  # down: where it stopped, as the dead dispatcher journaled

    @classmethod
    def down(cls, halted: Halted) -> HeldLeg:
        """A forklift that was down when the dispatcher died (its agent is not asked: it
        may be dead, paused or cut off)."""
        return cls(halted.vehicle, halted.freeze.pose, None, False, "", halted)


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
    work: MissionWork | None = None  # the work as picked up, where it is not read as above
    down: dict[int, Halted] = field(default_factory=dict)  # down, and where they stopped
    # Each breakdown as its agent reported it ("broken", "repaired"), perhaps while no
    # dispatcher listened: what the clock has heard of it.
    breakdowns: dict[int, str] = field(default_factory=dict)


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
        if h.halted is not None:  # down: it goes on with what it was to do once it moves
            delivers_next[h.vehicle] = h.halted.next_task is TaskKind.DELIVER
            end, handling = h.halted.freeze.t_stand, 0.0
        elif h.leg is None:  # never moved: ready when the mission's first subtask is
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
                     t_free, delivers_next, legs, t, down=_down(held))


def recovered_orders(work: OrderWork, held: list[HeldLeg], t: float) -> Recovered:
    """An order mission as the book its dead dispatcher journaled has it (`work`, replayed),
    and the AGVs as their agents hold them. A leg an agent committed that the journal has not
    heard of (the dead dispatcher never had the answer) is the trip the book had decided for
    it, committed; a leg postponed that it has heard of only as it was, postponed. Both are
    fed to the work (and journaled) before the engine starts from it."""
    poses, t_free, legs = {}, {}, {}
    for h in held:
        poses[h.vehicle] = h.pose
        end = h.halted.freeze.t_stand if h.halted is not None else 0.0
        if h.leg is not None:
            legs[h.vehicle], end = h.leg, h.leg.t_end
            last = work.last_leg(h.vehicle)
            if last is None or h.leg.t_start > last[0]:  # committed, answer never heard
                trip = work.trips.get(h.vehicle)
                if trip is None or trip.kind is None:
                    raise UserError(f"AGV {h.vehicle} drives a leg from t={h.leg.t_start:.2f} "
                                    f"that its order book never decided")
                work.serve(Decision(h.vehicle, h.leg.t_start, trip.kind, trip, False), h.leg,
                           h.leg.t_end + work.handling(trip.kind))
            elif h.leg.t_start == last[0] and h.leg.t_end != last[1] and \
                    h.vehicle in work.pending:
                work.amended(h.leg)
        t_free[h.vehicle] = max(t, end, work.trip_since(h.vehicle) or 0.0)
    return Recovered(tuple(work.done()), (), poses, t_free, {v: True for v in poses}, legs, t,
                     work, _down(held))


def _down(held: list[HeldLeg]) -> dict[int, Halted]:
    return {h.vehicle: h.halted for h in held if h.halted is not None}
