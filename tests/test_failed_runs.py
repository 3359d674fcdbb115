"""A failed run leaves its evidence: whatever ends a mission early (stuck, a signal), its run
directory holds the recording up to then, which `fleet analyze` reads as not finished and
whose summary says how far the mission got and where each forklift stood."""

import json
import os
import re
import signal
import subprocess
import sys
import threading
from pathlib import Path

import pytest

from fleet.analysis.analyze import analyze
from fleet.cli import main
from fleet.dispatching.decision import Strategy, TaskKind
from fleet.mission.engine import Engine, EngineOptions, MissionStuck, engine_options
from fleet.mission.spec import Mission, MissionKind
from fleet.mission.standstill import Cause, Standstill, VehicleStanding
from fleet.planning.trajectory import Pose
from fleet.recording.inprocess import recorded_run, write_recording
from fleet.recording.mission_record import recorded_standstill
from fleet.recording.reader import read_recording
from fleet.wire.protocol import MissionStopped, ProtocolError, SubtaskEvent, decode, encode
from fleet.world.layout_file import load_layout

ROOT = Path(__file__).resolve().parent.parent

# Two forklifts, six stacks they can fill, and a seventh walled in: no mission finishes here
# (`fleet layout check` says so), and the engine gives up within seconds.
WALLED = """name = "walled"
description = "a stack no forklift can reach"
cell_size = 2.0
starts = ["4,6,S", "5,6,S"]

[bounds]
x = [0.0, 16.0]
y = [0.0, 16.0]

[[cluster]]
name = "a"
fill = ["0,7..0,5", "1,7..1,5"]

[[cluster]]
name = "b"
fill = ["1,1"]

[[obstacle]]
name = "wall"
kind = "wall"
cells = ["6,7..7,7", "0,0..2,0", "0,1", "2,1", "0,2..2,2"]

[[station]]
name = "p1"
cell = "4,7"
dock = "4,6,S"

[[station]]
name = "p2"
cell = "5,7"
dock = "5,6,S"
"""


@pytest.fixture
def walled(tmp_path) -> Path:
    path = tmp_path / "walled.toml"
    path.write_text(WALLED)
    return path


def test_a_stuck_engine_says_how_far_it_got_and_where_each_forklift_stands(walled):
    mission = Mission(str(walled), MissionKind.FILL, Strategy.GREEDY)
    engine = Engine(mission, EngineOptions(max_consecutive_failures=40))
    with pytest.raises(MissionStuck, match="41 decisions in a row failed by t=") as stuck:
        engine.run()
    stopped = stuck.value.standstill
    assert stopped.cause is Cause.STUCK and stopped.reason == str(stuck.value)
    assert stopped.t == engine.now and stopped.failures_in_a_row == 41
    # The last failure, a forklift's choice that ended a dispatch without a decision; the
    # count in all is that of the failures announced.
    assert re.search(r"the last: dispatch of forklift \d for t=[\d.]+ s: no target offered; "
                     r"no solid decision within iter_dispatch=10$", str(stuck.value))
    assert stopped.decision_failures == len(engine.record.failures) > 41
    assert (stopped.stacks_done, stopped.stacks_total) == (6, 7)  # b#1 is walled in
    assert [(v.vehicle, v.pose, v.t_free, v.next_task) for v in stopped.vehicles] == \
        [(s.vehicle, s.pose, s.t_free, s.next_task) for s in engine.fleet.values()]
    assert not any(v.down for v in stopped.vehicles)
    head, *forklifts = stopped.lines()
    assert head.startswith(f"stuck at t={stopped.t:.2f} s with 6 of 7 stacks done, 41 "
                           f"decisions in a row failed")
    assert [line.split(" at ")[0] for line in forklifts] == ["forklift 1", "forklift 2"]


def test_a_standstill_travels_and_reads_back_as_it_was():
    stopped = Standstill(Cause.LOST, "forklift 2 lost", 12.5, 3, 24, 0, 7, (
        VehicleStanding(1, Pose((4, 6), 3), 14.0, TaskKind.RETURN, False, ("p1", "p2"),
                        "plan for t=12.00 s: no path"),
        VehicleStanding(2, Pose((5, 6), 1), 12.5, TaskKind.DELIVER, True, (), "")))
    message = decode(encode(stopped.message(), "dispatcher", 1, 12.5)).message
    assert Standstill.of_message(message) == stopped
    with pytest.raises(ProtocolError, match=r"dispatch\.stopped: 'hung' is not a valid Cause"):
        Standstill.of_message(MissionStopped("hung", "", 0.0, 0, 1, 0, 0, []))


