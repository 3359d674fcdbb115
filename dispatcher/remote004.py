"""Seed 004 as processes: the tracker's seam (fleet/mission/tracking004.py, `Vehicles`) when
each lifting AGV is its agent process (vehicle_agent/lifting.py), and the order mission run
through it.

The dispatcher keeps the mission and the tracker's events, as the engine does for seed 000;
each AGV takes and lets go of its cells in the reservation service and plans its own paths,
on request, in the events' fixed order. Requests about one cell reach the store one after
the other: each waits until the last one about that cell is answered and its change is in the
dispatcher's mirror. Requests about different cells overlap: the store holds, for a cell
whose requests are all answered, exactly what the mirror holds, so whether a take will be
given is known before it is asked, and the tracker goes on while the AGVs' agents ask the
store. Before the next instant every answer of this one is in; a store that refuses a take
the mirror said it would give (someone outside the mission holds the cell) ends the mission,
saying so. A plan waits for every answer. So every take finds its cell as it would in
process, and a run of processes gives the in-process events, move for move.

A killed agent (a `kill_vehicle` fault) is killed when the tracker strikes it: the fault
clock stops the fault injector at that instant and waits for its ack, then for the agent's
liveliness token to go; until the injector's new agent is up, the dispatcher lets go of the
AGV's cells itself (the AGV stands; only its last move's cell behind it is let go), and
asks the agent nothing.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import statistics
import time
from concurrent.futures import Future, ThreadPoolExecutor
from contextlib import ExitStack, closing
from typing import TypeVar

import zenoh

from dispatcher.clock import FastClock
from dispatcher.liveness import Liveness, ParticipantLost
from dispatcher.pacing import LEAD_WALL_S
from fleet.errors import UserError
from fleet.mission.faults import DETECT_TIMEOUT_S, Scenario
from fleet.mission.faults004 import injected004
from fleet.mission.freeze import BREAKDOWN
from fleet.mission.record004 import Publish, run_mission004
from fleet.mission.spec import ClockMode, Mission
from fleet.mission.tracking004 import Routed, RouteQuery, Stuck, TrackingParams
from fleet.planning.geometry import Cell
from fleet.planning.reservations import INF, Interval, WriteResult
from fleet.planning.rules004 import XY
from fleet.runtime.bus import Requester, RequestFailed
from fleet.wire.convert import held_to_wire
from fleet.wire.protocol import (
    ZONE,
    CellReply,
    CellRequest,
    MissionDone,
    RouteReply,
    RouteRequest,
)
from fleet.wire.topics import DISPATCHER, Keys
from fleet.world.floor004 import Floor004
from reservation.client import ReservationClient
from reservation.mirror import TableMirror

log = logging.getLogger("fleet.dispatcher")
REQUEST_TIMEOUT_S = 60.0  # a search on paper004 takes milliseconds
SYNC_TIMEOUT_S = 30.0
ASKING_AT_ONCE = 16  # requests in flight: more than a 2-core machine's processes can serve
LATE_S = 0.3  # an instant handled this much wall time after it came is late
AGENT_BACK_S = 60.0  # for a restarted agent to come up (a fresh process on a busy machine)
Answer = TypeVar("Answer", CellReply, RouteReply)


class RemoteVehicles:
    def __init__(self, session: zenoh.Session, keys: Keys, floor: Floor004, mirror: TableMirror,
                 liveness: Liveness, reservations: ReservationClient,
                 fault_clock: FastClock | None = None) -> None:
        self.keys, self.floor, self.mirror, self.liveness = keys, floor, mirror, liveness
        # the dispatcher's own writes: closed zones, and the cells of AGVs without an agent
        self.reservations = reservations
        self.fault_clock = fault_clock  # stops the fault injector at an agent's fault
        self.absent: set[int] = set()  # AGVs whose agent a fault took, not back yet
        # no retry: an agent that does not answer is gone (liveliness says so)
        self.requester = Requester(session, DISPATCHER, REQUEST_TIMEOUT_S, retry_s=0.0)
        self.asking = ThreadPoolExecutor(ASKING_AT_ONCE, thread_name_prefix="cells")
        # the store's cells asked about, not yet answered
        self.pending: dict[Cell, Future[None]] = {}
        self.view = _SettledView(self)

    def take(self, vehicle: int, xy: XY, t: float) -> bool:
        cell = self.floor.cell(xy)
        self.settle(cell)  # the cell's last holder has let it go first, as in process
        if self.mirror.table.conflict(vehicle, cell, t, INF) is not None:
            return False  # the store holds what the mirror holds: it would refuse
        if vehicle in self.absent:
            self._write(self.reservations.commit(vehicle, [Interval(cell, t, INF)]), t)
        else:
            self.pending[cell] = self.asking.submit(self._ask_cell, vehicle, xy, t, True)
        return True

    def release(self, vehicle: int, xy: XY, t: float) -> None:
        """Let the cell go without waiting for it: what a decision depends on is whether a
        cell is free when taken, so only a take of that cell, a read of it and a plan wait
        (`settle`), and each decision sees what it would see in process."""
        cell = self.floor.cell(xy)
        self.settle(cell)  # its take is in first
        if vehicle in self.absent:
            self._write(self.reservations.release(vehicle, t, [cell]), t)
        else:
            self.pending[cell] = self.asking.submit(self._ask_cell, vehicle, xy, t, False)

    def down(self, vehicle: int, t: float, cause: str) -> None:
        """A killed agent is killed now: every request so far answered first, then the
        injector stopped at t (it kills), then its token seen gone."""
        if cause == BREAKDOWN:
            return  # its agent stands the AGV still and goes on answering
        self.settle()
        self.absent.add(vehicle)
        self._fault_instant(t)
        if not self.liveness.wait_gone(vehicle, DETECT_TIMEOUT_S):
            raise ParticipantLost(f"AGV {vehicle}'s agent was to be gone at t={t:g} "
                                  f"({cause}), but its liveliness token stayed for "
                                  f"{DETECT_TIMEOUT_S:g} s")

    def up(self, vehicle: int, t: float) -> None:
        """The injector starts the AGV's new agent at t; it is asked again once it is up."""
        if vehicle not in self.absent:
            return
        self._fault_instant(t)
        self.liveness.wait_for([vehicle], AGENT_BACK_S)
        self.absent.discard(vehicle)

    def _fault_instant(self, t: float) -> None:
        if self.fault_clock is None:
            raise ParticipantLost(f"a fault of an agent at t={t:g} with no fault injector to "
                                  f"apply it")
        self.fault_clock.advance(t)  # returns once the injector has applied what is due

    def _ask_cell(self, vehicle: int, xy: XY, t: float, take: bool) -> None:
        request = CellRequest(self.requester.next_id(), vehicle, xy, t, take)
        reply = self._ask(vehicle, request, CellReply, t)
        if not reply.ok:
            what = "take" if take else "let go of"
            raise ParticipantLost(f"AGV {vehicle} could not {what} {xy} at t={t}, which this "
                                  f"dispatcher's copy of the store had "
                                  f"{'free' if take else 'held by it'}: {reply.reason}")
        self._sync(reply.revision)

    def settle(self, cell: Cell | None = None) -> None:
        """Wait until every request about the store's cell (None: every cell) is answered
        and its change is in this mirror; a refusal or an agent's failure is raised here."""
        for asked in [cell] if cell is not None else list(self.pending):
            done = self.pending.pop(asked, None)
            if done is not None:
                done.result()

    def next_instant(self) -> None:
        """Every answer of this instant in before the tracker moves on."""
        self.settle()

    def close_down(self) -> None:
        """Stop asking (a mission that ended well has settled everything; one that failed has
        said why already)."""
        self.asking.shutdown(wait=True, cancel_futures=True)

    def route(self, query: RouteQuery) -> Routed:
        self.settle()  # the plan is made on a table holding every change so far
        request = RouteRequest(
            self.requester.next_id(), query.vehicle, query.t, query.task.value, query.start,
            query.goal, int(query.heading), self.mirror.revision, query.home, query.relaxed,
            sorted(query.blocked), sorted(query.moving), sorted(query.stagnant),
            held_to_wire(self.mirror.table.reservations_after(query.t)))
        reply = self._ask(query.vehicle, request, RouteReply, query.t)
        return Routed(tuple(reply.cells) if reply.found else None, reply.planning_s)

    def close(self, xys: list[XY], t0: float, t1: float) -> None:
        self.settle()
        self._write(self.reservations.commit(
            ZONE, [Interval(self.floor.cell(xy), t0, t1) for xy in xys]), t0)

    def _write(self, written: WriteResult, t: float) -> None:
        """One of the dispatcher's own writes, in its mirror before the tracker goes on."""
        if not written.ok:
            raise ParticipantLost(f"the reservation service refused the dispatcher's write "
                                  f"at t={t:g}: {written.reason}")
        self._sync(written.revision)

    def _ask(self, vehicle: int, message: CellRequest | RouteRequest,
             expected: type[Answer], t: float) -> Answer:
        try:
            reply = self.requester.request(self.keys.vehicle_task(vehicle), message, t).message
        except RequestFailed as exc:
            gone = self.liveness.wait_gone(vehicle, 2.0)
            raise ParticipantLost(f"AGV {vehicle}{' is gone' if gone else ''}: "
                                  f"{exc}") from None
        if not isinstance(reply, expected) or reply.request_id != message.request_id:
            raise ParticipantLost(f"AGV {vehicle} answered {message.TYPE} "
                                  f"{message.request_id} with {reply}")
        return reply

    def _sync(self, revision: int) -> None:
        if not self.mirror.wait_for(revision, SYNC_TIMEOUT_S):
            raise ParticipantLost(f"the reservation table did not reach revision {revision} "
                                  f"within {SYNC_TIMEOUT_S:g} s")


