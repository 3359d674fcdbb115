"""Faults on a seed-004 floor: breakdowns and closed zones, struck by the tracker at their
instants and judged from the events alone (fleet/analysis/analyze004.py, fault_breaches)."""

import dataclasses

import pytest

from fleet.analysis.analyze004 import fault_breaches, recorded_events
from fleet.analysis.verdicts004 import judge
from fleet.cli import main
from fleet.mission.faults import Fault, FaultKind, ScenarioError, load_scenario
from fleet.mission.faults004 import check_faults004
from fleet.mission.orders004 import Mission004, generate_orders
from fleet.mission.tracking004 import BrokeDown, Moved, Repaired, Turned, ZoneClosed
from fleet.planning.rules004 import Kind
from fleet.recording.reader import read_recording
from fleet.wire.protocol import ZONE
from fleet.world.floor004 import Floor004Shape, build, paper004

SMALL = build(Floor004Shape(blocks_across=4, double_rows=4, stations=2, piles_per_side=2,
                            block_width=3, transit_rows=2), "small004")


def run(faults=(), vehicles=6, orders=16, seed=3):
    mission = Mission004(SMALL, vehicles, generate_orders(SMALL, orders, seed), faults=faults)
    return mission, mission.run()


def starts(vehicles: int):
    return {v: SMALL.parking[v - 1] for v in range(1, vehicles + 1)}


def layout_cell(xy):
    """The floor's (x, y) as a layout cell (col, row from the bottom), as scenarios name it."""
    return (xy[0], SMALL.height - 1 - xy[1])


def test_a_broken_down_agv_stands_until_repaired_and_the_others_finish_round_it():
    _, plain = run()
    first = next(e for e in plain.events if isinstance(e, Moved) and e.vehicle == 2)
    at = first.t0 + 20.3  # under way
    _, result = run((Fault(FaultKind.VEHICLE_BREAKDOWN, at, vehicle=2, duration=45.0),))
    events = result.events
    (down,) = [e for e in events if isinstance(e, BrokeDown)]
    (up,) = [e for e in events if isinstance(e, Repaired)]
    assert (down.vehicle, down.t, down.until) == (2, at, at + 45.0) and up.t == at + 45.0
    began = [e.t0 for e in events if isinstance(e, Moved | Turned) and e.vehicle == 2]
    assert not [t for t in began if at <= t < at + 45.0]  # stood the whole time
    assert [t for t in began if t >= at + 45.0]  # and went on after
    assert len(result.picked) == 16 and result.completion_s != plain.completion_s
    assert fault_breaches(list(events)) == []
    assert judge(SMALL, events, starts(6)).passed
    # A move while broken down is named from the events alone.
    moved = next(e for e in events if isinstance(e, Moved) and e.vehicle == 2 and e.t0 > at)
    forged = [*events, dataclasses.replace(moved, t0=at + 1.0, t1=at + 2.0)]
    assert [b.vehicle for b in fault_breaches(forged)] == [2]


def test_a_closed_zone_is_entered_by_nobody_while_closed_and_held_by_zone():
    column = SMALL.grid.aisle_columns[1]
    rows = range(SMALL.grid.aisle_rows[0] + 1, SMALL.grid.aisle_rows[2])
    xys = [(column, y) for y in rows]
    assert all(SMALL.kind(xy) is Kind.FLOOR for xy in xys)
    _, plain = run()
    used = sum(isinstance(e, Moved) and e.to in xys and 30 <= e.t0 < 130 for e in plain.events)
    assert used  # the zone is on the fleet's way
    fault = Fault(FaultKind.CLOSE_ZONE, 30.0, duration=100.0,
                  cells=tuple(layout_cell(xy) for xy in xys))
    mission, result = run((fault,))
    (zone,) = [e for e in result.events if isinstance(e, ZoneClosed)]
    assert (zone.t0, zone.t1) == (30.0, 130.0) and set(zone.cells) <= set(xys)
    assert not [e for e in result.events if isinstance(e, Moved) and e.to in zone.cells
                and e.t0 < 130.0 and e.t1 > 30.0]
    table = mission.tracker.vehicles.view
    assert {r.cell for r in table.reservations(ZONE)} == {SMALL.cell(xy) for xy in zone.cells}
    assert len(result.picked) == 16 and fault_breaches(list(result.events)) == []
    assert judge(SMALL, result.events, starts(6)).passed


def test_the_shipped_mixed_scenario_runs_on_paper004():
    floor = paper004()
    scenario = load_scenario("mixed", "paper004")
    assert {f.kind for f in scenario.faults} == {FaultKind.VEHICLE_BREAKDOWN,
                                                 FaultKind.CLOSE_ZONE}
    result = Mission004(floor, 8, generate_orders(floor, 24, 0), faults=scenario.faults).run()
    assert len(result.picked) == 24
    kinds = {type(e).__name__ for e in result.events}
    assert {"BrokeDown", "Repaired", "ZoneClosed"} <= kinds
    assert fault_breaches(list(result.events)) == []
    assert judge(floor, result.events, {v: floor.parking[v - 1] for v in range(1, 9)}).passed


