"""The vehicle agent: one vehicle of the kind the layout names, its own OS process, talking
to the others only over zenoh.

It declares a liveliness token, parks at its start pose (a reservation to infinity), keeps a
mirror of the reservation service's table, and answers tasks on fleet/<run>/vehicle/<id>/task:
plan with its kind's planner against the mirror, commit what its kind's conflict policy says
through the service, replan when the service refuses the commit (another vehicle got there
first), answer with the committed trajectory. It drives what it committed on the clock and
publishes its state on a grid of instants every vehicle shares: every 0.5 s of sim time in
fast mode (then acknowledges the tick), at 10 Hz in real time.

Zenoh callbacks only enqueue; one worker thread does everything that blocks, in arrival order.
"""

from __future__ import annotations

import itertools
import logging
import math
import queue
import threading
import time
from contextlib import ExitStack
from dataclasses import dataclass

import zenoh

from fleet.mission.battery import Battery
from fleet.mission.driving import FAST_STATE_PERIOD_S, REALTIME_STATE_PERIOD_S, Drive, state_period
from fleet.mission.seam import Task
from fleet.mission.spec import ClockMode
from fleet.planning.reservations import Interval
from fleet.planning.trajectory import FailureReason, PlanFailure, Pose, Trajectory
from fleet.runtime.bus import LEASE_MS, Requester, Stream, asked, received
from fleet.runtime.lifecycle import Stopped
from fleet.runtime.tasks import result_to_wire, task_from_wire
from fleet.vehicles.kind import Commitment
from fleet.wire.convert import leg_from_wire, step_from_wire, step_to_wire
from fleet.wire.protocol import (
    AmendRequest,
    ClockAck,
    ClockTick,
    HaltRequest,
    InjectFault,
    Message,
    MissionDone,
    ProtocolError,
    Reply,
    ResumeRequest,
    StatusRequest,
    TaskRequest,
    TaskResult,
    VehicleFault,
    VehicleStatus,
    encode,
)
from fleet.wire.topics import Keys, vehicle_sender
from fleet.world.layout import Layout
from fleet.world.site import planners_for
from reservation.client import ReservationClient, wait_for_service
from reservation.mirror import TableMirror
from vehicle_agent.clock import SimClock, tick_problem

log = logging.getLogger("fleet.agent")
MAX_COMMIT_ATTEMPTS = 5
DUE_MARGIN_S = 0.001  # wake just after an instant, so it has come
SYNC_TIMEOUT_S = 10.0
# Real time: a forklift whose newest tick heard was sent this long ago (ticks every 0.5 s)
# publishes no state: it may be down, and the dispatcher's word on where it stands is awaited.
CLOCK_SILENCE_S = 1.0
# Real time: a commit must be applied this long before its plan starts, so that the reply is
# back before the forklift is due to move (else it would have stood where it no longer holds).
COMMIT_SLACK_S = 0.05


@dataclass(frozen=True)
class _Task:
    """A query on the task key: a task, or a halt, resume or status request."""

    query: zenoh.Query


@dataclass(frozen=True)
class _Tick:
    """A tick of the fast clock: the worker's, in turn with the tasks."""

    tick: ClockTick


@dataclass(frozen=True)
class _Inject:
    """A fault the injector sends (fleet run --faults)."""

    query: zenoh.Query


@dataclass(frozen=True)
class _Done:
    """A sample on dispatch/done: the mission's result, once decoded."""

    sample: zenoh.Sample


