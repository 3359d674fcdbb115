"""Seed 004 as processes: one agent process per lifting AGV taking its cells from the real
reservation service and planning its own paths, the dispatcher tracking them, the recorder
writing the events; the run equals the in-process one and is judged from its recording."""

from pathlib import Path

import mcap.reader
import pytest
from mission_check import journal_overlaps

from dispatcher.remote004 import first_difference
from fleet.analysis.analyze004 import analyze004
from fleet.cli import main
from fleet.dispatching.decision import Strategy
from fleet.errors import UserError
from fleet.mission.faults import Fault, FaultKind, load_scenario
from fleet.mission.faults004 import injected004
from fleet.mission.heat004 import history_heat
from fleet.mission.orders004 import Mission004, generate_orders
from fleet.mission.record import digest_of
from fleet.mission.record004 import event_from_wire, event_to_wire, record_of
from fleet.mission.resume004 import FaultInstant, where_it_died
from fleet.mission.spec import ClockMode, Mission, MissionKind
from fleet.mission.tracking004 import (
    BrokeDown,
    MadeWay,
    Met,
    Moved,
    Replanned,
    TrackingParams,
)
from fleet.planning.astar004 import Costs
from fleet.planning.reservations import INF, Interval, ReservationTable
from fleet.recording.reader import read_recording
from fleet.recording.writer import RecordingWriter, mission_info
from fleet.runtime.bus import wait_alive
from fleet.runtime.local_run import RunSpec, run_processes
from fleet.wire.protocol import AgvEvent, CellRequest, MissionInfo, RouteRequest, encode
from fleet.wire.topics import Keys
from fleet.world.floor004 import Floor004Shape, build
from fleet.world.layout_file import load_layout
from reservation.journal import Journal

SHAPE = dict(blocks_across=4, double_rows=4, stations=2, piles_per_side=2, block_width=3,
             transit_rows=2)


def small_floor_file(folder: Path) -> Path:
    """A small seed-004 floor as a layout file (its numbers; the loader builds the floor)."""
    floor = build(Floor004Shape(**SHAPE), "small004")
    numbers = "\n".join(f"{k} = {v}" for k, v in SHAPE.items())
    path = folder / "small004.toml"
    path.write_text(f'name = "small004"\ncell_size = 1.0\nvehicle = {{ kind = "lifting-agv" }}\n'
                    f"[bounds]\nx = [0.0, {floor.width}.0]\ny = [0.0, {floor.height}.0]\n"
                    f"[floor004]\n{numbers}\n")
    return path


