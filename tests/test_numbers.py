"""One definition per number (docs/metrics.md): `fleet run`'s summary and `fleet analyze` of
its recording give the same figures, computed from the recording alone, and they agree with
the dispatcher's own accounting where both count the same thing."""

import json

import pytest

from fleet.cli import main
from fleet.commands.run import VALUE_COLUMN
from fleet.forklift_time import maneuver_length, time_use
from fleet.protocol import Halt, MissionDone, Resume
from fleet.recording import read_recording

PER_FORKLIFT = ("busy_s", "stopped_s", "postponed_s", "handling_s", "down_s", "idle_s")


def run_json(capsys, *args: str) -> dict:
    assert main(["run", "--inprocess", "--layout", "small", "--json", *args]) == 0
    out, err = capsys.readouterr()
    assert err == ""  # no progress with --json
    return json.loads(out)


def analyze_json(capsys, path) -> dict:
    assert main(["analyze", str(path), "--json"]) == 0
    return json.loads(capsys.readouterr().out)


def dispatcher_record(path) -> dict:
    return [m for _, m in read_recording(path).of(MissionDone)][-1].record


def assert_every_instant_counted_once(summary: dict) -> None:
    span = max(summary["end_time_s"], summary["all_parked_s"])
    for v in summary["vehicles"]:
        assert sum(v[k] for k in PER_FORKLIFT) == pytest.approx(span), v
        assert v["waiting_s"] == pytest.approx(v["stopped_s"] + v["postponed_s"])
        assert v["utilisation"] == pytest.approx(v["busy_s"] / span)


def test_the_summary_and_the_analysis_of_its_recording_give_the_same_numbers(tmp_path, capsys):
    summary = run_json(capsys, "--out", str(tmp_path))
    report = analyze_json(capsys, tmp_path)
    assert summary["vehicles"] == report["vehicles"]
    for key in ("end_time_s", "all_parked_s", "stacks_done", "subtasks", "decision_failures",
                "plans_failed", "undecided"):
        assert summary[key] == report[key], key
    assert summary["verdicts"] == {"safety": True, "work": True, "messages": True,
                                   "passed": True}
    assert summary["recording"] == str(tmp_path / "run.mcap")
    assert len(summary["digest"]) == 64 and summary["mission"]["layout"] == "small"
    assert_every_instant_counted_once(summary)

    # The dispatcher's record counts waiting as stop maneuvers and postponements, busy as
    # driving, and every decision failure; the recording alone gives the same.
    record = dispatcher_record(tmp_path)
    for v in summary["vehicles"]:
        assert v["waiting_s"] == pytest.approx(record["wait_s"][str(v["vehicle"])])
        assert v["busy_s"] == pytest.approx(record["busy_s"][str(v["vehicle"])])
    assert summary["waiting_s"] == pytest.approx(sum(record["wait_s"].values()))
    assert summary["postponed_s"] > 0 and summary["stopped_s"] > 0  # both parts seen here
    assert summary["decision_failures"] == record["decision_failures"]
    assert summary["plans_failed"] == sum(f["stage"] == "plan" for f in record["failures"])


def test_the_text_summary_prints_the_lines_of_the_analysis(tmp_path, capsys):
    assert main(["run", "--inprocess", "--layout", "small", "--quiet",
                 "--out", str(tmp_path)]) == 0
    summary, err = capsys.readouterr()
    assert err == ""  # --quiet: no progress
    assert main(["analyze", str(tmp_path)]) == 0
    analysis = capsys.readouterr().out.splitlines()
    continued = "\n" + " " * VALUE_COLUMN  # fleet run breaks a line wider than 80 columns
    numbers = [line for line in summary.replace(continued, " ").splitlines() if line.startswith(
        ("  end time", "  stacks", "  subtasks", "  decision failures", "  waiting"))]
    assert len(numbers) == 5 and all(line in analysis for line in numbers)
    assert "plans failed" in numbers[3] and "stopped" in numbers[4]

    def table(lines: list[str]) -> dict[str, list[str]]:
        """The per-forklift table's columns by name (names end in "s" or "%")."""
        start = next(k for k, line in enumerate(lines) if line.startswith("  forklift"))
        names = ["forklift", *(f"{unit} {kind}" for unit, kind in zip(
            lines[start].split()[1::2], lines[start].split()[2::2], strict=True))]
        rows = [line.split() for line in lines[start + 1:] if line[2:10].strip().isdigit()]
        return {name: [row[k] for row in rows] for k, name in enumerate(names)}

    ran = table(summary.splitlines())
    analyzed = table(analysis)
    assert ran.keys() <= analyzed.keys() and "stopped s" in ran and "postponed s" in ran
    for name, column in ran.items():
        assert column == analyzed[name], name


