"""A run directory belongs to one run (fleet/recording/rundir.py, docs/runtime.md):
`fleet run --out`
never removes a file it did not write in the same run, `--force` replaces only an earlier
run's directory, whole; default names never collide; every segment carries the run's id and
a segment of another run is refused by name (run, analyze, plot, compare); a recorder
restarted by a fault writes segments of the same run; `fleet runs` lists runs with their
verdicts; `fleet compose collect` never writes over another run's copy."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

from fleet.analysis.analyze import analyze
from fleet.cli import main
from fleet.commands.compose import place_copy
from fleet.commands.runs import SUMMARY, write_summary
from fleet.dispatching.decision import Strategy
from fleet.errors import UserError
from fleet.mission.engine import engine_options
from fleet.mission.spec import Mission, MissionKind
from fleet.recording.inprocess import Outgoing, recorded_run, write_recording
from fleet.recording.reader import read_description, read_recording
from fleet.recording.rundir import MARKER, claim, claim_new, default_name, run_id_of
from fleet.recording.segments import RUN_FILE, segment_paths
from fleet.recording.writer import RecordingWriter, mission_info
from fleet.runtime.local_run import RunSpec, run_processes
from fleet.wire.protocol import MissionInfo, VehicleState, encode
from fleet.world.layout_file import load_layout
from recorder.process import output_in

ROOT = Path(__file__).resolve().parent.parent
SMALL = ["--inprocess", "--layout", "small", "--strategy", "greedy"]  # about 2 s


def files(folder: Path) -> dict[str, bytes]:
    """Every file under `folder` (relative path -> content)."""
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*"))
            if p.is_file()}


def fleet(args: list[str], capsys) -> tuple[int, str, str]:
    code = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture(scope="module")
def small_run(tmp_path_factory) -> Path:
    """A judged in-process run of the small layout, claimed as `fleet run` claims it."""
    out = tmp_path_factory.mktemp("small") / "run"
    assert main(["run", *SMALL, "--out", str(out)]) == 0
    return out


def described_segment(path: Path, layout: str) -> Path:
    """A short segment as a recorder writes it for a mission on `layout`: its description,
    then the dispatcher's announcement of the mission."""
    info = mission_info(Mission(layout, MissionKind.FILL, Strategy.GREEDY), load_layout(layout),
                        len(load_layout(layout).vehicle_starts), "fast", command="test")
    writer = RecordingWriter(path)
    writer.describe(info)
    writer.write("fleet/default/dispatch/mission", encode(info, "dispatcher", 1, 0.0),
                 time.time_ns(), 0.0)
    writer.close()
    return path


def write_numbered(path: Path, stream: list[Outgoing], skip: int) -> None:
    """The stream as a recorder would have heard it, but for message `skip`, lost on the
    way (its sender numbered it: the recording shows the gap)."""
    writer = RecordingWriter(path)
    count: dict[tuple[str, str], int] = {}
    for k, o in enumerate(stream):
        count[o.key, o.sender] = count.get((o.key, o.sender), 0) + 1
        if isinstance(o.message, MissionInfo):
            writer.describe(o.message)
        if k != skip:
            writer.write(o.key, encode(o.message, o.sender, count[o.key, o.sender], o.sim_time),
                         1_700_000_000_000_000_000 + k * 1_000_000, o.sim_time)
    writer.close()


# -- --out and --force ---------------------------------------------------------------------