def test_fast_mode_processes_equal_the_inprocess_run_and_the_recording_is_judged(tmp_path):
    layout_file = small_floor_file(tmp_path)
    floor = load_layout(str(layout_file)).floor
    vehicles, orders, seed = 8, 20, 2
    # With the heat cost: every agent plans on the T_value the dispatcher's history run gave.
    heat = history_heat(floor, vehicles, orders, seed)
    reference = Mission004(floor, vehicles, generate_orders(floor, orders, seed),
                           TrackingParams(costs=Costs(heat=2.0, t_value=heat))).run()
    assert any(isinstance(e, Replanned) for e in reference.events)  # the remote planner replans
    assert any(isinstance(e, Met) for e in reference.events)
    assert reference.events != Mission004(floor, vehicles, generate_orders(
        floor, orders, seed)).run().events  # the heat changed the paths
    mission = Mission(str(layout_file), MissionKind.ORDERS, Strategy.NEAREST, vehicles, seed,
                      orders=orders, heat=2.0)
    run_dir = tmp_path / "run"
    refusals: list[str] = []

    def intrude(session, keys, launcher) -> None:
        """Requests no AGV may act on, mid-run: each refused with a reason, nothing taken."""
        assert wait_alive(session, keys.vehicle_alive(1), 60.0)
        for payload in (b"\x93garbage", encode(CellRequest("x1", 1, (999, 3), 0.0, True),
                                                  "dispatcher", 1, 0.0),
                        encode(CellRequest("x2", 2, (1, 1), 0.0, True), "dispatcher", 2, 0.0),
                        encode(RouteRequest("x3", 1, 0.0, "M1", (1, 1), (2, 2), 1,
                                            held=[(2, 1, 1, 5.0, 1.0)]), "dispatcher", 3, 0.0),
                        encode(RouteRequest("x4", 1, 0.0, "M1", (1, 1), (2, 2), 1,
                                            held=[(2, 1, 1, k, k + 0.5) for k in range(5)]),
                               "dispatcher", 4, 0.0)):
            for reply in session.get(keys.vehicle_task(1), payload=payload, timeout=10.0):
                assert reply.ok is None
                refusals.append(reply.err.payload.to_string())

    outcome = run_processes(RunSpec(mission, vehicles, run_dir), on_ready=intrude)
    assert [r.split(":")[0] for r in refusals] == ["rejected", "refused", "a request for AGV 2 "
                                                   "sent to AGV 1", "refused", "refused"], refusals
    assert "must have t0 < t1" in refusals[-2]  # the tables a plan was sent, not ones
    assert "holds cell (1, 1) more than 4 times" in refusals[-1]  # of this floor
    assert outcome.error == ""
    assert outcome.done.record == record_of(reference)  # move for move: the events' digest
    assert outcome.done.digest == digest_of(record_of(reference))
    # The store never held a cell for two AGVs at once, over the whole history.
    assert journal_overlaps(run_dir / "reservation.journal") == []
    with open(run_dir / "run.mcap", "rb") as f:  # the mcap library's own reader
        summary = mcap.reader.make_reader(f).get_summary()
    schemas = {c.topic: summary.schemas[c.schema_id].name for c in summary.channels.values()}
    assert schemas["fleet/default/dispatch/agv"] == "agv004.event"
    report = analyze004(read_recording(run_dir))
    assert report.passed and report.finished and report.heat_w == 2.0
    assert report.orders_picked == orders and report.clock == "fast"
    assert report.completion_s == reference.completion_s
    assert report.counts["cells"] == reference.counts["cells"]


FAULTS = """
[[fault]]
kind = "vehicle_breakdown"
at = 40.5
vehicle = 2
duration = 30.0

[[fault]]
kind = "close_zone"
at = 20.0
duration = 60.0
cells = "9,8..9,10"
"""


def test_the_real_time_clock_paces_the_instants_and_gives_the_fast_runs_events(tmp_path):
    """Sim time runs at 40 x wall time; what the AGVs do depends only on sim time, so the
    events are the fast run's whatever the machine's load (a late instant is counted), a
    breakdown and a closed zone included (the dispatcher strikes them at their instants)."""
    layout_file = small_floor_file(tmp_path)
    floor = load_layout(str(layout_file)).floor
    (tmp_path / "faults.toml").write_text(FAULTS)
    faults = load_scenario(tmp_path / "faults.toml").faults
    reference = Mission004(floor, 4, generate_orders(floor, 8, 5), faults=faults).run()
    struck = {type(e).__name__ for e in reference.events}
    assert {"BrokeDown", "Repaired", "ZoneClosed"} <= struck
    mission = Mission(str(layout_file), MissionKind.ORDERS, Strategy.NEAREST, 4, 5, orders=8)
    outcome = run_processes(RunSpec(mission, 4, tmp_path / "run", ClockMode.REALTIME, 40.0,
                                    faults_source=str(tmp_path / "faults.toml")))
    assert outcome.error == ""
    assert outcome.done.record == record_of(reference)
    timing = outcome.done.timing
    assert timing["speed"] == 40.0 and timing["instants"] > 100
    assert 0 <= timing["late"] <= timing["instants"]
    report = analyze004(read_recording(tmp_path / "run"))
    assert report.passed and report.clock == "realtime"
    assert report.faults == 2 and report.fault_breaches == []


