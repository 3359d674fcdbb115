"""The engine's executor when the forklifts are agent processes: a task goes to the agent on
fleet/<run>/vehicle/<id>/task, the agent plans and commits, and the answer is the committed
trajectory. The dispatcher reads the reservation table from its own mirror of the service and
waits for the mirror to hold each change before deciding again, so it decides on exactly the
table the in-process engine would."""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence

import zenoh

from dispatcher.liveness import UNSERVED_RETRY_S, Liveness, ParticipantLost
from fleet.mission.freeze import Freeze
from fleet.mission.seam import Task, VehicleLost, freeze_changes
from fleet.planning.geometry import Cell
from fleet.planning.reservations import Interval, ReservationTable
from fleet.planning.trajectory import PlanFailure, Pose, Trajectory
from fleet.runtime.bus import Requester, RequestFailed
from fleet.runtime.tasks import result_from_wire, task_to_wire
from fleet.vehicles.kind import VehicleKind
from fleet.wire.convert import leg_from_wire, step_to_wire
from fleet.wire.protocol import (
    GOODS,
    AmendRequest,
    HaltRequest,
    Message,
    Reply,
    ResumeRequest,
    StatusRequest,
    TaskResult,
    VehicleStatus,
)
from fleet.wire.topics import DISPATCHER, Keys
from reservation.client import ReservationClient
from reservation.mirror import TableMirror

log = logging.getLogger("fleet.dispatcher")
SENDER = DISPATCHER
TASK_TIMEOUT_S = 120.0  # a search is capped far below this; the agent may first resync
SYNC_TIMEOUT_S = 30.0


