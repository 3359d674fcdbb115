"""`fleet plot RUN` on a seed-004 recording: snapshots of the floor (snapshot_T.png) at given
or default instants, from the recorded tracking events alone (fleet/views/state004.py,
fleet/views/snapshot004.py), beside the heat maps."""

from __future__ import annotations

import pytest
from test_scene import decode

from fleet.analysis.analyze004 import end_time_s, recorded_events, recorded_starts
from fleet.cli import main
from fleet.mission.orders004 import Mission004, generate_orders
from fleet.mission.record004 import event_to_wire
from fleet.mission.tracking004 import BrokeDown, Moved, Paused, Picked, Repaired, ZoneClosed
from fleet.planning.rules004 import Direction
from fleet.recording.reader import read_recording
from fleet.views.scene import FORKLIFTS, NS
from fleet.views.scene004 import scene_views
from fleet.views.snapshot004 import snapshot
from fleet.views.state004 import floor_at
from fleet.world.layout_file import load_layout

PNG = b"\x89PNG\r\n\x1a\n"
LAYOUT = load_layout("paper004")
FLOOR = LAYOUT.floor


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """A small seed-004 mission recorded in process: its directory, events and starts."""
    out = tmp_path_factory.mktemp("plot004") / "run"
    assert main(["run", "--layout", "paper004", "--orders", "4", "--vehicles", "3",
                 "--inprocess", "--quiet", "--out", str(out)]) == 0
    recording = read_recording(out)
    events, unreadable = recorded_events(recording, FLOOR)
    assert not unreadable
    return out, events, recorded_starts(recording, FLOOR)


def test_plot_draws_the_heat_and_snapshots_at_a_quarter_half_and_three_quarters(
        run, tmp_path, capsys):
    out, events, _ = run
    assert main(["plot", str(out), "--out", str(tmp_path)]) == 0
    printed = capsys.readouterr().out
    end = end_time_s(events)
    names = ["heat.png", *(f"snapshot_{t:08.2f}.png" for t in (end / 4, end / 2, 3 * end / 4))]
    for name in names:
        assert f"wrote {tmp_path / name}" in printed
        assert (tmp_path / name).read_bytes()[:8] == PNG
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(names)


def test_plot_draws_a_snapshot_at_each_time_given(run, tmp_path, capsys):
    out, _, _ = run
    assert main(["plot", str(out), "--out", str(tmp_path), "--at", "10", "--at", "42.5"]) == 0
    capsys.readouterr()
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "heat.png", "snapshot_00010.00.png", "snapshot_00042.50.png"]
    assert (tmp_path / "snapshot_00042.50.png").stat().st_size > 20_000  # a floor drawn


def test_a_time_past_the_end_is_refused_in_one_line(run, tmp_path, capsys):
    out, events, _ = run
    assert main(["plot", str(out), "--out", str(tmp_path / "p"), "--at", "5",
                 "--at", "100000"]) == 2
    err = capsys.readouterr().err
    assert err.strip() == (f"fleet plot: error: --at 100000: the run ended at "
                           f"{end_time_s(events):.2f} s; snapshots are drawn from 0 to "
                           f"{end_time_s(events):.2f} s")
    assert not (tmp_path / "p").exists()  # refused before anything was drawn


def test_every_agv_is_in_the_cell_its_recorded_move_arrived_in_and_between_while_moving(run):
    _, events, starts = run
    state = floor_at(events, starts, 0.0)
    assert [a.cell for a in state.agvs] == list(FLOOR.parking[:3])  # where each started
    moves = [e for e in events if isinstance(e, Moved)]
    assert len(moves) > 100
    for move in moves[::25]:
        arrived = floor_at(events, starts, move.t1).agvs[move.vehicle - 1]
        assert arrived.cell == move.to and (arrived.x, arrived.y) == move.to
        halfway = floor_at(events, starts, (move.t0 + move.t1) / 2).agvs[move.vehicle - 1]
        assert (halfway.cell, halfway.to) == (move.origin, move.to)
        assert (halfway.x, halfway.y) == ((move.origin[0] + move.to[0]) / 2,
                                          (move.origin[1] + move.to[1]) / 2)


