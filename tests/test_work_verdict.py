"""The work verdict checks what physically happened (fleet/analysis/served.py, motion.py, the
safety verifier between instants): clean recordings of small fill, small empty and a run
whose recorder was killed pass; each check catches a clean recording damaged in its way."""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import pytest

from fleet.cli import main
from fleet.dispatching.decision import Strategy
from fleet.mission.engine import engine_options
from fleet.mission.spec import Mission, MissionKind
from fleet.recording.inprocess import Outgoing, recorded_run, write_recording
from fleet.recording.writer import RecordingWriter
from fleet.wire.protocol import (
    MissionDone,
    MissionInfo,
    StackDone,
    SubtaskEvent,
    VehicleState,
    encode,
)
from fleet.world.layout_file import load_layout

LAYOUT = "small"


def clean(kind: MissionKind) -> list[Outgoing]:
    """What a fault-free mission on the small layout puts on the wire."""
    mission = Mission(LAYOUT, kind, Strategy.GREEDY)
    layout = load_layout(LAYOUT)
    return recorded_run(mission, layout, engine_options(mission, layout, None))[1]


@pytest.fixture(scope="module")
def fill() -> list[Outgoing]:
    return clean(MissionKind.FILL)


@pytest.fixture(scope="module")
def empty() -> list[Outgoing]:
    return clean(MissionKind.EMPTY)


def analyzed(path: Path, capsys) -> tuple[int, dict]:
    status = main(["analyze", str(path), "--json"])
    return status, json.loads(capsys.readouterr().out)


def analyze_stream(tmp_path: Path, stream: list[Outgoing], capsys) -> tuple[int, dict]:
    path = tmp_path / "run.mcap"
    write_recording(path, stream, load_layout(LAYOUT))
    return analyzed(path, capsys)


def with_message(o: Outgoing, **changes) -> Outgoing:
    return dataclasses.replace(o, message=dataclasses.replace(o.message, **changes))


def stack_events(stream: list[Outgoing]) -> list[int]:
    return [k for k, o in enumerate(stream) if isinstance(o.message, StackDone)]


def assert_clean(report: dict) -> None:
    assert report["passed"] and report["work_done"] and report["safe"]
    assert report["stacks_done"] == report["stacks_announced"] == report["stacks_expected"]
    assert report["stacks_not_served"] == report["stacks_out_of_order"] == 0
    assert report["impossible_states"] == report["overlaps"] == 0


@pytest.mark.parametrize("kind", ["fill", "empty"])
def test_clean_missions_pass_the_work_verdict(kind, fill, empty, tmp_path, capsys):
    status, report = analyze_stream(tmp_path, fill if kind == "fill" else empty, capsys)
    assert status == 0
    assert_clean(report)
    assert report["stacks_unverified"] == []  # every stack seen served


def test_a_run_whose_recorder_was_killed_passes(tmp_path, capsys):
    """Real processes: the recorder killed and another started, so one run in two segments
    with a window no recorder saw. What the states cannot show there is taken on the
    dispatcher's word, and said so; everything else is seen."""
    run = tmp_path / "killed"
    assert main(["run", "--layout", LAYOUT, "--faults", "kill_recorder", "--json",
                 "--out", str(run)]) == 0
    capsys.readouterr()
    status, report = analyzed(run, capsys)
    assert status == 0, report
    assert len(report["segments"]) == 2
    assert_clean(report)


def test_a_stack_announced_for_another_forklift_is_not_served(fill, tmp_path, capsys):
    k = stack_events(fill)[5]
    named = fill[k].message
    stream = list(fill)
    stream[k] = with_message(fill[k], vehicle=3 - named.vehicle)  # the other forklift
    status, report = analyze_stream(tmp_path, stream, capsys)
    assert status == 1 and not report["work_done"]
    (wrong,) = report["stacks_not_served_first"]
    assert wrong["stack"] == f"{named.cluster}#{named.index}"
    assert wrong["vehicle"] == 3 - named.vehicle
    assert report["stacks_done"] == 23 and report["stacks_announced"] == 24
    assert report["stacks_lost"] == [wrong["stack"]]