BREAKDOWN = """name = "breakdown on small"
description = "forklift 1 breaks down for 50 s"

[[fault]]
kind = "vehicle_breakdown"
at = 100.3
vehicle = 1
duration = 50.0
"""


def test_a_forklift_down_is_counted_down_not_waiting(tmp_path, capsys):
    scenario = tmp_path / "breakdown.toml"
    scenario.write_text(BREAKDOWN)
    summary = run_json(capsys, "--faults", str(scenario), "--out", str(tmp_path / "run"))
    assert summary["vehicles"] == analyze_json(capsys, tmp_path / "run")["vehicles"]
    first, second = summary["vehicles"]
    assert first["down_s"] == pytest.approx(50.0) and second["down_s"] == 0
    assert_every_instant_counted_once(summary)
    # The breakdown is neither stopped nor postponed time. The dispatcher's record drops
    # what forklift 1 drove and stood of the plan the breakdown cut (it keeps the account of
    # before that plan); the recording has it, and forklift 2's account is the same in both.
    record = dispatcher_record(tmp_path / "run")
    assert record["cut_subtasks"] and {s["vehicle"] for s in (
        record["subtasks"][k] for k in record["cut_subtasks"])} == {1}
    assert second["waiting_s"] == pytest.approx(record["wait_s"]["2"])
    assert second["busy_s"] == pytest.approx(record["busy_s"]["2"])
    assert first["waiting_s"] >= record["wait_s"]["1"]
    assert first["busy_s"] > record["busy_s"]["1"]


def subtask(vehicle: int, t_i: float, steps: list[tuple[str, float, float]],
            handling: float = 5.0) -> dict:
    t_end = steps[-1][2]
    return {"vehicle": vehicle, "kind": "deliver", "t_i": t_i, "t_end": t_end,
            "t_done": t_end + handling,
            "steps": [[label, "0,0,E", "1,0,E", t0, t1, 1, 1] for label, t0, t1 in steps]}


def halt(t: float, t_stand: float, moving: bool) -> Halt:
    return Halt(1, t, "test", moving, "1,0,E", t_stand, [], 0.0, 0.0, 0.0)


def test_a_cut_plan_counts_only_what_was_driven_and_the_wait_for_the_next():
    # Forklift 1 drives 0-10 and 10-20; frozen at 5 while moving, it completes the maneuver in
    # progress (to 10), drives none of the rest, and starts again at 12 (postponed 2 s).
    plan = [subtask(1, 0.0, [("forward", 0.0, 10.0), ("forward", 10.0, 20.0)]),
            subtask(1, 12.0, [("stop", 12.0, 14.0), ("forward", 14.0, 24.0)])]
    (v,) = time_use(plan, [halt(5.0, 10.0, moving=True)], [], 1, 40.0, "empty", 1.0)
    assert (v.busy_s, v.stopped_s, v.postponed_s, v.handling_s, v.down_s, v.idle_s) == \
        pytest.approx((20.0, 2.0, 2.0, 5.0, 0.0, 11.0))
    assert v.waiting_s == pytest.approx(4.0) and v.subtasks == 2


def test_a_forklift_down_part_way_finishes_its_maneuver_after_the_resume():
    # A fill begins with the claim of the first goods (to 5 s: handling). Down at 9, 4 s into
    # the maneuver 5-15, resumed at 35: down 26 s, then the 6 s left of it (to 41); the rest
    # of that plan is not driven, and its next subtask waits for nothing.
    plan = [subtask(1, 5.0, [("forward", 5.0, 15.0), ("forward", 15.0, 25.0)]),
            subtask(1, 41.0, [("forward", 41.0, 51.0)])]
    resume = Resume(1, 35.0, 41.0)
    (v,) = time_use(plan, [halt(9.0, 15.0, moving=False)], [resume], 1, 60.0, "fill", 2.0)
    assert (v.busy_s, v.postponed_s, v.down_s, v.handling_s, v.idle_s) == \
        pytest.approx((20.0, 0.0, 26.0, 10.0, 4.0))
    assert v.distance_m == pytest.approx(2 * 2.0 * maneuver_length("forward"))
