"""A dispatcher that dies while forklifts are down (docs/faults.md, "A restarted dispatcher
picks the mission up"): it journals where each one stopped, and its successor reads it
there and moves them on when they come back, in process and as real processes."""

from __future__ import annotations

import functools
from collections import Counter

import msgpack
import pytest
from test_order_faults import Parked

from dispatcher.pickup import journaled
from dispatcher.work_journal import WorkJournal
from fleet.analysis.analyze import analyze
from fleet.cli import main
from fleet.dispatching.decision import Strategy, TaskKind
from fleet.errors import UserError
from fleet.mission.engine import Engine, EngineOptions
from fleet.mission.faults import load_scenario
from fleet.mission.freeze import BREAKDOWN, Freeze, ScheduledPacer
from fleet.mission.halt_log import Halted, Resumed, from_record, is_halt_record, standing
from fleet.mission.order_work import OrderWork
from fleet.mission.pickup import HeldLeg, recovered_orders
from fleet.mission.spec import ClockMode, Mission, MissionKind
from fleet.recording.inprocess import Interrupted
from fleet.recording.reader import read_recording
from fleet.runtime.local_run import RunSpec, run_processes
from fleet.wire.protocol import Halt, Resume
from fleet.world.layout_file import load_layout

PAPER002 = load_layout("paper002")
MISSION = Mission("paper002", MissionKind.ORDERS, Strategy.NEAREST, 4, 0, orders=16)


class Log:
    """A journal kept in `records`, each as msgpack gives it back."""

    def __init__(self, records: list) -> None:
        self.records = records

    def append(self, record: list) -> None:
        self.records.append(msgpack.unpackb(msgpack.packb(record)))


def _down_engine(mission: Mission, records: list) -> Engine:
    """An engine of AGV 2 killed that journals into `records`."""
    return Engine(mission, EngineOptions(work_log=Log(records)), PAPER002,
                  pacer=ScheduledPacer(load_scenario("kill_vehicle", "paper002")))


@functools.cache
def a_freeze(step: bool) -> Freeze:
    """A freeze as an engine made it: with the maneuver in progress, or at rest."""
    records: list = []
    engine = _down_engine(MISSION, records)
    engine.run()
    (halted,) = [from_record(r) for r in records if r[0] == "halted"]
    freeze = halted.freeze
    if step:
        assert freeze.step is not None  # the shipped kill is in the middle of a delivery
        return freeze
    return Freeze(freeze.vehicle, freeze.t, freeze.cells, None, freeze.pose, freeze.t)


@pytest.mark.parametrize("step", [True, False])
@pytest.mark.parametrize("battery", [None, 63.25])
def test_a_halt_record_reads_back_as_written(step, battery):
    halted = Halted(a_freeze(step), BREAKDOWN, TaskKind.RETURN, battery)
    raw = msgpack.unpackb(msgpack.packb(halted.to_record()))
    assert is_halt_record(raw) and from_record(raw) == halted
    assert from_record(msgpack.unpackb(msgpack.packb(Resumed(3, 12.5).to_record()))) == \
        Resumed(3, 12.5)


def test_the_forklifts_standing_are_those_halted_last_and_not_resumed():
    freeze = a_freeze(False)

    def halted(vehicle: int, t: float) -> list:
        return Halted(Freeze(vehicle, t, freeze.cells, None, freeze.pose, t), "agent killed",
                      TaskKind.DELIVER).to_record()

    records = [halted(1, 5.0), halted(2, 6.0), Resumed(1, 9.0).to_record(), halted(1, 20.0),
               Resumed(2, 21.0).to_record(), halted(3, 22.0)]
    down = standing(records)
    assert sorted(down) == [1, 3] and down[1].freeze.t == 20.0


