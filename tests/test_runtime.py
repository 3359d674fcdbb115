"""The distributed runtime: real processes (router, reservation service, one agent per
forklift, dispatcher) talking over real zenoh sessions on loopback."""

import itertools
import json
import logging
import math
import os
import select
import signal
import subprocess
import sys
from collections import defaultdict
from pathlib import Path

import mcap.reader
import msgpack
import pytest
from mission_check import journal_overlaps, record_problems
from test_paper_missions import check_paper_mission
from websockets.sync.client import connect

from dispatcher.liveness import UNSERVED_RETRY_S
from dispatcher.remote import TASK_TIMEOUT_S
from dispatcher.remote004 import REQUEST_TIMEOUT_S
from fleet.analysis.analyze import analyze
from fleet.dispatching.decision import Strategy
from fleet.mission.driving import states_until
from fleet.mission.engine import Engine, engine_options, run_mission
from fleet.mission.record import digest
from fleet.mission.spec import ClockMode, Mission, MissionKind
from fleet.mission.standstill import Cause
from fleet.recording.inprocess import vehicle_states
from fleet.recording.mission_record import recorded_standstill, summary_of
from fleet.recording.reader import read_recording
from fleet.runtime.bus import (
    BusConfig,
    Requester,
    RequestFailed,
    free_port,
    open_session,
    wait_alive,
)
from fleet.runtime.lifecycle import ORPHAN_GRACE_S, PARENT_ENV
from fleet.runtime.local_run import RunSpec, run_processes
from fleet.wire.protocol import (
    Progress,
    Reply,
    StackDone,
    StatusRequest,
    TaskRequest,
    TaskResult,
    VehicleState,
    decode,
    encode,
)
from fleet.wire.topics import Keys
from fleet.world.layout_file import load_layout
from reservation.client import ReservationClient
from reservation.mirror import TableMirror

ROOT = Path(__file__).resolve().parent.parent


@pytest.mark.parametrize("strategy,kind", [("ann", "fill"), ("ann", "empty"),
                                           ("traffic", "fill"), ("traffic", "empty")])
def test_fast_mode_processes_equal_the_inprocess_reference(strategy, kind, tmp_path):
    mission = Mission("paper", MissionKind(kind), Strategy(strategy))
    layout = load_layout("paper")
    engine = Engine(mission, engine_options(mission, layout, None), layout)
    reference = engine.run()
    check_paper_mission(reference)  # the reference itself is sound (test_paper_missions.py)
    outcome = run_processes(RunSpec(mission, 4, tmp_path))
    assert outcome.error == ""
    assert outcome.done.digest == digest(reference)
    assert outcome.done.record["end_time_s"] == reference.end_time
    assert journal_overlaps(tmp_path / "reservation.journal") == []
    with open(tmp_path / "run.mcap", "rb") as f:  # the mcap library's own reader
        summary = mcap.reader.make_reader(f).get_summary()
    schemas = {c.topic: summary.schemas[c.schema_id].name for c in summary.channels.values()}
    assert schemas["fleet/default/vehicle/1/state"] == "vehicle.state"
    assert schemas["/view/forklifts"] == "foxglove.SceneUpdate"
    recording = read_recording(tmp_path / "run.mcap")
    report = analyze(recording)
    assert report.passed and report.complete and report.finished
    assert (len(report.overlaps), len(report.outside_reservation), report.messages_lost,
            report.stacks_done, report.stacks_duplicated) == (0, 0, 0, 136, [])
    assert report.end_time_s == reference.end_time
    # Every forklift's recorded states are the ones the reference drives, instant by instant.
    recorded = sorted((r.key, r.envelope.sim_time, m) for r, m in recording.of(VehicleState))
    driven = sorted((o.key, o.sim_time, o.message)
                    for o in vehicle_states(reference, layout, Keys(), engine.drive_log))
    assert recorded == driven


# -- hostile messages on every key while a mission runs ---------------------------------------

def hostile_payloads(key: str) -> list[bytes]:
    good = encode(VehicleState(1, "0,0,E", 0, "", False), "intruder", 1, 0.0)
    wrong_version = msgpack.packb({"v": 99, "type": "vehicle.state", "sender": "intruder",
                                   "seq": 1, "t": 0.0, "body": {}})
    return [b"\xc1 not msgpack " + key.encode(), good[:-3], wrong_version]