def test_a_stack_handled_for_less_than_its_handling_time_is_not_served(fill, tmp_path,
                                                                        capsys):
    """The dispatcher says the unloading ended 1 s earlier than the forklift stood there for
    5 s: it was still driving when the unloading would have begun."""
    k = stack_events(fill)[3]
    stream = list(fill)
    stream[k] = with_message(fill[k], t=fill[k].message.t - 1.0)
    status, report = analyze_stream(tmp_path, stream, capsys)
    assert status == 1
    (short,) = report["stacks_not_served_first"]
    assert "moving" in short["why"]


@pytest.mark.parametrize("kind", ["fill", "empty"])
def test_stacks_taken_up_against_their_clusters_order_are_caught(kind, fill, empty, tmp_path,
                                                                 capsys):
    """The recording says the mission was the other kind: its stacks were taken up in the
    order the other way round (and each served)."""
    stream = list(fill if kind == "fill" else empty)
    k = next(k for k, o in enumerate(stream) if isinstance(o.message, MissionInfo))
    stream[k] = with_message(stream[k], kind="empty" if kind == "fill" else "fill")
    write_recording(tmp_path / "run.mcap", stream, load_layout(LAYOUT))
    status, report = analyzed(tmp_path / "run.mcap", capsys)
    assert status == 1
    assert report["stacks_not_served"] == 0 and report["stacks_done"] == 24
    assert report["stacks_out_of_order"] > 0
    first = report["stacks_out_of_order_first"][0]
    assert first["taken"] != first["first"]


def test_a_state_jumping_farther_than_the_speed_allows_is_impossible(fill, tmp_path, capsys):
    k = next(k for k, o in enumerate(fill) if isinstance(o.message, VehicleState)
             and o.message.vehicle == 1 and o.message.maneuver == "forward" and o.sim_time > 20)
    stream = list(fill)
    stream[k] = with_message(fill[k], x=fill[k].message.x + 5.0)  # 4 m/s at most: 2 m
    status, report = analyze_stream(tmp_path, stream, capsys)
    assert status == 1 and not report["work_done"]
    jumps = report["impossible_states_first"]
    assert [(j["vehicle"], j["t"]) for j in jumps] == [(1, fill[k].sim_time),
                                                       (1, fill[k].sim_time + 0.5)]
    assert "moved" in jumps[0]["why"]


@pytest.mark.parametrize("change, why", [
    ({"y": 0.25}, "off every grid pose"),
    ({"theta": 0.1}, "off every grid pose"),
    ({"pose": "shifted"}, "but says"),
    ({"speed": 1}, "speed level 1"),
])
def test_a_state_standing_still_off_its_grid_pose_is_impossible(change, why, fill, tmp_path,
                                                                capsys):
    k = next(k for k, o in enumerate(fill) if isinstance(o.message, VehicleState)
             and o.message.vehicle == 2 and o.message.maneuver == "" and o.sim_time > 100)
    state = fill[k].message
    if "pose" in change:  # one cell off what it stands on
        col, row, heading = state.pose.split(",")
        change = {"pose": f"{int(col) + 1},{row},{heading}"}
    else:
        change = {name: getattr(state, name) + d if name != "speed" else d
                  for name, d in change.items()}
    stream = list(fill)
    stream[k] = with_message(fill[k], **change)
    status, report = analyze_stream(tmp_path, stream, capsys)
    assert status == 1
    (wrong,) = report["impossible_states_first"]
    assert wrong["vehicle"] == 2 and wrong["t"] == fill[k].sim_time and why in wrong["why"]


def write_records(path: Path, records: list[tuple[Outgoing, int, int]],
                  info: MissionInfo) -> None:
    """Write (message, sequence number, log time) records as they are given."""
    writer = RecordingWriter(path)
    writer.describe(info)
    for o, seq, log_ns in records:
        writer.write(o.key, encode(o.message, o.sender, seq, o.sim_time), log_ns, o.sim_time)
    writer.close()


def numbered(stream: list[Outgoing]) -> list[tuple[Outgoing, int, int]]:
    """Each message with its stream's sequence number and a log time (its sim time)."""
    count: dict[tuple[str, str], int] = {}
    out = []
    for o in stream:
        count[o.key, o.sender] = count.get((o.key, o.sender), 0) + 1
        out.append((o, count[o.key, o.sender], int(o.sim_time * 1e9) + len(out)))
    return out


