"""`fleet recorder` / `python -m recorder`: records everything under fleet/<run>/ to MCAP.

A zenoh callback only stamps the receive time and enqueues; one writer thread decodes what
it needs (the sim time, the run's description), writes each payload as it travelled, feeds
the Foxglove views (into the file, and to a live WebSocket view with --foxglove) and flushes
the file about once a second, so a killed recorder loses at most about a second. It publishes
its status on fleet/<run>/recorder/status at every flush and once the mission's result is in
the file (and answers queries there), so `fleet run` knows when it may stop the recorder.
A recorder started mid-run (a restarted one writes the run's next segment, run-N.mcap:
fleet.recording.segments.next_segment) asks the dispatcher what the run is, so its file is described
too. Every segment carries the run id of the run directory it is written in (its marker,
fleet/recording/rundir.py), so a restarted recorder's segments are of the same run.
"""

from __future__ import annotations

import json
import logging
import queue
import re
import socket
import threading
import time
from collections.abc import Sequence
from contextlib import ExitStack
from pathlib import Path

import zenoh

from fleet.errors import UserError
from fleet.recording.format import VDA5050_PREFIX
from fleet.recording.reader import Recorded, numbers_before, unbroken_run
from fleet.recording.rundir import claim_new
from fleet.recording.segments import RUN_FILE, next_segment, segment_number
from fleet.recording.writer import RecordingWriter
from fleet.runtime.argtypes import port_problem
from fleet.runtime.bus import Stream, open_session
from fleet.runtime.lifecycle import process_main, stop_on_signals
from fleet.runtime.process_configs import RecorderConfig
from fleet.vda5050 import TOPICS as VDA_TOPICS
from fleet.vda5050.messages import serial_number
from fleet.vda5050.schemas import schema_text
from fleet.wire.protocol import (
    AgvHistory,
    MissionDone,
    MissionInfo,
    MqttTraffic,
    ProtocolError,
    RecorderStatus,
    decode,
    encode,
)
from fleet.wire.topics import RECORDER, Keys
from fleet.world.layout import LayoutError
from fleet.world.layout_file import parse_layout

log = logging.getLogger("fleet.recorder")
SENDER = RECORDER
FLUSH_PERIOD_S = 1.0
HISTORY_TIMEOUT_S = 30.0  # a long mission's events come back in one answer


def main(argv: Sequence[str] | None = None) -> int:
    return process_main(RecorderConfig, serve, "python -m recorder", argv)


