"""One definition per number (docs/metrics.md): `fleet run`'s summary and `fleet analyze` of
its recording give the same figures, computed from the recording alone, and they agree with
the dispatcher's own accounting where both count the same thing. A recording with a window
without a recorder gives the figures of the run recorded whole (what it missed is in the
dispatcher's record), or says they are incomplete; a restarted dispatcher's counts add up."""

import dataclasses
import json
from collections import Counter
from pathlib import Path

import pytest

from fleet.analysis.analyze import analyze
from fleet.analysis.report import Report
from fleet.analysis.time_use import time_use
from fleet.cli import main
from fleet.commands.run import VALUE_COLUMN
from fleet.dispatching.decision import Strategy
from fleet.mission.engine import engine_options
from fleet.mission.record import SubtaskRecord
from fleet.mission.spec import Mission, MissionKind
from fleet.recording.format import NS
from fleet.recording.inprocess import Outgoing, recorded_run
from fleet.recording.mission_record import dispatcher_restarts
from fleet.recording.reader import read_recording
from fleet.recording.writer import RecordingWriter
from fleet.vehicles.forklift import Forklift
from fleet.wire.protocol import (
    DecisionFailure,
    Halt,
    MissionDone,
    MissionInfo,
    Progress,
    Resume,
    StackDone,
    SubtaskEvent,
    encode,
)
from fleet.world.layout_file import load_layout

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
            handling: float = 5.0) -> SubtaskRecord:
    t_end = steps[-1][2]
    return SubtaskRecord(vehicle, "deliver", "a", 1, t_i, t_end, t_end + handling, False,
                         tuple((label, "0,0,E", "1,0,E", t0, t1, 1, 1)
                               for label, t0, t1 in steps), ())


def halt(t: float, t_stand: float, moving: bool) -> Halt:
    return Halt(1, t, "test", moving, "1,0,E", t_stand, [], 0.0, 0.0, 0.0)


def test_a_cut_plan_counts_only_what_was_driven_and_the_wait_for_the_next():
    # Forklift 1 drives 0-10 and 10-20; frozen at 5 while moving, it completes the maneuver in
    # progress (to 10), drives none of the rest, and starts again at 12 (postponed 2 s).
    plan = [subtask(1, 0.0, [("forward", 0.0, 10.0), ("forward", 10.0, 20.0)]),
            subtask(1, 12.0, [("stop", 12.0, 14.0), ("forward", 14.0, 24.0)])]
    (v,) = time_use(plan, [halt(5.0, 10.0, moving=True)], [], 1, 40.0, "empty",
                    Forklift(cell_size=1.0))
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
    (v,) = time_use(plan, [halt(9.0, 15.0, moving=False)], [resume], 1, 60.0, "fill",
                    Forklift(cell_size=2.0))
    assert (v.busy_s, v.postponed_s, v.down_s, v.handling_s, v.idle_s) == \
        pytest.approx((20.0, 0.0, 26.0, 10.0, 4.0))
    assert v.distance_m == pytest.approx(2 * 2.0)  # two forward maneuvers of one 2 m cell


# -- a run recorded in segments: what no recorder heard is taken from the dispatcher's record

BASE_NS = 1_700_000_000 * NS  # the first message's receive time; one message a millisecond
Item = tuple[Outgoing, int, int]  # a message, its stream's number, its receive time
FIGURES = ("subtasks", "decision_failures", "plans_failed", "undecided", "end_time_s",
           "all_parked_s", "vehicles", "stacks_done")


@pytest.fixture(scope="module")
def greedy_small() -> list[Item]:
    """What a fault-free greedy fill of small puts on the wire, numbered per stream (19
    decision failures: 3 plans failed, 16 choices without a goal)."""
    mission = Mission("small", MissionKind.FILL, Strategy.GREEDY)
    layout = load_layout("small")
    stream = recorded_run(mission, layout, engine_options(mission, layout, None))[1]
    count: Counter = Counter()
    items = []
    for k, o in enumerate(stream):
        count[o.key, o.sender] += 1
        items.append((o, count[o.key, o.sender], BASE_NS + k * 1_000_000))
    return items


def write(path: Path, items: list[Item]) -> Path:
    """A segment as a recorder writes it (the run's description first)."""
    writer = RecordingWriter(path)
    writer.describe(next(o.message for o, _, _ in items if isinstance(o.message, MissionInfo)))
    for o, seq, log_ns in items:
        writer.write(o.key, encode(o.message, o.sender, seq, o.sim_time), log_ns, o.sim_time)
    writer.close()
    return path


def recorded(run_dir: Path, items: list[Item], unheard: range | None = None) -> Report:
    """The analysis of the items as recorded; `unheard`: positions sent while no recorder
    ran (the first recorder killed before them, the next started after)."""
    if unheard is None:
        write(run_dir / "run.mcap", items)
    else:
        write(run_dir / "run.mcap", items[:unheard.start])
        info = items[0][0]  # a later recorder asks the dispatcher what the run is
        write(run_dir / "run-2.mcap", [(info, 0, items[unheard.stop][2] - 1),
                                       *items[unheard.stop:]])
    return analyze(read_recording(run_dir))