@pytest.mark.parametrize(("change", "named"), [
    (lambda r: r[:5], "9 fields, not 4"),
    (lambda r: [*r[:1], 0, *r[2:]], "vehicle must be a number from 1"),
    (lambda r: [*r[:2], -1.0, *r[3:]], "t must be a time in seconds"),
    (lambda r: [*r[:4], "fly", *r[5:]], "unknown task kind 'fly'"),
    (lambda r: [*r[:5], "1,2,Q", *r[6:]], "pose '1,2,Q' must look like"),
    (lambda r: [*r[:7], [[1]], *r[8:]], "a cell is [col, row]"),
    (lambda r: [*r[:8], ["drive"], r[9]], "the maneuver in progress is malformed"),
    (lambda r: [*r[:9], 120.0], "battery must be a charge within 0..100 %"),
    (lambda r: ["resumed", 1], "a resumed record has 2 fields, not 1"),
])
def test_a_malformed_halt_record_is_refused_naming_what_is_wrong(change, named):
    raw = msgpack.unpackb(msgpack.packb(
        Halted(a_freeze(True), "agent killed", TaskKind.DELIVER, 50.0).to_record()))
    with pytest.raises(ValueError, match=named.replace("[", r"\[").replace("(", r"\(")):
        from_record(change(raw))


def test_a_journal_splits_into_who_is_down_and_the_order_book(tmp_path):
    """The halt records tell who is down; the rest replay the book as before; a malformed
    one is refused naming the file, and nothing is cut off it."""
    records: list = []
    _down_engine(MISSION, records).run()
    assert [r[0] for r in records if is_halt_record(r)] == ["halted", "resumed"]
    journal = WorkJournal(tmp_path / "dispatcher.journal")
    for record in records[:next(i for i, r in enumerate(records) if r[0] == "resumed")]:
        journal.append(record)
    down, book = journaled(journal)
    assert list(down) == [2] and not any(is_halt_record(r) for r in book)
    OrderWork.replayed(PAPER002, MISSION, 4, book)  # the book's own records replay
    journal.append(["halted", 2, 1.0])
    size = journal.path.stat().st_size
    with pytest.raises(UserError, match=r"dispatcher\.journal: not a dispatcher's journal: "
                                        r"a halted record has 9 fields, not 2"):
        journaled(WorkJournal(journal.path))
    assert journal.path.stat().st_size == size


def test_a_kill_of_the_dispatcher_as_a_forklift_stops_is_refused_by_name(tmp_path, capsys):
    """The injector would apply both at one tick and the dispatcher die before it saw the
    forklift stop; at different instants, or as a forklift comes back, it is fine."""
    faults = ('[[fault]]\nkind = "cut_link"\nat = 50.0\nvehicle = 3\nduration = 40.0\n'
              '[[fault]]\nkind = "kill_service"\nat = {at}\nservice = "dispatcher"\n')
    path = tmp_path / "same.toml"
    path.write_text(faults.format(at=50.0))
    assert main(["faults", "check", str(path)]) == 2
    assert "fault 2 (kill_service of dispatcher at 50 s): fault 1 (cut_link of forklift 3 " \
           "at 50 s for 40 s) starts at the same instant" in capsys.readouterr().err
    for at in (50.5, 90.0):
        path.write_text(faults.format(at=at))
        assert main(["faults", "check", str(path)]) == 0


class _KilledAt(ScheduledPacer):
    """A scenario's pacer whose dispatcher dies at t: the run ends before its first
    decision from t on."""

    def __init__(self, scenario, t: float) -> None:
        super().__init__(scenario)
        self.t = t

    def before_decision(self, t_next: float, t_free: dict[int, float]) -> dict[int, float]:
        if t_next >= self.t:
            raise Interrupted("killed")
        return t_free