def test_an_inprocess_run_asked_to_stop_ends_whole_between_two_decisions(tmp_path):
    """Asked to stop after the fifth committed subtask, the run stops before the next
    decision: five subtasks recorded, every one of them driven, and the verdicts say the
    mission did not finish and was safe up to there."""
    layout = load_layout("small")
    mission = Mission("small", MissionKind.FILL, Strategy.GREEDY)
    stop = threading.Event()
    heard: list[float] = []  # the instant the mission reached at each commit

    def progress(done, total, t, failures):
        heard.append(t)
        if len(heard) == 5:
            stop.set()

    options = engine_options(mission, layout, None, progress)
    done, stream = recorded_run(mission, layout, options, stop=stop)
    assert not done.ok and done.error == "stopped by a signal before the mission ended"
    write_recording(tmp_path / "run.mcap", stream, layout)
    recording = read_recording(tmp_path / "run.mcap")
    assert len(recording.of(SubtaskEvent)) == 5
    report = analyze(recording)
    assert not report.finished and report.safe and not report.work_done
    stopped = recorded_standstill(recording)
    assert stopped.cause is Cause.STOPPED and stopped.t >= heard[-1]


def test_a_stuck_mission_leaves_its_recording_in_process_and_with_processes(walled, tmp_path,
                                                                            capsys):
    """In one process and as processes, a stuck mission's run directory holds its recording,
    and `fleet run` says how far it got and where each forklift stood; the two runs agree.
    `fleet analyze` reads the recording as a mission not finished, `fleet runs` lists it as
    stuck, and `fleet plot --at` draws the wedge."""
    stopped = {}
    for name, flags in (("inprocess", ["--inprocess"]), ("processes", [])):
        out = tmp_path / name
        assert main(["run", "--layout", str(walled), "--strategy", "greedy", "--out",
                     str(out), "--quiet", *flags]) == 1
        said = capsys.readouterr()
        assert "fleet run: the mission did not finish: 401 decisions in a row failed" in said.err
        assert re.search(r"\n  stopped +stuck at t=[\d.]+ s with 6 of 7 stacks done", said.out)
        for vehicle in (1, 2):  # where each stands, on one of the two docks
            assert re.search(rf"\n {{21}}forklift {vehicle} at [45],6,S from t=", said.out)
        assert "work               FAIL: 6 of 7 stacks" in said.out
        assert "record digest" not in said.out
        kept = json.loads((out / "summary.json").read_text())  # what fleet run judged
        assert kept["finished"] is False and kept["stopped"]["cause"] == "stuck"
        assert [v["vehicle"] for v in kept["stopped"]["vehicles"]] == [1, 2]
        stopped[name] = kept["stopped"]
        # Every failure it counted, to the last, is announced (docs/metrics.md).
        report = analyze(read_recording(out))
        assert report.messages_whole and report.decision_failures == \
            report.messages["dispatch.failure"] == kept["stopped"]["decision_failures"]
    assert stopped["processes"] == stopped["inprocess"]  # the fast clock agrees, stuck too

    out, t = tmp_path / "processes", stopped["processes"]["t"]
    assert main(["analyze", str(out), "--json"]) == 1
    report = json.loads(capsys.readouterr().out)
    assert report["complete"]  # the recorder closed its file: summary section and footer
    assert not report["finished"] and not report["work_done"] and report["safe"]
    assert report["mission_error"].startswith("401 decisions in a row failed by t=")
    assert report["stopped"] == stopped["processes"]
    assert main(["runs", str(out)]) == 0
    assert f"FAIL: work; stuck at t={t:.2f} s" in capsys.readouterr().out
    assert main(["plot", str(out), "--at", f"{t:.2f}", "--no-gif"]) == 0
    assert (out / f"snapshot_{t:08.2f}.png").exists()


def test_ctrl_c_to_an_inprocess_fleet_run_leaves_a_readable_recording(tmp_path):
    """SIGINT to `fleet run --inprocess` once its mission is under way (its first progress
    line, 5 s in): it stops before its next decision, writes what it did and says how far
    it got. The mission must outlast that line: paper's fill alone now ends in about 4 s, so
    it runs the faults of examples/kill3_cut1.toml without the lookahead, the liveness gap
    of docs/benchmarks.md, which takes minutes."""
    run = subprocess.Popen([sys.executable, "-m", "fleet", "run", "--inprocess", "--faults",
                            "examples/kill3_cut1.toml", "--lookahead", "none", "--out",
                            str(tmp_path)], cwd=ROOT, stdout=subprocess.PIPE,
                           stderr=subprocess.PIPE, env={**os.environ, "PYTHONUNBUFFERED": "1"})
    for line in run.stderr:  # plain progress lines: no terminal
        if b"stacks, t=" in line:
            break
    run.send_signal(signal.SIGINT)
    out, err = run.communicate(timeout=120)
    assert run.returncode == 130, err.decode()
    assert b"the mission did not finish: stopped by a signal" in err
    assert re.search(rb"\n  stopped +stopped at t=", out)
    recording = read_recording(tmp_path)
    report = analyze(recording)
    assert not report.finished and report.safe and 0 < report.stacks_done < 136
    assert recorded_standstill(recording).cause is Cause.STOPPED
