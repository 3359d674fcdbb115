"""`fleet bench campaign`: seeded random fault scenarios, each judged by its recording's
verdicts; a failing run's scenario is written out and replays bit for bit."""

import json
from pathlib import Path

import pytest

import bench.campaign as campaign
from fleet.cli import main
from fleet.mission.faults import FaultKind, load_scenario, parse_scenario, scenario_toml
from fleet.mission.spec import ClockMode, MissionKind
from fleet.world.layout_file import load_layout

SMALL = load_layout("small")


def test_a_run_draws_its_faults_from_the_seed_and_its_number_alone():
    def draw(seed, index, clock=ClockMode.FAST):
        return campaign.draw_scenario(seed, index, SMALL, 2, MissionKind.FILL, 500.0, clock)

    assert draw(7, 3) == draw(7, 3)
    assert draw(7, 3) != draw(7, 4) and draw(7, 3) != draw(8, 3)
    drawn = [draw(7, i) for i in range(30)]
    assert all(2 <= len(s.faults) <= campaign.MAX_FAULTS for s in drawn)
    kinds = {f.kind for s in drawn for f in s.faults}
    assert kinds == set(campaign.MOVING_KINDS)  # the fast clock: the kinds that move time
    assert all(campaign.FIRST_AT_S <= f.at <= 400.0 and f.duration is not None
               for s in drawn for f in s.faults)
    realtime = {f.kind for i in range(30) for f in draw(7, i, ClockMode.REALTIME).faults}
    assert {FaultKind.KILL_SERVICE, FaultKind.SLOW_PLANNER} <= realtime
    for scenario in drawn:  # written as a scenario file, read back the same
        assert parse_scenario(scenario_toml(scenario, "a\nheader"), "file") == scenario


def campaign_json(capsys, tmp_path, *flags):
    code = main(["bench", "campaign", "--layout", "small", "--runs", "3", "--seed", "11",
                 "--out", str(tmp_path / "out"), "--json", *flags])
    result = json.loads(capsys.readouterr().out)
    assert result == json.loads((tmp_path / "out" / "campaign.json").read_text()) | \
        {"machine": result["machine"]}
    return code, result


