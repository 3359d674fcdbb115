"""`fleet dispatcher` / `python -m dispatcher`: the dispatcher process.

It owns the mission: it waits for the reservation service and the forklift agents, runs the
engine's dispatching loop (rank, Algorithm 1, scores, MLP) with the agents as executor and
the clock as pacer, publishes what the run is (dispatch/mission), each subtask, stack done and
decision failure as it happens, progress and, at the end, the mission record on
fleet/<run>/dispatch/done. It then stays up until it is stopped, so the
last message is delivered before its session closes.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import threading
import time
from collections.abc import Callable, Sequence
from contextlib import ExitStack, closing
from dataclasses import dataclass
from pathlib import Path

import zenoh

from dispatcher.claims import Claims, Roster
from dispatcher.clock import FastClock, RealtimeClock
from dispatcher.liveness import Liveness, ParticipantLost
from dispatcher.pacing import LEAD_WALL_S
from dispatcher.pickup import journaled, pick_up
from dispatcher.remote import SENDER, RemoteExecutor
from dispatcher.remote004 import dispatch_mission004
from dispatcher.vda5050_master import ACTIONS as VDA5050_ACTIONS
from dispatcher.vda5050_master import VDA5050_LEAD_WALL_S, MasterExecutor
from dispatcher.work_journal import WorkJournal
from fleet.errors import UserError
from fleet.mission.engine import Engine, EngineOptions, MissionStuck, engine_options
from fleet.mission.faults import load_scenario
from fleet.mission.order_work import order_fleet
from fleet.mission.orders004 import fleet004
from fleet.mission.record import MissionSummary, digest_of
from fleet.mission.record004 import tracking_params
from fleet.mission.spec import EXTERNAL, ClockMode, Mission, MissionKind
from fleet.mission.standstill import Cause
from fleet.recording.writer import mission_info
from fleet.runtime.bus import (
    Requester,
    RequestFailed,
    Stream,
    asked,
    follow_recorded,
    open_session,
)
from fleet.runtime.lifecycle import Stopped, process_main, stop_on_signals
from fleet.runtime.process_configs import DispatcherConfig
from fleet.wire.protocol import (
    ZONE,
    AgvEvent,
    AgvHistory,
    Message,
    MissionDone,
    MissionInfo,
    Progress,
    ProtocolError,
    encode,
)
from fleet.wire.topics import DISPATCHER, Keys, published_by
from fleet.world.layout import Layout
from fleet.world.layout_file import load_layout
from reservation.client import ReservationClient
from reservation.mirror import TableMirror

log = logging.getLogger("fleet.dispatcher")
RECORDED_WAIT_S = 10.0
Publish = Callable[[Message, float], None]
# Why a mission that runs stops early, by the error that stopped it (else Cause.FAILED).
CAUSES: dict[type[Exception], Cause] = {Stopped: Cause.STOPPED, ParticipantLost: Cause.LOST}


def main(argv: Sequence[str] | None = None) -> int:
    return process_main(DispatcherConfig, serve, "python -m dispatcher", argv)


@dataclass(frozen=True)
class MissionSetup:
    """The mission as this dispatcher runs it, settled before it starts: its fleet (claims
    may have decided its size), whether it is picked up after a restart, the engine's options
    (built once) and the flags."""

    config: DispatcherConfig
    mission: Mission
    layout: Layout
    options: EngineOptions | None  # None: --dispatch external runs no engine
    recover: bool

    @property
    def vehicles(self) -> list[int]:
        return list(range(1, fleet_limit(self.mission, self.layout) + 1))


def fleet_limit(mission: Mission, layout: Layout) -> int:
    """The mission's fleet, or at most: one forklift per start pose, or on an order mission
    the paper's ten AGVs (one per charging pile at most, where they start)."""
    if layout.floor is not None:
        return fleet004(layout.floor, mission.vehicles)
    if mission.kind is MissionKind.ORDERS:
        return order_fleet(layout, mission.vehicles)
    return mission.vehicles or len(layout.vehicle_starts)