def test_out_never_touches_a_folder_that_is_not_a_run_directory(small_run, tmp_path, capsys):
    mine = tmp_path / "mine"
    (mine / "sub").mkdir(parents=True)
    (mine / "notes.txt").write_text("my notes")
    (mine / "sub" / "keep.txt").write_text("keep")
    shutil.copy(small_run / RUN_FILE, mine / RUN_FILE)  # recordings of the user's own
    shutil.copy(small_run / RUN_FILE, mine / "run-2.mcap")
    (mine / "run-7.mcap").write_bytes(b"named so by the user")
    before = files(mine)
    code, _, err = fleet(["run", *SMALL, "--out", mine], capsys)
    assert code == 2 and f"{mine} is not empty" in err and "--force" in err
    assert "notes.txt" in err and len(err.strip().splitlines()) == 1
    code, _, err = fleet(["run", *SMALL, "--out", mine, "--force"], capsys)
    assert code == 2 and f"{mine} is not a run directory (no {MARKER}" in err
    assert files(mine) == before  # nothing removed, nothing written, not even a marker
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mine"]  # nothing left beside it
    # A run of processes (fleet run without --inprocess, the benchmarks, the tests) is held
    # to the same: a new directory, or one claimed for it and still empty.
    mission = Mission("small", MissionKind.FILL, Strategy.GREEDY)
    with pytest.raises(UserError, match=f"{mine} is not empty"):
        run_processes(RunSpec(mission, 2, mine))
    finished = claim(tmp_path / "finished").path
    shutil.copy(small_run / RUN_FILE, finished / RUN_FILE)
    with pytest.raises(UserError, match=f"{finished} is not empty"):
        run_processes(RunSpec(mission, 2, finished))
    assert files(mine) == before and sorted(files(finished)) == [MARKER, RUN_FILE]


def test_force_never_replaces_home_or_the_current_directory(tmp_path, monkeypatch, capsys):
    run = claim(tmp_path / "run").path  # a run directory, yet where the user is
    (run / "sub").mkdir()
    (run / "notes.txt").write_text("mine")
    before = files(run)
    monkeypatch.chdir(run)
    code, _, err = fleet(["run", *SMALL, "--out", ".", "--force"], capsys)
    assert code == 2 and "is the current directory: --force never replaces it" in err
    monkeypatch.chdir(run / "sub")
    code, _, err = fleet(["run", *SMALL, "--out", run, "--force"], capsys)
    assert code == 2 and "is a parent of the current directory" in err
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("HOME", str(run))
    code, _, err = fleet(["run", *SMALL, "--out", run, "--force"], capsys)
    assert code == 2 and "is your home directory" in err
    assert files(run) == before


def test_force_replaces_an_earlier_run_directory_whole(tmp_path, capsys):
    out = tmp_path / "run"
    code, _, _ = fleet(["run", *SMALL, "--out", out], capsys)
    assert code == 0
    old_id = run_id_of(out)
    (out / "gantt.png").write_bytes(b"an old plot")  # what the old run left beside it
    (out / "logs").mkdir()
    (out / "logs" / "dispatcher.log").write_text("an old log")
    before = files(out)
    code, _, err = fleet(["run", *SMALL, "--out", out], capsys)
    assert code == 2 and f"{out} is not empty" in err and files(out) == before
    code, _, err = fleet(["run", *SMALL, "--out", out, "--force"], capsys)
    assert code == 0
    assert f"--force: replaced the run directory {out}: removed run {old_id} (" in err
    assert "gantt.png" in err and "logs/" in err
    assert sorted(files(out)) == [MARKER, RUN_FILE, SUMMARY]  # the new run's, nothing else
    new_id = run_id_of(out)
    assert new_id != old_id and read_recording(out).run_id == new_id
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]  # the old one gone whole


def test_default_names_of_runs_started_in_the_same_second_differ(tmp_path):
    now = time.strptime("20261201-101500", "%Y%m%d-%H%M%S")
    name = default_name("small", "greedy", now)
    assert name == default_name("small", "greedy", now) == "20261201-101500-small-greedy"
    (tmp_path / f"{name}-3").write_text("a file of that name")  # taken too, by a file
    runs = [claim_new(tmp_path, name) for _ in range(3)]
    assert [r.path.name for r in runs] == [name, f"{name}-2", f"{name}-4"]
    assert len({r.run_id for r in runs}) == 3
    assert [run_id_of(r.path) for r in runs] == [r.run_id for r in runs]
    assert (tmp_path / f"{name}-3").read_text() == "a file of that name"