class _SettledView:
    """The store as the tracker reads it: a cell is read once every request about it is
    answered and in the mirror (the tracker reads the cells it asks about, so the requests
    about other cells stay in flight)."""

    def __init__(self, fleet: RemoteVehicles) -> None:
        self.fleet = fleet

    def conflict(self, vehicle: int, cell: Cell, t0: float, t1: float) -> int | None:
        self.fleet.settle(cell)
        return self.fleet.mirror.table.conflict(vehicle, cell, t0, t1)

    def parked_from(self, vehicle: int, cell: Cell) -> float:
        self.fleet.settle(cell)
        return self.fleet.mirror.table.parked_from(vehicle, cell)


class RealtimePace:
    """The real-time clock of a seed-004 run: sim time = speed x wall seconds since sim time
    0, which comes LEAD_WALL_S after the clock is made (as seed 000's). Each instant of the
    tracker waits until its wall time; how late each was handled (wall seconds after its
    time: the AGVs' answers took longer than the time between instants) is kept, and one
    more than LATE_S late is counted late. A fleet that keeps up has a p99 lateness within
    fleet bench runtime's 0.1 s, and then gives the fast run's events."""

    def __init__(self, speed: float, lead_wall_s: float = LEAD_WALL_S) -> None:
        self.speed = speed
        self.zero = time.monotonic() + lead_wall_s
        self.lateness: list[float] = []  # of every instant (0: on time)
        self.late: list[float] = []  # how late each late instant was (wall seconds)
        self.worst_at = 0.0  # the sim time of the latest one

    @property
    def instants(self) -> int:
        return len(self.lateness)

    def __call__(self, t: float) -> None:
        wait = self.zero + t / self.speed - time.monotonic()
        self.lateness.append(max(0.0, -wait))
        if wait > 0:
            time.sleep(wait)  # the clock itself: nothing is due before then
        elif -wait > LATE_S:
            if -wait > max(self.late, default=0.0):
                self.worst_at = t
            self.late.append(-wait)

    def summary(self) -> dict[str, float]:
        ordered = sorted(self.lateness) or [0.0]
        p99 = ordered[min(len(ordered) - 1, math.ceil(0.99 * len(ordered)) - 1)]
        return {"speed": self.speed, "instants": self.instants, "late": len(self.late),
                "worst_late_s": max(self.late, default=0.0), "worst_late_at_s": self.worst_at,
                "lateness_p50_s": round(statistics.median(ordered), 4),
                "lateness_p99_s": round(p99, 4)}


