"""Algorithm 1's lookahead as a mission's own setting (`fleet run --lookahead`): it reaches
the dispatching, the record and the recording name it, and the default goes unsaid so that
the records of missions run with it keep their digests."""

from __future__ import annotations

import argparse
import math

import pytest

from fleet.analysis.analyze import analyze
from fleet.dispatching.decision import Strategy
from fleet.errors import UserError
from fleet.mission.engine import engine_options
from fleet.mission.record import digest_of
from fleet.mission.spec import Mission, MissionKind
from fleet.params import LOOKAHEAD_S
from fleet.recording.inprocess import recorded_run, write_recording
from fleet.recording.mission_record import summary_of
from fleet.recording.reader import read_recording
from fleet.runtime.args import add_mission_args, mission_argv, mission_from_args
from fleet.world.layout_file import load_layout


def parsed(*argv: str) -> Mission:
    parser = argparse.ArgumentParser(exit_on_error=False)
    add_mission_args(parser)
    args = parser.parse_args(list(argv))
    return mission_from_args(args, load_layout(args.layout))


def test_the_flag_gives_the_mission_its_lookahead_and_renders_back():
    assert parsed().lookahead == LOOKAHEAD_S
    assert "--lookahead" not in mission_argv(parsed())
    assert parsed("--lookahead", "none").lookahead == math.inf
    assert parsed("--lookahead", "12.5").lookahead == 12.5
    for given in (parsed("--lookahead", "none"), parsed("--lookahead", "0")):
        assert parsed(*mission_argv(given)) == given


def test_the_flag_is_refused_where_it_means_nothing_or_is_no_time():
    with pytest.raises(UserError, match="--lookahead is Algorithm 1's"):
        parsed("--layout", "paper002", "--lookahead", "30")
    with pytest.raises(argparse.ArgumentError, match="or none"):
        parsed("--lookahead", "-1")


def test_a_mission_run_with_its_own_lookahead_says_so_in_its_record_and_recording(tmp_path):
    """Small, greedy fill: without a lookahead a forklift is chosen while it runs ahead of
    the other, and fewer choices fail (10 against 19 with the default's). The record names
    the lookahead; the recording read back gives the same record, and the analysis names
    it."""
    layout = load_layout("small")
    records = {}
    for lookahead in (LOOKAHEAD_S, math.inf):
        mission = Mission("small", MissionKind.FILL, Strategy.GREEDY, lookahead=lookahead)
        done, stream = recorded_run(mission, layout, engine_options(mission, layout, None))
        assert done.ok
        records[lookahead] = done.record
    assert "lookahead" not in records[LOOKAHEAD_S]["mission"]
    assert records[math.inf]["mission"]["lookahead"] == "inf"
    assert records[math.inf]["decision_failures"] < records[LOOKAHEAD_S]["decision_failures"]

    write_recording(tmp_path / "run.mcap", stream, layout)
    recording = read_recording(tmp_path / "run.mcap")
    assert digest_of(summary_of(recording).to_dict()) == digest_of(records[math.inf])
    report = analyze(recording)
    assert report.passed
    assert "strategy greedy, clock inprocess, seed 0, no lookahead" in "\n".join(report.lines())
