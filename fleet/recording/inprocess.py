"""The in-process reference run written as a recording: the same keys, schemas, senders and
sequence numbers a run of processes puts on the wire, so analysis and plots have one input.

The engine's dispatch events are recorded as they happened; the reservation changes are the
ones its table applied; the forklifts' states are driven from the committed trajectories on
the fast-mode grid, exactly as each agent would publish them.
"""

from __future__ import annotations

import threading
import time
from collections import defaultdict
from dataclasses import dataclass, replace
from pathlib import Path

from fleet.mission.battery import battery_of
from fleet.mission.drive_log import DriveLog
from fleet.mission.driving import FAST_STATE_PERIOD_S, replayed, states_until
from fleet.mission.engine import Engine, EngineOptions, MissionStuck
from fleet.mission.faults import Scenario
from fleet.mission.freeze import Disruption, ScheduledPacer
from fleet.mission.record import MissionRecord, MissionSummary, digest_of
from fleet.mission.seam import NoPacer, Pacer
from fleet.mission.spec import Mission
from fleet.mission.standstill import Cause, Standstill
from fleet.recording.writer import RecordingWriter, mission_info
from fleet.wire.convert import change_time, change_to_wire
from fleet.wire.protocol import Message, MissionDone, MissionInfo, Progress, WireChange, encode
from fleet.wire.topics import DISPATCHER, Keys, Topic, expected_sender, published_by
from fleet.world.layout import Layout


@dataclass(frozen=True)
class Outgoing:
    key: str
    message: Message
    sender: str
    sim_time: float


def outgoing(keys: Keys, topic: Topic, message: Message, sim_time: float,
             *values: int) -> Outgoing:
    """A message on the run's key of a topic (its placeholders `values`), in the name of that
    key's one sender."""
    key = topic.key(keys.run, *values)
    return Outgoing(key, message, expected_sender(key), sim_time)


def vehicle_states(record: MissionRecord, layout: Layout, keys: Keys, drive_log: DriveLog,
                   until: float | None = None, info: MissionInfo | None = None
                   ) -> list[Outgoing]:
    """Each forklift's state on the fast-mode grid, from t = 0 to the mission's last tick
    (`until`: the instant a mission that did not finish reached), driven as its agent was
    told to (`Engine.drive_log`); a forklift that is down says nothing until it moves again."""
    if until is None:
        until = states_until(max(record.end_time, record.all_parked_time))
    out = []
    for vehicle, start in zip(record.vehicles, record.starts, strict=True):
        battery = None if info is None else battery_of(info, vehicle, layout)
        drive, silent = replayed(vehicle, start, layout, battery, drive_log[vehicle])
        for t in drive.due(until, FAST_STATE_PERIOD_S, before=True):
            if not any(t0 <= t < t1 for t0, t1 in silent):
                out.append(outgoing(keys, Keys.vehicle_state, drive.state_at(t), t, vehicle))
            drive.forget_before(t)  # as its agent does: each state reads the legs from t on
    return out


def inprocess_stream(info: MissionInfo, record: MissionRecord, layout: Layout,
                     events: list[tuple[Message, float]], changes: list[WireChange],
                     done: MissionDone, drive_log: DriveLog, stopped: Standstill | None = None,
                     keys: Keys | None = None) -> list[Outgoing]:
    """Everything a run of processes would have published, in sim-time order; of a mission
    that did not finish (`stopped`), up to the instant it reached, and how far it got."""
    keys = keys or Keys()
    dispatcher = published_by(DISPATCHER)  # the topic of each of the dispatcher's messages
    stream = [outgoing(keys, Keys.dispatch_mission, info, 0.0)]
    stream += [outgoing(keys, Keys.reservation_change, c, change_time(c)) for c in changes]
    stream += [outgoing(keys, dispatcher[type(m)], m, t) for m, t in events]
    stream += vehicle_states(record, layout, keys, drive_log,
                             None if stopped is None else stopped.t, info)
    stream.sort(key=lambda o: o.sim_time)  # stable: table changes before what they cause
    if stopped is not None:
        stream.append(outgoing(keys, Keys.dispatch_stopped, stopped.message(), stopped.t))
    stream.append(outgoing(keys, Keys.dispatch_done, done, record.end_time))
    return stream