def dispatch_mission004(session: zenoh.Session, keys: Keys, mission: Mission, floor: Floor004,
                        vehicles: list[int], liveness: Liveness, startup_timeout_s: float,
                        publish: Publish, tracking: TrackingParams,
                        clock: ClockMode = ClockMode.FAST, speed: float = 1.0,
                        scenario: Scenario | None = None) -> MissionDone:
    """Wait for the reservation service and the AGVs, then run the mission through them on
    the fast or the real-time clock (never raises for a mission that could not finish: the
    error goes into the result)."""
    t0 = time.perf_counter()
    with ExitStack() as scope:
        try:
            liveness.wait_for_service(startup_timeout_s)
            mirror = TableMirror()
            reservations = ReservationClient(session, keys, Requester(session, DISPATCHER))
            scope.enter_context(reservations.follow(mirror))
            liveness.wait_for(vehicles, startup_timeout_s)
            log.info("%d lifting AGVs and the reservation service are up", len(vehicles))
            pace = RealtimePace(speed) if clock is ClockMode.REALTIME else None
            injected = injected004(scenario) if scenario is not None else None
            # ticked at an agent's fault alone, on either clock: the tracker's instant then
            # waits for the injector as the fast clock does (the real-time one is there)
            fault_clock = scope.enter_context(closing(FastClock(
                session, keys, [], liveness, injected))) if injected is not None else None
            fleet = RemoteVehicles(session, keys, floor, mirror, liveness, reservations,
                                   fault_clock)
            scope.callback(fleet.close_down)

            def next_instant(t: float) -> None:
                fleet.next_instant()
                if pace is not None:
                    pace(t)

            done = run_mission004(mission, floor, len(vehicles), fleet, publish, next_instant,
                                  tracking, scenario.faults if scenario is not None else ())
            fleet.settle()  # the last cells let go: the store ends as the fleet stands
            if pace is None:
                return done
            timing = pace.summary()
            log.info("real time at speed %g: %d of %d instants handled late (the latest by "
                     "%.2f s)", speed, timing["late"], timing["instants"],
                     timing["worst_late_s"])
            return dataclasses.replace(done, timing=timing)
        except (ParticipantLost, RequestFailed, Stuck, UserError, ValueError) as exc:
            log.error("mission failed: %s", exc)
            return MissionDone(False, error=str(exc), wall_s=time.perf_counter() - t0)
