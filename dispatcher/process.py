"""`fleet dispatcher` / `python -m dispatcher`: the dispatcher process.

It owns the mission: it waits for the reservation service and the forklift agents, runs the
engine's dispatching loop (rank, Algorithm 1, scores, MLP) with the agents as executor and
the clock as pacer, publishes what the run is (dispatch/mission), each subtask, stack done and
decision failure as it happens, progress and, at the end, the mission record on
fleet/<run>/dispatch/done. It then stays up until it is stopped, so the
last message is delivered before its session closes.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import logging
import threading
import time
from pathlib import Path

from dispatcher.claims import Claims, Roster
from dispatcher.clock import FastClock, RealtimeClock
from dispatcher.liveness import Liveness, ParticipantLost
from dispatcher.pickup import pick_up
from dispatcher.remote import SENDER, RemoteExecutor
from fleet.commands.run import add_mission_args, engine_options, mission_from_args
from fleet.errors import UserError
from fleet.mission.engine import Engine, MissionStuck
from fleet.mission.faults import load_scenario
from fleet.mission.record import MissionSummary, digest_of
from fleet.recording.writer import mission_info
from fleet.runtime.argtypes import positive_float, scenario_arg
from fleet.runtime.bus import (
    Requester,
    RequestFailed,
    Stream,
    add_bus_arguments,
    bus_config,
    follow_recorded,
    open_session,
    stop_on_signals,
)
from fleet.wire.protocol import (
    ZONE,
    MissionDone,
    MissionInfo,
    Progress,
    ProtocolError,
    encode,
)
from fleet.wire.topics import DISPATCHER, Keys, published_by
from fleet.world.layout_file import load_layout
from reservation.client import ReservationClient
from reservation.mirror import TableMirror

log = logging.getLogger("fleet.dispatcher")
RECORDED_WAIT_S = 10.0


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_bus_arguments(p)
    add_mission_args(p)
    p.add_argument("--clock", choices=["fast", "realtime"], default="fast",
                   help="fast: discrete events, deterministic; realtime: sim time = speed x "
                   "wall time (default fast)")
    p.add_argument("--speed", type=positive_float, default=1.0,
                   help="real-time clock: sim seconds per wall second (default 1)")
    p.add_argument("--startup-timeout", type=positive_float, default=120.0, metavar="SECONDS",
                   help="seconds to wait for the reservation service and every agent "
                   "(default 120)")
    p.add_argument("--command", default="",
                   help="the command line that started the run, for its recording (default: "
                   "this process's)")
    p.add_argument("--faults", metavar="SCENARIO", type=scenario_arg,
                   help="fault scenario (docs/faults.md): the fast clock stops at its "
                   "instants until each fault is detected; the real-time clock closes its "
                   "zones when their time comes (default: no faults)")
    p.add_argument("--recorded", action="store_true",
                   help="fast clock: hold sim time while no recorder runs, so a recorder "
                   "killed and restarted misses nothing that happened meanwhile")
    p.add_argument("--recover", action="store_true",
                   help="a restarted dispatcher: pick the mission up from what the "
                   "reservation service and the forklifts hold (fill missions)")
    p.add_argument("--exit-when-done", action="store_true",
                   help="exit after publishing the result (once the recorder has it, with "
                   "--recorded) instead of waiting to be stopped")
    p.add_argument("--claims", action="store_true",
                   help="hand out forklift ids to agents started with --id auto; without "
                   "--vehicles the fleet is whoever claimed one before claims stopped for "
                   "--gather seconds (docs/deployment.md)")
    p.add_argument("--gather", type=positive_float, default=5.0, metavar="SECONDS",
                   help="--claims without --vehicles: start once no new forklift has claimed "
                   "an id for this many seconds (default 5)")
    p.add_argument("--restart-marker", type=Path,
                   help="create this file when the mission starts; if it is already there, "
                   "this is a restart: pick the mission up as --recover does (a container "
                   "keeps its files across restarts, not across re-creation; default: none)")


class Stopped(Exception):
    """SIGTERM or SIGINT arrived in the middle of the mission."""


def serve(args: argparse.Namespace) -> int:
    mission = mission_from_args(args)
    layout = load_layout(mission.layout)
    options = engine_options(mission, layout, args.weights)
    keys = Keys(args.run)
    roster = None  # the claims of the dispatcher this one replaces
    if args.restart_marker is not None and args.restart_marker.exists():
        args.recover = True
        roster = read_roster(args.restart_marker)
        log.warning("%s exists: this dispatcher was restarted, it picks the mission up",
                    args.restart_marker)
    stop = threading.Event()
    in_mission = threading.Event()

    def stop_requested() -> None:  # runs in the main thread, wherever it is
        stop.set()
        if in_mission.is_set():
            raise Stopped("stopped by a signal before the mission ended")

    stop_on_signals(stop_requested)
    session = open_session(bus_config(args))
    claims = None
    try:
        limit = mission.vehicles or len(layout.vehicle_starts)
        if args.claims:
            claims = Claims(session, keys, Roster(limit, roster or {}, closed=bool(roster)))
            ids = claims.gather(mission.vehicles, args.gather, args.startup_timeout, stop)
            if not ids:
                raise ParticipantLost(f"no forklift claimed an id within "
                                      f"{args.startup_timeout:g} s")
            mission = dataclasses.replace(mission, vehicles=len(ids))
            log.info("the fleet: %d forklifts", len(ids))
        if args.restart_marker is not None and not args.recover:
            write_roster(args.restart_marker, claims.roster.ids if claims else {})
        n = mission.vehicles or len(layout.vehicle_starts)
        vehicles = list(range(1, n + 1))
        token = session.liveliness().declare_token(keys.dispatcher_alive)
        info = mission_info(mission, layout, n, args.clock, args.speed, args.command)
        # Each of the dispatcher's topics, by the message it carries (every event must reach
        # the recorder: its publishers wait rather than drop).
        streams = {cls: Stream(session, topic.key(keys.run), topic.sender, topic.reliable)
                   for cls, topic in published_by(DISPATCHER).items()}
        info_pub, done_pub = streams[MissionInfo], streams[MissionDone]
        info_answer = session.declare_queryable(  # for a recorder that joins late
            keys.dispatch_mission, lambda q: q.reply(q.key_expr, encode(info, SENDER, 0, 0.0)))
        liveness = Liveness(session, keys)
        recorded = threading.Event()
        status = follow_recorded(session, keys, recorded, log)
        try:
            in_mission.set()
            info_pub.put(info, 0.0)
            done = run_mission(session, keys, args, mission, layout, options, vehicles,
                               liveness, lambda message, t: streams[type(message)].put(
                                   message, t))
        except Stopped as exc:  # arrived just as the mission returned
            done = MissionDone(False, error=str(exc))
        finally:
            in_mission.clear()
        done_pub.put(done, done.record.get("end_time_s", 0.0))
        log.info("mission %s; %s", "done" if done.ok else "failed", done.error or done.digest)
        if not args.exit_when_done:
            stop.wait()
        elif args.recorded and not recorded.wait(RECORDED_WAIT_S):
            log.warning("the recorder had not recorded the result within %g s",
                        RECORDED_WAIT_S)
        liveness.close()
        for declared in (info_answer, *streams.values(), token, status):
            declared.undeclare()
    finally:
        if claims is not None:
            claims.close()
        session.close()
    return 0 if done.ok else 1


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


def run_mission(session, keys: Keys, args, mission, layout, options, vehicles: list[int],
                liveness: Liveness, publish) -> MissionDone:
    """Wait for everyone, run the engine, and say how it went (never raises for a mission
    that could not finish: the error goes into the result)."""
    t0 = time.perf_counter()
    clock = None
    try:
        liveness.wait_for_service(args.startup_timeout)
        mirror = TableMirror()
        reservations = ReservationClient(session, keys, Requester(session, SENDER))
        changes = reservations.follow(mirror)
        liveness.wait_for(vehicles, args.startup_timeout)
        log.info("%d forklifts and the reservation service are up", len(vehicles))
        executor = RemoteExecutor(session, keys, reservations, mirror, liveness, vehicles,
                                  layout.vehicle_kind)
        recovered, tick, wall = None, 0, 0.0
        if args.recover:
            recovered, tick, wall = pick_up(executor, layout, vehicles, options.params)
            log.info("picked the mission up at t=%.2f: %d stacks done", recovered.t,
                     len(recovered.done) + len(recovered.undelivered))
        scenario = load_scenario(args.faults) if args.faults else None
        if args.clock == "fast":
            clock = FastClock(session, keys, vehicles, liveness, log, scenario, args.recorded,
                              tick, recovered.t if recovered else 0.0)
        else:
            closed = frozenset(r.cell for r in mirror.table.reservations(ZONE))
            clock = RealtimeClock(session, keys, args.speed, vehicles, liveness, log, scenario,
                                  tick, recovered.t if recovered else 0.0, wall, closed)

        def progress(done: int, total: int, t: float, failures: int) -> None:
            publish(Progress(done, total, t, failures), t)

        options.progress = progress
        options.events = publish
        record = Engine(mission, options, layout, executor, clock, recovered).run()
        changes.undeclare()
        as_dict = MissionSummary.of_record(record).to_dict()
        return MissionDone(True, record=as_dict, digest=digest_of(as_dict),
                           wall_s=time.perf_counter() - t0, rejections=executor.rejections,
                           detections=getattr(clock, "detected", []))
    except (ParticipantLost, MissionStuck, RequestFailed, ProtocolError, Stopped) as exc:
        log.error("mission failed: %s", exc)
        return MissionDone(False, error=str(exc), wall_s=time.perf_counter() - t0)
    finally:
        if clock is not None:
            clock.close()