def test_a_stack_recorded_by_two_recorders_at_once_counts_once(fill, tmp_path, capsys):
    """Two recorders overlapping (the second started before the first was gone): the stack
    messages both recorded, byte for byte the same, are one stack done each."""
    records = numbered(fill)
    k = stack_events(fill)[7]
    both = range(stack_events(fill)[5], k + 1)  # two stacks among what both recorded
    info = fill[0].message
    write_records(tmp_path / "run.mcap", records[:both.stop], info)
    write_records(tmp_path / "run-2.mcap", [(o, seq, log_ns + 300_000_000)  # its own clock
                                            for o, seq, log_ns in records[both.start:]], info)
    status, report = analyzed(tmp_path, capsys)
    assert status == 0 and report["stacks_duplicated"] == []
    assert report["stacks_done"] == report["stacks_announced"] == 24
    assert [s["duplicates"] for s in report["segments"]] == [0, len(both)]


def test_a_mission_that_failed_fails_the_work_verdict(fill, tmp_path, capsys):
    stream = list(fill)
    stream[-1] = with_message(fill[-1], ok=False, error="401 decisions in a row failed")
    status, report = analyze_stream(tmp_path, stream, capsys)
    assert status == 1 and not report["work_done"] and not report["finished"]
    assert report["stacks_done"] == 24  # every stack served, and still not a finished run
    assert main(["analyze", str(tmp_path / "run.mcap")]) == 1
    assert "the mission did not finish (401 decisions in a row failed)" in \
        capsys.readouterr().out


def announced_at_commit(stream: list[Outgoing]) -> list[Outgoing]:
    """The stream as a run of processes publishes it: each stack announced when its
    delivery is committed (at its decision), not when its handling ends."""
    decided = {(m.target, m.stack): o.sim_time for o in stream
               if isinstance(m := o.message, SubtaskEvent) and m.stack is not None}
    moved = [dataclasses.replace(o, sim_time=decided[o.message.cluster, o.message.index])
             if isinstance(o.message, StackDone) else o for o in stream]
    return sorted(moved, key=lambda o: o.sim_time)


def test_a_run_that_died_counts_the_stacks_served_not_those_announced(fill, tmp_path,
                                                                      capsys):
    setting_out = [o.sim_time for o in fill if isinstance(o.message, SubtaskEvent)
                   and o.message.stack is not None]
    died_at = setting_out[12] + 1.0  # a forklift on its way to a stack
    stream = [o for o in announced_at_commit(fill) if o.sim_time < died_at
              and not isinstance(o.message, MissionDone)]
    announced = [o.message for o in stream if isinstance(o.message, StackDone)]
    reached = [m for m in announced if m.t < died_at]
    assert len(reached) < len(announced)
    status, report = analyze_stream(tmp_path, stream, capsys)
    assert status == 1 and not report["finished"]
    assert report["stacks_announced"] == len(announced)
    assert report["stacks_done"] == len(reached)
    assert report["stacks_not_served"] == len(announced) - len(reached)
    assert all("no state of its forklift after" in n["why"]
               for n in report["stacks_not_served_first"])
    assert main(["analyze", str(tmp_path / "run.mcap")]) == 1
    assert f"{len(reached)} of 24 stacks served ({len(announced)} announced)" in \
        capsys.readouterr().out


def test_an_overlap_between_the_instants_of_the_states_is_caught(fill, tmp_path, capsys):
    """Forklift 2 reports where forklift 1 was, a quarter of a second later: never at an
    instant at which forklift 1 has a state, so only the check between instants sees the
    two on one cell."""
    stream = [o for o in fill if not (isinstance(o.message, VehicleState)
                                      and o.message.vehicle == 2)]
    stream += [dataclasses.replace(o, key=o.key.replace("/1/", "/2/"), sender="vehicle-2",
                                   message=dataclasses.replace(o.message, vehicle=2),
                                   sim_time=o.sim_time + 0.25)
               for o in fill if isinstance(o.message, VehicleState) and o.message.vehicle == 1]
    stream.sort(key=lambda o: o.sim_time)
    status, report = analyze_stream(tmp_path, stream, capsys)
    assert status == 1 and not report["safe"]
    assert report["overlaps"] > 0 and report["overlaps_between"] == report["overlaps"]
    first = report["overlaps_first"][0]
    assert first["vehicles"] == [1, 2] and first["between"] and first["cells"]
    assert not math.isclose(first["t"] * 2, round(first["t"] * 2))  # not on the grid
