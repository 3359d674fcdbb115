"""Every shipped fault scenario on paper with four forklifts, as real processes on the fast
clock: the mission completes, its recording passes every verdict, and the record equals the
in-process reference run of the same scenario bit for bit (faults are detected the way they
would be anyway, at their sim instants)."""

import functools

import pytest
from mission_check import journal_overlaps

from fleet.analysis.analyze import analyze
from fleet.dispatching.decision import Strategy
from fleet.mission.engine import Engine, engine_options
from fleet.mission.faults import builtin_scenarios, load_scenario
from fleet.mission.freeze import ScheduledPacer
from fleet.mission.record import digest
from fleet.mission.spec import Mission, MissionKind
from fleet.recording.reader import read_recording
from fleet.runtime.local_run import RunSpec, run_processes
from fleet.wire.protocol import Halt, Resume, StackReopened, VehicleFault, ZoneClosed
from fleet.world.layout_file import load_layout
from reservation.journal import Journal

MISSION = Mission("paper", MissionKind.FILL, Strategy.ANN, 4, 0)


@functools.cache
def reference_digest(scenario: str | None) -> str:
    layout = load_layout("paper")
    pacer = ScheduledPacer(load_scenario(scenario)) if scenario else None
    engine = Engine(MISSION, engine_options(MISSION, layout, None), layout, pacer=pacer)
    return digest(engine.run())


@pytest.mark.parametrize("name", builtin_scenarios())
def test_a_fault_scenario_with_processes_completes_safely_as_the_reference(name, tmp_path):
    scenario = load_scenario(name)
    # Every kind at once runs behind access control too: restarted processes log in again,
    # the injector as the operator.
    outcome = run_processes(RunSpec(MISSION, 4, tmp_path, faults=scenario, faults_source=name,
                                    secure=name == "mixed"))
    assert outcome.error == "" and outcome.done.ok
    # Faults that change no sim time (a slow planner, a service restarted) leave the record
    # of the fault-free run; the others that of the in-process run of the same scenario. A
    # restarted dispatcher's record starts where it picked the mission up: no reference.
    moves = {f.kind.value for f in scenario.faults} & {
        "kill_vehicle", "stall_vehicle", "cut_link", "vehicle_breakdown", "close_zone"}
    restarted = any(f.service == "dispatcher" for f in scenario.faults)
    if not restarted:
        assert outcome.done.digest == reference_digest(name if moves else None)
    # The table never held a cell twice, and no request was applied twice, whatever restarted.
    assert journal_overlaps(tmp_path / "reservation.journal") == []
    ids = [c.request_id for c in Journal(tmp_path / "reservation.journal").replay().changes
           if c.request_id]
    assert len(ids) == len(set(ids))
    recording = read_recording(tmp_path)
    report = analyze(recording)
    assert report.passed, report.verdict_lines()
    assert (len(report.overlaps), len(report.outside_reservation), report.stacks_done,
            report.stacks_duplicated, report.stacks_lost) == (0, 0, 136, [], [])
    halted = {m.vehicle for _, m in recording.of(Halt)}
    resumed = {m.vehicle for _, m in recording.of(Resume)}
    logs = {p.name for p in (tmp_path / "logs").iterdir()}
    for fault in scenario.faults:
        kind, v = fault.kind.value, fault.vehicle
        if kind in ("kill_vehicle", "stall_vehicle", "cut_link", "vehicle_breakdown"):
            assert v in halted and v in resumed  # stopped, and moving again afterwards
        if kind == "kill_vehicle":
            assert f"agent-{v}-2.log" in logs
            assert "restarted: waiting for the dispatcher" in \
                (tmp_path / "logs" / f"agent-{v}-2.log").read_text()
        if kind == "vehicle_breakdown":
            states = [m.state for _, m in recording.of(VehicleFault) if m.vehicle == v]
            assert states == ["broken", "repaired"]
        if kind == "close_zone":
            (zone,) = [m for _, m in recording.of(ZoneClosed)]
            assert (zone.t0, zone.t1) == (fault.at, fault.until)
        if kind == "kill_service" and fault.service == "reservation":
            assert "serving" in (tmp_path / "logs" / "reservation-2.log").read_text()
        if kind == "kill_service" and fault.service == "dispatcher":
            log = (tmp_path / "logs" / "dispatcher-2.log").read_text()
            assert f"picked the mission up at t={fault.at:.2f}" in log
            # forklifts down then are where the dead one's journal stopped them
            down = sorted(f.vehicle for f in scenario.faults if f.vehicle is not None
                          and f.at < fault.at < f.until)
            said = f"forklift{'s' if len(down) > 1 else ''} {', '.join(map(str, down))} down"
            assert (said in log) == bool(down)
            assert len(outcome.done.record["stacks_done"]) == 136  # with those done before
        if kind == "kill_service" and fault.service == "recorder":
            assert (tmp_path / "run-2.mcap").exists() and len(recording.segments) == 2
        if kind == "slow_planner":
            assert "slow_planner" in (tmp_path / "logs" / f"agent-{v}.log").read_text()
    if "kill_vehicle" in {f.kind.value for f in scenario.faults}:
        assert list(recording.of(StackReopened))  # the killed forklift's delivery went back