KILL = """
[[fault]]
kind = "kill_vehicle"
at = 40.5
vehicle = 2
duration = 30.0
"""


@pytest.mark.parametrize("clock,speed", [(ClockMode.FAST, 1.0), (ClockMode.REALTIME, 40.0)])
def test_a_killed_agent_dies_at_its_instant_and_its_restart_gives_the_inprocess_run(
        clock, speed, tmp_path):
    """The injector kills AGV 2's agent when the tracker strikes it (t = 40.5, mid-mission)
    and starts a new one 30 s later; meanwhile the AGV stands holding its cell, the
    dispatcher lets go of the cell its last move left, and nobody asks the dead agent
    anything: the events are the in-process run's, where the kill is a stop told by its
    cause."""
    layout_file = small_floor_file(tmp_path)
    floor = load_layout(str(layout_file)).floor
    (tmp_path / "kill.toml").write_text(KILL)
    faults = load_scenario(tmp_path / "kill.toml").faults
    reference = Mission004(floor, 4, generate_orders(floor, 8, 5), faults=faults).run()
    down = [e for e in reference.events if isinstance(e, BrokeDown)]
    assert [(e.vehicle, e.t, e.until, e.cause) for e in down] == [(2, 40.5, 70.5,
                                                                   "agent killed")]
    # AGV 2 was on a leg when it was struck, and drove on after its agent came back
    assert any(isinstance(e, Moved) and e.vehicle == 2 and e.t0 < 40.5 for e in reference.events)
    assert any(isinstance(e, Moved) and e.vehicle == 2 and e.t0 >= 70.5
               for e in reference.events)
    mission = Mission(str(layout_file), MissionKind.ORDERS, Strategy.NEAREST, 4, 5, orders=8)
    outcome = run_processes(RunSpec(
        mission, 4, tmp_path / "run", clock, speed, faults=injected004(load_scenario(
            tmp_path / "kill.toml")), faults_source=str(tmp_path / "kill.toml"),
        clocked_agents=False))
    assert outcome.error == ""
    assert outcome.done.record == record_of(reference)
    assert [(a.what, a.t) for a in outcome.injected] == [("kill agent-2", 40.5),
                                                        ("restart agent-2", 70.5)]
    logs = sorted(p.name for p in (tmp_path / "run" / "logs").iterdir())
    assert "agent-2-2.log" in logs  # the new agent, which answered from t = 70.5 on
    report = analyze004(read_recording(tmp_path / "run"))
    assert report.passed and report.faults == 1 and report.fault_breaches == []
    assert journal_overlaps(tmp_path / "run" / "reservation.journal") == []


AGENT_FAULTS = {"stall_vehicle": ("agent stalled", "stall agent-2", "continue agent-2"),
                "cut_link": ("link lost", "cut the link of agent-2",
                             "restore the link of agent-2")}


# The cut lasts 3 s of wall time at speed 10: longer than the zenoh lease (1 s), so the
# router drops the agent's session and the agent comes back on a new one.
@pytest.mark.parametrize("kind,clock,speed", [("stall_vehicle", ClockMode.FAST, 1.0),
                                              ("cut_link", ClockMode.REALTIME, 10.0)])