class Intruder:
    """Once the mission is under way (its first progress message), sends garbage, a truncated
    message and a wrong-version message to every key some process listens on."""

    def __init__(self, vehicles: int) -> None:
        self.vehicles = vehicles
        self.sent: dict[str, list] = defaultdict(list)
        self.states: dict[int, list[float]] = defaultdict(list)
        self.rejections: list[str] = []  # what fleet run's own listener logged
        self.forged = 0  # well-formed messages in someone else's name

    def on_ready(self, session, keys, launcher) -> None:
        self.session, self.keys = session, keys
        self.subscriber = session.declare_subscriber(keys.vehicle_state("*"), self._on_state)

    def _on_state(self, sample) -> None:
        vehicle = Keys.vehicle_in(str(sample.key_expr))
        self.states[vehicle].append(decode(sample.payload.to_bytes()).sim_time)

    def on_progress(self, progress: Progress) -> None:
        if self.sent:
            return
        keys = self.keys
        for key in (keys.reservation_change, keys.clock, keys.dispatch_progress,
                    keys.dispatch_done, *(keys.clock_ack(v) for v in self.vehicle_ids)):
            for payload in hostile_payloads(key):
                self.session.put(key, payload)
                self.sent[key].append(payload)
        for key in (keys.reservation_request("test"),
                    *(keys.vehicle_task(v) for v in self.vehicle_ids)):
            for payload in hostile_payloads(key):
                self.sent[key] += list(self.session.get(key, payload=payload, timeout=30))
        # Well-formed but absurd, from someone else, where only the recorder listens.
        absurd = VehicleState(1, "0,0,E", 0, "", False, math.inf, 1e300, 0.0)
        for key, message in ((keys.vehicle_state(1), absurd),
                             (keys.dispatch_stack, StackDone("s1", 1, 1, 1e300))):
            self.session.put(key, encode(message, "intruder", 2**62, 1e300))
            self.forged += 1

    @property
    def vehicle_ids(self) -> range:
        return range(1, self.vehicles + 1)

    def run(self, spec: RunSpec):
        handler = ListHandler(self.rejections)
        logging.getLogger("fleet.run").addHandler(handler)
        try:
            return run_processes(spec, self.on_progress, self.on_ready)
        finally:
            logging.getLogger("fleet.run").removeHandler(handler)

    def check(self, run_dir: Path, clock: str) -> None:
        """Every listener logged each of the three, with the key, and answered the queries
        with a refusal."""
        keys = self.keys
        agents = [f"agent-{v}" for v in self.vehicle_ids]
        listeners = {keys.reservation_change: [*agents, "dispatcher"], keys.clock: agents,
                     keys.reservation_request("test"): ["reservation"]}
        for v in self.vehicle_ids:
            listeners[keys.vehicle_task(v)] = [f"agent-{v}"]
            if clock == "fast":  # only the fast clock waits for acknowledgements
                listeners[keys.clock_ack(v)] = ["dispatcher"]
        logs = {p.stem: p.read_text() for p in (run_dir / "logs").glob("*.log")}
        for key, names in listeners.items():
            for name in names:
                rejected = [line for line in logs[name].splitlines()
                            if f"rejected a message on {key}:" in line
                            or f"rejected a request on {key}:" in line]
                assert len(rejected) == 3, (name, key, logs[name][-2000:])
        for key in (keys.dispatch_progress, keys.dispatch_done):
            assert len([r for r in self.rejections if f"on {key}:" in r]) == 3
        for reply in self.sent[keys.reservation_request("test")]:
            answer = decode(reply.ok.payload.to_bytes()).message
            assert isinstance(answer, Reply) and not answer.ok
            assert answer.reason.startswith("malformed request")
        for v in self.vehicle_ids:
            replies = self.sent[keys.vehicle_task(v)]
            assert len(replies) == 3
            assert all(r.err.payload.to_bytes().startswith(b"rejected: ") for r in replies)