def figures(report: Report) -> dict:
    return {k: getattr(report, k) for k in FIGURES}


def position(items: list[Item], cls: type, nth: int = 0, start: int = 0) -> int:
    return [k for k, (o, _, _) in enumerate(items) if isinstance(o.message, cls)
            and k >= start][nth]


def kinds(items: list[Item]) -> set[type]:
    return {type(o.message) for o, _, _ in items}


def test_a_window_without_a_recorder_takes_the_dispatchers_record(greedy_small, tmp_path):
    items = greedy_small
    whole = recorded(tmp_path / "whole", items)
    start = position(items, DecisionFailure, 1) - 30
    unheard = range(start, start + 200)
    assert {SubtaskEvent, StackDone, DecisionFailure, Progress} <= \
        kinds(items[unheard.start:unheard.stop])
    split = recorded(tmp_path / "split", items, unheard)
    assert split.recorder_gaps and split.messages_not_recorded > 0
    assert figures(split) == figures(whole) and split.incomplete == []
    assert (whole.decision_failures, whole.plans_failed) == (19, 3)
    assert split.numbers_lines() == whole.numbers_lines()
    # Without the dispatcher's result, nothing tells what was sent then: the analysis says so.
    cut = [it for it in items if not isinstance(it[0].message, MissionDone)]
    lost = {cls: sum(isinstance(o.message, cls) for o, _, _ in items[unheard.start:unheard.stop])
            for cls in (SubtaskEvent, DecisionFailure, StackDone)}
    unfinished = recorded(tmp_path / "unfinished", cut, unheard)
    assert lost[DecisionFailure] == 1 and lost[SubtaskEvent] > 1 and lost[StackDone] >= 1
    assert unfinished.incomplete == [f"{lost[SubtaskEvent]} subtasks not recorded",
                                     "1 announced decision failure not recorded",
                                     f"{lost[StackDone]} stack{'s' * (lost[StackDone] > 1)} "
                                     "done not recorded"]
    assert unfinished.subtasks == whole.subtasks - lost[SubtaskEvent]
    assert unfinished.numbers_lines()[-4:] == [
        "  incomplete         these figures miss what no recorder or record kept:",
        *(f"                     {why}" for why in unfinished.incomplete)]


def restart_point(items: list[Item]) -> int:
    """Just after the first progress report, after the third failure, that counts the failures
    before it: a dispatcher announces each before reporting it, but an in-process recording
    holds a failure at the later instant it was decided for (sim-time order)."""
    return next(k + 1 for k, (o, _, _) in enumerate(items)
                if k > position(items, DecisionFailure, 2) and isinstance(o.message, Progress)
                and o.message.failures == sum(isinstance(i.message, DecisionFailure)
                                              for i, _, _ in items[:k]))


def restarted(items: list[Item], at: int) -> tuple[list[Item], int]:
    """The dispatcher killed just before position `at` and a new one picking the mission up
    (docs/faults.md): its messages numbered from 1 again on every key after its own mission
    message; its record holds what it announced only (in the order it decided it), its count
    of decision failures starts at 0. With the old one's count when it died (the failures it
    announced)."""
    info = items[0][0]
    old = sum(isinstance(o.message, DecisionFailure) for o, _, _ in items[:at])
    count: Counter = Counter({info.key: 1})
    new: list[Item] = [(info, 1, items[at][2] - 1)]
    for o, seq, log_ns in items[at:]:
        if o.sender == "dispatcher":
            count[o.key] += 1
            seq = count[o.key]
        if isinstance(o.message, Progress):
            o = dataclasses.replace(o, message=dataclasses.replace(
                o.message, failures=max(0, o.message.failures - old)))
        new.append((o, seq, log_ns))
    announced = [o.message for o, _, _ in new[1:] if o.sender == "dispatcher"]
    done = announced[-1]
    own = [SubtaskRecord.of_event(m).to_dict() for m in announced if isinstance(m, SubtaskEvent)]
    failures = [{"t": m.t, "vehicle": m.vehicle, "stage": m.stage, "reason": m.reason}
                for m in announced if isinstance(m, DecisionFailure)]
    record = dict(done.record, subtasks=[s for s in done.record["subtasks"] if s in own],
                  failures=failures, decision_failures=len(failures))
    o, seq, log_ns = new[-1]
    new[-1] = (dataclasses.replace(o, message=dataclasses.replace(done, record=record)), seq,
               log_ns)
    return items[:at] + new, old


def test_a_restarted_dispatchers_figures_are_added(greedy_small, tmp_path):
    items = greedy_small
    at = restart_point(items)
    run, old_count = restarted(items, at)
    whole = recorded(tmp_path / "whole", items)
    (restart,) = dispatcher_restarts(read_recording(write(tmp_path / "run.mcap", run)))
    assert restart.at_ns == run[at][2] and not restart.unrecorded
    both = recorded(tmp_path / "both", run)
    assert 0 < old_count < whole.decision_failures
    assert figures(both) == figures(whole) and both.incomplete == []
    # Each counted its own failures and announced each (the old one to its last report).
    new_count = whole.decision_failures - old_count
    assert [(c.dispatcher, c.announced, c.final) for c in both.failure_counts] == \
        [(1, old_count, False), (2, new_count, True)]
    assert both.failure_counts[1].counted == new_count and both.messages_whole