def test_a_stalled_or_cut_off_agent_is_left_alone_until_its_fault_ends(kind, clock, speed,
                                                                        tmp_path):
    """The injector stops AGV 2's agent (SIGSTOP) or silences its zenoh link when the
    tracker strikes it, mid-leg, and continues it or restores the link 30 s later. The
    agent stays up but hears nothing meanwhile, so the dispatcher lets go of its cell and
    asks it nothing (a request to it would wait for an answer that cannot come before the
    fault's end, which waits for the request); the events are the in-process run's, where
    the fault is a stop told by its cause, and the recording passes every verdict."""
    layout_file = small_floor_file(tmp_path)
    floor = load_layout(str(layout_file)).floor
    scenario = tmp_path / "fault.toml"
    scenario.write_text(KILL.replace('"kill_vehicle"', f'"{kind}"'))
    cause, begin, end = AGENT_FAULTS[kind]
    faults = load_scenario(scenario).faults
    reference = Mission004(floor, 4, generate_orders(floor, 8, 5), faults=faults).run()
    down = [e for e in reference.events if isinstance(e, BrokeDown)]
    assert [(e.vehicle, e.t, e.until, e.cause) for e in down] == [(2, 40.5, 70.5, cause)]
    assert any(isinstance(e, Moved) and e.vehicle == 2 and e.t0 >= 70.5
               for e in reference.events)
    mission = Mission(str(layout_file), MissionKind.ORDERS, Strategy.NEAREST, 4, 5, orders=8)
    outcome = run_processes(RunSpec(
        mission, 4, tmp_path / "run", clock, speed, faults=injected004(load_scenario(scenario)),
        faults_source=str(scenario), clocked_agents=False))
    assert outcome.error == ""
    assert outcome.done.record == record_of(reference)
    assert [(a.what, a.t) for a in outcome.injected] == [(begin, 40.5), (end, 70.5)]
    logs = sorted(p.name for p in (tmp_path / "run" / "logs").iterdir())
    assert "agent-2-2.log" not in logs  # the same agent went on
    report = analyze004(read_recording(tmp_path / "run"))
    assert report.passed and report.faults == 1 and report.fault_breaches == []
    assert journal_overlaps(tmp_path / "run" / "reservation.journal") == []


def run_with_service_killed(tmp_path: Path, service: str, before_end: bool = False,
                            clock: ClockMode = ClockMode.FAST, speed: float = 1.0,
                            more: str = ""):
    """8 orders for 4 AGVs on the small floor as processes, `service` killed at t = 40 (or
    at the last order's last second) and started again 2 s of wall time later, with the
    faults of `more` (TOML), which must give the record of the in-process run with those:
    that run."""
    layout_file = small_floor_file(tmp_path)
    floor = load_layout(str(layout_file)).floor
    scenario = tmp_path / "kill.toml"
    scenario.write_text(more)
    reference = Mission004(floor, 4, generate_orders(floor, 8, 5),
                           faults=load_scenario(scenario).faults).run()
    at = reference.completion_s - 1.0 if before_end else 40.0
    scenario.write_text(f'[[fault]]\nkind = "kill_service"\nat = {at}\n'
                        f'service = "{service}"\ndowntime = 2.0\n{more}')
    mission = Mission(str(layout_file), MissionKind.ORDERS, Strategy.NEAREST, 4, 5, orders=8)
    outcome = run_processes(RunSpec(
        mission, 4, tmp_path / "run", clock, speed,
        faults=injected004(load_scenario(scenario)), faults_source=str(scenario),
        clocked_agents=False))
    assert outcome.error == ""
    assert outcome.done.record == record_of(reference)
    applied = [(a.what, a.t) for a in outcome.injected]
    assert (f"kill the {service} for 2 s", at) in applied
    assert more or applied == [(f"kill the {service} for 2 s", at)]
    return reference, outcome


def test_a_killed_reservation_service_is_waited_for_and_changes_no_event(tmp_path):
    """The injector kills the reservation service at t = 40 (the tracker's instant holds
    until it has) and starts a new one from the journal 2 s of wall time later; the AGVs'
    takes and let-goes wait for it. The events are those of the run without the fault, the
    table never held a cell twice, no request was applied twice, and every verdict
    passes."""
    reference, _ = run_with_service_killed(tmp_path, "reservation")
    floor = load_layout(str(tmp_path / "small004.toml")).floor
    faults = load_scenario(tmp_path / "kill.toml").faults
    assert Mission004(floor, 4, generate_orders(floor, 8, 5), faults=faults).run().events \
        == reference.events  # in one process there is no service to kill
    assert "reservation-2.log" in {p.name for p in (tmp_path / "run" / "logs").iterdir()}
    journal = tmp_path / "run" / "reservation.journal"
    assert journal_overlaps(journal) == []
    ids = [c.request_id for c in Journal(journal).replay().changes if c.request_id]
    assert len(ids) == len(set(ids))
    assert analyze004(read_recording(tmp_path / "run")).passed


