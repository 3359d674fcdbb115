"""Seed 004 as processes: the tracker's seam (fleet/mission/tracking004.py, `Vehicles`) when
each lifting AGV is its agent process (vehicle_agent/lifting.py), and the order mission run
through it.

The dispatcher keeps the mission and the tracker's events, as the engine does for seed 000;
each AGV takes and lets go of its cells in the reservation service and plans its own paths,
on request, in the events' fixed order. The tracker reads and changes its own table, as in
process (so every decision is the in-process one); each change is told to the store by the
AGV's agent in the background: requests about one cell one after the other (a take after
the let-go before it), about different cells at once. The store holds what the table holds
once every request so far is answered, which is so before the next instant (on the
real-time clock, while the tracker waits for it) and before a fault strikes; a store that
refuses a take the table gave (someone outside the mission holds the cell) ends the
mission, saying so. A plan is made by the AGV's agent on the table sent with the request,
and waits for no answer. So a run of processes gives the in-process events, move for move.

A dispatcher killed by the injector (at a service fault's instant, every request answered
and the instant journaled) is picked up by its successor: it runs the tracker again in its
own process up to that instant, against its table alone and telling nobody (`Replay`;
fleet/mission/resume004.py), checks that the store holds what the replay's table holds,
and goes on from there through the agents. Its events go on from the dead one's numbers.

An agent a fault takes (`kill_vehicle`, `stall_vehicle`, `cut_link`) is taken when the
tracker strikes its AGV: every request so far answered first, then the fault clock stops
the fault injector at that instant and waits for its ack (a killed agent's liveliness token
must then go; a stalled or cut-off one may keep it until its lease runs out). Until the
fault is over the dispatcher lets go of the AGV's cells itself (the AGV stands; only its
last move's cell behind it is let go) and asks the agent nothing; at the fault's end the
injector starts a new agent, continues the stalled one or restores its link, and the agent
is asked again once its token is there.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import statistics
import time
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from contextlib import ExitStack, closing
from dataclasses import dataclass, field
from typing import TypeVar

import zenoh

from dispatcher.clock import FastClock
from dispatcher.liveness import UNSERVED_RETRY_S, Liveness, ParticipantLost
from dispatcher.pacing import LEAD_WALL_S
from dispatcher.work_journal import WorkJournal
from fleet.errors import UserError
from fleet.mission.faults import DETECT_TIMEOUT_S, FaultKind, Scenario
from fleet.mission.faults004 import injected004
from fleet.mission.freeze import BREAKDOWN, CAUSES
from fleet.mission.record004 import Publish, run_mission004
from fleet.mission.resume004 import FaultInstant, where_it_died
from fleet.mission.spec import ClockMode, Mission
from fleet.mission.tracking004 import LocalVehicles, Routed, RouteQuery, Stuck, TrackingParams
from fleet.planning.geometry import Cell
from fleet.planning.reservations import INF, Interval, ReservationTable, ReservationView
from fleet.planning.rules004 import XY
from fleet.runtime.bus import LEASE_MS, Requester, RequestFailed
from fleet.wire.convert import held_to_wire
from fleet.wire.protocol import (
    ZONE,
    CellReply,
    CellRequest,
    Message,
    MissionDone,
    RouteReply,
    RouteRequest,
)
from fleet.wire.topics import DISPATCHER, Keys
from fleet.world.floor004 import Floor004
from reservation.client import ReservationClient

log = logging.getLogger("fleet.dispatcher")
REQUEST_TIMEOUT_S = 60.0  # a search on paper004 takes milliseconds
ASKING_AT_ONCE = 16  # requests in flight: more than a 2-core machine's processes can serve
LATE_S = 0.3  # an instant handled this much wall time after it came is late
AGENT_BACK_S = 60.0  # for a restarted agent to come up (a fresh process on a busy machine)
# After a silence shorter than the lease, its end may still cost the session (the router
# hears the next keep-alive, a quarter lease later, too late): trusted again after this.
# Every process of a run keeps the default lease (fleet/runtime/bus.py).
SILENCE_SETTLES_S = 1.5 * LEASE_MS / 1000
Answer = TypeVar("Answer", CellReply, RouteReply)


@dataclass
class Replay:
    """A restarted dispatcher's run of the tracker up to where its predecessor died: in this
    process (`local` plans on the tracker's table with the mission's costs), telling nobody;
    at that instant it waits for the agents present then and goes live (`went_live`)."""

    died: FaultInstant
    local: LocalVehicles
    vehicles: list[int]
    went_live: Callable[[float], None]
    absent: set[int] = field(default_factory=set)  # AGVs whose agent a fault took
    ticks: int = 0  # the fault clock's ticks the dead dispatcher had sent
    started: float = field(default_factory=time.perf_counter)


class RemoteVehicles:
    def __init__(self, session: zenoh.Session, keys: Keys, floor: Floor004,
                 liveness: Liveness, reservations: ReservationClient,
                 fault_clock: FastClock | None = None, journal: WorkJournal | None = None
                 ) -> None:
        self.keys, self.floor, self.liveness = keys, floor, liveness
        # The table as the tracker changes it, in its order: the in-process table, which the
        # store holds too once every request so far is answered.
        self.table = ReservationTable()
        # the dispatcher's own writes: closed zones, and the cells of AGVs without an agent
        self.reservations = reservations
        self.fault_clock = fault_clock  # stops the fault injector at an agent's fault
        # AGVs whose agent a fault took, not back yet: how often its token had come before
        self.absent: dict[int, int] = {}
        # asked again only while nothing serves an AGV's key but its token is here (as seed
        # 000's RemoteExecutor): one that does not answer in time is gone
        self.requester = Requester(session, DISPATCHER, REQUEST_TIMEOUT_S, UNSERVED_RETRY_S)
        self.asking = ThreadPoolExecutor(ASKING_AT_ONCE, thread_name_prefix="cells")
        # the last request about each cell the store was asked about, not yet settled
        self.pending: dict[Cell, Future[None]] = {}
        self.journal = journal  # each service fault's instant, where a successor goes on
        self.replay: Replay | None = None  # until the predecessor's death (None: live)
        self.service_faults = 0

    @property
    def replaying(self) -> bool:
        return self.replay is not None

    @property
    def view(self) -> ReservationView:
        return self.table

    def take(self, vehicle: int, xy: XY, t: float) -> bool:
        cell = self.floor.cell(xy)
        if not self.table.commit(vehicle, [Interval(cell, t, INF)]).ok:
            return False  # held: the store, told all the table was, would refuse too
        if self.replay is None:
            self._tell(cell, vehicle, xy, t, take=True)
        return True

    def release(self, vehicle: int, xy: XY, t: float) -> None:
        cell = self.floor.cell(xy)
        self.table.release(vehicle, t, [cell])
        if self.replay is None:
            self._tell(cell, vehicle, xy, t, take=False)

    def _tell(self, cell: Cell, vehicle: int, xy: XY, t: float, take: bool) -> None:
        """Tell the store in the background, after the last request about the cell is
        answered (a take of a cell after its let-go by the AGV before)."""
        before = self.pending.get(cell)
        self.pending[cell] = self.asking.submit(self._in_turn, before, vehicle, xy, t, take,
                                                vehicle in self.absent)

    def _in_turn(self, before: Future[None] | None, vehicle: int, xy: XY, t: float,
                 take: bool, absent: bool) -> None:
        if before is not None:
            before.result()  # asked earlier, so running or done: the pool takes tasks in turn
        if absent:  # the dispatcher writes for an AGV whose agent is gone
            cells = [self.floor.cell(xy)]
            written = self.reservations.commit(vehicle, [Interval(cells[0], t, INF)]) \
                if take else self.reservations.release(vehicle, t, cells)
            ok, reason = written.ok, written.reason
        else:
            request = CellRequest(self.requester.next_id(), vehicle, xy, t, take)
            reply = self._ask(vehicle, request, CellReply, t)
            ok, reason = reply.ok, reply.reason
        if not ok:
            what = "take" if take else "let go of"
            raise ParticipantLost(f"AGV {vehicle} could not {what} {xy} at t={t}, which the "
                                  f"mission's table had {'free' if take else 'held by it'} "
                                  f"(held by someone outside the mission?): {reason}")

    def down(self, vehicle: int, t: float, cause: str) -> None:
        """The fault takes the AGV's agent now: every request so far answered first, then
        the injector stopped at t (it kills, stalls or cuts); a killed agent's token seen
        gone."""
        if cause == BREAKDOWN:
            return  # its agent stands the AGV still and goes on answering
        if self.replay is not None:
            self.replay.absent.add(vehicle)
            self.replay.ticks += 1
            return
        self.settle()
        self.absent[vehicle] = self.liveness.appearances(vehicle)
        self._fault_instant(t)
        if cause == CAUSES[FaultKind.KILL_VEHICLE] and not self.liveness.wait_gone(
                vehicle, DETECT_TIMEOUT_S):
            raise ParticipantLost(f"AGV {vehicle}'s agent was to be gone at t={t:g} "
                                  f"({cause}), but its liveliness token stayed for "
                                  f"{DETECT_TIMEOUT_S:g} s")

    def up(self, vehicle: int, t: float) -> None:
        """The injector gives the AGV its agent back at t (a new one, the stalled one
        continued, its link restored); it is asked again once its token is there."""
        if self.replay is not None:
            if vehicle in self.replay.absent:
                self.replay.absent.remove(vehicle)
                self.replay.ticks += 1
            return
        if vehicle not in self.absent:
            return
        self.settle()  # what the dispatcher wrote for it is in first
        self._fault_instant(t)
        self.liveness.wait_back(vehicle, self.absent.pop(vehicle), SILENCE_SETTLES_S,
                                AGENT_BACK_S)

    def service_fault(self, t: float) -> None:
        """A service is killed at t: every request so far answered and the instant journaled
        (where this dispatcher's successor goes on if it is the one), then the injector
        stopped at t (it kills, and starts a new one a moment later: the reservation
        service from its journal, which the agents' and the dispatcher's requests wait
        for)."""
        self.service_faults += 1
        if self.replay is not None:
            self.replay.ticks += 1
            if self.service_faults == self.replay.died.number:
                self._go_live(t)
            return
        self.settle()
        if self.journal is not None and self.fault_clock is not None:
            self.journal.append(FaultInstant(self.service_faults, t,
                                             self.fault_clock.tick + 1).to_record())
        self._fault_instant(t)

    def _go_live(self, t: float) -> None:
        """Where the predecessor died: the agents then present up, the store checked to
        hold the replayed table, and from now on the agents asked."""
        assert self.replay is not None
        replay, self.replay = self.replay, None
        died = replay.died
        if (died.t, died.tick) != (t, replay.ticks):
            raise ParticipantLost(f"the dead dispatcher's journal puts its death at service "
                                  f"fault {died.number}, t={died.t:g}, fault clock tick "
                                  f"{died.tick}; this mission reaches it at t={t:g}, tick "
                                  f"{replay.ticks}: not the mission it ran")
        replayed_s = time.perf_counter() - replay.started
        store = self.reservations.table()
        if (differs := first_difference(store, self.table)) is not None:
            raise ParticipantLost(f"picking the mission up at t={t:g}: the reservation store "
                                  f"does not hold what the dead dispatcher left ({differs})")
        self.absent = {v: self.liveness.appearances(v) for v in sorted(replay.absent)}
        self.liveness.wait_for([v for v in replay.vehicles if v not in self.absent],
                               AGENT_BACK_S)
        if self.journal is not None:  # a later death before the next fault is no pick-up's
            self.journal.append(FaultInstant(died.number, t, died.tick, True).to_record())
        log.info("picked the mission up at t=%g, where the dead dispatcher was killed (its "
                 "run replayed in %.2f s; the store holds the same %d reservations, past ones "
                 "included)", t, replayed_s, len(self.table.reservations()))
        replay.went_live(t)

    def _fault_instant(self, t: float) -> None:
        if self.fault_clock is None:
            raise ParticipantLost(f"a fault of an agent at t={t:g} with no fault injector to "
                                  f"apply it")
        self.fault_clock.advance(t)  # returns once the injector has applied what is due

    def settle(self) -> None:
        """Wait until every request so far is answered: the store holds the table; a
        refusal or an agent's failure is raised here."""
        pending, self.pending = self.pending, {}
        for done in pending.values():
            done.result()

    def next_instant(self) -> None:
        """Every answer of this instant in before the tracker moves on (on the real-time
        clock, while the next instant is not due yet)."""
        self.settle()

    def close_down(self) -> None:
        """Stop asking (a mission that ended well has settled everything; one that failed has
        said why already)."""
        self.asking.shutdown(wait=True, cancel_futures=True)

    def route(self, query: RouteQuery) -> Routed:
        """The AGV's agent plans on the table sent along: the store's once every request so
        far is answered (so the plan waits for none of them)."""
        if self.replay is not None:
            return self.replay.local.route(query)
        request = RouteRequest(
            self.requester.next_id(), query.vehicle, query.t, query.task.value, query.start,
            query.goal, int(query.heading), query.home, query.relaxed, sorted(query.blocked),
            sorted(query.moving), sorted(query.stagnant),
            held_to_wire(self.table.reservations_after(query.t)))
        reply = self._ask(query.vehicle, request, RouteReply, query.t)
        return Routed(tuple(reply.cells) if reply.found else None, reply.planning_s)

    def close(self, xys: list[XY], t0: float, t1: float) -> None:
        """Closed by the dispatcher itself, once the store holds the table (a cell let go
        a moment ago is free in both)."""
        intervals = [Interval(self.floor.cell(xy), t0, t1) for xy in xys]
        written = self.table.commit(ZONE, intervals)
        assert written.ok, written.reason  # the tracker closes only the cells nobody holds
        if self.replay is not None:
            return
        self.settle()
        written = self.reservations.commit(ZONE, intervals)
        if not written.ok:
            raise ParticipantLost(f"the reservation service refused to close a zone at "
                                  f"t={t0:g}: {written.reason}")

    def _ask(self, vehicle: int, message: CellRequest | RouteRequest,
             expected: type[Answer], t: float) -> Answer:
        try:
            reply = self.requester.request(
                self.keys.vehicle_task(vehicle), message, t,
                retry_while=lambda: vehicle in self.liveness.alive).message
        except RequestFailed as exc:
            gone = self.liveness.wait_gone(vehicle, 2.0)
            raise ParticipantLost(f"AGV {vehicle}{' is gone' if gone else ''}: "
                                  f"{exc}") from None
        if not isinstance(reply, expected) or reply.request_id != message.request_id:
            raise ParticipantLost(f"AGV {vehicle} answered {message.TYPE} "
                                  f"{message.request_id} with {reply}")
        return reply


def first_difference(store: ReservationTable, table: ReservationTable) -> str | None:
    """The first reservation one table holds and the other does not, said (None: none)."""
    held = {(r.vehicle, r.cell, r.t0, r.t1) for r in store.reservations()}
    replayed = {(r.vehicle, r.cell, r.t0, r.t1) for r in table.reservations()}
    for name, extra in (("the store", held - replayed), ("the replayed table", replayed - held)):
        if extra:
            vehicle, cell, t0, t1 = min(extra, key=lambda r: (r[2], r[0], r[1]))
            return f"only {name} has {vehicle}'s hold of {cell} from t={t0:g} to t={t1:g}, " \
                   f"and {len(extra) - 1} more"
    return None


class RealtimePace:
    """The real-time clock of a seed-004 run: sim time = speed x wall seconds since sim time
    0, which comes LEAD_WALL_S after the clock is made (as seed 000's). Each instant of the
    tracker waits until its wall time; how late each was handled (wall seconds after its
    time: the AGVs' answers took longer than the time between instants) is kept, and one
    more than LATE_S late is counted late. A fleet that keeps up has a p99 lateness within
    fleet bench runtime's 0.1 s, and then gives the fast run's events."""

    def __init__(self, speed: float, lead_wall_s: float = LEAD_WALL_S) -> None:
        self.speed, self.lead_wall_s = speed, lead_wall_s
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

    def go_on_from(self, t: float) -> None:
        """A restarted dispatcher's clock: sim time t comes LEAD_WALL_S from now (it stood
        still while no dispatcher ran, for nothing moves but what the tracker moves)."""
        self.zero = time.monotonic() + self.lead_wall_s - t / self.speed

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
                        scenario: Scenario | None = None, journal: WorkJournal | None = None,
                        recover: bool = False, number: Publish | None = None,
                        whole: Callable[[], None] = lambda: None) -> MissionDone:
    """Wait for the reservation service and the AGVs, then run the mission through them on
    the fast or the real-time clock (never raises for a mission that could not finish: the
    error goes into the result). `journal` keeps each service fault's instant; `recover`:
    pick up the mission of the dispatcher that died at the last one, whose events were
    published already (`number` numbers them as they were, sending nothing); `whole` is
    called once this dispatcher holds every event so far (at once, unless it picks up)."""
    t0 = time.perf_counter()
    with ExitStack() as scope:
        try:
            died = _where_it_died(journal, scenario) if recover else None
            if died is None:
                whole()
            liveness.wait_for_service(startup_timeout_s)
            reservations = ReservationClient(session, keys, Requester(session, DISPATCHER))
            if died is None:
                liveness.wait_for(vehicles, startup_timeout_s)
                log.info("%d lifting AGVs and the reservation service are up", len(vehicles))
            pace = RealtimePace(speed) if clock is ClockMode.REALTIME else None
            injected = injected004(scenario) if scenario is not None else None
            # ticked at an agent's fault alone, on either clock: the tracker's instant then
            # waits for the injector as the fast clock does (the real-time one is there)
            fault_clock = scope.enter_context(closing(FastClock(
                session, keys, [], liveness, injected, tick=died.tick if died else 0,
                t=died.t if died else 0.0))) if injected is not None else None

            def went_live(t: float) -> None:
                whole()  # a restarted recorder may ask for what it missed now
                if pace is not None:
                    pace.go_on_from(t)

            fleet = RemoteVehicles(session, keys, floor, liveness, reservations, fault_clock,
                                   journal)
            if died is not None:  # the tracker's one table, planned on in this process
                fleet.replay = Replay(died, LocalVehicles(floor, tracking, fleet.table),
                                      vehicles, went_live)
            scope.callback(fleet.close_down)

            def next_instant(t: float) -> None:
                fleet.next_instant()
                if pace is not None and not fleet.replaying:
                    pace(t)

            def publish_or_number(message: Message, t: float) -> None:
                if not fleet.replaying:
                    publish(message, t)
                elif number is not None:  # sent by the dead one already
                    number(message, t)

            done = run_mission004(mission, floor, len(vehicles), fleet, publish_or_number,
                                  next_instant, tracking,
                                  scenario.faults if scenario is not None else ())
            if fleet.replaying:
                raise ParticipantLost(f"the mission ended before the instant its dead "
                                      f"dispatcher's journal names (t={died.t:g})")
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


def _where_it_died(journal: WorkJournal | None, scenario: Scenario | None) -> FaultInstant:
    if journal is None:
        raise UserError("a seed-004 mission is picked up where its dead dispatcher's journal "
                        "says it died: give the dead one's --journal")
    return where_it_died(journal.records(), scenario.faults if scenario is not None else (),
                         str(journal.path))