def test_a_dispatcher_that_died_while_no_recorder_ran_leaves_its_figures_incomplete(
        greedy_small, tmp_path):
    """The old dispatcher's last subtask and the new one's first messages, its first
    progress report (number 1) among them, were sent while no recorder ran."""
    items = greedy_small
    at = restart_point(items)
    run, old_count = restarted(items, at)
    last_old = max(k for k, (o, _, _) in enumerate(run[:at])
                   if isinstance(o.message, SubtaskEvent))
    unheard = range(last_old, position(run, Progress, 1, at))
    heard = run[:unheard.start]
    seen_count = max(o.message.failures for o, _, _ in heard if isinstance(o.message, Progress))
    report = recorded(tmp_path / "run", run, unheard)
    assert report.incomplete == ["dispatcher 1 of 2 died while no recorder ran"]
    whole = recorded(tmp_path / "whole", items)
    assert report.subtasks == whole.subtasks - 1  # the old one's last: in no record
    # The failures announced as recorded or in the new one's record: not the old one's
    # unheard; its count is not judged (what it sent last is unknown), the new one's is.
    old_unheard = sum(isinstance(o.message, DecisionFailure) for o, _, _ in run[last_old:at])
    assert report.decision_failures == whole.decision_failures - old_unheard
    assert report.plans_failed == whole.plans_failed - sum(
        isinstance(o.message, DecisionFailure) and o.message.stage == "plan"
        for o, _, _ in run[last_old:at])
    assert seen_count > 0 and [c.known for c in report.failure_counts] == [False, True]
    assert report.failure_counts[1].counted == whole.decision_failures - old_count
    assert report.messages_whole
    assert report.work_done  # every stack is in the new record
    text = "\n".join(report.numbers_lines())
    assert "incomplete         these figures miss" in text and "dispatcher 1 of 2 died" in text


def test_a_dispatcher_that_announced_its_last_stacks_while_no_recorder_ran(greedy_small,
                                                                          tmp_path):
    """The recorder is back before the old dispatcher dies, but that one announced no stack
    after the window: its stacks announced then have no later number to count them by. The
    new dispatcher's record has them; the figures say the old one's may be short."""
    items = greedy_small
    at = restart_point(items)
    run, _ = restarted(items, at)
    last_stack = max(k for k, (o, _, _) in enumerate(run[:at]) if isinstance(o.message, StackDone))
    unheard = range(last_stack - 40, last_stack + 1)
    assert at - unheard.stop > 0 and not any(isinstance(o.message, StackDone)
                                             for o, _, _ in run[unheard.stop:at])
    report = recorded(tmp_path / "run", run, unheard)
    assert not dispatcher_restarts(read_recording(tmp_path / "run"))[0].unrecorded
    unseen = sorted(f"{o.message.cluster}#{o.message.index}"
                    for o, _, _ in run[unheard.start:unheard.stop]
                    if isinstance(o.message, StackDone))
    assert unseen and report.stacks_not_recorded == unseen
    assert report.stacks_lost == [] and report.work_done and report.passed, report.lines()
    (tail,) = [why for why in report.incomplete if why.startswith("any ")]
    assert "stacks done sent after the last recorded, while no recorder ran, are not " \
        "counted (dispatcher 1 of 2)" in tail


def test_a_killed_recorder_leaves_the_numbers_of_the_run_without_faults(tmp_path, capsys):
    """Real processes on the fast clock, the recorder killed at 400 s and another started
    2 s (wall) later: the same mission, the same record, the same figures."""
    reference = run_json(capsys, "--out", str(tmp_path / "reference"))
    assert main(["run", "--layout", "small", "--json", "--faults", "kill_recorder",
                 "--out", str(tmp_path / "killed")]) == 0
    killed = json.loads(capsys.readouterr().out)
    assert killed["digest"] == reference["digest"]
    for key in ("end_time_s", "all_parked_s", "stacks_done", "subtasks", "decision_failures",
                "plans_failed", "undecided", "waiting_s", "stopped_s", "postponed_s"):
        assert killed[key] == pytest.approx(reference[key]), key
    # Per forklift, figure by figure (approx compares no nested structures).
    assert [v["vehicle"] for v in killed["vehicles"]] == \
        [v["vehicle"] for v in reference["vehicles"]]
    for mine, theirs in zip(killed["vehicles"], reference["vehicles"], strict=True):
        assert mine.keys() == theirs.keys()
        for figure, value in theirs.items():
            assert mine[figure] == pytest.approx(value), (mine["vehicle"], figure)
    report = analyze_json(capsys, tmp_path / "killed")
    assert len(report["segments"]) == 2 and report["recorder_gaps"]
    assert report["incomplete"] == [] and report["vehicles"] == killed["vehicles"]