class ListHandler(logging.Handler):
    def __init__(self, into: list[str]) -> None:
        super().__init__(logging.WARNING)
        self.into = into

    def emit(self, record: logging.LogRecord) -> None:
        self.into.append(record.getMessage())


def test_hostile_messages_in_fast_mode_change_nothing(tmp_path):
    """Garbage on every key during a fast-mode run: every listener rejects it with a logged
    reason, nobody dies, and the record is still identical to the in-process reference."""
    mission = Mission("small", MissionKind.FILL, Strategy.ANN)
    layout = load_layout("small")
    reference = run_mission(mission, engine_options(mission, layout, None), layout)
    intruder = Intruder(2)
    outcome = intruder.run(RunSpec(mission, 2, tmp_path))
    assert outcome.error == ""
    assert outcome.done.digest == digest(reference)
    intruder.check(tmp_path, "fast")
    recording = read_recording(tmp_path / "run.mcap")
    report = analyze(recording)
    assert report.passed, report.lines()
    assert report.malformed == 3 * (4 + 2)  # the garbage put on 6 keys, recorded as it came
    assert report.foreign == intruder.forged == 2  # recorded, and believed nowhere
    last_tick = states_until(max(reference.end_time, reference.all_parked_time))
    grid = [k * 0.5 for k in range(int(last_tick / 0.5) + 1) if k * 0.5 < last_tick]
    assert grid[-1] >= max(reference.end_time, reference.all_parked_time)  # seen as it ends
    for vehicle in intruder.vehicle_ids:  # every instant of the shared grid, exactly once
        times = [r.envelope.sim_time for r, m in recording.of(VehicleState)
                 if m.vehicle == vehicle and r.envelope.sender == f"vehicle-{vehicle}"]
        assert times == grid


def test_realtime_mission_is_safe_and_shrugs_off_hostile_messages(tmp_path):
    mission = Mission("small", MissionKind.FILL, Strategy.ANN)
    intruder = Intruder(2)
    outcome = intruder.run(RunSpec(mission, 2, tmp_path, clock=ClockMode.REALTIME, speed=40.0))
    assert outcome.error == ""
    record = outcome.done.record
    recording = read_recording(tmp_path / "run.mcap")
    assert record_problems(summary_of(recording), load_layout("small")) == []
    assert len(record["stacks_done"]) == 24
    assert journal_overlaps(tmp_path / "reservation.journal") == []
    for vehicle in intruder.vehicle_ids:  # 10 Hz of wall time, but at most 0.5 s of sim time
        times = sorted(intruder.states[vehicle])
        gaps = sorted(b - a for a, b in itertools.pairwise(times))
        assert len(times) > 50 and gaps[len(gaps) // 2] == 0.5
    intruder.check(tmp_path, "realtime")
    report = analyze(recording)
    assert report.passed, report.lines()
    assert report.stacks_done == 24 and report.messages_lost == 0
    assert report.foreign == intruder.forged == 2
    # Decided a lead ahead, every subtask is for the fast clock's instant: the same record,
    # unless the dispatcher says it fell behind (a machine too busy to keep up).
    layout = load_layout("small")
    reference = Engine(Mission("small", MissionKind.FILL, Strategy.ANN, 2),
                       engine_options(mission, layout, None), layout).run()
    late = "decided late" in (tmp_path / "logs" / "dispatcher.log").read_text()
    assert late or outcome.done.digest == digest(reference)


def test_a_recorder_killed_mid_run_leaves_a_readable_recording(tmp_path):
    """SIGKILL the recorder once it holds a few hundred messages: the run stops (a child
    died), and `fleet analyze` reads what the file holds up to the last flushed chunk."""
    mission = Mission("small", MissionKind.FILL, Strategy.TRAFFIC)

    def on_ready(session, keys, launcher):
        recorder = next(c.proc for c in launcher.children if c.name == "recorder")
        statuses = session.declare_subscriber(keys.recorder_status)  # one a flush (~1 s)
        while decode(statuses.recv().payload.to_bytes()).message.messages < 300:
            pass
        recorder.kill()
        statuses.undeclare()

    outcome = run_processes(RunSpec(mission, 2, tmp_path, clock=ClockMode.REALTIME, speed=20.0),
                            on_ready=on_ready)
    assert "recorder exited with status -9" in outcome.error
    recording = read_recording(tmp_path / "run.mcap")
    assert not recording.complete and recording.problem
    assert len(recording.messages) > 0 and recording.span_s > 0
    report = analyze(recording)
    assert not report.passed and report.stacks_lost  # the rest of the mission is not in it
    assert report.overlaps == [] and report.outside_reservation == []  # what is, is sound
    assert report.messages_lost == 0  # a cut at the end loses nothing in the middle


def test_an_agent_that_dies_unannounced_is_recovered_from_and_its_work_done(tmp_path):
    """No fault scenario: forklift 2's agent just dies. The dispatcher sees its token go,
    freezes it where it stands, and forklift 1 does the rest; the recording passes."""
    children = {}

    def on_ready(session, keys, launcher):
        children.update({c.name: c.proc for c in launcher.children})

    def on_progress(progress):
        if children["agent-2"].poll() is None:
            children["agent-2"].kill()

    mission = Mission("small", MissionKind.FILL, Strategy.TRAFFIC)
    outcome = run_processes(RunSpec(mission, 2, tmp_path), on_progress, on_ready)
    assert outcome.error == "" and outcome.done.ok
    record = outcome.done.record
    [(vehicle, _, cause)] = [h for h in record["halts"] if h[0] == 2]
    assert vehicle == 2 and "agent lost" in cause and record["resumes"] == []
    assert len(record["stacks_done"]) == 24
    report = analyze(read_recording(tmp_path))
    assert report.passed and report.stacks_done == 24
    assert children["agent-2"].returncode == -signal.SIGKILL
    others = {name: p.returncode for name, p in children.items() if name != "agent-2"}
    assert others == dict.fromkeys(others, 0)  # each stopped cleanly, session closed


# -- two agents, one contested goal ----------------------------------------------------------

def fleet_process(args, **kwargs) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "fleet", *args], cwd=ROOT,
                            env={**os.environ, "PYTHONUNBUFFERED": "1"}, **kwargs)


