"""A run recorded in segments (a recorder killed and restarted: run.mcap, run-2.mcap, ...):
read as one recording, with the windows without a recorder reported as such. Messages sent
then are not recorded, not lost; a sender that starts numbering again is a new stream; a
segment torn by the kill is read up to its last complete chunk. Then the same with real
processes: a recorder SIGKILLed mid-stream and a second one started on run-2.mcap, both
segments of the run directory's run (its id, tests/test_run_dirs.py for more)."""

from __future__ import annotations

import dataclasses
import json
import os
import signal
import subprocess
import sys
import threading
from pathlib import Path

import pytest
import zenoh

from fleet.analysis.analyze import analyze
from fleet.analysis.streams import sequence_gaps, sequence_holes
from fleet.cli import main
from fleet.dispatching.decision import Strategy
from fleet.mission.engine import engine_options
from fleet.mission.spec import Mission, MissionKind
from fleet.recording.format import NS
from fleet.recording.inprocess import Outgoing, recorded_run
from fleet.recording.reader import read_recording, recording_file
from fleet.recording.rundir import claim
from fleet.recording.segments import RUN_FILE, next_segment, segment_paths
from fleet.recording.writer import RecordingWriter, mission_info
from fleet.runtime.bus import BusConfig, Stream, free_port, open_session
from fleet.wire.protocol import (
    MissionInfo,
    RecorderStatus,
    StackDone,
    VehicleState,
    WireChange,
    decode,
    encode,
)
from fleet.wire.topics import Keys
from fleet.world.layout_file import load_layout

LAYOUT = "small"
ROOT = Path(__file__).resolve().parent.parent
BASE_NS = 1_700_000_000 * NS  # the first message's receive time
STEP_NS = 1_000_000  # one message a millisecond: message k is received at BASE + k ms


@pytest.fixture(scope="module")
def clean_stream() -> list[Outgoing]:
    """What a fault-free fill of the small layout puts on the wire (3040 messages)."""
    mission = Mission(LAYOUT, MissionKind.FILL, Strategy.GREEDY)
    layout = load_layout(LAYOUT)
    return recorded_run(mission, layout, engine_options(mission, layout, None))[1]


Item = tuple[Outgoing, int, int]  # the message, its sequence number, its receive time


def numbered(stream: list[Outgoing]) -> list[Item]:
    """Each message with its stream's number (1, 2, ... per key and sender) and a receive
    time one millisecond after the one before."""
    count: dict[tuple[str, str], int] = {}
    out = []
    for k, o in enumerate(stream):
        count[o.key, o.sender] = count.get((o.key, o.sender), 0) + 1
        out.append((o, count[o.key, o.sender], BASE_NS + k * STEP_NS))
    return out


def write(path: Path, items: list[Item], describe: bool = True,
          chunk_bytes: int | None = None) -> Path:
    """A segment as a recorder writes it: the run's description (a recorder gets it from the
    dispatcher, also when it joins late), then the messages as they came."""
    writer = RecordingWriter(path, **({"chunk_bytes": chunk_bytes} if chunk_bytes else {}))
    for o, seq, log_ns in items:
        if describe and isinstance(o.message, MissionInfo):
            writer.describe(o.message)
        writer.write(o.key, encode(o.message, o.sender, seq, o.sim_time), log_ns, o.sim_time)
    writer.close()
    return path


def with_info(items: list[Item], later: list[Item]) -> list[Item]:
    """A later segment: the dispatcher's answer to the recorder's question first (seq 0, no
    stream's), as a recorder joining late records it, then what it heard."""
    info = items[0][0]
    assert isinstance(info.message, MissionInfo)
    return [(info, 0, later[0][2] - 1), *later]


def report_json(path: Path, capsys) -> tuple[int, dict]:
    status = main(["analyze", str(path), "--json"])
    return status, json.loads(capsys.readouterr().out)


NEW_KEYS = {"path", "segments", "recorder_gaps", "not_recorded", "messages_not_recorded",
            "unverified", "outside_reservation_unverified",
            "outside_reservation_unverified_first", "double_bookings_unverified",
            "double_bookings_unverified_first", "stacks_not_recorded"}


