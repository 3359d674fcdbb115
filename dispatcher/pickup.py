"""A restarted dispatcher picks the mission up (docs/faults.md): the stacks done are the goods
the reservation service holds (an order mission's book is what its journal replays), each
vehicle says what it has committed, and the clock goes on from the last tick they heard.
Asking each agent is also a barrier: an agent answers in turn, so a task the dead dispatcher
had sent is committed (or failed) before it answers, and the table read afterwards holds
everything. A forklift that was down is where the dead one's journal stopped it."""

from __future__ import annotations

import dataclasses
import logging

from dispatcher.liveness import ParticipantLost
from dispatcher.remote import RemoteExecutor
from dispatcher.work_journal import WorkJournal
from fleet.errors import UserError
from fleet.mission.halt_log import Halted, is_halt_record, standing
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

log = logging.getLogger("fleet.dispatcher")


def journaled(journal: WorkJournal | None) -> tuple[dict[int, Halted], list[object]]:
    """What the dead dispatcher journaled: the forklifts down when it died, and where each
    stopped; and the records of an order mission's book."""
    if journal is None:
        return {}, []
    records = journal.records()
    try:
        down = standing(r for r in records if is_halt_record(r))
    except ValueError as exc:
        raise UserError(f"{journal.path}: not a dispatcher's journal: {exc}") from None
    return down, [r for r in records if not is_halt_record(r)]


def pick_up(executor: RemoteExecutor, layout: Layout, mission: Mission, vehicles: list[int],
            params: DispatchParams, journal: WorkJournal | None = None,
            down: dict[int, Halted] | None = None, book: list[object] | None = None
            ) -> tuple[Recovered, int, float]:
    """The mission as the store and the vehicles hold it (and the dead dispatcher's
    `journal`: the forklifts `down` and an order mission's `book`, as `journaled` read
    them), and the last tick they heard: its number and (real time) its wall anchor. A
    forklift that is down is taken at the journal's word; its agent, if it answers at all
    (dead, paused or cut off, it does not), says only which tick it heard."""
    down = down or {}
    statuses, held = [], []
    for v in vehicles:
        if v in down:
            held.append(HeldLeg.down(down[v]))
            if v in executor.liveness.alive:  # it may say which tick it heard, no more
                try:
                    statuses.append(executor.status(v))
                except ParticipantLost as exc:
                    log.warning("forklift %d, down, did not answer: %s", v, exc)
            continue
        s = executor.status(v)
        statuses.append(s)
        if s.down:
            raise ParticipantLost(
                f"forklift {v} was down when the dispatcher died, and no --journal says "
                f"where it stopped" if journal is None else
                f"forklift {v} was down when the dispatcher died, and its journal "
                f"{journal.path} does not say where it stopped (the dispatcher died between "
                f"stopping it and journaling that, or between journaling its resumption and "
                f"telling it)")
        try:
            steps = tuple(step_from_wire(st, f"vehicle.status.steps[{i}]")
                          for i, st in enumerate(s.steps))
            pose = Pose.parse(s.pose)
            leg = Trajectory(s.vehicle, Pose.parse(s.start), steps[-1].end, steps[0].t0,
                             steps, (), 0) if steps else None
        except (ValueError, ProtocolError) as exc:
            raise ParticipantLost(f"forklift {s.vehicle}'s status is malformed: {exc}") from None
        held.append(HeldLeg(s.vehicle, pose, leg, s.loaded, s.kind))
    breakdowns = {s.vehicle: s.breakdown for s in statuses if s.breakdown}
    if odd := {v: b for v, b in breakdowns.items() if b not in ("broken", "repaired")}:
        raise ParticipantLost(f"forklifts' statuses name breakdowns that are neither broken "
                              f"nor repaired: {odd}")
    if not statuses:
        raise ParticipantLost("every forklift was down when the dispatcher died, and none "
                              "answered: no one can say which tick it heard last")
    last = max(statuses, key=lambda s: s.tick)
    if mission.kind is MissionKind.ORDERS:
        if journal is None:
            raise UserError("an order mission is picked up from its dispatcher's journal of "
                            "the order book: give the dead one's --journal")
        work = OrderWork.replayed(layout, mission, len(vehicles), book or [], journal)
        recovered = recovered_orders(work, held, last.t)
    else:
        goods = [Interval(r.cell, r.t0, r.t1) for r in executor.store.reservations(GOODS)]
        stacks = [(s.cluster, s.index, s.cell) for s in layout.stacks]
        work = stack_work(mission.kind, layout, params, executor.store,
                          planners_for(layout))
        recovered = recovered_state(stacks, goods, held, last.t, work)
    return dataclasses.replace(recovered, breakdowns=breakdowns), last.tick, last.wall
