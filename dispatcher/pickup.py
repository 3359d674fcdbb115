"""A restarted dispatcher picks the mission up (docs/faults.md): the stacks done are the goods
the reservation service holds (an order mission's book is what its journal replays), each
vehicle says what it has committed, and the clock goes on from the last tick they heard.
Asking each agent is also a barrier: an agent answers in turn, so a task the dead dispatcher
had sent is committed (or failed) before it answers, and the table read afterwards holds
everything."""

from __future__ import annotations

from dispatcher.liveness import ParticipantLost
from dispatcher.remote import RemoteExecutor
from dispatcher.work_journal import WorkJournal
from fleet.errors import UserError
from fleet.mission.order_work import OrderWork
from fleet.mission.pickup import HeldLeg, Recovered, recovered_orders, recovered_state
from fleet.mission.spec import Mission, MissionKind
from fleet.mission.work import stack_work
from fleet.params import DispatchParams
from fleet.planning.reservations import Interval
from fleet.planning.trajectory import Pose, Trajectory
from fleet.wire.convert import step_from_wire
from fleet.wire.protocol import GOODS, ProtocolError
from fleet.world.layout import Layout
from fleet.world.site import planners_for


def pick_up(executor: RemoteExecutor, layout: Layout, mission: Mission, vehicles: list[int],
            params: DispatchParams, journal: WorkJournal | None = None
            ) -> tuple[Recovered, int, float]:
    """The mission as the store and the vehicles hold it (and an order mission's `journal`),
    and the last tick they heard: its number and (real time) its wall anchor."""
    statuses = [executor.status(v) for v in vehicles]
    held = []
    for s in statuses:
        if s.down:
            raise ParticipantLost(f"forklift {s.vehicle} was down when the dispatcher died; "
                                  f"where it stopped is not known to a new dispatcher (not "
                                  f"supported yet)")
        try:
            steps = tuple(step_from_wire(st, f"vehicle.status.steps[{i}]")
                          for i, st in enumerate(s.steps))
            pose = Pose.parse(s.pose)
            leg = Trajectory(s.vehicle, Pose.parse(s.start), steps[-1].end, steps[0].t0,
                             steps, (), 0) if steps else None
        except (ValueError, ProtocolError) as exc:
            raise ParticipantLost(f"forklift {s.vehicle}'s status is malformed: {exc}") from None
        held.append(HeldLeg(s.vehicle, pose, leg, s.loaded, s.kind, s.down))
    last = max(statuses, key=lambda s: s.tick)
    if mission.kind is MissionKind.ORDERS:
        if journal is None:
            raise UserError("an order mission is picked up from its dispatcher's journal of "
                            "the order book: give the dead one's --journal")
        work = OrderWork.replayed(layout, mission, len(vehicles), journal.records(), journal)
        return recovered_orders(work, held, last.t), last.tick, last.wall
    goods = [Interval(r.cell, r.t0, r.t1) for r in executor.store.reservations(GOODS)]
    stacks = [(s.cluster, s.index, s.cell) for s in layout.stacks]
    work = stack_work(mission.kind, layout, params, executor.store,
                      planners_for(layout))
    return recovered_state(stacks, goods, held, last.t, work), last.tick, last.wall