def test_a_lifted_shelf_rides_on_its_agv_and_is_not_home_until_it_is_dropped(run):
    _, events, starts = run
    pauses = [e for e in events if isinstance(e, Paused)]
    lifts = [e for e in pauses if e.label == "lift"]
    assert len(lifts) == 4  # one an order
    for lift in lifts:
        drop = next(e for e in pauses if e.label == "drop" and e.vehicle == lift.vehicle
                    and e.t0 >= lift.t1)
        assert drop.at == lift.at  # home again
        home, v = lift.at, lift.vehicle - 1
        assert home not in floor_at(events, starts, lift.t0).away  # lifting: still home
        for t in (lift.t1, (lift.t1 + drop.t0) / 2, drop.t0, (drop.t0 + drop.t1) / 2):
            state = floor_at(events, starts, t)
            assert home in state.away and state.agvs[v].shelf == home
        dropped = floor_at(events, starts, drop.t1)
        assert home not in dropped.away and dropped.agvs[v].shelf is None
    final = floor_at(events, starts, end_time_s(events))
    assert final.away == frozenset() and final.picked == 4


def test_a_shelf_dropped_and_lifted_again_in_place_is_home_between():
    home = FLOOR.slots[0].xy
    events = [Paused(1, 0.0, 2.0, home, "lift"), Paused(1, 5.0, 7.0, home, "drop"),
              Paused(1, 7.0, 9.0, home, "lift"), Picked(3.0, 1, "station-1")]
    starts = {1: home}
    assert [home in floor_at(events, starts, t).away for t in (1, 2, 6, 7, 8, 9)] == \
        [False, True, True, False, False, True]
    assert floor_at(events, starts, 3.0).picked == 1


def test_breakdowns_and_closed_zones_hold_over_their_time():
    a, b = FLOOR.parking[0], FLOOR.parking[1]
    events = [BrokeDown(3.0, 1, a, 10.0), Repaired(8.0, 1, a), ZoneClosed(2.0, 4.0, (b,))]
    starts = {1: a}
    assert [floor_at(events, starts, t).agvs[0].down for t in (2.9, 3.0, 7.9, 8.0)] == \
        [False, True, True, False]
    assert [floor_at(events, starts, t).closed for t in (1.0, 2.0, 4.0)] == \
        [frozenset(), frozenset({b}), frozenset()]


def test_the_snapshot_draws_each_agv_with_its_number_heading_and_shelf(run):
    _, events, starts = run
    lift = next(e for e in events if isinstance(e, Paused) and e.label == "lift")
    state = floor_at(events, starts, lift.t1)
    fig = snapshot(FLOOR, state, "paper004: 4 orders, 3 lifting AGVs, seed 0")
    gids = {a.get_gid() for a in fig.findobj() if a.get_gid()}
    assert {f"agv/{v}" for v in (1, 2, 3)} <= gids
    assert {f"number/{v}" for v in (1, 2, 3)} <= gids
    assert {g for g in gids if g.startswith("carried/")} == \
        {f"carried/{a.vehicle}" for a in state.agvs if a.shelf is not None}
    assert f"carried/{lift.vehicle}" in gids
    body = next(a for a in fig.findobj() if a.get_gid() == f"agv/{lift.vehicle}")
    agv = state.agvs[lift.vehicle - 1]
    step = {Direction.UP: (0, -1), Direction.DOWN: (0, 1), Direction.LEFT: (-1, 0),
            Direction.RIGHT: (1, 0)}[agv.heading]  # the body's point is where it heads
    corners = {(round(x - agv.x, 2), round(y - agv.y, 2)) for x, y in body.get_xy()}
    assert (round(0.46 * step[0], 2), round(0.46 * step[1], 2)) in corners
    assert (round(-0.46 * step[0], 2), round(-0.46 * step[1], 2)) not in corners
    texts = [t.get_text() for t in fig.findobj() if t.get_gid() == f"number/{lift.vehicle}"]
    assert texts == [str(lift.vehicle)]


def test_the_foxglove_scene_and_the_snapshot_put_the_agvs_in_the_same_place():
    events = Mission004(FLOOR, 3, generate_orders(FLOOR, 3, 1)).run().events
    views = scene_views(LAYOUT, 0, "orders", 3)
    frames = views.start()
    for e in events:
        wire = event_to_wire(e)
        frames += views.on_message("k", wire, wire.t0)
    starts = {v: xy for v, xy in enumerate(FLOOR.parking[:3], 1)}
    checked = 0
    for _, message, ns in [f for f in frames if f[0] == FORKLIFTS][::10]:
        update = decode(message)
        state = floor_at(events, starts, ns / NS)
        for entity, agv in zip(update.entities, state.agvs, strict=True):
            meta = {kv.key: kv.value for kv in entity.metadata}
            assert meta["cell"] == f"{agv.cell[0]},{agv.cell[1]}"
            assert meta["heading"] == agv.heading.name.lower()
            assert meta["shelf"] == ("" if agv.shelf is None else
                                     f"{agv.shelf[0]},{agv.shelf[1]}")
        checked += 1
    assert checked > 10