class Recorder:
    def __init__(self, session: zenoh.Session, keys: Keys, writer: RecordingWriter,
                 live=None, exit_when_done: bool = False) -> None:
        self.session = session
        self.keys = keys
        self.writer = writer
        self.live = live
        self.inbox: queue.Queue[tuple[str, bytes, int] | None] = queue.Queue()
        self.views = None  # Foxglove scene views, once the run's description is known
        self.vehicle_kind = "forklift"  # the layout's, once known: VDA 5050 serial numbers
        self.done_seen = False
        self.exit_when_done = exit_when_done
        self.lock = threading.Lock()  # status answers read what the writer thread counts
        # What this segment holds of the messages a recorder also asks for (the seed-004
        # events, the result), by key and number: one both heard live and answered is
        # written once.
        self.asked_keys = (keys.dispatch_agv, keys.dispatch_done)
        self.written: set[tuple[str, int]] = set()
        # A restarted recorder's catch-up is in its inbox: until then it does not say the
        # result is recorded, so nobody stops it (or the dispatcher) before it has asked.
        self.caught_up = threading.Event()

    def run(self) -> None:
        with ExitStack() as scope:
            scope.callback(self.writer.close)  # last: what the declarations below feed
            scope.enter_context(self.session.declare_subscriber(self.keys.everything,
                                                                self._on_sample))
            scope.enter_context(self.session.declare_queryable(self.keys.recorder_status,
                                                               self._status))
            self.status_pub = scope.enter_context(
                Stream(self.session, self.keys.recorder_status, SENDER, reliable=True))
            scope.enter_context(
                self.session.liveliness().declare_token(self.keys.recorder_alive))
            self._ask_for_mission()
            if (segment_number(self.writer.path) or 1) == 1:
                self.caught_up.set()  # nothing was written before this one
            scope.enter_context(self.session.liveliness().declare_subscriber(
                self.keys.dispatcher_alive, self._on_dispatcher, history=True))
            log.info("recording %s to %s", self.keys.everything, self.writer.path)
            self._write_until_stopped()
        log.info("wrote %d messages to %s", self.writer.messages, self.writer.path)

    def _write_until_stopped(self) -> None:
        next_flush = time.monotonic() + FLUSH_PERIOD_S
        while True:
            try:
                item = self.inbox.get(timeout=max(0.0, next_flush - time.monotonic()))
            except queue.Empty:
                item = ()  # time to flush
            if item is None:
                break
            if item:
                self._record(*item)
            if time.monotonic() >= next_flush:
                self.writer.flush()
                self._announce()
                next_flush = time.monotonic() + FLUSH_PERIOD_S
        while not self.inbox.empty():  # what arrived before the stop
            if (item := self.inbox.get_nowait()) is not None:
                self._record(*item)

    def stop(self) -> None:
        # From a signal handler in the main thread, which may be inside inbox.get holding the
        # queue's lock: put from another thread, or it could wait on itself.
        threading.Thread(target=self.inbox.put, args=(None,), daemon=True).start()

    def _on_sample(self, sample: zenoh.Sample) -> None:
        self.inbox.put((str(sample.key_expr), sample.payload.to_bytes(), time.time_ns()))

    def _ask_for_mission(self) -> None:
        """A recorder started mid-run asks the dispatcher what the run is, and its result if
        it has ended (one restarted after the end of a seed-004 run, which does not wait for
        a recorder)."""
        def ask() -> None:
            for key in (self.keys.dispatch_mission, self.keys.dispatch_done):
                for reply in self.session.get(key, timeout=5.0):
                    if reply.ok is not None:
                        self.inbox.put((key, reply.ok.payload.to_bytes(), time.time_ns()))

        threading.Thread(target=ask, daemon=True, name="ask-mission").start()

    def _on_dispatcher(self, sample: zenoh.Sample) -> None:
        if sample.kind == zenoh.SampleKind.PUT:
            threading.Thread(target=self._catch_up, daemon=True, name="catch-up").start()

    def _catch_up(self) -> None:
        """Each time a dispatcher's token comes (declared once it holds every event so far:
        a seed-004 one that picks a mission up, after its replay), ask it for the seed-004
        events this recording lacks: those numbered after the unbroken run that this
        segment and the earlier ones hold (a restarted recorder's predecessors, or events
        a killed dispatcher published that never arrived). Asked once this recorder's
        subscriber is up, so every later one comes live; a seed-000 dispatcher keeps none
        and answers nothing."""
        held = numbers_before(self.writer.path, self.keys.dispatch_agv)
        with self.lock:  # what an earlier segment holds is not written again
            self.written |= {(self.keys.dispatch_agv, n) for n in held}
            after = unbroken_run({n for key, n in self.written if key == self.keys.dispatch_agv})
        request = encode(AgvHistory(after), SENDER, 0, 0.0)
        caught = 0
        # Every reply is on the one key: unconsolidated, or zenoh keeps only the last.
        for reply in self.session.get(self.keys.dispatch_agv_history, payload=request,
                                      timeout=HISTORY_TIMEOUT_S,
                                      consolidation=zenoh.ConsolidationMode.NONE):
            if reply.ok is not None:
                self.inbox.put((self.keys.dispatch_agv, reply.ok.payload.to_bytes(),
                                time.time_ns()))
                caught += 1
        if caught:
            log.info("caught up on %d seed-004 events after event %d", caught, after)
        with self.lock:  # one of this thread and the writer sees both: it ends the file
            first = not self.caught_up.is_set()
            self.caught_up.set()
            done = first and self.exit_when_done and self.done_seen
        if first:
            self._announce()
        if done:
            self.inbox.put(None)  # after every answer

    def _record(self, key: str, payload: bytes, log_ns: int) -> None:
        """Write the message as it came; then what it tells (the run's description, the
        views). Nothing a sender puts in a message stops the recording."""
        try:
            envelope = decode(payload)
        except ProtocolError as exc:  # recorded as it came: the analyzer reports it
            log.warning("recording a malformed message on %s: %s", key, exc)
            envelope = None
        recorded = Recorded(key, log_ns, 0, envelope)
        if recorded.genuine and key in self.asked_keys:  # a forgery takes no number's place
            with self.lock:
                if (key, envelope.seq) in self.written:
                    return  # live, and again in an answer (or held by an earlier segment)
                self.written.add((key, envelope.seq))
        sim_time = envelope.sim_time if envelope is not None else 0.0
        with self.lock:
            self.writer.write(key, payload, log_ns, sim_time)
        if not recorded.genuine:
            return
        message = envelope.message
        try:
            if isinstance(message, MissionInfo) and not self.writer.described:
                self._describe(message, log_ns)
            if isinstance(message, MqttTraffic):
                self._mqtt_view(message, log_ns, sim_time)
            if isinstance(message, MissionDone):
                with self.lock:
                    self.done_seen = True
                    done = self.exit_when_done and self.caught_up.is_set()
                self.writer.flush()
                self._announce()
                if done:
                    self.inbox.put(None)  # this thread reads the inbox: no lock to wait on
            if self.views is not None:
                self._show(self.views.on_message(key, message, sim_time))
        except Exception:  # a view or description failing must not lose the recording
            log.exception("could not show the message on %s", key)

    def _mqtt_view(self, traffic: MqttTraffic, log_ns: int, sim_time: float) -> None:
        """A VDA 5050 message also as JSON on /vda5050/SERIAL/TOPIC (forklift-N, agv-N) with
        the official schema, for Foxglove (one that is not a JSON object stays on its raw
        channel only)."""
        if traffic.topic not in VDA_TOPICS:
            return
        try:
            if not isinstance(json.loads(traffic.payload), dict):
                return
        except ValueError:
            return
        with self.lock:
            serial = serial_number(self.vehicle_kind, traffic.vehicle)
            self.writer.write_json(f"{VDA5050_PREFIX}{serial}/{traffic.topic}",
                                   traffic.payload, f"vda5050.{traffic.topic}",
                                   schema_text(traffic.topic), log_ns, sim_time)

    def _announce(self) -> None:
        """Publish how far the recording is (fleet run waits for the mission's result)."""
        self.status_pub.put(self._current_status(), 0.0)

    def _current_status(self) -> RecorderStatus:
        with self.lock:
            return RecorderStatus(str(self.writer.path), self.writer.messages,
                                  self.done_seen and self.caught_up.is_set())

    def _describe(self, info: MissionInfo, log_ns: int) -> None:
        from fleet.views.scene004 import scene_views

        self.writer.describe(info)
        try:
            layout = parse_layout(info.layout_toml, "the mission's layout")
        except LayoutError as exc:
            log.warning("no Foxglove views: %s", exc)
            return
        self.vehicle_kind = layout.vehicle.kind
        self.views = scene_views(layout, log_ns, kind=info.kind, vehicles=info.vehicles)
        self._show(self.views.start())

    def _show(self, messages) -> None:
        for topic, message, log_ns in messages:
            self.writer.write_view(topic, message, log_ns)
            if self.live is not None:
                self.live.publish(topic, message)

    def _status(self, query: zenoh.Query) -> None:
        query.reply(query.key_expr, encode(self._current_status(), SENDER, 0, 0.0))