def test_conflicting_commits_one_wins_the_other_is_told_why_and_replans(tmp_path):
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    keys = Keys(f"c{os.getpid()}")
    common = ["--run", keys.run, "--connect", endpoint]
    with open(tmp_path / "services.log", "wb") as logs:  # the children keep their copies
        router = fleet_process(["router", "--listen", endpoint], stderr=logs)
        service = fleet_process(["reservation", *common, "--journal",
                                 str(tmp_path / "journal")], stderr=logs)
    agents = {v: fleet_process(["agent", *common, "--id", str(v), "--layout", "small"],
                               stderr=subprocess.PIPE, text=True) for v in (1, 2)}
    session = open_session(BusConfig("client", (endpoint,), connect_timeout_ms=30_000))
    try:
        for v in agents:
            assert wait_alive(session, keys.vehicle_alive(v), 60)
        mirror = TableMirror()
        changes = ReservationClient(session, keys, Requester(session, "test")).follow(mirror)
        assert mirror.wait_until(lambda table: table.vehicles() == [1, 2], 30)
        starts = load_layout("small").vehicle_starts
        goals = ["1,4,W", "1,3,W"]  # both forklifts prefer the same one
        service.send_signal(signal.SIGSTOP)  # the commits queue up until both are planned
        try:
            pending = {v: session.get(keys.vehicle_task(v), timeout=60, payload=encode(
                TaskRequest(f"t{v}", v, "deliver", str(starts[v - 1]), 0.0, goals, [], False,
                            mirror.revision), "test", v, 0.0)) for v in agents}
            for proc in agents.values():  # both have planned on the same table
                while "committing task" not in proc.stderr.readline():
                    pass
        finally:
            service.send_signal(signal.SIGCONT)
        results = {v: decode(next(iter(pending[v])).ok.payload.to_bytes()).message
                   for v in agents}
        assert all(isinstance(r, TaskResult) and r.ok for r in results.values())
        losers = [v for v, r in results.items() if r.rejections]
        assert len(losers) == 1
        loser, winner = losers[0], 3 - losers[0]
        assert f"held by vehicle {winner}" in results[loser].rejections[0]
        assert results[loser].goal != results[winner].goal  # the winner parks there for good
        changes.undeclare()
    finally:
        session.close()
        codes = []
        for group in ((*agents.values(), service), (router,)):  # the router last
            for proc in group:
                proc.send_signal(signal.SIGTERM)
            codes += [proc.wait(30) for proc in group]
    assert codes == [0, 0, 0, 0]  # each closed its session and exited
    assert "refused the commit" in agents[loser].stderr.read()
    assert journal_overlaps(tmp_path / "journal") == []