def serve(config: DispatcherConfig) -> int:
    layout = load_layout(config.mission.layout)
    if config.dispatch != "internal" and (config.clock is not ClockMode.REALTIME
                                          or layout.floor is not None):
        raise UserError(f"--dispatch {config.dispatch} runs forklifts or lane AGVs on the "
                        "real-time clock: give --clock realtime and a layout of either")
    if config.dispatch == "vda5050" and layout.has_lanes:
        raise UserError("--dispatch vda5050 runs fill and empty missions on a forklift "
                        "layout; a lane layout's AGVs take a master's orders with --dispatch "
                        "external")
    if config.dispatch == "vda5050" and (config.faults or config.claims or config.recover
                                         or config.mission.kind not in VDA5050_ACTIONS):
        raise UserError("--dispatch vda5050 runs fill and empty missions, without --faults, "
                        "--claims or --recover yet (docs/vda5050.md)")
    # bad weights: at once (an external session runs no engine: it needs none)
    options = engine_options(config.mission, layout, config.weights) \
        if config.dispatch != "external" else None
    keys = Keys(config.bus.run)
    marker = config.restart_marker
    restarted = marker is not None and marker.exists()
    roster = read_roster(marker) if restarted else None  # the claims of the one it replaces
    if restarted:
        log.warning("%s exists: this dispatcher was restarted, it picks the mission up", marker)
    recover = config.recover or restarted
    if config.journal is not None and not recover and config.journal.exists() and \
            config.journal.stat().st_size:
        raise UserError(f"--journal {config.journal} holds an earlier mission's order book: "
                        f"pick that mission up (--recover) or give another file")
    stop = threading.Event()
    in_mission = threading.Event()

    def stop_requested() -> None:  # runs in the main thread, wherever it is
        stop.set()
        if in_mission.is_set():
            raise Stopped("stopped by a signal before the mission ended")

    stop_on_signals(stop_requested)
    with ExitStack() as scope:
        session = scope.enter_context(open_session(config.bus.config()))  # closed last
        mission = config.mission
        if config.claims:
            mission, roster = _claimed_fleet(scope, session, keys, config, layout, roster, stop)
        if marker is not None and not recover:
            write_roster(marker, roster or {})
        setup = MissionSetup(config, mission, layout, options, recover)

        def alive() -> None:  # a restarted recorder asks for the events it lacks then
            scope.enter_context(session.liveliness().declare_token(keys.dispatcher_alive))

        if layout.floor is None:  # a seed-004 one once it holds every event so far
            alive()
        info = mission_info(mission, layout, len(setup.vehicles), config.clock.value,
                            config.speed, config.command)
        info = dataclasses.replace(info, dispatch=config.dispatch)
        if config.dispatch == "external":  # no mission of ours: a master's orders
            info = dataclasses.replace(info, kind=EXTERNAL, strategy="vda5050")
        streams = _streams(scope, session, keys)
        scope.enter_context(session.declare_queryable(  # for a recorder that joins late
            keys.dispatch_mission, lambda q: q.reply(q.key_expr, encode(info, SENDER, 0, 0.0))))
        scope.enter_context(session.declare_queryable(  # for a recorder that restarted
            keys.dispatch_agv_history, lambda q: _history(q, streams[AgvEvent])))
        scope.enter_context(session.declare_queryable(  # ... after the mission ended
            keys.dispatch_done, lambda q: _answer(q, streams[MissionDone].since(0))))
        liveness = scope.enter_context(closing(Liveness(session, keys)))
        recorded = threading.Event()
        scope.enter_context(follow_recorded(session, keys, recorded, log))
        try:
            in_mission.set()
            streams[MissionInfo].put(info, 0.0)
            done = dispatch_mission(session, keys, setup, liveness, lambda message, t:
                                    streams[type(message)].put(message, t), info,
                                    lambda message, t: streams[type(message)].number(message, t),
                                    alive)
        except Stopped as exc:  # arrived just as the mission returned
            done = MissionDone(False, error=str(exc))
        finally:
            in_mission.clear()
        streams[MissionDone].put(done, done.record.get("end_time_s", 0.0))
        log.info("mission %s; %s", "done" if done.ok else "failed", done.error or done.digest)
        if not config.exit_when_done:
            stop.wait()
        elif config.recorded and not recorded.wait(RECORDED_WAIT_S):
            log.warning("the recorder had not recorded the result within %g s",
                        RECORDED_WAIT_S)
    return 0 if done.ok else 1