class Agent:
    def __init__(self, session: zenoh.Session, keys: Keys, vehicle: int, layout: Layout,
                 start: Pose, battery: Battery | None = None) -> None:
        self.session = session
        self.keys = keys
        self.vehicle = vehicle
        self.layout = layout
        self.sender = vehicle_sender(vehicle)
        self.mirror = TableMirror()
        self.vehicle_kind = layout.vehicle_kind
        self.planners = planners_for(layout)
        self.drive = Drive(vehicle, start, layout, battery)
        self.drive_lock = threading.Lock()
        self.clock = SimClock()
        self.reservations = ReservationClient(session, keys, Requester(session, self.sender),
                                              self.clock.now)
        self.inbox: queue.Queue[_Task | _Tick | _Inject | _Done] = queue.Queue()
        self.answers: dict[str, TaskResult] = {}  # by task id: a repeated task is answered again
        self.seq = itertools.count(1)  # of task replies (each stream counts its own)
        self.stopping = threading.Event()
        # Down: stalled, cut off, broken down or restarted, until the dispatcher says where
        # the forklift stands and that it moves again (ResumeRequest). Says nothing meanwhile.
        self.down = False
        self.slow = 1.0  # planning takes this many times longer (an injected fault)
        # Set from the clock's callback and the worker: `down`, `breakdown`, `resumed_at`,
        # `down_heeded_from`.
        self.status_lock = threading.Lock()
        # Its breakdown, as reported, until it moves again: "broken" (it stands when the
        # dispatcher says when), "repaired", or "" (none). A restarted dispatcher asks: what
        # was reported while none listened is not lost.
        self.breakdown = ""
        self.resumed_at = 0.0  # nothing before it is said once resumed
        self.down_heeded_from = 0.0  # ticks before this may still list us as down
        self.fault_pub: Stream | None = None
        self.last_kind = ""  # what the last committed leg was for (a restarted dispatcher asks)

    # -- the process ---------------------------------------------------------------------------
    def run(self, service_timeout_s: float = 60.0, exit_when_done: bool = False) -> None:
        """Serve until stopped, or (`exit_when_done`) until the mission's result is out."""
        wait_for_service(self.session, self.keys, service_timeout_s)
        with ExitStack() as scope:
            scope.enter_context(self.reservations.follow(self.mirror))
            if self.mirror.table.reservations(self.vehicle):
                # The table holds cells of ours: this is a restart. Where the forklift stands
                # is what the store holds and the dispatcher says; wait for its ResumeRequest.
                self.down = True
                log.info("vehicle %d restarted: waiting for the dispatcher", self.vehicle)
            else:
                self._park()
            self.fault_pub = scope.enter_context(Stream(
                self.session, self.keys.vehicle_fault(self.vehicle), self.sender, reliable=True))
            # States are reliable too: a recording must hold every one (the recorder only
            # enqueues, so it does not hold us up); acks pace the clock.
            state_pub = scope.enter_context(Stream(
                self.session, self.keys.vehicle_state(self.vehicle), self.sender, reliable=True))
            ack_pub = scope.enter_context(Stream(
                self.session, self.keys.clock_ack(self.vehicle), self.sender, reliable=True))
            session, keys, v, put = self.session, self.keys, self.vehicle, self.inbox.put
            scope.enter_context(session.declare_queryable(keys.vehicle_task(v),
                                                          lambda q: put(_Task(q))))
            scope.enter_context(session.declare_subscriber(keys.clock, self._on_clock))
            scope.enter_context(session.declare_queryable(keys.vehicle_inject(v),
                                                          lambda q: put(_Inject(q))))
            scope.enter_context(session.declare_subscriber(keys.dispatch_done,
                                                           lambda s: put(_Done(s))))
            scope.enter_context(session.liveliness().declare_token(keys.vehicle_alive(v)))
            ticker = threading.Thread(target=self._realtime_states, args=(state_pub,),
                                      daemon=True)
            ticker.start()
            scope.callback(ticker.join)
            scope.callback(self.stopping.set)  # first: the state thread ends
            log.info("vehicle %d ready at %s", self.vehicle, self.drive.pose)
            self._work(state_pub, ack_pub, exit_when_done)

    def _work(self, state_pub: Stream, ack_pub: Stream, exit_when_done: bool) -> None:
        """The worker: everything that blocks, in arrival order."""
        while True:
            match self.inbox.get():
                case _Task(query):
                    self._answer(query)
                case _Tick(tick):
                    self._fast_tick(tick, state_pub, ack_pub)
                case _Inject(query):
                    self._on_inject(query)
                case _Done(sample) if exit_when_done and \
                        received(sample, MissionDone, log) is not None:
                    log.info("vehicle %d: the mission is over", self.vehicle)
                    return
            if self.mirror.needs_resync:
                self.reservations.resync(self.mirror)

    def stop(self) -> None:
        """Stop now, from a signal handler (it runs in the main thread, which is the worker):
        a task or commit in progress is abandoned; nothing half-done is committed, because a
        commit is one request the service applies whole or not at all."""
        self.stopping.set()
        raise Stopped("stopped by a signal")

    def _park(self) -> None:
        cells = self.vehicle_kind.body_cells_at_rest(self.drive.pose)
        written = self.reservations.commit(self.vehicle, [Interval(c, 0.0, math.inf)
                                                          for c in cells],
                                           request_id=f"{self.sender}:park")
        if not written.ok:
            raise RuntimeError(f"cannot park at the start pose {self.drive.pose}: "
                               f"{written.reason}")
        self.mirror.wait_for(written.revision, SYNC_TIMEOUT_S)

    # -- tasks ---------------------------------------------------------------------------------
    def _answer(self, query: zenoh.Query) -> None:
        try:
            message = asked(query, (TaskRequest, HaltRequest, AmendRequest, ResumeRequest,
                                    StatusRequest), log)
            if message is None:
                return
            if not isinstance(message, TaskRequest):
                if isinstance(message, HaltRequest):
                    reply = self._halt(message)
                elif isinstance(message, AmendRequest):
                    reply = self._amend(message)
                elif isinstance(message, ResumeRequest):
                    reply = self._resume(message)
                else:
                    reply = self._status()
                query.reply(query.key_expr, self._encode(reply, self.clock.now()))
                return
            answer = self.answers.get(message.task_id)
            if answer is None:
                answer = self.answers[message.task_id] = self._perform(message)
            query.reply(query.key_expr, self._encode(answer, message.t_i))
        finally:
            query.drop()

    def _perform(self, message: TaskRequest) -> TaskResult:
        try:
            task = task_from_wire(message)
        except ProtocolError as exc:
            return self._failed(message, FailureReason.START_BLOCKED, f"bad task: {exc}")
        if task.vehicle != self.vehicle:
            return self._failed(message, FailureReason.START_BLOCKED,
                                f"task for vehicle {task.vehicle} sent to {self.vehicle}")
        if task.start != self.drive.pose:
            return self._failed(message, FailureReason.START_BLOCKED,
                                f"the task starts at {task.start} but the forklift will "
                                f"stand at {self.drive.pose}")
        if not self.mirror.wait_for(message.revision, SYNC_TIMEOUT_S):
            self.reservations.resync(self.mirror)
        rejections: list[str] = []
        for attempt in range(MAX_COMMIT_ATTEMPTS):
            leg = self._plan(task)
            if isinstance(leg, PlanFailure):
                return result_to_wire(message.task_id, self.vehicle, leg, self.mirror.revision,
                                      rejections)
            result = leg.trajectory
            if self.clock.realtime and self.clock.now() > result.t_start:
                return self._failed(message, FailureReason.LATE,
                                    f"planned for t={result.t_start:.2f} but it is already "
                                    f"t={self.clock.now():.2f}", rejections)
            log.info("committing task %s (attempt %d)", message.task_id, attempt + 1)
            start = self.clock.wall_at(result.t_start)
            written = self.reservations.commit(
                self.vehicle, leg.intervals, leg.release_from,
                tuple(a.amendment for a in leg.amends), leg.route, based_on=message.revision,
                deadline=None if start is None else start - COMMIT_SLACK_S,
                request_id=f"{self.sender}:{message.task_id}:{attempt}")
            if written.ok:
                with self.drive_lock:
                    self.drive.add(result, task.loaded, task.after)
                self.last_kind = message.kind
                return result_to_wire(message.task_id, self.vehicle, result, written.revision,
                                      rejections, [a.trajectory for a in leg.amends])
            rejections.append(written.reason)
            if written.conflict_vehicle is None:  # halted since, or too late: no replanning
                return self._failed(message, FailureReason.REFUSED, written.reason, rejections)
            log.info("task %s: the store refused the commit (%s); replanning",
                     message.task_id, written.reason)
            self.mirror.wait_for(written.revision, SYNC_TIMEOUT_S)
        return self._failed(message, FailureReason.REFUSED,
                            f"{len(rejections)} commits refused; last: {rejections[-1]}",
                            rejections)

    def _plan(self, task: Task) -> Commitment | PlanFailure:
        """Plan against the mirror, and settle what to commit against the same table."""
        planner = self.planners.get(task.filled)
        started = time.perf_counter()
        with self.mirror.frozen():
            result = planner.plan(self.vehicle, task.start, task.t_i, task.goals,
                                  self.mirror.table)
            if isinstance(result, Trajectory):
                result = self.planners.policy.commitment(result, self.mirror.table)
        if self.slow > 1:  # an injected slow planner: as if the search ran on a slower CPU
            time.sleep((self.slow - 1) * (time.perf_counter() - started))
        return result

    def _amend(self, message: AmendRequest) -> Reply:
        """Another AGV's commit postponed our last leg (seed 002's collision rules): drive
        the amended one. It differs only after the instant it was committed at, which the
        states published so far have not reached."""
        try:
            if message.vehicle != self.vehicle:
                raise ValueError(f"amendment for vehicle {message.vehicle} sent to "
                                 f"{self.vehicle}")
            leg = leg_from_wire(message.leg, message.TYPE)
            with self.drive_lock:
                self.drive.amend(leg)
        except ValueError as exc:  # ProtocolError too
            return Reply(message.request_id, False, self.mirror.revision, reason=str(exc))
        log.info("leg from t=%.2f amended: now ends at t=%.2f", leg.t_start, leg.t_end)
        return Reply(message.request_id, True, self.mirror.revision)

    # -- faults (docs/faults.md) ---------------------------------------------------------------
    def _halt(self, message: HaltRequest) -> Reply:
        """The dispatcher froze us at t: complete the maneuver in progress, nothing after."""
        if message.vehicle != self.vehicle:
            return Reply(message.request_id, False, self.mirror.revision,
                         reason=f"halt for vehicle {message.vehicle} sent to {self.vehicle}")
        if self.clock.realtime and self.clock.now() > message.t:
            log.error("the halt for t=%.2f came late, at t=%.2f", message.t, self.clock.now())
        with self.drive_lock:
            if message.stand:  # broken down: it stands where it is from t, and says so
                self.drive.stop(message.t)
            else:
                self.drive.cut(message.t)
        self.last_kind = ""  # what was cut did not arrive
        log.info("halted at t=%.2f: standing %s", message.t,
                 "where it is" if message.stand else
                 f"at {self.drive.pose} after the maneuver in progress")
        return Reply(message.request_id, True, self.mirror.revision)

    def _resume(self, message: ResumeRequest) -> Reply:
        """Back from being down: take the store's table afresh and the dispatcher's word for
        where we stand, then move again from t_resume."""
        if message.vehicle != self.vehicle:
            return Reply(message.request_id, False, self.mirror.revision,
                         reason=f"resume for vehicle {message.vehicle} sent to {self.vehicle}")
        try:
            pose = Pose.parse(message.pose)
            step = step_from_wire(message.step, "dispatch.resume_request.step") \
                if message.step is not None else None
            if message.battery is not None and not 0.0 <= message.battery <= 100.0:
                raise ValueError(f"dispatch.resume_request.battery must be a charge within "
                                 f"0..100 %, not {message.battery!r}")
        except (ValueError, ProtocolError) as exc:
            return Reply(message.request_id, False, self.mirror.revision, reason=str(exc))
        self.reservations.resync(self.mirror)
        with self.drive_lock:
            self.drive.restart(pose, message.loaded, step, message.t_stop, message.t_resume,
                               message.battery)
        with self.status_lock:  # ticks sent before our answer may still list us as down
            self.resumed_at, self.down, self.breakdown = message.t_resume, False, ""
            self.down_heeded_from = self.clock.heeds_down_from(message.t_resume,
                                                               LEASE_MS / 1000)
        self.last_kind = ""
        log.info("resumed at t=%.2f from %s (table at revision %d)", message.t_resume,
                 step.start if step else pose, self.mirror.revision)
        return Reply(message.request_id, True, self.mirror.revision)

    def _status(self) -> VehicleStatus:
        """What we hold, for a restarted dispatcher (answered in turn: nothing in flight)."""
        tick = self.clock.tick
        with self.drive_lock:
            leg = self.drive.legs[-1] if self.drive.legs else None
            return VehicleStatus(
                self.vehicle, str(self.drive.pose), leg.loaded if leg else self.drive.loaded,
                self.last_kind if leg else "", str(leg.trajectory.start) if leg else "",
                [step_to_wire(s) for s in leg.trajectory.steps] if leg else [], self.down,
                tick.tick if tick else 0, tick.t if tick else 0.0,
                tick.wall if tick else 0.0, self.breakdown)

    def _on_inject(self, query: zenoh.Query) -> None:
        """A fault injected by `fleet run --faults`: a breakdown, its repair, a slow planner."""
        try:
            message = asked(query, InjectFault, log)
            if message is None:
                return
            t = self.clock.now()
            if message.kind == "slow_planner":
                self.slow = message.factor
            elif message.kind == "breakdown":  # it stands once the dispatcher says when
                with self.status_lock:
                    self.breakdown = "broken"
                self.fault_pub.put(VehicleFault(self.vehicle, t, "broken"), t)
            elif message.kind == "repair":
                with self.status_lock:
                    self.breakdown = "repaired" if self.breakdown else ""
                self.fault_pub.put(VehicleFault(self.vehicle, t, "repaired"), t)
            else:
                query.reply_err(f"rejected: unknown fault {message.kind!r}".encode())
                return
            log.warning("fault injected at t=%.2f: %s", t, message.kind)
            query.reply(query.key_expr, self._encode(
                Reply(message.request_id, True, self.mirror.revision), t))
        finally:
            query.drop()

    def _failed(self, message: TaskRequest, reason: FailureReason, detail: str,
                rejections: list[str] | None = None) -> TaskResult:
        log.warning("task %s failed: %s: %s", message.task_id, reason.value, detail)
        return result_to_wire(message.task_id, self.vehicle, PlanFailure(reason, detail, 0),
                              self.mirror.revision, rejections or [])

    # -- the clock and the state stream --------------------------------------------------------
    def _on_clock(self, sample: zenoh.Sample) -> None:
        """A fast tick is the worker's, in turn with tasks; a real-time one is taken at once,
        even while the worker plans (the state thread needs to know the clock is heard)."""
        tick = received(sample, ClockTick, log)
        if tick is None:
            return
        if tick.mode == ClockMode.FAST:
            self.inbox.put(_Tick(tick))
        else:
            self._take(tick)

    def _take(self, tick: ClockTick) -> bool:
        problem = tick_problem(tick, self.clock.tick)
        if problem:
            log.warning("ignored tick %d on %s: %s", tick.tick, self.keys.clock, problem)
            return False
        with self.status_lock:
            if self.vehicle in tick.down and tick.t >= self.down_heeded_from \
                    and not self.breakdown:
                self.down = True  # held as down: we were cut off, stalled or restarted
        self.clock.take(tick)  # after `down`: the state thread reads them unlocked
        return True

    def _fast_tick(self, tick: ClockTick, state_pub, ack_pub) -> None:
        if not self._take(tick) or self.down:
            return
        self._publish_states(state_pub, tick.t, FAST_STATE_PERIOD_S, before=True)
        ack_pub.put(ClockAck(tick.tick, self.vehicle), tick.t)

    def _realtime_states(self, state_pub: Stream) -> None:
        """Wake when the next instant of the grid comes due and publish it (and any missed)."""
        wait = REALTIME_STATE_PERIOD_S
        while not self.stopping.wait(wait):
            wait = REALTIME_STATE_PERIOD_S
            tick = self.clock.tick
            if tick is None or tick.mode != ClockMode.REALTIME or self.down:
                continue
            if self.clock.silent_for() > CLOCK_SILENCE_S:
                continue  # cut off or stalled: silent until the clock is heard (and says)
            period = state_period(ClockMode.REALTIME, tick.speed)
            self._publish_states(state_pub, self.clock.now(), period)
            ahead = (self.drive.next_k * period - self.clock.now()) / tick.speed
            wait = min(REALTIME_STATE_PERIOD_S, max(0.0, ahead)) + DUE_MARGIN_S

    def _publish_states(self, state_pub: Stream, until: float, period: float,
                        before: bool = False) -> None:
        """Every grid instant up to `until` not published yet (a late wake-up catches up)."""
        with self.drive_lock:
            self.drive.skip_to(self.resumed_at, period)  # nothing before a resume is said
            due = self.drive.due(until, period, before)
            states = [(t, self.drive.state_at(t)) for t in due]
            if due:
                self.drive.forget_before(due[-1])
        for t, state in states:
            state_pub.put(state, t)

    # -- wire ----------------------------------------------------------------------------------
    def _encode(self, message: Message, t: float) -> bytes:
        return encode(message, self.sender, next(self.seq), t)