class Interrupted(Exception):
    """A stop was asked (Ctrl-C, SIGTERM): the run ends before its next decision."""


class StopBetweenDecisions:
    """The pacer of a run that may be asked to stop: once `asked` is set, the run ends before
    its next decision, so what it recorded ends whole between two decisions (a commit and its
    subtask both in, or neither); the rest is the wrapped pacer's."""

    def __init__(self, pacer: Pacer, asked: threading.Event) -> None:
        self.pacer = pacer
        self.asked = asked

    def before_decision(self, t_next: float, t_free: dict[int, float]) -> dict[int, float]:
        if self.asked.is_set():
            raise Interrupted("stopped by a signal before the mission ended")
        return self.pacer.before_decision(t_next, t_free)

    def finish(self, t_end: float) -> None:
        self.pacer.finish(t_end)

    def disruptions(self, t_next: float, down: frozenset[int]) -> list[Disruption]:
        return self.pacer.disruptions(t_next, down)

    def resumed(self, vehicle: int) -> None:
        self.pacer.resumed(vehicle)

    def instant(self, t: float) -> float:
        return self.pacer.instant(t)


def recorded_run(mission: Mission, layout: Layout, options: EngineOptions,
                 command: str = "", scenario: Scenario | None = None,
                 stop: threading.Event | None = None) -> tuple[MissionDone, list[Outgoing]]:
    """Run the mission in this process (with the scenario's faults at their instants): its
    result, and everything a run of processes would have published (options.progress still
    hears the progress). A mission that gets stuck, or is asked to `stop`, ends as a failed
    result, with what happened up to then and how far it got."""
    events: list[tuple[Message, float]] = []
    told = options.progress

    def progress(done: int, total: int, t: float, failures: int) -> None:
        events.append((Progress(done, total, t, failures), t))
        if told is not None:
            told(done, total, t, failures)

    options = replace(options, progress=progress,
                      events=lambda message, t: events.append((message, t)))
    t0 = time.perf_counter()
    pacer: Pacer = ScheduledPacer(scenario) if scenario is not None else NoPacer()
    engine = Engine(mission, options, layout,
                    pacer=pacer if stop is None else StopBetweenDecisions(pacer, stop))
    stopped = None
    try:
        record = engine.run()
    except MissionStuck as exc:
        stopped = exc.standstill
    except Interrupted as exc:
        stopped = engine.standstill(Cause.STOPPED, str(exc))
    if stopped is None:
        as_dict = MissionSummary.of_record(record).to_dict()
        done = MissionDone(True, record=as_dict, digest=digest_of(as_dict),
                           wall_s=time.perf_counter() - t0)
    else:
        record = engine.record
        done = MissionDone(False, error=stopped.reason, wall_s=time.perf_counter() - t0)
    info = mission_info(mission, layout, len(record.vehicles), "inprocess", command=command)
    changes = [change_to_wire(c) for c in engine.executor.store.changes]
    return done, inprocess_stream(info, record, layout, events, changes, done, engine.drive_log,
                                  stopped)


def write_recording(path: Path, stream: list[Outgoing], layout: Layout) -> None:
    """Write a stream as a recording, with its Foxglove view channels. Log times are the
    run's start (now) plus sim time, as the view channels have them. Written in a run
    directory, it carries that run's id, as a recorder's segment does (RecordingWriter)."""
    from fleet.views.scene004 import scene_views

    writer = RecordingWriter(path)
    seq: dict[tuple[str, str], int] = defaultdict(int)
    now = time.time_ns()
    info = next(o.message for o in stream if isinstance(o.message, MissionInfo))
    writer.describe(info)
    views = scene_views(layout, now, kind=info.kind, vehicles=info.vehicles)
    for topic, message, log_ns in views.start():
        writer.write_view(topic, message, log_ns)
    try:
        for o in stream:
            seq[o.key, o.sender] += 1
            payload = encode(o.message, o.sender, seq[o.key, o.sender], o.sim_time)
            writer.write(o.key, payload, views.log_ns(o.sim_time), o.sim_time)
            for topic, message, log_ns in views.on_message(o.key, o.message, o.sim_time):
                writer.write_view(topic, message, log_ns)
    finally:
        writer.close()