# -- stopping ---------------------------------------------------------------------------------

def test_a_request_nobody_serves_is_asked_again_only_while_its_server_may_come():
    """When a cut link comes back, zenoh may bring an agent's liveliness token before its
    queryable: the dispatcher asks again while the token is here (`retry_while`), and gives
    up at once on an agent whose token is gone."""
    with open_session(BusConfig("peer", (), ())) as session:
        requester = Requester(session, "test", timeout_s=5.0, retry_s=10.0)
        key = f"t{os.getpid()}/vehicle/1/task"
        served = []

        def answer(query):
            query.reply(query.key_expr, encode(Reply(asked.request_id, True, 0), "agent-1", 1, 0))

        def token_here() -> bool:  # the queryable comes after the first request found none
            if not served:
                served.append(session.declare_queryable(key, answer))
            return True

        asked = StatusRequest(requester.next_id(), 1)
        assert requester.request(key, asked, retry_while=token_here).message == \
            Reply(asked.request_id, True, 0)
        assert len(served) == 1  # the first request found nobody, the second its agent
        checked = []
        with pytest.raises(RequestFailed, match="nobody answered"):
            requester.request(f"t{os.getpid()}/vehicle/2/task", asked,
                              retry_while=lambda: bool(checked.append(1)))
        assert checked == [1]  # asked once: the token is gone
    # An agent that does not answer in time is not asked again: its timeout outlasts the retry
    assert min(TASK_TIMEOUT_S, REQUEST_TIMEOUT_S) > UNSERVED_RETRY_S


def children_of(pid: int) -> list[int]:
    """Processes started by `fleet run` with this pid (they carry it in their environment)."""
    marker = f"{PARENT_ENV}={pid}".encode()
    found = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                if marker in (entry / "environ").read_bytes().split(b"\0"):
                    found.append(int(entry.name))
            except OSError:
                continue  # gone meanwhile, or not ours to read
    return found