@pytest.mark.parametrize("before_end", [False, True], ids=["mid-mission", "at-the-end"])
def test_a_killed_recorders_successor_catches_up_and_the_recording_is_judged_whole(
        before_end, tmp_path):
    """The injector kills the recorder at t = 40 (or a second before the last order, so
    that the mission ends while none runs) and starts a new one 2 s of wall time later;
    the tracker does not wait for it, so the events of those 2 s and what the dead one had
    not written reach no recorder live. The new one writes run-2.mcap and asks the
    dispatcher for every event after those run.mcap holds, and for the result: the two
    segments hold every event once, in the dispatcher's numbering, and are judged as the
    run without the fault."""
    reference, _ = run_with_service_killed(tmp_path, "recorder", before_end)
    assert "caught up on" in (tmp_path / "run" / "logs" / "recorder-2.log").read_text()
    recording = read_recording(tmp_path / "run")
    report = analyze004(recording)
    assert [s.split()[0] for s in report.segments] == ["run.mcap", "run-2.mcap"]
    assert report.passed and report.events_missing == [] and report.restarts == []
    assert report.orders_picked == 8
    numbers = [r.envelope.seq for r, _ in recording.of(AgvEvent)]
    assert sorted(numbers) == list(range(1, len(reference.events) + 1))  # each once


RECORDER_FIRST = '[[fault]]\nkind = "kill_service"\nat = 39.0\nservice = "recorder"\n' \
    'downtime = 2.0\n'


@pytest.mark.parametrize("clock,speed,more", [
    (ClockMode.FAST, 1.0, ""), (ClockMode.REALTIME, 40.0, ""),
    (ClockMode.FAST, 1.0, KILL.replace("at = 40.5", "at = 30.5")),
    (ClockMode.FAST, 1.0, RECORDER_FIRST)],
    ids=["fast", "realtime", "with-an-agent-down", "with-the-recorder-down"])
def test_a_killed_dispatchers_successor_replays_the_mission_to_its_death_and_goes_on(
        clock, speed, more, tmp_path):
    """The injector kills the dispatcher at t = 40, the tracker's instant (every request
    answered, the instant journaled), and starts a new one 2 s of wall time later. It runs
    the tracker again in its own process up to t = 40, telling nobody, finds the store
    holding what the dead one left, and goes on through the agents (on the real-time
    clock, sim time stood still meanwhile, since nothing moves but what the tracker
    moves). The record is the run without the fault; the recording holds every event
    once, the new dispatcher's numbered on from the dead one's. With AGV 2's agent killed
    at t = 30.5 for 30 s, the new dispatcher leaves it alone until the injector, on its
    fault clock going on from the dead one's tick, starts it again at t = 60.5. With the
    recorder killed at t = 39, a moment of wall time before the dispatcher, the new
    recorder finds no dispatcher, or one replaying: it asks for the events it lacks once
    the new one's token says it holds them all."""
    reference, outcome = run_with_service_killed(tmp_path, "dispatcher", clock=clock,
                                                 speed=speed, more=more)
    logs = tmp_path / "run" / "logs"
    assert "picked the mission up at t=40," in (logs / "dispatcher-2.log").read_text()
    if more == RECORDER_FIRST:
        assert "caught up on" in (logs / "recorder-2.log").read_text()
    elif more:
        assert [(a.what, a.t) for a in outcome.injected] == [
            ("kill agent-2", 30.5), ("kill the dispatcher for 2 s", 40.0),
            ("restart agent-2", 60.5)]
        assert "agent-2-2.log" in {p.name for p in logs.iterdir()}
    recording = read_recording(tmp_path / "run")
    report = analyze004(recording)
    assert report.passed and report.events_missing == [] and report.orders_picked == 8
    if more != RECORDER_FIRST:  # else the new dispatcher may have said what the run is
        (went_on,) = report.restarts  # to no recorder: the first it published
        assert went_on is not None and went_on >= 40.0
    numbers = [r.envelope.seq for r, _ in recording.of(AgvEvent)]
    assert sorted(numbers) == list(range(1, len(reference.events) + 1))  # each once
    assert journal_overlaps(tmp_path / "run" / "reservation.journal") == []


