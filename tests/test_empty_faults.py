"""Empty missions take faults too (docs/faults.md): a claim cut short puts the stack back with
its goods still on it, and goods a forklift carries when it breaks down for good stay on it."""

import math

import pytest
from test_recovery import commit, drive_east

from fleet.analysis.analyze import analyze
from fleet.dispatching.decision import Strategy, TaskKind
from fleet.mission.engine import Engine, engine_options
from fleet.mission.faults import (
    Fault,
    FaultKind,
    Scenario,
    ScenarioError,
    builtin_scenarios,
    check_against,
    load_scenario,
)
from fleet.mission.freeze import Motion, ScheduledPacer, cascade
from fleet.mission.record import digest
from fleet.mission.spec import Mission, MissionKind
from fleet.planning.reservations import Interval, ReservationTable
from fleet.recording.inprocess import recorded_run, write_recording
from fleet.recording.reader import read_recording
from fleet.runtime.local_run import RunSpec, run_processes
from fleet.wire.protocol import GOODS, StackReopened
from fleet.world.layout_file import load_layout

SMALL = load_layout("small")
EMPTY = Mission("small", MissionKind.EMPTY, Strategy.ANN, 2, 0)


def fits_small(name: str) -> bool:
    """A shipped scenario that names only forklifts and cells the small layout has."""
    try:
        check_against(load_scenario(name), SMALL, len(SMALL.vehicle_starts))
    except ScenarioError:
        return False
    return True


def judged(scenario: Scenario, tmp_path):
    done, stream = recorded_run(EMPTY, SMALL, engine_options(EMPTY, SMALL, None),
                                scenario=scenario)
    write_recording(tmp_path / "run.mcap", stream, SMALL)
    recording = read_recording(tmp_path / "run.mcap")
    return done.record, recording, analyze(recording)


@pytest.mark.parametrize("name", [n for n in builtin_scenarios() if fits_small(n)])
def test_a_shipped_scenario_on_an_empty_mission_passes_every_verdict(name, tmp_path):
    _, _, report = judged(load_scenario(name), tmp_path)
    assert report.passed, report.verdict_lines()
    assert (report.stacks_done, report.stacks_duplicated, report.stacks_lost) == (24, [], [])


def fault_free_subtasks():
    return Engine(EMPTY, engine_options(EMPTY, SMALL, None), SMALL).run().subtasks


def test_a_claim_cut_short_leaves_the_goods_on_their_stack_to_claim_again(tmp_path):
    claim = next(s for s in fault_free_subtasks()
                 if s.kind is TaskKind.DELIVER and s.vehicle == 2 and s.t_i > 50)
    at = round((claim.t_i + claim.t_end) / 2, 2)  # on its way to the stack
    scenario = Scenario("cut claim", "", (Fault(FaultKind.KILL_VEHICLE, at, 2, 40.0),))
    record, recording, report = judged(scenario, tmp_path)
    reopened = [m for _, m in recording.of(StackReopened)]
    assert [(m.cluster, m.index, m.vehicle) for m in reopened] == \
        [(claim.target, claim.stack_index, 2)]
    assert report.passed, report.verdict_lines()
    assert report.stacks_done == 24  # claimed again, once
    done = [d for d in record["stacks_done"] if d[:2] == [claim.target, claim.stack_index]]
    assert len(done) == 1 and done[0][2] > at


def test_goods_a_forklift_carries_when_it_breaks_down_for_good_stay_on_it(tmp_path):
    """Its stack was emptied (the goods left it): done, and not to do again; the other
    forklift empties the rest. The goods never reach a station."""
    back = next(s for s in fault_free_subtasks()
                if s.kind is TaskKind.RETURN and s.vehicle == 1 and s.t_i > 100)
    claim = next(s for s in reversed(fault_free_subtasks())
                 if s.vehicle == 1 and s.kind is TaskKind.DELIVER and s.t_i < back.t_i)
    at = round((back.t_i + back.t_end) / 2, 2)
    scenario = Scenario("broken", "", (Fault(FaultKind.VEHICLE_BREAKDOWN, at, 1),))
    record, recording, report = judged(scenario, tmp_path)
    # A delivery decided ahead for after the return is cut and goes back; the stack whose
    # goods it carries does not.
    reopened = [(m.cluster, m.index, m.vehicle) for _, m in recording.of(StackReopened)]
    assert (claim.target, claim.stack_index, 1) not in reopened
    assert all(v == 1 for _, _, v in reopened)
    assert [claim.target, claim.stack_index] in [d[:2] for d in record["stacks_done"]]
    assert report.passed and report.stacks_done == 24, report.verdict_lines()
    assert all(s["vehicle"] == 2 for i, s in enumerate(record["subtasks"])
               if s["t_i"] > at and i not in record["cut_subtasks"])


def test_who_would_cross_a_claimed_cell_stops_when_the_claim_is_cancelled():
    """Forklift 1 drives to claim the goods on (3, 0); forklift 2 planned to drive over that
    cell once they are gone. The claim is cancelled: the goods stay, so 2 stops too."""
    table = ReservationTable()
    a = drive_east(1, 1, range(0, 3), t0=0.0)  # to the stack (3, 0), claimed until t=10
    commit(table, a)
    assert table.commit(GOODS, [Interval((3, 0), 0.0, 10.0)]).ok
    b = drive_east(2, 0, range(-12, 6), t0=0.0)  # reaches (3, 0) at t=13 or so
    commit(table, b)
    motions = {1: Motion(1, a.start, (a,)), 2: Motion(2, b.start, (b,))}
    claims = {1: [(3, 0)]}
    kept = cascade(table, 0.5, motions, {1}, {(3, 0): 1}.get, frozenset(), -math.inf,
                   lambda vehicle: claims.get(vehicle, ()))
    assert set(kept.freezes) == {1, 2}
    fill = cascade(table, 0.5, motions, {1}, {(3, 0): 1}.get)  # goods that never came
    assert set(fill.freezes) == {1}


@pytest.mark.parametrize("name", ["kill_vehicle", "kill_dispatcher"])
def test_an_empty_mission_of_processes_takes_faults_as_the_reference_does(name, tmp_path):
    """A claim cut short with processes gives the in-process record bit for bit; a restarted
    dispatcher picks an empty mission up from the goods the store still holds."""
    scenario = load_scenario(name)
    outcome = run_processes(RunSpec(EMPTY, 2, tmp_path, faults=scenario, faults_source=name))
    assert outcome.error == "" and outcome.done.ok
    report = analyze(read_recording(tmp_path))
    assert report.passed and report.stacks_done == 24, report.verdict_lines()
    if name == "kill_dispatcher":
        assert "picked the mission up at t=350.00" in \
            (tmp_path / "logs" / "dispatcher-2.log").read_text()
        assert len(outcome.done.record["stacks_done"]) == 24  # with those done before
    else:
        reference = Engine(EMPTY, engine_options(EMPTY, SMALL, None), SMALL,
                           pacer=ScheduledPacer(scenario)).run()
        assert outcome.done.digest == digest(reference)