def test_a_restarted_engine_takes_the_agvs_down_from_the_journal_and_moves_them_on():
    """The engine dies while AGV 2's agent is dead and AGV 1 is broken down; a new one reads
    where they stopped, asks only the others, and resumes both at the scenario's instants:
    every order once, and the mission ends when the one never killed ends."""
    scenario = load_scenario("kill_dispatcher_while_down", "paper002")
    (killed,) = [f.at for f in scenario.faults if f.service == "dispatcher"]
    records: list = []
    first = Engine(MISSION, EngineOptions(work_log=Log(records)), PAPER002,
                   pacer=_KilledAt(scenario, killed))
    with pytest.raises(Interrupted):
        first.run()
    down = standing(r for r in records if is_halt_record(r))
    assert sorted(down) == [1, 2]
    assert (down[1].cause, down[2].cause) == (BREAKDOWN, "agent killed")
    assert all(h.freeze == first.faults.down[v].freeze for v, h in down.items())
    held = [HeldLeg.down(down[v]) if v in down else
            HeldLeg(v, slot.pose, (first.faults.driven[v] or [None])[-1], False, "")
            for v, slot in first.fleet.items()]
    work = OrderWork.replayed(PAPER002, MISSION, 4,
                              [r for r in records if not is_halt_record(r)], Log(records))
    later = ScheduledPacer(scenario)
    later.pending = [t for t in later.pending if t > killed]
    second = Engine(MISSION, EngineOptions(work_log=Log(records)), PAPER002,
                    Parked(first.executor.store), later,
                    recovered_orders(work, held, killed))
    # Each goes on with what it was to do, a shelf aboard as it had (told when resumed).
    assert {v: second.fleet[v].next_task for v in down} == \
        {v: first.fleet[v].next_task for v in down}
    assert any(first.work.loaded(first.fleet[v].next_task) for v in down)
    record = second.run()
    assert Counter(i for _, i, _ in record.stacks_done) == Counter(range(1, 17))
    ups = {f.vehicle: f.until for f in scenario.faults if f.vehicle is not None}
    assert sorted(record.resumes) == sorted(ups.items())
    assert standing(r for r in records if is_halt_record(r)) == {}  # back, and journaled so
    reference = Engine(MISSION, layout=PAPER002, pacer=ScheduledPacer(scenario)).run()
    assert record.end_time == reference.end_time


def test_processes_pick_an_order_mission_up_with_agvs_down(tmp_path):
    """As real processes: the new dispatcher finds AGV 2 dead and AGV 1 broken down in the
    journal, waits for neither, and resumes each when it is back; every order once, every
    verdict passing, and the mission ends when the in-process run of the scenario does."""
    scenario = load_scenario("kill_dispatcher_while_down", "paper002")
    outcome = run_processes(RunSpec(MISSION, 4, tmp_path, faults=scenario,
                                    faults_source="kill_dispatcher_while_down"))
    assert outcome.error == "" and outcome.done.ok, outcome.error
    assert Counter(i for _, i, _ in outcome.done.record["stacks_done"]) == \
        Counter(range(1, 17))
    log = (tmp_path / "logs" / "dispatcher-2.log").read_text()
    assert "picked the mission up at t=70.00: 3 stacks done; forklifts 1, 2 down" in log
    recording = read_recording(tmp_path)
    report = analyze(recording)
    assert report.passed, report.verdict_lines()
    assert {m.vehicle for _, m in recording.of(Halt) if not m.moving} == {1, 2}
    assert sorted((m.vehicle, m.t) for _, m in recording.of(Resume)) == [(1, 95.3), (2, 90.0)]
    reference = Engine(MISSION, layout=PAPER002, pacer=ScheduledPacer(scenario)).run()
    assert outcome.done.record["end_time_s"] == reference.end_time


def test_processes_pick_an_order_mission_up_with_agvs_down_on_the_real_time_clock(tmp_path):
    """At 20 times real time the repair may come while no dispatcher listens: the new one
    asks the broken AGV, and every order is done once with every verdict passing."""
    scenario = load_scenario("kill_dispatcher_while_down", "paper002")
    outcome = run_processes(RunSpec(MISSION, 4, tmp_path, ClockMode.REALTIME, 20.0,
                                    faults=scenario,
                                    faults_source="kill_dispatcher_while_down"))
    assert outcome.error == "" and outcome.done.ok, outcome.error
    assert Counter(i for _, i, _ in outcome.done.record["stacks_done"]) == \
        Counter(range(1, 17))
    assert "picked the mission up" in (tmp_path / "logs" / "dispatcher-2.log").read_text()
    recording = read_recording(tmp_path)
    report = analyze(recording)
    assert report.passed, report.verdict_lines()
    assert {m.vehicle for _, m in recording.of(Halt) if not m.moving} == {1, 2}
    assert {m.vehicle for _, m in recording.of(Resume)} == {1, 2}