class RemoteExecutor:
    def __init__(self, session: zenoh.Session, keys: Keys, reservations: ReservationClient,
                 mirror: TableMirror, liveness: Liveness, vehicles: list[int],
                 vehicle_kind: VehicleKind) -> None:
        self.keys = keys
        self.vehicle_kind = vehicle_kind
        self.reservations = reservations  # follows into `mirror`
        self.mirror = mirror
        self.liveness = liveness
        self.vehicles = vehicles
        # Asked again only while its token is here and nothing serves its key (a timeout is
        # longer than the retry: an agent that does not answer in time is not asked again)
        self.task_requester = Requester(session, SENDER, TASK_TIMEOUT_S, UNSERVED_RETRY_S)
        self.rejections: list[str] = []  # commits the store refused before an agent replanned
        self.amended: list[Trajectory] = []  # others' legs the commits postponed, not taken

    @property
    def store(self) -> ReservationTable:
        # The table itself: only this dispatcher's own requests change it, and it waits for
        # each change to arrive before it reads again.
        return self.mirror.table

    def park(self, vehicle: int, pose: Pose) -> None:
        cells = set(self.vehicle_kind.body_cells_at_rest(pose))

        def parked(table: ReservationTable) -> bool:
            return cells <= {r.cell for r in table.reservations(vehicle) if r.t1 == math.inf}

        if not self.mirror.wait_until(parked, SYNC_TIMEOUT_S):
            raise ParticipantLost(f"forklift {vehicle} is not parked at {pose} (its agent "
                                  f"holds {self.mirror.table.reservations(vehicle)})")

    def take_amended(self) -> list[Trajectory]:
        taken, self.amended = self.amended, []
        return taken

    def execute(self, task: Task) -> Trajectory | PlanFailure:
        message = task_to_wire(task, self.task_requester.next_id(), self.mirror.revision)
        try:
            reply = self._ask(task.vehicle, message, task.t_i)
        except RequestFailed as exc:
            self.liveness.wait_gone(task.vehicle, 2.0)  # a dead agent: say so, not "no reply"
            raise VehicleLost(task.vehicle, f"forklift {task.vehicle}: {exc}") from None
        if not isinstance(reply, TaskResult) or reply.task_id != message.task_id:
            raise ParticipantLost(f"forklift {task.vehicle} answered task {message.task_id} "
                                  f"with {reply}")
        self.rejections.extend(reply.rejections)
        result = result_from_wire(reply)
        if isinstance(result, Trajectory):
            self._sync(reply.revision)
            for k, wire in enumerate(reply.amended):  # each AGV postponed drives it so
                leg = leg_from_wire(wire, f"{reply.TYPE}.amended[{k}]")
                self._tell(leg.vehicle, AmendRequest(self.task_requester.next_id(),
                                                     leg.vehicle, wire), task.t_i)
                self.amended.append(leg)
        return result

    def reserve_goods(self, intervals: Sequence[Interval]) -> None:
        written = self.reservations.commit(GOODS, intervals)
        if written.ok:
            self._sync(written.revision)

    def freeze(self, t: float, freezes: list[Freeze], goods: list[Cell], zone: frozenset[Cell],
               zone_until: float, moving: list[int], standing: list[int]) -> None:
        """Commit the freeze to the store change by change (releases first: each change is
        valid on its own), then tell the forklifts that can move to stop."""
        for owner, intervals, release_from, cells in freeze_changes(t, freezes, goods, zone,
                                                                    zone_until):
            written = self.reservations.commit(owner, intervals) if intervals else \
                self.reservations.release(owner, release_from, cells)
            if not written.ok:
                raise ParticipantLost(f"the reservation service refused a freeze at t={t}: "
                                      f"{written.reason}")
            self._sync(written.revision)
        for vehicle in moving:
            self._tell(vehicle, HaltRequest(self.task_requester.next_id(), vehicle, t), t)
        for vehicle in standing:  # down already: if it cannot hear, it stands all the same
            try:
                self._tell(vehicle, HaltRequest(self.task_requester.next_id(), vehicle, t, True),
                           t)
            except ParticipantLost as exc:
                log.warning("forklift %d did not hear where to stand: %s", vehicle, exc)

    def resume(self, vehicle: int, freeze: Freeze, t: float, loaded: bool,
               battery: float | None = None) -> None:
        step = step_to_wire(freeze.step) if freeze.step is not None else None
        self._tell(vehicle, ResumeRequest(self.task_requester.next_id(), vehicle, freeze.t, t,
                                          str(freeze.pose), loaded, step, battery), t)

    def status(self, vehicle: int) -> VehicleStatus:
        """What a forklift holds (a restarted dispatcher asks)."""
        try:
            reply = self._ask(vehicle, StatusRequest(self.task_requester.next_id(), vehicle))
        except RequestFailed as exc:
            raise ParticipantLost(f"forklift {vehicle} did not say what it holds: "
                                  f"{exc}") from None
        if not isinstance(reply, VehicleStatus) or reply.vehicle != vehicle:
            raise ParticipantLost(f"forklift {vehicle} answered its status with {reply}")
        return reply

    def _tell(self, vehicle: int, message: Message, t: float) -> None:
        try:
            reply = self._ask(vehicle, message, t)
        except RequestFailed as exc:
            raise ParticipantLost(f"forklift {vehicle} did not take {message.TYPE}: "
                                  f"{exc}") from None
        if not isinstance(reply, Reply) or not reply.ok:
            raise ParticipantLost(f"forklift {vehicle} refused {message.TYPE}: "
                                  f"{getattr(reply, 'reason', reply)}")

    def _ask(self, vehicle: int, message: Message, t: float = 0.0) -> Message:
        """A forklift agent's reply; asked again while nothing serves its key but its token is
        here (the token may come back before the queryable does)."""
        return self.task_requester.request(
            self.keys.vehicle_task(vehicle), message, t,
            retry_while=lambda: vehicle in self.liveness.alive).message

    def _sync(self, revision: int) -> None:
        if not self.mirror.wait_for(revision, SYNC_TIMEOUT_S):
            raise ParticipantLost(f"the reservation table did not reach revision {revision} "
                                  f"within {SYNC_TIMEOUT_S:g} s")
