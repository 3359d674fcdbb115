"""Fleets larger than their docks (fleet/mission/work.py `FillWork.held_back`, the engine's
parking and letting go): an empty forklift is not sent for goods while as many carry or fetch
them as the clusters can take and one fewer than the docks, so that loaded forklifts never
take every dock; the ones held back park out of the way, and the loaded ones they keep from a
stack wait for them in the wait-for graph."""

from __future__ import annotations

import sys
from pathlib import Path

from fleet.analysis.analyze import analyze
from fleet.dispatching.decision import Strategy, TaskKind, VehicleView
from fleet.mission.engine import Engine, EngineOptions, Planned
from fleet.mission.record import digest
from fleet.mission.spec import Mission, MissionKind
from fleet.mission.work import FillWork, stack_work
from fleet.params import DispatchParams
from fleet.planning.reservations import ReservationTable
from fleet.recording.reader import read_recording
from fleet.runtime.local_run import RunSpec, run_processes
from fleet.world.generator import Shape, generate_layout, generate_toml
from fleet.world.site import planners_for

sys.path.insert(0, str(Path(__file__).parent))
from mission_check import mission_problems

# 16 forklifts on 12 docks: greedy filling wedged here before forklifts were held back (all
# docks taken by loaded forklifts, the empty ones standing in front of the next stacks).
CROWDED = generate_layout(Shape(aisles=2, depth=10, lane_depth=3, vehicles=16))


def fill_work(layout) -> FillWork:
    work = stack_work(MissionKind.FILL, layout, DispatchParams(), ReservationTable(),
                      planners_for(layout))
    assert isinstance(work, FillWork)
    return work


def views(next_tasks: list[TaskKind]) -> list[VehicleView]:
    return [VehicleView(i + 1, CROWDED.vehicle_starts[i], 0.0, task, None, None)
            for i, task in enumerate(next_tasks)]


def held(work: FillWork, view: VehicleView, fleet: list[VehicleView], down: int = 0) -> bool:
    """Whether `view` is held back, with `fleet` up and `down` more forklifts down."""
    return view.vehicle in work.held_back(fleet, len(fleet) + down)


def test_an_empty_forklift_waits_while_the_goods_in_flight_reach_the_limit():
    work = fill_work(CROWDED)
    docks, clusters = len(CROWDED.stations), len(CROWDED.clusters)
    assert (docks, clusters) == (12, 8)
    limit = min(clusters, docks - 1)
    assert work.in_flight_limit() == limit
    for loaded in (limit - 1, limit, len(CROWDED.vehicle_starts) - 1):
        fleet = views([TaskKind.DELIVER] * loaded
                      + [TaskKind.RETURN] * (len(CROWDED.vehicle_starts) - loaded))
        empty = fleet[-1]
        assert held(work, empty, fleet) is (loaded >= limit)
        assert not held(work, fleet[0], fleet)  # a loaded one is never held back


def test_the_limit_follows_the_clusters_left_and_an_empty_forklift_stays_parked_at_the_end():
    work = fill_work(CROWDED)
    fleet = views([TaskKind.DELIVER] * 2 + [TaskKind.RETURN] * 14)
    assert not held(work, fleet[-1], fleet)
    for name in list(work.queue)[:-2]:  # all but two clusters filled
        work.queue[name] = []
    assert work.in_flight_limit() == 2
    assert held(work, fleet[-1], fleet)
    for name in work.queue:
        work.queue[name] = []
    # Every stack assigned: no goods left to fetch, and the docks cannot hold all 16.
    assert held(work, fleet[-1], views([TaskKind.RETURN] * 16))
    twelve = views([TaskKind.RETURN] * 12)
    assert not held(work, twelve[-1], twelve)  # 12 all end at a dock


def test_a_fleet_no_larger_than_its_docks_is_never_held_back():
    """It can never take every dock while one of its forklifts is empty."""
    work = fill_work(CROWDED)
    fleet = views([TaskKind.DELIVER] * 11 + [TaskKind.RETURN])
    assert len(fleet) == len(CROWDED.stations) == 12
    assert not held(work, fleet[-1], fleet)
    assert held(work, fleet[-1], fleet + views([TaskKind.DELIVER] * 13)[12:])
    # A thirteenth forklift down still counts: it comes back, and the rules do not change.
    assert held(work, fleet[-1], fleet, down=1)


def test_a_fleet_larger_than_its_docks_fills_a_floor_where_it_wedged():
    decisions: list[Planned] = []
    engine = Engine(Mission(CROWDED.name, MissionKind.FILL, Strategy.GREEDY),
                    EngineOptions(planned=decisions.append), layout=CROWDED)
    record = engine.run()
    assert len(record.stacks_done) == len(CROWDED.stacks)
    assert mission_problems(record, CROWDED) == []
    parked = [s for s in record.subtasks if s.target == "park"]
    assert parked, "no forklift was held back and parked"
    assert all(s.kind is TaskKind.ASIDE for s in parked)
    # A return decided while the goods in flight were at the limit of the moment (the
    # clusters with stacks left, at most one fewer than the docks) is one of a forklift let
    # go to clear the way, and those are few.
    over = []
    for p in decisions:
        clusters = sum(1 for left in p.remaining.values() if left)
        if p.decision.kind is TaskKind.RETURN and p.trajectory is not None and clusters:
            in_flight = sum(1 for v in p.fleet if v.next_task is TaskKind.DELIVER)
            if in_flight >= min(clusters, len(CROWDED.stations) - 1):
                over.append((p.decision.t_i, p.decision.vehicle))
    assert over, "no forklift fetched goods over the limit: none was let go"
    for t, vehicle in over:  # let go since the delivery that emptied it
        emptied = max(s.t_i for s in record.subtasks
                      if s.vehicle == vehicle and s.kind is TaskKind.DELIVER and s.t_i < t)
        assert any(v == vehicle and emptied <= t_let <= t for t_let, v in engine.let_go_at), (
            t, vehicle)
    assert len(engine.let_go_at) < len(CROWDED.stacks) / 4  # far fewer than the stacks


def test_as_processes_a_held_back_fleet_fills_as_in_process(tmp_path):
    """Ten forklifts on eight docks, one agent process each: held back, parked and let go
    as the engine in process decides, bit for bit, and every verdict passes."""
    shape = Shape(aisles=1, depth=12, lane_depth=2, vehicles=10)
    path = tmp_path / "crowded.toml"
    path.write_text(generate_toml(shape))
    mission = Mission(str(path), MissionKind.FILL, Strategy.GREEDY)
    engine = Engine(mission)
    reference = engine.run()
    assert len(reference.stacks_done) == len(engine.layout.stacks)
    assert engine.let_go_at and any(s.target == "park" for s in reference.subtasks)
    outcome = run_processes(RunSpec(mission, 10, tmp_path / "run"))
    assert outcome.error == ""
    assert outcome.done.digest == digest(reference)
    report = analyze(read_recording(tmp_path / "run" / "run.mcap"))
    assert report.passed and report.complete and report.finished