# -- naming -------------------------------------------------------------------------------

def test_segments_are_named_and_ordered_by_number(tmp_path):
    assert next_segment(tmp_path) == tmp_path / RUN_FILE
    assert next_segment(tmp_path / "not yet") == tmp_path / "not yet" / RUN_FILE
    assert segment_paths(tmp_path) == []
    for name in ("run.mcap", "run-2.mcap", "run-10.mcap", "run-9.mcap", "run-3.mcap",
                 "run-1.mcap", "run-02.mcap", "run-x.mcap", "other.mcap", "run-4.mcap.tmp"):
        (tmp_path / name).write_bytes(b"")
    expected = [tmp_path / n for n in ("run.mcap", "run-2.mcap", "run-3.mcap", "run-9.mcap",
                                       "run-10.mcap")]
    assert segment_paths(tmp_path) == expected
    assert segment_paths(tmp_path / RUN_FILE) == expected
    assert segment_paths(tmp_path / "other.mcap") == [tmp_path / "other.mcap"]  # on its own
    assert segment_paths(tmp_path / "run-2.mcap") == [tmp_path / "run-2.mcap"]
    assert next_segment(tmp_path) == tmp_path / "run-11.mcap"  # after the last, not a hole
    (tmp_path / "run-10.mcap").unlink()
    (tmp_path / "run-9.mcap").unlink()
    assert next_segment(tmp_path) == tmp_path / "run-4.mcap"


# -- reading -------------------------------------------------------------------------------

def test_segments_read_as_one_recording_in_order(clean_stream, tmp_path, capsys):
    items = numbered(clean_stream)
    single = read_recording(write(tmp_path / "single.mcap", items))
    run = tmp_path / "run"
    parts = [items[:1000], items[1000:2000], items[2000:]]
    write(run / "run.mcap", parts[0])
    write(run / "run-3.mcap", parts[2])  # no description: it comes from the first
    write(run / "run-2.mcap", parts[1])
    for path in (run, run / RUN_FILE):
        recording = read_recording(path)
        assert [s.path.name for s in recording.segments] == ["run.mcap", "run-2.mcap",
                                                             "run-3.mcap"]
        assert [s.messages for s in recording.segments] == [1000, 1000, len(items) - 2000]
        assert recording.messages == single.messages  # the union, in log-time order
        assert recording.complete and recording.problem == ""
        assert recording.metadata == single.metadata
        assert recording.attachments == single.attachments
        assert recording.path == run / RUN_FILE
        gaps = recording.gaps
        assert [(g.after.name, g.before.name) for g in gaps] == [("run.mcap", "run-2.mcap"),
                                                                 ("run-2.mcap", "run-3.mcap")]
        assert [(g.start_ns, g.end_ns) for g in gaps] == [(items[999][2], items[1000][2]),
                                                          (items[1999][2], items[2000][2])]
    assert recording_file(run) == run / RUN_FILE
    # Nothing went unrecorded: the analysis is the single file's, but for the new fields.
    status, whole = report_json(tmp_path / "single.mcap", capsys)
    status_run, split = report_json(run, capsys)
    assert status == status_run == 0
    assert {k: v for k, v in split.items() if k not in NEW_KEYS} == \
        {k: v for k, v in whole.items() if k not in NEW_KEYS}
    assert split["messages_not_recorded"] == 0 and split["not_recorded"] == []
    assert split["unverified"] == [] and whole["recorder_gaps"] == []
    assert [g["after"] for g in split["recorder_gaps"]] == [str(run / "run.mcap"),
                                                            str(run / "run-2.mcap")]
    assert [Path(s["path"]).name for s in split["segments"]] == ["run.mcap", "run-2.mcap",
                                                                 "run-3.mcap"]