def test_a_dispatcher_restart_is_told_by_the_new_ones_first_event(tmp_path):
    """Each dispatcher says what the run is as its message 1; the restart's first event is
    the lowest numbered of those recorded after that which number above every event
    recorded before it: not an old one a recorder caught up on later to fill a hole."""
    layout_file = small_floor_file(tmp_path)
    mission = Mission(str(layout_file), MissionKind.ORDERS, Strategy.NEAREST, 2, 5, orders=2)
    info = mission_info(mission, load_layout(str(layout_file)), 2, "fast")
    keys = Keys()
    writer = RecordingWriter(tmp_path / "run.mcap")
    writer.describe(info)

    def write(message, seq: int, log_ns: int) -> None:
        key = keys.dispatch_mission if isinstance(message, MissionInfo) else keys.dispatch_agv
        writer.write(key, encode(message, "dispatcher", seq, 0.0), log_ns, 0.0)

    write(info, 1, 1)
    for n, t in ((1, 0.0), (3, 2.0), (4, 3.0)):  # event 2 went unrecorded
        write(AgvEvent("stagnant", 1, t), n, 1 + n)
    write(info, 1, 10)  # the new dispatcher, then event 2 caught up on, then its own
    write(AgvEvent("stagnant", 1, 1.0), 2, 11)
    write(AgvEvent("stagnant", 2, 7.5), 5, 12)
    writer.close()
    assert analyze004(read_recording(tmp_path / "run.mcap")).restarts == [7.5]


def test_a_seed004_dispatcher_is_picked_up_only_where_the_injector_killed_it():
    """Its successor reads where it died from its journal: the last service fault's
    instant, which must be a kill of the dispatcher that its scenario schedules; anything
    else is refused saying why."""
    kill = Fault(FaultKind.KILL_SERVICE, 40.0, service="dispatcher")
    other = Fault(FaultKind.KILL_SERVICE, 20.0, service="reservation")
    records = [FaultInstant(1, 20.0, 1).to_record(), FaultInstant(2, 40.0, 3).to_record()]
    assert where_it_died(records, [other, kill], "j") == FaultInstant(2, 40.0, 3)
    with pytest.raises(UserError, match="j names no instant the dead dispatcher reached"):
        where_it_died([], [kill], "j")
    with pytest.raises(UserError, match="t=20, is no kill of the dispatcher"):
        where_it_died(records[:1], [other, kill], "j")
    with pytest.raises(UserError, match="not a seed-004 dispatcher's journal: service_fault "
                                        "tick 1 is not a whole number from its number, 2"):
        where_it_died([["service_fault", 2, 40.0, 1]], [kill], "j")
    with pytest.raises(UserError, match="not a record"):
        where_it_died([["served", 1, 0.0, 3.0, 1.0]], [kill], "j")
    # a successor that picked the mission up and died before the next service fault
    picked = [*records, FaultInstant(2, 40.0, 3, picked_up=True).to_record()]
    with pytest.raises(UserError, match="had picked the mission up at t=40 and died before"):
        where_it_died(picked, [other, kill], "j")


