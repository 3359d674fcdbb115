"""`fleet bench scale`: the floors it generates for a fleet, the growth it reports, and one
small run of it for real (two forklifts, in process and as processes)."""

from __future__ import annotations

import json

import pytest

from bench.scale import (
    MIN_LANE_DEPTH,
    PARKING_PER_FORKLIFT,
    STACKS_PER_FORKLIFT,
    floor_for,
    growth,
)
from fleet.cli import main
from fleet.world.generator import generate_layout


@pytest.mark.parametrize("vehicles", [1, 2, 5, 12, 33, 64, 100])
def test_the_floor_has_room_to_park_and_about_ten_stacks_a_forklift(vehicles):
    shape = floor_for(vehicles)
    layout = generate_layout(shape)
    assert len(layout.vehicle_starts) == vehicles
    assert shape.slots_per_aisle * shape.aisles >= PARKING_PER_FORKLIFT * vehicles
    assert shape.lane_depth >= MIN_LANE_DEPTH
    assert len(layout.stacks) >= STACKS_PER_FORKLIFT * vehicles or shape.lane_depth == 5
    smaller = floor_for(vehicles - 1) if vehicles > 1 else shape
    assert (smaller.aisles, smaller.depth) <= (shape.aisles, shape.depth)  # grows with it


def test_growth_is_per_mode_from_each_size_to_the_next():
    rows = [{"vehicles": v, "mode": "inprocess", "completed": True,
             "wall_per_decision_ms": ms, "peak_mb": mb}
            for v, ms, mb in ((10, 20.0, 100.0), (20, 40.0, 150.0), (40, 160.0, 300.0))]
    rows.append({"vehicles": 80, "mode": "inprocess", "completed": False})
    steps = growth(rows)
    assert steps["processes"] == []
    assert [(s["from"], s["to"], s["wall_per_decision_x"], s["exponent"], s["peak_mb_x"])
            for s in steps["inprocess"]] == [(10, 20, 2.0, 1.0, 1.5), (20, 40, 4.0, 2.0, 2.0)]


def test_two_forklifts_fill_their_floor_the_same_in_process_and_as_processes(capsys):
    assert main(["bench", "scale", "--fleets", "2", "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    rows = {row["mode"]: row for row in result["rows"]}
    assert set(rows) == {"inprocess", "processes"}
    for row in rows.values():
        assert row["completed"] and row["passed"]
        assert row["stacks_done"] == row["stacks"] == len(generate_layout(floor_for(2)).stacks)
        assert row["decisions"] >= 2 * row["stacks"]  # a deliver and a return each
        assert row["wall_per_decision_ms"] > 0 and row["peak_mb"] > 0
    assert rows["processes"]["peak_agent_mb"] > 0 and rows["inprocess"]["peak_agent_mb"] is None
    assert rows["processes"]["peak_mb"] > rows["inprocess"]["peak_mb"]  # 7 interpreters
    assert result["same_record"] == {"2": True}


def test_a_mission_given_up_reports_how_far_it_got_and_keeps_its_recording(tmp_path, capsys):
    """32 forklifts cannot fill their floor in 15 s of wall time: the run is stopped, its row
    says how many stacks were done by when, and its directory is kept in --keep. (Run with
    no lookahead, which the report and the recording name.)"""
    from fleet.analysis.analyze import analyze
    from fleet.recording.reader import read_recording

    keep = tmp_path / "kept"
    assert main(["bench", "scale", "--fleets", "32", "--modes", "inprocess", "--timeout",
                 "0.25", "--keep", str(keep), "--lookahead", "none", "--json"]) == 1
    result = json.loads(capsys.readouterr().out)
    assert result["lookahead"] is None
    (row,) = result["rows"]
    assert row["timed_out"] and not row["completed"] and not row["passed"]
    assert row["recording"] == str(keep / "32-inprocess")
    assert (keep / "scale-32.toml").is_file()
    report = analyze(read_recording(keep / "32-inprocess"))
    assert report.mission["lookahead"] is None
    assert row["stacks"] == len(generate_layout(floor_for(32)).stacks)
    assert row["stacks_done"] == report.stacks_done < row["stacks"]
    assert main(["bench", "scale", "--fleets", "2", "--keep", str(keep)]) == 2
    assert "--keep" in capsys.readouterr().err