# -- run identity --------------------------------------------------------------------------

def test_every_segment_carries_the_run_id_of_its_directory(small_run, tmp_path):
    assert read_description(small_run / RUN_FILE)["segment"] == {"run_id": run_id_of(small_run)}
    assert read_recording(small_run).run_id == run_id_of(small_run)
    lone = described_segment(tmp_path / "lone.mcap", "small")  # outside a run directory
    assert read_recording(lone).run_id is None and "segment" not in read_description(lone)


def test_a_segment_of_another_run_is_refused_by_name(small_run, tmp_path, capsys):
    """The issue's crash: a segment of a run on another layout beside a run's recording made
    analyze, plot and compare (and run's verdicts) fail with a KeyError."""
    paper = claim(tmp_path / "paper")
    described_segment(paper.path / RUN_FILE, "paper")
    foreign = paper.path / "run-2.mcap"
    shutil.copy(small_run / RUN_FILE, foreign)
    before = files(paper.path)
    small_id = run_id_of(small_run)
    for command in (["analyze", paper.path], ["plot", paper.path, "--no-gif"],
                    ["compare", paper.path, small_run]):
        code, _, err = fleet(command, capsys)
        assert code == 2, command
        assert f"{foreign}: a recording of another run (run id {small_id}; this " \
            f"directory's run is {paper.run_id}, from {MARKER})" in err, command
        assert "Traceback" not in err and len(err.strip().splitlines()) == 1
    code, _, err = fleet(["run", *SMALL, "--out", paper.path], capsys)
    assert code == 2 and f"{paper.path} is not empty" in err
    assert files(paper.path) == before  # refused, not dropped: the user still has it
    # The other way round, and a run.mcap that is not the directory's own.
    mixed = tmp_path / "small"
    shutil.copytree(small_run, mixed)
    shutil.copy(paper.path / RUN_FILE, mixed / "run-2.mcap")
    with pytest.raises(ValueError, match=rf"{mixed / 'run-2.mcap'}: a recording of another "
                                         rf"run \(run id {paper.run_id}; .* is {small_id}"):
        read_recording(mixed)
    (mixed / "run-2.mcap").unlink()
    shutil.copy(paper.path / RUN_FILE, mixed / RUN_FILE)
    with pytest.raises(ValueError, match=rf"{mixed / RUN_FILE}: a recording of another run"):
        read_recording(mixed)
    assert analyze(read_recording(small_run)).passed  # the run itself reads as it did


def test_recordings_without_a_run_id_read_as_before_unless_of_another_mission(tmp_path):
    old = tmp_path / "old"
    old.mkdir()  # a run directory from before markers: no ids anywhere
    described_segment(old / RUN_FILE, "small")
    described_segment(old / "run-2.mcap", "small")
    recording = read_recording(old)
    assert [s.path.name for s in recording.segments] == [RUN_FILE, "run-2.mcap"]
    assert recording.run_id is None
    described_segment(old / "run-3.mcap", "paper")
    with pytest.raises(ValueError, match=rf"{old / 'run-3.mcap'}: a recording of another run "
                                         rf"than run.mcap \(layout 'paper', not 'small'"):
        read_recording(old)
    (old / "run-3.mcap").unlink()
    marked = claim(tmp_path / "new")  # a segment with an id beside one without
    described_segment(marked.path / "x.mcap", "small")
    shutil.move(marked.path / "x.mcap", old / "run-3.mcap")
    with pytest.raises(ValueError, match=rf"run-3.mcap: a recording of another run \(run id "
                                         rf"{marked.run_id}; this directory's run is without "
                                         rf"one, from run.mcap\)"):
        read_recording(old)