def test_a_store_that_does_not_hold_the_replayed_table_is_named():
    replayed, store = ReservationTable(), ReservationTable()
    for table in (replayed, store):
        table.commit(1, [Interval((0, 0), 0.0, INF)])
    assert first_difference(store, replayed) is None
    store.commit(2, [Interval((1, 0), 5.0, INF)])
    assert first_difference(store, replayed) == \
        "only the store has 2's hold of (1, 0) from t=5 to t=inf, and 0 more"


def test_the_events_no_segment_holds_are_counted_up_to_what_the_result_says_was_sent():
    """The dispatcher numbers its events 1, 2, ...; those missing, in runs, up to the count
    its recorded result gives (after the last one recorded too)."""
    from fleet.analysis.analyze004 import missing_runs

    assert missing_runs([1, 2, 5, 6, 9], published=12) == [(3, 4), (7, 8), (10, 12)]
    assert missing_runs([2, 3]) == [(1, 1)] and missing_runs([], 0) == []


def test_a_restarted_recorder_asks_after_the_first_gap_its_predecessors_left():
    """A recorder killed during its own catch-up wrote later events live and only some of
    the earlier ones: its successor asks from the first number missing, and writes none of
    those already held again."""
    from fleet.recording.reader import unbroken_run

    assert unbroken_run(set()) == 0 and unbroken_run({2, 3}) == 0
    assert unbroken_run({1, 2, 3}) == 3
    assert unbroken_run({1, 2, 3, 5, 3000, 3001}) == 3


def test_every_event_kind_goes_over_the_wire_and_back_unchanged():
    floor = build(Floor004Shape(**SHAPE), "small004")
    events = Mission004(floor, 8, generate_orders(floor, 20, 2)).run().events
    kinds = {type(e).__name__ for e in events}
    assert {"Moved", "Turned", "Paused", "Met", "Replanned", "Picked", "LegDone"} <= kinds
    extra = [MadeWay(3.0, 1, 2, (4, 5), (6, 7)),  # rarer kinds, made by hand
             BrokeDown(4.0, 2, (1, 1), 9.0), BrokeDown(5.0, 3, (2, 2), INF, "agent killed")]
    for e in [*events, *extra]:
        assert event_from_wire(event_to_wire(e), floor) == e


def test_fleet_run_on_paper004_in_process_then_analyze(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["run", "--layout", "paper004", "--orders", "4", "--vehicles", "3",
                 "--inprocess", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "mission orders on paper004 with 3 lifting AGVs, seed 0, inprocess clock" in printed
    assert "orders             4 of 4 picked" in printed
    assert "work               pass: 4 of 4 orders, 0 shelf slips" in printed
    wide = [line for line in printed.splitlines() if len(line) > 80 and str(out) not in line]
    assert wide == []
    assert main(["analyze", str(out)]) == 0
    assert "giving way         pass" in capsys.readouterr().out
    assert main(["runs", str(tmp_path)]) == 0
    assert "paper004" in capsys.readouterr().out
    assert main(["plot", str(out)]) == 0  # Figures 10-11 of this run
    assert f"wrote {out / 'heat.png'}" in capsys.readouterr().out
    assert (out / "heat.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.parametrize("flags,named", [
    (["--battery", "n_op=6"], "without --battery yet"),
    (["--order-area", "lower-left"], "--order-area"),
    (["--faults", "slow_planner"], "only vehicle_breakdown, close_zone, kill_vehicle, "
                                   "stall_vehicle, cut_link, kill_service are built yet"),
    (["--mission", "fill"], "runs order missions, not --mission fill"),
    (["--vehicles", "500"], "--vehicles 500: the AGVs of paper004 start on its 96 parking"),
])
def test_what_paper004_does_not_run_is_refused_by_name(flags, named, tmp_path, capsys):
    assert main(["run", "--layout", "paper004", "--out", str(tmp_path / "r"), *flags]) == 2
    err = capsys.readouterr().err
    assert named in err and "Traceback" not in err
    assert not (tmp_path / "r").exists()  # refused before anything started