def serve(config: RecorderConfig) -> int:
    # What can be refused here is, at once, not after waiting for the router.
    if config.out_dir is None:
        _refuse_existing(config.out)
    busy = None if config.foxglove is None else \
        port_problem(config.foxglove, config.foxglove_host)
    if busy:
        raise UserError(f"--foxglove {config.foxglove}: {busy}")
    with ExitStack() as scope:
        # Connected first, then the file: a recorder that cannot connect leaves no file (and
        # no run directory) behind, so the same command may simply be tried again.
        session = scope.enter_context(open_session(config.bus.config()))
        out = config.out if config.out_dir is None else \
            output_in(config.out_dir, socket.gethostname(), time.gmtime())
        _refuse_existing(out)
        live = _live_view(config)
        if live is not None:
            scope.enter_context(live)
        recorder = Recorder(session, Keys(config.bus.run), RecordingWriter(out), live,
                            config.exit_when_done)
        stop_on_signals(recorder.stop)
        recorder.run()
    return 0


def _live_view(config: RecorderConfig):
    """The Foxglove live view of --foxglove, or None."""
    if config.foxglove is None:
        return None
    from recorder.live import LiveView

    try:
        live = LiveView(port=config.foxglove, host=config.foxglove_host)
    except RuntimeError as exc:  # foxglove's own error: the port taken meanwhile, a bad host
        raise UserError(f"--foxglove {config.foxglove}: cannot serve the live view on "
                        f"{config.foxglove_host}: {exc}") from None
    log.info("Foxglove live view on ws://%s:%d", config.foxglove_host, live.port)
    return live


def _refuse_existing(path: Path) -> None:
    if path.exists():
        raise UserError(f"{path} exists: a recording is never overwritten; give another "
                        f"--out")


def output_in(folder: Path, host: str, now: time.struct_time) -> Path:
    """Where a recorder with --out-dir writes: the next segment of this host's latest run
    directory (a restarted recorder: the segment takes the directory's run id), else a new
    run directory claimed for now and the host (DATE-TIME-HOST, -2 after it if taken)."""
    named = re.compile(rf"(\d{{8}}-\d{{6}})-{re.escape(host)}(?:-(\d+))?")
    mine = []  # (date-time, suffix number), directory
    if folder.is_dir():
        mine = sorted(((m[1], int(m[2] or 1)), p) for p in folder.iterdir()
                      if p.is_dir() and (m := named.fullmatch(p.name)))
    if mine:
        return next_segment(mine[-1][1])
    return claim_new(folder, f"{time.strftime('%Y%m%d-%H%M%S', now)}-{host}").path / RUN_FILE