def test_a_campaign_reports_every_run_and_replays_each_bit_for_bit(capsys, tmp_path):
    code, result = campaign_json(capsys, tmp_path)
    assert result["runs"] == 3 and len(result["per_run"]) == 3
    assert result["completed"] + result["wedged"] + result["crashed"] == 3
    assert [r["kind"] for r in result["per_run"]] == ["fill", "empty", "fill"]
    failing = [r for r in result["per_run"] if r["failed"]]
    assert result["verdict_failures"] == sum(r["verdicts"] is not None and
                                             not r["verdicts"]["passed"]
                                             for r in result["per_run"])
    assert code == (1 if failing else 0)
    base = result["fault_free_end_s"]
    for row in result["per_run"]:
        assert isinstance(row["deadlocks"], list) and len(row["faults"]) >= 2
        if row["completed"]:
            assert row["extra_s"] == pytest.approx(row["end_time_s"] - base[row["kind"]])
        assert (row["replay"] is not None) is row["failed"]
    # A run's scenario, written as the campaign writes a failing one, replays bit for bit.
    row = result["per_run"][1]
    spec = campaign.CampaignSpec("small", 3, 11)
    scenario = campaign.draw_scenario(11, 1, SMALL, 2, MissionKind.EMPTY,
                                      base["empty"], ClockMode.FAST)
    path = campaign.write_replay(tmp_path, spec, MissionKind.EMPTY, scenario, row)
    assert load_scenario(path) == scenario
    assert main(["run", "--inprocess", "--layout", "small", "--mission", "empty", "--faults",
                 str(path), "--out", str(tmp_path / "replay"), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["digest"] == row["digest"]


def test_a_wedged_run_counts_as_wedged_and_leaves_its_scenario(capsys, tmp_path, monkeypatch):
    """A mission that raises MissionStuck (here run 1, made to) is wedged, not a crash: its
    scenario is written out with how to replay it, and what it recorded beside it."""
    real = campaign.run_inprocess

    def wedging(mission, layout, scenario, folder, weights, progress):
        if scenario is not None and scenario.name.endswith("-1"):
            return campaign.Outcome(False, True, "401 decisions in a row failed at t=9 s", "",
                                    None, None, [])
        return real(mission, layout, scenario, folder, weights, progress)

    monkeypatch.setattr(campaign, "run_inprocess", wedging)
    code, result = campaign_json(capsys, tmp_path, "--kind", "empty")
    assert code == 1 and result["wedged"] == 1 and result["kinds"] == ["empty"]
    assert result["completed"] + result["wedged"] == result["runs"] == 3
    wedged = result["per_run"][1]
    assert (wedged["completed"], wedged["wedged"], wedged["verdicts"]) == (False, True, None)
    replay = tmp_path / "out" / "campaign-11-1.toml"
    assert wedged["replay"] == str(replay) and wedged["run_dir"] == str(tmp_path / "out" /
                                                                        "campaign-11-1")
    text = replay.read_text()
    assert "# replay: fleet run --inprocess --layout small --mission empty --faults" in text
    assert load_scenario(replay).name == "campaign-11-1"



def test_a_campaign_takes_the_weights_of_a_floor_without_shipped_ones(capsys, tmp_path):
    """--weights as fleet run takes it: the ANN strategy scores with that file, and a
    failing run's replay line passes it on."""
    from fleet.dispatching.weights import __file__ as shipped

    weights = tmp_path / "mine.json"
    weights.write_text((Path(shipped).parent / "small.json").read_text())
    assert main(["bench", "campaign", "--layout", "small", "--runs", "1", "--kind", "fill",
                 "--weights", str(weights), "--out", str(tmp_path / "out"), "--json"]) in (0, 1)
    mine = json.loads(capsys.readouterr().out)
    reference = main(["run", "--inprocess", "--layout", "small", "--json",
                      "--out", str(tmp_path / "reference")])
    assert reference == 0
    assert mine["fault_free_end_s"]["fill"] == json.loads(capsys.readouterr().out)["end_time_s"]
    spec = campaign.CampaignSpec("small", 1, 11, weights=weights)
    scenario = campaign.draw_scenario(11, 0, SMALL, 2, MissionKind.FILL, 500.0, ClockMode.FAST)
    path = campaign.write_replay(tmp_path, spec, MissionKind.FILL, scenario, mine["per_run"][0])
    assert f"--mission fill --weights {weights} --faults {path}" in path.read_text()
    with pytest.raises(SystemExit) as refused:  # argparse refuses it, naming the file
        main(["bench", "campaign", "--layout", "small", "--weights", str(tmp_path / "none.json")])
    assert refused.value.code == 2 and "none.json' does not exist" in capsys.readouterr().err


def test_a_campaign_writes_only_in_a_new_or_empty_directory(capsys, tmp_path):
    (tmp_path / "mine.txt").write_text("kept")
    assert main(["bench", "campaign", "--layout", "small", "--out", str(tmp_path)]) == 2
    assert f"--out {tmp_path} is not empty" in capsys.readouterr().err
    assert [p.name for p in tmp_path.iterdir()] == ["mine.txt"]


def test_a_mission_that_gets_stuck_is_wedged_with_its_recording(tmp_path):
    """The campaign's own in-process run of a mission no forklift can finish (a stack walled
    in): wedged, not crashed, and judged from what it recorded."""
    from test_failed_runs import WALLED

    from fleet.dispatching.decision import Strategy
    from fleet.mission.spec import Mission
    from fleet.recording.rundir import claim
    from fleet.world.layout_file import parse_layout

    (tmp_path / "walled.toml").write_text(WALLED)
    layout = parse_layout(WALLED, "walled.toml")
    mission = Mission(str(tmp_path / "walled.toml"), MissionKind.FILL, Strategy.GREEDY)
    outcome = campaign.run_inprocess(mission, layout, None, claim(tmp_path / "run").path,
                                     None, lambda done, t: None)
    assert (outcome.completed, outcome.wedged) == (False, True)
    assert "decisions in a row failed" in outcome.error
    assert outcome.report is not None and not outcome.report.passed


@pytest.mark.parametrize("seed", [101, 202])
def test_random_small_missions_with_random_faults_always_complete(capsys, tmp_path, seed):
    """The property the campaigns measure at scale: whatever faults the seed draws (2 to 4 of
    them, on fill and empty missions), every mission completes and passes every verdict."""
    code = main(["bench", "campaign", "--layout", "small", "--runs", "8", "--seed", str(seed),
                 "--out", str(tmp_path / "out"), "--json"])
    result = json.loads(capsys.readouterr().out)
    failed = [(r["index"], r["kind"], r["error"]) for r in result["per_run"] if r["failed"]]
    assert (code, result["completed"], result["verdict_failures"], failed) == (0, 8, 0, [])