def started_run(tmp_path) -> tuple[subprocess.Popen, list[int]]:
    """`fleet run` on the paper warehouse as a user starts it, once its mission is under way
    (its first progress message), with the pids of the processes it started."""
    port = free_port()
    run = fleet_process(["run", "--port", str(port), "--out", str(tmp_path)],
                        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    session = open_session(BusConfig("client", (f"tcp/127.0.0.1:{port}",),
                                     connect_timeout_ms=60_000))
    try:
        progress = session.declare_subscriber(Keys("default").dispatch_progress)
        progress.recv()  # blocks until the first subtask is done
    finally:
        session.close()
    return run, children_of(run.pid)


def exited(pid: int, timeout: float) -> bool:
    """Wait for a process that is not our child to end (a pidfd becomes readable)."""
    try:
        fd = os.pidfd_open(pid)
    except ProcessLookupError:
        return True
    try:
        return bool(select.select([fd], [], [], timeout)[0])
    finally:
        os.close(fd)


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_fleet_run_stopped_by_a_signal_stops_every_process_and_leaves_its_recording(tmp_path,
                                                                                    sig):
    """Ctrl-C (SIGINT) or SIGTERM: every child stops, the dispatcher first, so the recording
    is closed whole and says how far the mission got."""
    run, children = started_run(tmp_path)
    assert len(children) == 8  # router, recorder, reservation, four agents, dispatcher
    run.send_signal(sig)
    assert run.wait(60) == 130
    assert "the mission did not finish: interrupted" in run.stderr.read().decode()
    assert all(exited(pid, 0) for pid in children)
    recording = read_recording(tmp_path)
    assert recording.complete  # the recorder closed its file: summary and footer written
    report = analyze(recording)
    assert not report.finished and report.safe and not report.work_done
    stopped = recorded_standstill(recording)
    assert stopped.cause is Cause.STOPPED and stopped.stacks_done < stopped.stacks_total
    assert [v.vehicle for v in stopped.vehicles] == [1, 2, 3, 4]
    kept = json.loads((tmp_path / "summary.json").read_text())
    assert kept["finished"] is False and kept["stopped"]["cause"] == "stopped"


def test_children_of_a_killed_fleet_run_stop_by_themselves(tmp_path):
    run, children = started_run(tmp_path)
    names = {pid: command_of(pid) for pid in children}
    run.kill()  # no chance to stop anything
    run.wait()
    assert [names[pid] for pid in children if not exited(pid, 30)] == []


def command_of(pid: int) -> str:
    """What a process runs, as `fleet agent`; "" once it has ended."""
    try:
        return " ".join(a.decode() for a in
                        Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0")[2:4])
    except OSError:
        return ""


STUCK_CHILD = """
import threading, time
from fleet.runtime.lifecycle import setup_logging, stop_on_signals, watch_parent
setup_logging()
watch_parent()
stop_on_signals(lambda: None)  # a stop that cannot cut its wait short
print("ready", flush=True)
threading.Event().wait()
"""


def test_an_orphan_that_cannot_stop_cleanly_exits_with_its_stacks_in_its_log(tmp_path):
    """Its fleet run killed, a child asks itself to stop; one stuck all the same exits
    ORPHAN_GRACE_S later and its log says where it was."""
    log = tmp_path / "child.log"
    parent = subprocess.Popen(  # stands for fleet run: starts the child, then waits
        [sys.executable, "-c", f"import os, subprocess, sys; os.environ['{PARENT_ENV}'] = "
         "str(os.getpid()); subprocess.Popen(sys.argv[1:]); sys.stdin.read()",
         sys.executable, "-c", STUCK_CHILD],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=log.open("wb"), cwd=ROOT)
    assert parent.stdout.readline() == b"ready\n"
    child, = children_of(parent.pid)
    parent.kill()
    parent.wait()
    assert exited(child, ORPHAN_GRACE_S + 10)
    said = log.read_text()
    assert f"fleet run (pid {parent.pid}) is gone" in said
    minutes, seconds = divmod(int(ORPHAN_GRACE_S), 60)
    assert f"Timeout (0:{minutes:02d}:{seconds:02d})!" in said  # faulthandler's header ...
    assert "in <module>" in said  # ... and every thread's stack


def test_the_live_view_shows_the_forklifts_of_a_running_mission(tmp_path):
    """`fleet run --foxglove`: a Foxglove WebSocket client connected mid-mission is offered
    the view channels and receives forklifts on /view/forklifts."""
    port = free_port()
    seen: dict[str, object] = {}

    def on_progress(progress):
        if seen:
            return
        with connect(f"ws://127.0.0.1:{port}", subprotocols=["foxglove.sdk.v1"],
                     open_timeout=10) as ws:
            channels = {}
            while "/view/forklifts" not in channels:
                message = json.loads(ws.recv(timeout=10))
                if message["op"] == "advertise":
                    channels.update({c["topic"]: c for c in message["channels"]})
            forklifts = channels["/view/forklifts"]
            ws.send(json.dumps({"op": "subscribe", "subscriptions": [
                {"id": 1, "channelId": forklifts["id"]}]}))
            while not isinstance(frame := ws.recv(timeout=10), bytes) or frame[0] != 1:
                pass  # until the first message data frame
            seen.update(channels=channels, data=frame[1 + 4 + 8:])

    mission = Mission("small", MissionKind.FILL, Strategy.TRAFFIC)
    outcome = run_processes(RunSpec(mission, 2, tmp_path, foxglove=port), on_progress)
    assert outcome.error == ""
    assert {"/view/warehouse", "/view/forklifts", "/view/reserved"} <= set(seen["channels"])
    assert seen["channels"]["/view/forklifts"]["schemaName"] == "foxglove.SceneUpdate"
    assert b"forklift/" in seen["data"]  # a SceneUpdate with a forklift entity