BUILT = ("only vehicle_breakdown, close_zone, kill_vehicle, stall_vehicle, cut_link, "
         "kill_service are built yet")


@pytest.mark.parametrize("fault,named", [
    (Fault(FaultKind.SLOW_PLANNER, 10.0, vehicle=1, duration=5.0, factor=3.0), BUILT),
    (Fault(FaultKind.VEHICLE_BREAKDOWN, 10.0, vehicle=9), "the run has AGVs 1 to 6"),
    (Fault(FaultKind.CLOSE_ZONE, 10.0, duration=5.0, cells=((0, 0),)),
     "cell 0,0 is not floor an AGV of small004 drives on"),
])
def test_faults_a_seed004_run_cannot_take_are_refused_naming_them(fault, named):
    with pytest.raises(ScenarioError, match=named):
        check_faults004((fault,), SMALL, 6, "s")


@pytest.mark.parametrize("kind", ["kill_vehicle", "stall_vehicle", "cut_link"])
def test_a_dispatcher_killed_as_an_agents_fault_starts_or_ends_is_refused(kind):
    """The injector would apply both at one tick and the dispatcher die at the first, so a
    new one could not tell where it died."""
    kill = Fault(FaultKind.KILL_SERVICE, 40.0, service="dispatcher")
    for agent in (Fault(FaultKind(kind), 40.0, vehicle=2, duration=10.0),
                  Fault(FaultKind(kind), 30.0, vehicle=2, duration=10.0)):
        with pytest.raises(ScenarioError, match=rf"fault 2 \({kind} of AGV 2 at .*\) starts or "
                                                r"ends at the same instant"):
            check_faults004((kill, agent), SMALL, 6, "s")
    check_faults004((kill, Fault(FaultKind(kind), 30.0, vehicle=2, duration=5.0)), SMALL, 6, "s")


def test_fleet_run_refuses_a_scenario_of_another_kind_before_starting(tmp_path, capsys):
    assert main(["run", "--layout", "paper004", "--faults", "slow_planner", "--inprocess",
                 "--out", str(tmp_path / "r")]) == 2
    err = capsys.readouterr().err
    assert "slow_planner" in err and BUILT in err
    assert "Traceback" not in err
    assert not (tmp_path / "r").exists()
    assert main(["faults", "list", "--layout", "paper004"]) == 0
    listed = capsys.readouterr().out.split("shipped scenarios")[1]
    assert {"mixed", "kill_vehicle", "stall_vehicle", "cut_link"} <= set(listed.split())
    assert {"kill_service", "kill_recorder", "kill_dispatcher"} <= set(listed.split())
    assert "slow_planner" not in listed


def test_a_killed_agent_in_process_is_a_stop_told_by_its_cause(tmp_path, capsys):
    """The shipped kill_vehicle of paper004 strikes AGV 3 mid-leg; in one process the
    AGV stands as a broken-down one does, the recording says why, and every verdict
    passes (tests/test_runtime004.py runs it as processes, with the injector's kill)."""
    out = tmp_path / "r"
    assert main(["run", "--layout", "paper004", "--faults", "kill_vehicle", "--inprocess",
                 "--orders", "30", "--vehicles", "6", "--out", str(out)]) == 0
    assert "faults             pass: 1 struck" in capsys.readouterr().out
    events, problems = recorded_events(read_recording(out), paper004())
    struck = [e for e in events if isinstance(e, BrokeDown)]
    assert problems == [] and [(e.vehicle, e.t, e.until, e.cause) for e in struck] == [
        (3, 100.5, 145.5, "agent killed")]
    assert any(getattr(e, "vehicle", 0) == 3 and getattr(e, "t0", 0) >= 145.5
               for e in events)  # it went on once its new agent was up



def test_waiting_out_a_fault_longer_than_the_watchdog_is_no_wedge():
    """A breakdown and a closed zone each longer than the watchdog's 300 s: the AGVs that
    wait them out are not named stuck, and the mission ends; one after the work is done
    strikes nothing."""
    column = SMALL.grid.aisle_columns[1]
    cells = tuple(layout_cell((column, y)) for y in range(SMALL.grid.aisle_rows[0] + 1,
                                                          SMALL.grid.aisle_rows[2]))
    faults = (Fault(FaultKind.VEHICLE_BREAKDOWN, 30.5, vehicle=2, duration=400.0),
              Fault(FaultKind.CLOSE_ZONE, 30.0, duration=400.0, cells=cells),
              Fault(FaultKind.VEHICLE_BREAKDOWN, 5000.0, vehicle=3, duration=10.0))
    _, result = run(faults)
    assert len(result.picked) == 16
    struck = [e for e in result.events if isinstance(e, BrokeDown)]
    assert [e.vehicle for e in struck] == [2]  # the one at t=5000 came after the work
    assert fault_breaches(list(result.events)) == []
    assert judge(SMALL, result.events, starts(6)).passed
