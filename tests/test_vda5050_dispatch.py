"""`fleet run --dispatch vda5050`: the internal dispatcher runs a whole fill or empty mission
as VDA 5050 orders over a real broker (a mosquitto the run starts), through the gateway, and the
result matches the direct run's within the tolerance docs/vda5050.md states."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from fleet.analysis.analyze import analyze
from fleet.dispatching.decision import Strategy
from fleet.mission.engine import Engine, engine_options, run_mission
from fleet.mission.seam import LocalExecutor
from fleet.mission.spec import Mission, MissionKind
from fleet.recording.reader import read_recording
from fleet.wire.protocol import GOODS, LegCommitted, MqttTraffic, SubtaskEvent
from fleet.world.layout_file import load_layout
from vda5050.gateway import engine_map

LAYOUT = "small"
SPEED = 10  # sim seconds a wall second: the mission's 600 s in about a minute
# The end time of a run through the gateway may be later than the direct run's by this much
# (docs/vda5050.md, "The internal dispatcher through the gateway"): each leg starts once the
# forklift stands ready and the gateway has had it planned, up to some 4 s of sim time at
# speed 10 after the decision instant (the gateway's lead of 1 to 2 s, its look every
# 0.05 s of wall time and the round trips, each wall second ten of sim time, on a machine
# as loaded as by the whole test suite: there the empty mission ended 75.8 s, 3.2 s a leg,
# after the direct run's 589.5 s); a forklift drives 24 legs on `small`, so up to 96 s. It
# may also end a little sooner: a leg that starts later meets the others elsewhere, and
# what follows differs.
LEG_DELAY_S, LEGS = 4.0, 24
END_TIME_TOLERANCE_S = LEG_DELAY_S * LEGS


@pytest.mark.parametrize("kind", [MissionKind.FILL, MissionKind.EMPTY])
def test_a_whole_mission_runs_as_vda5050_orders(tmp_path, kind):
    """Behind the router's access control (the gateway logged in as itself), every subtask
    goes out as a release of the forklift's one order, stitched at the node the last ended
    on, a drop at a stack and a pick at a station (the other way round when emptying);
    every stack is served once, no two forklifts ever share a cell, the MQTT traffic passes
    the VDA 5050 verdict, and the end time is the direct run's within the tolerance."""
    out = tmp_path / "run"
    done = subprocess.run([sys.executable, "-m", "fleet", "run", "--layout", LAYOUT,
                           "--mission", kind.value,
                           "--dispatch", "vda5050", "--secure", "--speed", str(SPEED),
                           "--json", "--out", str(out)], capture_output=True, text=True,
                          timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    summary = json.loads(done.stdout)
    recording = read_recording(out)
    report = analyze(recording)
    assert report.passed and report.complete, "\n".join(report.verdict_lines())
    assert report.protocol is not None and report.protocol.passed
    subtasks = [m for _, m in recording.of(SubtaskEvent)]
    legs = [m for _, m in recording.of(LegCommitted)]
    orders = [json.loads(m.payload) for _, m in recording.of(MqttTraffic)
              if m.topic == "order" and m.received]
    # one order a forklift, one release a subtask, each a leg the forklift's agent committed
    assert {o["orderId"] for o in orders} == {"mission-1", "mission-2"}
    assert len(orders) == len(subtasks) == len(legs) == 2 * summary["stacks_done"]
    at_stack = "drop" if kind is MissionKind.FILL else "pick"
    at_station = "pick" if kind is MissionKind.FILL else "drop"
    for o in orders:
        (action,) = o["nodes"][-1]["actions"]
        assert action["actionType"] == (at_stack if o["nodes"][-1]["nodeId"].startswith("stack")
                                        else at_station)
    mission, layout = Mission(LAYOUT, kind, Strategy.ANN), load_layout(LAYOUT)
    direct = run_mission(mission, engine_options(mission, layout, None), layout)
    assert abs(summary["end_time_s"] - direct.end_time) <= END_TIME_TOLERANCE_S, (
        summary["end_time_s"], direct.end_time)


class _Watching(LocalExecutor):
    """The in-process executor, noting for each task the map it is planned on and what the
    store holds as goods then."""

    def __init__(self, *args) -> None:
        super().__init__(*args)
        self.seen: list[tuple[frozenset, list]] = []

    def execute(self, task):
        self.seen.append((task.filled, self.store.reservations(GOODS)))
        return super().execute(task)


@pytest.mark.parametrize("kind", [MissionKind.FILL, MissionKind.EMPTY])
def test_the_gateway_plans_our_legs_on_the_engines_map_read_off_its_store(kind):
    """What the gateway of --dispatch vda5050 hands an agent to plan on, read off the store
    alone, is at every task of a whole mission the map the engine plans that task on."""
    layout = load_layout(LAYOUT)
    mission = Mission(LAYOUT, kind, Strategy.ANN)
    options = engine_options(mission, layout, None)
    engine = Engine(mission, options, layout)
    watching = _Watching(engine.vehicle_kind, engine.planners)
    engine = Engine(mission, options, layout, executor=watching)
    engine.run()
    stacks = frozenset(s.cell for s in layout.stacks)
    assert len(watching.seen) >= 2 * len(layout.stacks)
    for filled, goods in watching.seen:
        assert engine_map(goods, stacks, kind is MissionKind.EMPTY) == filled