def _claimed_fleet(scope: ExitStack, session: zenoh.Session, keys: Keys,
                   config: DispatcherConfig, layout: Layout, roster: dict[str, int] | None,
                   stop: threading.Event) -> tuple[Mission, dict[str, int]]:
    """The mission with the fleet that claimed its ids (--claims), and who holds which;
    the claims are served (to a restarted agent) for as long as `scope` lasts."""
    mission = config.mission
    limit = mission.vehicles or (len(layout.floor.parking) if layout.floor is not None
                                 else len(layout.piles) if mission.kind is MissionKind.ORDERS
                                 else len(layout.vehicle_starts))
    claims = scope.enter_context(closing(
        Claims(session, keys, Roster(limit, roster or {}, closed=bool(roster)))))
    ids = claims.gather(mission.vehicles, config.gather_s, config.startup_timeout_s, stop)
    if not ids:
        raise ParticipantLost(f"no forklift claimed an id within "
                              f"{config.startup_timeout_s:g} s")
    log.info("the fleet: %d forklifts", len(ids))
    return dataclasses.replace(mission, vehicles=len(ids)), claims.roster.ids


def _streams(scope: ExitStack, session: zenoh.Session, keys: Keys) -> dict[type[Message], Stream]:
    """Each of the dispatcher's topics, by the message it carries (every event must reach
    the recorder: its publishers wait rather than drop). A seed-004 run's events are kept
    too: they are its recording's whole account, and a restarted recorder asks for those
    its predecessor did not write (seed 000's record carries its subtasks instead); and
    the mission's result, for a recorder restarted after it."""
    return {cls: scope.enter_context(Stream(session, topic.key(keys.run), topic.sender,
                                            topic.reliable,
                                            keep=cls in (AgvEvent, MissionDone)))
            for cls, topic in published_by(DISPATCHER).items()}


def _history(query: zenoh.Query, events: Stream) -> None:
    """A restarted recorder's ask: every event numbered after the one it names, each as
    it was published."""
    if (request := asked(query, AgvHistory, log)) is not None:
        _answer(query, events.since(request.after))


def _answer(query: zenoh.Query, payloads: list[bytes]) -> None:
    """Each message kept, as it was published, in order."""
    for payload in payloads:
        query.reply(query.key_expr, payload)


def read_roster(path: Path) -> dict[str, int]:
    """The claims a restarted dispatcher's predecessor handed out (its restart marker)."""
    try:
        roster = json.loads(path.read_text() or "{}")
    except (OSError, ValueError) as exc:
        raise UserError(f"{path}: not a dispatcher's restart marker ({exc})") from None
    if not (isinstance(roster, dict) and all(isinstance(k, str) and isinstance(v, int)
                                             for k, v in roster.items())):
        raise UserError(f"{path}: not a dispatcher's restart marker (a name -> id map)")
    return roster


def write_roster(path: Path, ids: dict[str, int]) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(ids))


def _journal(config: DispatcherConfig, setup: MissionSetup, scope: ExitStack
             ) -> WorkJournal | None:
    """The dispatcher's journal (--journal): where forklifts went down, and an order
    mission's book (of seed 004: the instants of its service faults); the dead
    dispatcher's to go on with when this one picks the mission up, else a new one."""
    if config.journal is None:
        return None
    journal = WorkJournal(config.journal)
    scope.callback(journal.close)
    return journal


def dispatch_external(session: zenoh.Session, keys: Keys, setup: MissionSetup,
                      liveness: Liveness) -> MissionDone:
    """--dispatch external: no mission. Wait for the reservation service and the forklifts,
    then run the real-time clock (the forklifts drive on it) until stopped; a master gives
    the work through the VDA 5050 gateway. The result says how long it ran."""
    config = setup.config
    t0 = time.perf_counter()
    try:
        liveness.wait_for_service(config.startup_timeout_s)
        liveness.wait_for(setup.vehicles, config.startup_timeout_s)
        with closing(RealtimeClock(session, keys, config.speed, setup.vehicles,
                                   liveness)) as clock:
            log.info("%d forklifts up, the clock runs: waiting for a master's orders",
                     len(setup.vehicles))
            try:
                threading.Event().wait()  # until a signal stops this process
            except Stopped:
                end = clock.now()
        record = {"dispatch": "external", "end_time_s": round(end, 3)}
        return MissionDone(True, record=record, digest=digest_of(record),
                           wall_s=time.perf_counter() - t0)
    except ParticipantLost as exc:
        log.error("external dispatch failed: %s", exc)
        return MissionDone(False, error=str(exc), wall_s=time.perf_counter() - t0)


