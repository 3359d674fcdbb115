"""Every decision failure the dispatcher counts is announced (docs/metrics.md): a recording
holds as many dispatch.failure messages as the mission's count, in process and with
processes, for a mission that finished and one that did not; `fleet analyze` fails the
messages verdict of a recording where a failure counted was not announced."""

import dataclasses
import threading

import pytest

from fleet.analysis.analyze import analyze
from fleet.analysis.failure_count import FailureCount
from fleet.dispatching.decision import Strategy
from fleet.mission.engine import engine_options
from fleet.mission.faults import load_scenario
from fleet.mission.spec import Mission, MissionKind
from fleet.recording.inprocess import Outgoing, recorded_run, write_recording
from fleet.recording.reader import read_recording
from fleet.runtime.local_run import RunSpec, run_processes
from fleet.wire.protocol import DecisionFailure, MissionDone, MissionStopped
from fleet.world.layout_file import load_layout

SMALL = load_layout("small")
# A greedy fill of small with a forklift broken down for good: 41 decision failures, 35 of
# them choices without a goal.
FILL = Mission("small", MissionKind.FILL, Strategy.GREEDY, 2, 0)
BREAKDOWN = load_scenario("vehicle_breakdown")


def in_process(stop_after: int | None = None) -> list[Outgoing]:
    """What the greedy fill with the breakdown publishes; `stop_after`: asked to stop after
    that many committed subtasks (a mission that does not finish)."""
    stop = threading.Event()

    def progress(done, total, t, failures):
        nonlocal stop_after
        if stop_after is not None:
            stop_after -= 1
            if stop_after == 0:
                stop.set()

    options = engine_options(FILL, SMALL, None, progress)
    return recorded_run(FILL, SMALL, options, scenario=BREAKDOWN, stop=stop)[1]


@pytest.fixture(scope="module")
def finished() -> list[Outgoing]:
    return in_process()


@pytest.fixture(scope="module")
def stopped() -> list[Outgoing]:
    return in_process(stop_after=40)


def judged(stream: list[Outgoing], tmp_path):
    write_recording(tmp_path / "run.mcap", stream, SMALL)
    recording = read_recording(tmp_path / "run.mcap")
    return recording, analyze(recording)


def the(stream: list[Outgoing], cls: type):
    return [o.message for o in stream if isinstance(o.message, cls)]


def test_each_failure_of_a_finished_mission_is_announced(finished, tmp_path):
    recording, report = judged(finished, tmp_path)
    (done,) = the(finished, MissionDone)
    announced = [m for _, m in recording.of(DecisionFailure)]
    assert done.ok and len(announced) == done.record["decision_failures"] == 41
    assert report.decision_failures == len(announced) == len(done.record["failures"])
    assert report.failure_counts == [FailureCount(1, 41, 41, final=True, known=True)]
    assert report.messages_whole and report.passed, report.verdict_lines()
    # Each names its forklift, the instant decided for, its stage and why.
    assert {"score", "plan"} <= {m.stage for m in announced} <= {"score", "plan", "dispatch"}
    assert {m.vehicle for m in announced} <= {1, 2}
    assert all(m.reason for m in announced)
    assert report.decision_failures - report.plans_failed == 35  # choices without a goal


def test_each_failure_of_a_mission_that_did_not_finish_is_announced(stopped, tmp_path):
    recording, report = judged(stopped, tmp_path)
    (said,) = the(stopped, MissionStopped)
    assert not report.finished
    assert said.decision_failures == len(recording.of(DecisionFailure)) > 0
    assert report.failure_counts == [FailureCount(1, said.decision_failures,
                                                  said.decision_failures, True, True)]
    assert report.messages_whole


def unannounced(stream: list[Outgoing], nth: int) -> list[Outgoing]:
    """The stream as a dispatcher that counted its nth failure without announcing it would
    have sent it: the message gone (the later ones numbered on) and not in its record."""
    failures = [k for k, o in enumerate(stream) if isinstance(o.message, DecisionFailure)]
    gone = stream[failures[nth]].message
    out = [o for k, o in enumerate(stream) if k != failures[nth]]
    done = out[-1].message
    if done.ok:
        record = done.record
        kept = list(record["failures"])
        kept.remove({"t": gone.t, "vehicle": gone.vehicle, "stage": gone.stage,
                     "reason": gone.reason})
        out[-1] = dataclasses.replace(out[-1], message=dataclasses.replace(
            done, record=dict(record, failures=kept)))
    return out


@pytest.mark.parametrize("run", ["finished", "stopped"])
def test_a_failure_counted_but_not_announced_fails_the_messages_verdict(run, request,
                                                                         tmp_path):
    stream = request.getfixturevalue(run)
    clean = judged(stream, tmp_path / "clean")[1]
    _, report = judged(unannounced(stream, 3), tmp_path / "damaged")
    count = clean.decision_failures
    assert report.messages_lost == 0  # no number is missing: the failure was never sent
    assert report.failures_unannounced == [FailureCount(1, count, count - 1, True, True)]
    assert not report.messages_whole and not report.passed
    assert report.to_json()["messages_whole"] is False
    messages = next(line for line in report.verdict_lines() if line.startswith("messages"))
    assert messages.startswith("messages           FAIL: ")
    assert messages.endswith(f"; dispatcher 1 counted {count} decision failures, announced "
                             f"{count - 1}")


def test_a_restarted_dispatcher_announces_its_own_failures_with_processes(tmp_path):
    """The dispatcher killed and started again (real processes, the fast clock): each
    counted its own failures from 0 and announced each."""
    name = "kill_dispatcher"
    outcome = run_processes(RunSpec(FILL, 2, tmp_path, faults=load_scenario(name),
                                    faults_source=name))
    assert outcome.error == "" and outcome.done.ok
    recording = read_recording(tmp_path)
    report = analyze(recording)
    assert report.passed, report.verdict_lines()
    first, second = report.failure_counts
    assert first.known and second.final and first.agrees and second.agrees
    assert first.announced > 0 and second.announced > 0, report.failure_counts
    assert second.counted == outcome.done.record["decision_failures"]
    assert report.decision_failures == len(recording.of(DecisionFailure)) == \
        first.announced + second.announced > 0
