"""paper002's fault scenarios on an order mission (16 orders, four AGVs) as real processes on
zenoh: on the fast clock each completes with every order done once, its recording passes
every verdict, and its record equals the in-process run of the same scenario bit for bit; a
killed dispatcher's successor picks the mission up from its journal; on the real-time clock
every kind in one mission completes too (docs/faults.md)."""

from __future__ import annotations

import functools
from collections import Counter
from pathlib import Path

import pytest
from mission_check import journal_overlaps

from fleet.analysis.analyze import analyze
from fleet.dispatching.decision import Strategy
from fleet.mission.engine import Engine
from fleet.mission.faults import load_scenario
from fleet.mission.freeze import ScheduledPacer
from fleet.mission.record import digest
from fleet.mission.spec import ClockMode, Mission, MissionKind
from fleet.recording.reader import read_recording
from fleet.runtime.local_run import RunOutcome, RunSpec, run_processes
from fleet.wire.protocol import Halt, Resume, ZoneClosed
from fleet.world.layout_file import load_layout

MISSION = Mission("paper002", MissionKind.ORDERS, Strategy.NEAREST, 4, 0, orders=16)


@functools.cache
def reference_digest(scenario: str) -> str:
    engine = Engine(MISSION, layout=load_layout("paper002"),
                    pacer=ScheduledPacer(load_scenario(scenario, "paper002")))
    return digest(engine.run())


def every_order_once(outcome: RunOutcome, run_dir: Path) -> None:
    """The final record has every order once; the recording passes every verdict and the
    reservation journal never held a cell twice."""
    assert outcome.error == "" and outcome.done.ok, outcome.error
    done = Counter(index for _, index, _ in outcome.done.record["stacks_done"])
    assert done == Counter(range(1, MISSION.orders + 1))
    assert journal_overlaps(run_dir / "reservation.journal") == []
    report = analyze(read_recording(run_dir))
    assert report.passed, report.verdict_lines()
    assert (len(report.overlaps), len(report.outside_reservation)) == (0, 0)


@pytest.mark.parametrize("name", ["kill_vehicle", "stall_vehicle", "cut_link",
                                  "vehicle_breakdown", "close_zone"])
def test_a_fault_on_an_order_mission_as_processes_is_the_reference(name, tmp_path):
    scenario = load_scenario(name, "paper002")
    outcome = run_processes(RunSpec(MISSION, 4, tmp_path, faults=scenario,
                                    faults_source=name))
    every_order_once(outcome, tmp_path)
    assert outcome.done.digest == reference_digest(name)
    recording = read_recording(tmp_path)
    (fault,) = scenario.faults
    if fault.vehicle is not None:
        assert fault.vehicle in {m.vehicle for _, m in recording.of(Halt) if not m.moving}
        assert fault.vehicle in {m.vehicle for _, m in recording.of(Resume)}
    else:
        (zone,) = [m for _, m in recording.of(ZoneClosed)]
        assert (zone.t0, zone.t1) == (fault.at, fault.until)


def test_a_killed_dispatcher_picks_the_order_mission_up_from_its_journal(tmp_path):
    """The dispatcher dies mid-mission; the new one replays the order book's journal, asks
    the AGVs what they hold, and finishes: the record it ends with has every order once, and
    the mission ends as the fault-free one does (the kill costs no sim time)."""
    outcome = run_processes(RunSpec(MISSION, 4, tmp_path, faults=load_scenario(
        "kill_dispatcher", "paper002"), faults_source="kill_dispatcher"))
    every_order_once(outcome, tmp_path)
    log = (tmp_path / "logs" / "dispatcher-2.log").read_text()
    assert "picked the mission up at t=140.00" in log
    assert (tmp_path / "dispatcher.journal").stat().st_size > 0
    fault_free = Engine(MISSION, layout=load_layout("paper002")).run()
    assert outcome.done.record["end_time_s"] == fault_free.end_time


def test_every_kind_in_one_order_mission_behind_access_control(tmp_path):
    """paper002's mixed scenario (a slow planner, a killed, a stalled, a cut-off and a
    broken-down AGV, a zone, and the reservation service, the recorder and the dispatcher
    killed in turn), every process logged in: every order once, every verdict passing."""
    outcome = run_processes(RunSpec(MISSION, 4, tmp_path, faults=load_scenario(
        "mixed", "paper002"), faults_source="mixed", secure=True))
    every_order_once(outcome, tmp_path)
    assert (tmp_path / "run-2.mcap").exists()  # the recorder was restarted
    assert "picked the mission up" in (tmp_path / "logs" / "dispatcher-2.log").read_text()
    assert "serving" in (tmp_path / "logs" / "reservation-2.log").read_text()


def test_every_kind_in_one_order_mission_on_the_real_time_clock(tmp_path):
    """The same at 20 times real time, where faults are noticed as they come (a restarted
    agent takes seconds of wall time to be back, and must be before the dispatcher dies):
    the mission completes with every order once and its recording passes every verdict; no
    AGV heard of its halt too late."""
    outcome = run_processes(RunSpec(MISSION, 4, tmp_path, ClockMode.REALTIME, 20.0,
                                    faults=load_scenario("mixed", "paper002"),
                                    faults_source="mixed"))
    every_order_once(outcome, tmp_path)
    recording = read_recording(tmp_path)
    assert {m.vehicle for _, m in recording.of(Halt) if not m.moving} >= {1, 2}
    assert list(recording.of(Resume))
    for log in (tmp_path / "logs").glob("agent-*.log"):
        assert "came late" not in log.read_text(), log.name