def dispatch_mission(session: zenoh.Session, keys: Keys, setup: MissionSetup,
                     liveness: Liveness, publish: Publish, info: MissionInfo,
                     number: Publish | None = None,
                     whole: Callable[[], None] = lambda: None) -> MissionDone:
    """Wait for everyone, run the engine, and say how it went (never raises for a mission
    that could not finish: the error goes into the result). `info` is what the run is, as
    published; `number` numbers a message as `publish` would, sending nothing (what a dead
    dispatcher of seed 004 sent already); `whole`: a seed-004 dispatcher holds every event
    so far (at once, unless it picks a mission up)."""
    config, vehicles = setup.config, setup.vehicles
    if config.dispatch == "external":
        return dispatch_external(session, keys, setup, liveness)
    if setup.layout.floor is not None:  # seed 004's lifting AGVs, tracked cell by cell
        scenario = load_scenario(config.faults, setup.layout.name) if config.faults else None
        with ExitStack() as scope:
            return dispatch_mission004(
                session, keys, setup.mission, setup.layout.floor, vehicles, liveness,
                config.startup_timeout_s, publish, tracking_params(info), config.clock,
                config.speed, scenario, _journal(config, setup, scope), setup.recover, number,
                whole)
    t0 = time.perf_counter()
    engine = None  # once the mission runs
    with ExitStack() as scope:
        try:
            liveness.wait_for_service(config.startup_timeout_s)
            mirror = TableMirror()
            reservations = ReservationClient(session, keys, Requester(session, SENDER))
            scope.enter_context(reservations.follow(mirror))
            journal = _journal(config, setup, scope)
            # A forklift down when a dead dispatcher died (its journal says) may not be up.
            down, book = journaled(journal) if setup.recover else ({}, [])
            liveness.wait_for([v for v in vehicles if v not in down], config.startup_timeout_s)
            log.info("%d forklifts and the reservation service are up", len(vehicles) - len(down))
            if config.dispatch == "vda5050":  # each subtask a VDA 5050 order
                executor = MasterExecutor(session, keys, reservations, mirror, liveness,
                                          vehicles, setup.layout, config.mqtt,
                                          config.mission.kind)
                scope.callback(executor.close)
            else:
                executor = RemoteExecutor(session, keys, reservations, mirror, liveness,
                                          vehicles, setup.layout.vehicle_kind)
            recovered, tick, wall = None, 0, 0.0
            if setup.recover:
                recovered, tick, wall = pick_up(executor, setup.layout, setup.mission,
                                                vehicles, setup.options.params, journal,
                                                down, book)
                log.info("picked the mission up at t=%.2f: %d stacks done%s", recovered.t,
                         len(recovered.done) + len(recovered.undelivered),
                         f"; forklift{'s' if len(down) > 1 else ''} "
                         f"{', '.join(map(str, sorted(down)))} down" if down else "")
            scenario = load_scenario(config.faults, setup.layout.name) if config.faults \
                else None
            t = recovered.t if recovered else 0.0
            still_down = frozenset(down)
            heard = recovered.breakdowns if recovered else {}
            if config.clock is ClockMode.FAST:
                clock = FastClock(session, keys, vehicles, liveness, scenario, config.recorded,
                                  tick, t, still_down, heard)
            else:
                closed = frozenset(r.cell for r in mirror.table.reservations(ZONE))
                # Through the gateway a decision waits for its forklift to be ready to plan
                # (dispatcher/vda5050_master.py): taken far ahead, it would hold the others.
                lead = VDA5050_LEAD_WALL_S if config.dispatch == "vda5050" else LEAD_WALL_S
                clock = RealtimeClock(session, keys, config.speed, vehicles, liveness, scenario,
                                      tick, t, wall, closed, lead_wall_s=lead, down=still_down,
                                      heard=heard)
            scope.enter_context(closing(clock))

            def progress(done: int, total: int, t: float, failures: int) -> None:
                publish(Progress(done, total, t, failures), t)

            options = dataclasses.replace(setup.options, progress=progress, events=publish,
                                          work_log=journal)
            engine = Engine(setup.mission, options, setup.layout, executor, clock, recovered)
            record = engine.run()
            as_dict = MissionSummary.of_record(record).to_dict()
            return MissionDone(True, record=as_dict, digest=digest_of(as_dict),
                               wall_s=time.perf_counter() - t0, rejections=executor.rejections,
                               detections=clock.detected)
        except (ParticipantLost, MissionStuck, RequestFailed, ProtocolError, Stopped) as exc:
            log.error("mission failed: %s", exc)
            if engine is not None:  # how far it got, for the recording (docs/recording.md)
                stopped = exc.standstill if isinstance(exc, MissionStuck) else \
                    engine.standstill(CAUSES.get(type(exc), Cause.FAILED), str(exc))
                publish(stopped.message(), stopped.t)
            return MissionDone(False, error=str(exc), wall_s=time.perf_counter() - t0)