def test_two_recorders_at_once_record_each_message_once(clean_stream, tmp_path):
    """Segments that overlap in time (a recorder started before the other was gone): a
    message both recorded is read once."""
    items = numbered(clean_stream)
    write(tmp_path / "run.mcap", items[:1500])
    write(tmp_path / "run-2.mcap", [(o, s, t + 17) for o, s, t in items[1200:]])  # own clock
    recording = read_recording(tmp_path)
    assert len(recording.messages) == len(items)
    assert [s.duplicates for s in recording.segments] == [0, 300]
    assert recording.gaps == []
    assert sequence_gaps(recording) == []


def test_a_torn_segment_is_read_to_its_last_chunk(clean_stream, tmp_path, capsys):
    """The killed recorder's file has no footer and ends inside a record: its complete
    chunks count, and what was lost with the tear was not recorded, not lost."""
    items = numbered(clean_stream)
    first = write(tmp_path / "run.mcap", items[:1500], chunk_bytes=4096)
    data = first.read_bytes()
    first.write_bytes(data[: len(data) * 2 // 3])
    write(tmp_path / "run-2.mcap", with_info(items, items[1500:]))
    recording = read_recording(tmp_path)
    torn, second = recording.segments
    assert not torn.complete and "torn record" in torn.problem
    assert 0 < torn.messages < 1500 and second.complete
    assert not recording.complete
    assert recording.problem == f"run.mcap: {torn.problem}"
    kept = {(r.key, r.envelope.seq) for r in recording.messages if r.envelope.seq}
    assert kept == {(o.key, s) for o, s, _ in items[:torn.messages] + items[1500:]}
    report = analyze(recording)
    assert report.messages_lost == 0
    assert report.messages_not_recorded > 0 and report.passed, report.lines()
    status, out = report_json(tmp_path, capsys)
    assert status == 0 and not out["complete"] and "run.mcap: " in out["problem"]
    main(["analyze", str(tmp_path)])
    text = capsys.readouterr().out
    assert "truncated: run.mcap: the file ends in a torn record" in text
    assert "no recorder" in text and "not recorded" in text


def test_an_empty_segment_is_skipped_with_a_note(clean_stream, tmp_path):
    """A recorder killed before its first flush leaves an empty file."""
    items = numbered(clean_stream)
    write(tmp_path / "run.mcap", items[:1000])
    (tmp_path / "run-2.mcap").write_bytes(b"")
    write(tmp_path / "run-3.mcap", with_info(items, items[1000:]))
    recording = read_recording(tmp_path)
    assert len(recording.messages) == len(items) + 1  # and the answer to run-3's question
    assert "run-2.mcap: not read" in recording.problem and not recording.complete
    assert [g.before.name for g in recording.gaps] == ["run-3.mcap"]


# -- what was sent while no recorder ran -----------------------------------------------------

def split_around(items: list[Item], start: int, end: int) -> tuple[list[Item], list[Item]]:
    """The messages before `start` and from `end` on (those between were sent unheard)."""
    return items[:start], with_info(items, items[end:])


def test_a_window_without_a_recorder_is_not_recorded_rather_than_lost(clean_stream, tmp_path,
                                                                      capsys):
    items = numbered(clean_stream)
    start, end = 1000, 1200  # 200 messages sent while no recorder ran
    before, after = split_around(items, start, end)
    run = tmp_path / "run"
    write(run / "run.mcap", before)
    write(run / "run-2.mcap", after)
    # The same messages unheard by a recorder that was running: lost in transit.
    write(tmp_path / "lost.mcap", before + after)
    lost = analyze(read_recording(tmp_path / "lost.mcap"))
    report = analyze(read_recording(run))
    assert lost.messages_lost > 0 and not lost.passed  # the messages verdict fails
    assert report.messages_lost == 0 and report.gaps == []
    assert report.messages_not_recorded == lost.messages_lost
    assert {(n.key, n.missing) for n in report.not_recorded} == \
        {(g.key, g.missing) for g in lost.gaps}
    (down,) = report.recorder_gaps
    assert (down.wall_from_s, down.wall_to_s) == (items[start - 1][2] / NS,
                                                  items[end][2] / NS)
    assert Path(down.after).name == "run.mcap" and Path(down.before).name == "run-2.mcap"
    states = [o for o, _, _ in items[start:end] if isinstance(o.message, VehicleState)]
    assert down.sim_from_s <= states[0].sim_time and down.sim_to_s >= states[-1].sim_time
    assert all((n.wall_from_s, n.wall_to_s) == (down.wall_from_s, down.wall_to_s)
               for n in report.not_recorded)
    # Safety: nothing seen is unsafe; what was not seen is listed, per forklift.
    assert report.safe and report.overlaps == [] and report.outside_reservation == []
    windows = {(u.check, u.vehicle) for u in report.unverified}
    assert {("states", 1), ("states", 2)} <= windows
    for u in report.unverified:
        if u.check == "states":  # strictly around the forklift's own unheard instants
            own = [o.sim_time for o in states if o.message.vehicle == u.vehicle]
            assert u.sim_from_s < own[0] and own[-1] < u.sim_to_s
    # Table changes sent then: each forklift's reservations are unknown until it commits anew.
    if any(isinstance(o.message, WireChange) for o, _, _ in items[start:end]):
        assert {("reservations", 1), ("reservations", 2)} <= windows
    # Work: stacks announced then are known from the dispatcher's final record.
    unheard = sorted(f"{o.message.cluster}#{o.message.index}" for o, _, _ in items[start:end]
                     if isinstance(o.message, StackDone))
    assert unheard and report.stacks_not_recorded == unheard
    assert report.stacks_lost == [] and report.work_done and report.passed, report.lines()
    # Lost in transit, they are lost, as are stacks served while the states went unheard
    # (announced at commit, before the window: nothing shows they were served).
    assert set(unheard) <= set(lost.stacks_lost)
    status, out = report_json(run, capsys)
    assert status == 0 and out["messages_not_recorded"] == lost.messages_lost
    assert out["not_recorded"][0]["wall_from_s"] == down.wall_from_s
    assert out["unverified"] and out["recorder_gaps"][0]["sim_from_s"] == down.sim_from_s
    main(["analyze", str(run)])
    text = capsys.readouterr().out
    assert f"0 lost, {lost.messages_lost} not recorded (no recorder running)" in text
    assert "not verified       forklift 1 states from sim time" in text


def test_a_loss_in_transit_still_fails_next_to_a_recorder_gap(clean_stream, tmp_path):
    items = numbered(clean_stream)
    before, after = split_around(items, 1000, 1200)
    k = next(k for k, (o, _, _) in enumerate(after) if k > 100
             and isinstance(o.message, VehicleState) and o.message.vehicle == 2)
    gone = after.pop(k)  # sent while the second recorder ran, never heard
    write(tmp_path / "run.mcap", before)
    write(tmp_path / "run-2.mcap", after)
    report = analyze(read_recording(tmp_path))
    assert report.messages_lost == 1 and not report.passed
    (gap,) = report.gaps
    assert (gap.key, gap.first_missing) == (gone[0].key, gone[1])
    assert report.messages_not_recorded > 0  # the window is still told apart
    assert report.verdict_lines()[2].startswith("messages           FAIL: ")


def renumber(items: list[Item], key: str, start: int) -> list[Item]:
    """The key's messages numbered again from `start`: a sender restarted."""
    out, seq = [], start
    for o, s, t in items:
        if o.key == key:
            s, seq = seq, seq + 1
        out.append((o, s, t))
    return out


def test_a_restarted_sender_is_a_new_stream(clean_stream, tmp_path):
    items = numbered(clean_stream)
    key = Keys().vehicle_state(2)
    restarted = items[:1500] + renumber(items[1500:], key, 1)
    write(tmp_path / "one.mcap", restarted)
    recording = read_recording(tmp_path / "one.mcap")
    assert sequence_gaps(recording) == []  # neither a gap nor hidden among old numbers
    report = analyze(recording)
    assert report.messages_lost == 0 and report.passed
    # Its first three messages lost in transit: a new stream missing 1..3.
    lost = [(o, s, t) for o, s, t in renumber(items[1500:], key, 1)
            if not (o.key == key and s <= 3)]
    write(tmp_path / "two.mcap", items[:1500] + lost)
    (gap,) = sequence_gaps(read_recording(tmp_path / "two.mcap"))
    assert (gap.key, gap.missing, gap.first_missing) == (key, 3, 1)
    # Restarted while no recorder ran, its first messages sent then: not recorded.
    before, after = split_around(restarted, 1000, 1600)
    write(tmp_path / "run" / "run.mcap", before)
    write(tmp_path / "run" / "run-2.mcap", after)
    recording = read_recording(tmp_path / "run")
    assert sequence_gaps(recording) == []
    (hole,) = [h for h in sequence_holes(recording) if h.key == key]  # the old tail: unseen
    assert hole.window and hole.first == 1 and hole.missing == sum(
        1 for o, _, _ in restarted[1500:1600] if o.key == key)


def test_plot_and_compare_read_every_segment(clean_stream, tmp_path, capsys):
    items = numbered(clean_stream)
    before, after = split_around(items, 1000, 1200)
    write(tmp_path / "a" / "run.mcap", items)
    write(tmp_path / "b" / "run.mcap", before)
    write(tmp_path / "b" / "run-2.mcap", after)
    assert main(["compare", str(tmp_path / "a"), str(tmp_path / "b"), "--json"]) == 0
    both = json.loads(capsys.readouterr().out)
    assert both["a"]["segments"] == 1 and both["b"]["segments"] == 2
    assert both["b"]["messages_not_recorded"] > 0 and both["b"]["messages_lost"] == 0
    assert main(["plot", str(tmp_path / "b"), "--no-gif", "--at", "100"]) == 0
    captured = capsys.readouterr()
    assert "no recorder ran for 0.2 s between run.mcap and run-2.mcap" in captured.err
    assert (tmp_path / "b" / "gantt.png").exists()


# -- real processes ----------------------------------------------------------------------

def fleet_process(args: list[str], log: Path) -> subprocess.Popen:
    with open(log, "ab") as stderr:  # the child keeps its copy
        return subprocess.Popen([sys.executable, "-m", "fleet", *args], cwd=ROOT,
                                stderr=stderr, env={**os.environ, "PYTHONUNBUFFERED": "1"})


class Watch:
    """The recorders' liveliness token and status messages, as events to wait on."""

    def __init__(self, session: zenoh.Session, keys: Keys) -> None:
        self.cond = threading.Condition()
        self.alive = 0  # tokens seen appearing minus disappearing
        self.statuses: list[tuple[int, RecorderStatus]] = []  # (seq, status)
        self.token = session.liveliness().declare_subscriber(keys.recorder_alive,
                                                             self._on_token, history=True)
        self.status = session.declare_subscriber(keys.recorder_status, self._on_status)

    def _on_token(self, sample: zenoh.Sample) -> None:
        with self.cond:
            self.alive += 1 if sample.kind == zenoh.SampleKind.PUT else -1
            self.cond.notify_all()

    def _on_status(self, sample: zenoh.Sample) -> None:
        envelope = decode(sample.payload.to_bytes())
        with self.cond:
            self.statuses.append((envelope.seq, envelope.message))
            self.cond.notify_all()

    def wait(self, predicate, what: str) -> None:
        with self.cond:
            assert self.cond.wait_for(predicate, timeout=60), f"timed out waiting: {what}"

    def flushed(self, path: Path, count: int, seq: int = 1) -> None:
        """Until the recorder writing `path` says, in its status number k >= `seq`, that it
        holds count + k messages, all flushed before it said so. Status k counts at most
        k - 1 of its own and one answer of the dispatcher: so the file holds our `count`
        messages, and with k >= 2 (count + k = ours + answer + 1) its first status too."""
        self.wait(lambda: any(st.path == str(path) and k >= seq and st.messages >= count + k
                              for k, st in self.statuses), f"{count} messages in {path}")


def test_a_recorder_killed_and_restarted_writes_a_second_segment(tmp_path):
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    keys = Keys(f"seg{os.getpid()}")
    log = tmp_path / "processes.log"
    common = ["--run", keys.run, "--connect", endpoint]
    run = claim(tmp_path / "run")  # as fleet run claims it: its marker holds the run id
    run_dir = run.path
    router = fleet_process(["router", "--listen", endpoint], log)
    recorders: list[subprocess.Popen] = []
    session = open_session(BusConfig("client", (endpoint,), connect_timeout_ms=30_000))
    try:
        layout = load_layout(LAYOUT)
        info = mission_info(Mission(LAYOUT, MissionKind.FILL, Strategy.GREEDY), layout, 2,
                            "fast", command="test")
        # The dispatcher's answer to a recorder that joins late (what it asks on start).
        answer = session.declare_queryable(keys.dispatch_mission, lambda q: q.reply(
            q.key_expr, encode(info, "dispatcher", 0, 0.0)))
        watch = Watch(session, keys)
        states = Stream(session, keys.vehicle_state(1), "vehicle-1", reliable=True)
        sent = 0

        def publish(n: int) -> list[int]:
            nonlocal sent
            for _ in range(n):
                sent += 1
                states.put(VehicleState(1, "2,2,E", 0, "", False, 1.0, 1.0, 0.0), sent * 0.5)
            return list(range(sent - n + 1, sent + 1))

        def start_recorder() -> Path:
            out = next_segment(run_dir)
            alive = watch.alive
            recorders.append(fleet_process(["recorder", *common, "--out", str(out)], log))
            watch.wait(lambda: watch.alive > alive, f"the recorder writing {out}")
            return out

        first = start_recorder()
        assert first == run_dir / RUN_FILE
        heard = publish(40)
        watch.flushed(first, len(heard), seq=2)  # and so its own first status
        recorders[0].kill()  # SIGKILL: no chance to close the file
        assert recorders[0].wait(30) == -signal.SIGKILL
        watch.wait(lambda: watch.alive == 0, "the killed recorder's token to go")
        unheard = publish(25)  # no recorder running
        second = start_recorder()
        assert second == run_dir / "run-2.mcap"
        more = publish(30)
        watch.flushed(second, len(more), seq=2)
        recorders[1].send_signal(signal.SIGTERM)
        assert recorders[1].wait(30) == 0
        answer.undeclare()
    finally:
        session.close()
        for proc in (*recorders, router):
            if proc.poll() is None:
                proc.send_signal(signal.SIGTERM)
                proc.wait(30)
    assert segment_paths(run_dir) == [first, second]
    recording = read_recording(run_dir)
    ours = [r.envelope.seq for r in recording.messages if r.key == keys.vehicle_state(1)]
    assert set(heard) <= set(ours) and set(more) <= set(ours)
    assert not set(unheard) & set(ours)
    assert [s.complete for s in recording.segments] == [False, True]
    # The late recorder asked what the run is: its own segment describes it too; both are
    # of the directory's run.
    assert recording.run_id == run.run_id
    for path in (first, second):
        alone = read_recording(path)
        assert alone.run_id == run.run_id
        assert alone.metadata["run"]["layout"] == LAYOUT
        assert alone.attachments["layout.toml"].decode() == info.layout_toml
    assert recording.info == info
    report = analyze(recording)
    assert report.messages_lost == 0  # and each recorder's status stream counted on its own
    (missing,) = report.not_recorded
    assert (missing.key, missing.first_missing, missing.missing) == \
        (keys.vehicle_state(1), unheard[0], len(unheard))
    assert [(u.check, u.vehicle, u.sim_from_s, u.sim_to_s) for u in report.unverified] == \
        [("states", 1, heard[-1] * 0.5, more[0] * 0.5)]
    statuses = [r.envelope.seq for r in recording.messages if r.key == keys.recorder_status]
    assert statuses.count(1) == 2  # two recorders, each numbering from 1
    assert dataclasses.asdict(report)["recorder_gaps"][0]["after"] == str(first)