def test_a_recorder_restarted_by_a_fault_writes_segments_of_the_same_run(tmp_path):
    out = tmp_path / "run"
    done = subprocess.run([sys.executable, "-m", "fleet", "run", "--layout", "small",
                           "--strategy", "greedy", "--faults", "kill_recorder", "--out",
                           str(out)], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stdout + done.stderr
    run_id = run_id_of(out)
    segments = segment_paths(out)
    assert [p.name for p in segments] == [RUN_FILE, "run-2.mcap"]
    assert [read_description(p)["segment"]["run_id"] for p in segments] == [run_id] * 2
    recording = read_recording(out)
    assert recording.run_id == run_id and len(recording.segments) == 2
    assert len(recording.gaps) == 1 and analyze(recording).passed
    summary = json.loads((out / SUMMARY).read_text())
    assert summary["run_id"] == run_id and summary["passed"]
    assert summary["segments"] == {p.name: p.stat().st_size for p in segments}


# -- fleet runs ----------------------------------------------------------------------------

def test_fleet_runs_lists_runs_with_their_verdicts(small_run, tmp_path, capsys):
    runs = tmp_path / "runs"
    judged = runs / "judged"
    shutil.copytree(small_run, judged)
    # A run whose recording lost a message on the way: fleet run would have judged it FAIL.
    mission = Mission("small", MissionKind.FILL, Strategy.GREEDY)
    layout = load_layout("small")
    stream = recorded_run(mission, layout, engine_options(mission, layout, None))[1]
    lost = next(k for k, o in enumerate(stream) if k > 100 and isinstance(o.message,
                                                                           VehicleState))
    failed = claim(runs / "failed").path
    write_numbered(failed / RUN_FILE, stream, skip=lost)
    write_summary(failed, analyze(read_recording(failed)))
    unjudged = claim(runs / "unjudged").path
    write_recording(unjudged / RUN_FILE, stream, layout)
    broken = runs / "broken"
    broken.mkdir()
    (broken / RUN_FILE).write_bytes(b"not a recording")
    os.utime(broken / RUN_FILE, (1_600_000_000, 1_600_000_000))  # an old run, from 2020
    (runs / "not-a-run").mkdir()  # no marker, no recording: not listed

    assert main(["runs", str(runs), "--json"]) == 0
    rows = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    by_dir = {Path(r["directory"]).name: r for r in rows}
    assert rows[0]["directory"] == str(broken)  # oldest first
    assert sorted(by_dir) == ["broken", "failed", "judged", "unjudged"]
    assert by_dir["judged"]["verdict"] == "pass" and by_dir["judged"]["end_time_s"] > 0
    assert by_dir["judged"]["run_id"] == run_id_of(judged)
    assert {k: by_dir["judged"][k] for k in ("layout", "mission", "strategy", "clock",
                                             "vehicles")} == \
        {"layout": "small", "mission": "fill", "strategy": "greedy", "clock": "inprocess",
         "vehicles": 2}
    assert by_dir["failed"]["verdict"] == "FAIL"
    assert by_dir["failed"]["verdicts"] == {"safety": True, "work": True, "messages": False}
    assert by_dir["unjudged"]["verdict"] == "not analysed"
    assert by_dir["unjudged"]["layout"] == "small" and by_dir["unjudged"]["vehicles"] == 2
    assert by_dir["unjudged"]["end_time_s"] is None
    assert by_dir["broken"]["verdict"] == "unreadable"
    assert "not an MCAP recording" in by_dir["broken"]["problem"]

    assert main(["runs", str(runs)]) == 0
    table = capsys.readouterr().out.splitlines()
    assert table[0].split() == ["directory", "layout", "mission", "strategy", "clock",
                                "vehicles", "end", "time", "verdicts"]
    line = next(row for row in table if row.startswith(str(judged)))
    assert line.split()[1:6] == ["small", "fill", "greedy", "inprocess", "2"]
    assert line.endswith("  pass")
    assert next(row for row in table if row.startswith(str(failed))).endswith("FAIL: messages")

    # A summary vouches only for the segments it judged: a file added since voids it.
    shutil.copy(failed / RUN_FILE, judged / "run-2.mcap")
    assert main(["runs", str(judged), "--json"]) == 0
    (row,) = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert row["verdict"] == "not analysed" and "changed since it was judged" in row["problem"]


def test_fleet_runs_says_when_there_is_nothing_to_list(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert main(["runs"]) == 0
    assert "no runs yet" in capsys.readouterr().err
    assert main(["runs", str(tmp_path / "nowhere")]) == 2
    assert f"{tmp_path / 'nowhere'}: no such directory" in capsys.readouterr().err


# -- recorders of the compose deployment, and collecting their recordings -------------------

def test_a_restarted_compose_recorder_writes_the_next_segment_of_its_run(tmp_path):
    now = time.strptime("20261201-101500", "%Y%m%d-%H%M%S")
    first = output_in(tmp_path, "c0ffee", now)
    described_segment(first, "small")
    again = output_in(tmp_path, "c0ffee", now)  # the container restarted
    assert again == first.parent / "run-2.mcap"
    described_segment(again, "small")
    other = output_in(tmp_path, "beef", now)  # another container, the same second
    assert other.parent != first.parent and other.name == RUN_FILE
    run_id = run_id_of(first.parent)
    assert run_id and run_id_of(other.parent) != run_id
    recording = read_recording(first.parent)
    assert recording.run_id == run_id and len(recording.segments) == 2
    shutil.rmtree(other.parent)
    taken = claim_new(tmp_path, "20261201-101500-beef").path  # its name taken: -2
    assert output_in(tmp_path, "beef", now).parent == taken
    assert output_in(tmp_path, "beef", now) == taken / RUN_FILE


def test_collect_updates_its_own_copy_and_never_writes_over_another_run(tmp_path):
    volume = claim(tmp_path / "volume" / "20261201-101500-c0ffee").path
    described_segment(volume / RUN_FILE, "small")
    dest = tmp_path / "dest"
    dest.mkdir()

    def copied() -> Path:  # what tar extracts of the volume's directory
        staging = tmp_path / "staging"
        shutil.rmtree(staging, ignore_errors=True)
        return Path(shutil.copytree(volume, staging / volume.name))

    target = dest / volume.name
    assert place_copy(copied(), target) == target and files(target) == files(volume)
    (target / "gantt.png").write_bytes(b"a plot of it")  # fleet plot writes beside it
    described_segment(volume / "run-2.mcap", "small")  # the run went on: a new segment
    place_copy(copied(), target)
    assert files(target) == {**files(volume), "gantt.png": b"a plot of it"}
    other = claim(tmp_path / "elsewhere" / volume.name).path  # another run, the same name
    described_segment(other / RUN_FILE, "small")
    before = files(target)
    staged = Path(shutil.copytree(other, tmp_path / "staging2" / volume.name))
    with pytest.raises(UserError, match=rf"{target} exists and holds run {run_id_of(volume)}, "
                                        rf"not the volume's {run_id_of(other)}"):
        place_copy(staged, target)
    assert files(target) == before


def test_fleet_analyze_keeps_the_verdicts_of_a_run_directory_for_fleet_runs(tmp_path, capsys):
    mission = Mission("small", MissionKind.FILL, Strategy.GREEDY)
    layout = load_layout("small")
    stream = recorded_run(mission, layout, engine_options(mission, layout, None))[1]
    runs = tmp_path / "runs"
    unjudged = claim(runs / "unjudged").path
    write_recording(unjudged / RUN_FILE, stream, layout)
    by_file = claim(runs / "by-file").path
    write_recording(by_file / RUN_FILE, stream, layout)
    other = tmp_path / "other"  # a folder of the user's, with a recording of its own
    other.mkdir()
    write_recording(other / "mine.mcap", stream, layout)
    (other / SUMMARY).write_text("the user's own notes\n")

    def listed() -> dict[str, dict]:
        assert main(["runs", str(runs), "--json"]) == 0
        return {Path(r["directory"]).name: r
                for r in map(json.loads, capsys.readouterr().out.splitlines())}

    assert {name: r["verdict"] for name, r in listed().items()} == \
        {"unjudged": "not analysed", "by-file": "not analysed"}
    code, out, err = fleet(["analyze", unjudged], capsys)
    assert code == 0 and err == "" and "work               pass" in out
    assert fleet(["analyze", by_file / RUN_FILE, "--json"], capsys)[0] == 0
    assert fleet(["analyze", other / "mine.mcap"], capsys)[0] == 0
    rows = listed()
    assert {name: r["verdict"] for name, r in rows.items()} == \
        {"unjudged": "pass", "by-file": "pass"}
    assert rows["unjudged"]["end_time_s"] > 0 and rows["unjudged"]["incomplete"] is False
    summary = json.loads((unjudged / SUMMARY).read_text())
    assert summary["run_id"] == run_id_of(unjudged) and summary["incomplete"] == []
    assert (other / SUMMARY).read_text() == "the user's own notes\n"  # not ours: left alone
    # Judged again, it says the same: nothing is written (a read-only copy is no trouble).
    kept = (unjudged / SUMMARY).stat().st_mtime_ns
    assert fleet(["analyze", unjudged], capsys)[0] == 0
    assert (unjudged / SUMMARY).stat().st_mtime_ns == kept
    # Where the summary cannot be written, the analysis stands, with one note.
    (unjudged / SUMMARY).unlink()
    (unjudged / f".{SUMMARY}.tmp").mkdir()  # in the way of the summary's temporary file
    code, out, err = fleet(["analyze", unjudged], capsys)
    assert code == 0 and "work               pass" in out
    assert err.count("\n") == 1 and err.startswith("note: could not keep the run's summary")


def test_fleet_runs_says_which_runs_have_no_result(tmp_path, capsys):
    """An interrupted run (or one whose processes died): the recorder stopped normally, its
    file complete, without the dispatcher's result; or nothing was recorded at all. A torn
    file (a killed recorder) cannot tell without reading it all: not analysed."""
    mission = Mission("small", MissionKind.FILL, Strategy.GREEDY)
    layout = load_layout("small")
    stream = recorded_run(mission, layout, engine_options(mission, layout, None))[1]
    half = stream[: len(stream) // 2]
    runs = tmp_path / "runs"
    stopped = claim(runs / "stopped").path
    write_recording(stopped / RUN_FILE, half, layout)
    claim(runs / "nothing")  # claimed, then stopped before a recorder wrote anything
    torn = claim(runs / "torn").path
    write_recording(torn / RUN_FILE, half, layout)
    data = (torn / RUN_FILE).read_bytes()
    (torn / RUN_FILE).write_bytes(data[: len(data) * 2 // 3])
    finished = claim(runs / "finished").path
    write_recording(finished / RUN_FILE, stream, layout)
    assert main(["runs", str(runs), "--json"]) == 0
    rows = {Path(r["directory"]).name: r
            for r in map(json.loads, capsys.readouterr().out.splitlines())}
    assert {name: (r["verdict"], r["problem"]) for name, r in rows.items()} == {
        "stopped": ("no result", "its recording ends before the mission's result: "
                                 "interrupted, or a process died"),
        "nothing": ("no result", "nothing was recorded"),
        "torn": ("not analysed", ""),
        "finished": ("not analysed", "")}
    assert rows["stopped"]["layout"] == "small"
    assert main(["runs", str(runs)]) == 0
    table = capsys.readouterr().out
    assert "no result (nothing was recorded)" in table
