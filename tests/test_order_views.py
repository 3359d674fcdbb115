"""Views of seed 002's order missions (docs/agv-002.md, "Pictures of an order mission"): the
timeline the plots read, the plots of `fleet plot`, the Foxglove scene on a lane layout, and
the makespan curves of `fleet bench seed002`. On a hand-made record whose answers are worked
out below, and on a real in-process mission of twelve orders on micro-t (a second)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from matplotlib.container import ErrorbarContainer
from matplotlib.patches import Rectangle
from PIL import Image
from test_scene import decode

from fleet.cli import main
from fleet.commands.plot import read_run
from fleet.mission.record import MissionHeader, MissionSummary, StackRecord, SubtaskRecord
from fleet.views import order_plots
from fleet.views.makespan import curves, figure
from fleet.views.order_timeline import cell_seconds, timeline, tracks
from fleet.views.scene import SceneViews
from fleet.views.shelf_tracker import ShelfTracker
from fleet.wire.protocol import LegAmended, SubtaskEvent, VehicleState
from fleet.world.layout_file import load_layout

MICRO_T = load_layout("micro-t")
BASE = 1_700_000_000 * 10**9


def subtask(vehicle, kind, target, t_i, t_end, t_done, *steps):
    return SubtaskRecord(vehicle, kind, target, None, t_i, t_end, t_done, False, tuple(steps),
                         ())


def move(a, b, t0, t1):
    return ("move", f"{a},E", f"{b},E", t0, t1, 1, 1)


def wait(a, t0, t1):
    return ("wait", f"{a},E", f"{a},E", t0, t1, 0, 0)


def swap_record() -> MissionSummary:
    """Two AGVs on micro-t swap two shelves' slots. AGV 2 (from pile c2) takes shelf s-4-2
    to p1 and puts it in s-3-2's slot; AGV 1 (from c1) takes s-3-2, waits loaded under its
    slot from 8 to 12 s for a free station, waits 1 s more for another AGV (a collision rule),
    packs at p3 and puts it in s-4-2's slot, then goes to pile c4. AGV 1's stow was announced
    done at 28 s and then postponed to 30 s."""
    one = (subtask(1, "fetch", "s-3-2", 0.0, 8.0, 8.0, move("3,10", "3,2", 0.0, 8.0)),
           subtask(1, "pack", "p3", 12.0, 16.0, 26.0, wait("3,2", 12.0, 13.0),
                   move("3,2", "0,2", 13.0, 16.0)),
           subtask(1, "stow", "s-4-2", 26.0, 30.0, 30.0, move("0,2", "4,2", 26.0, 30.0)),
           subtask(1, "charge", "c4", 30.0, 38.0, 38.0, move("4,2", "6,10", 30.0, 38.0)))
    two = (subtask(2, "fetch", "s-4-2", 0.0, 5.0, 5.0, move("4,10", "4,2", 0.0, 5.0)),
           subtask(2, "pack", "p1", 5.0, 9.0, 19.0, move("4,2", "0,0", 5.0, 9.0)),
           subtask(2, "stow", "s-3-2", 19.0, 23.0, 23.0, move("0,0", "3,2", 19.0, 23.0)))
    subtasks = tuple(sorted(one + two, key=lambda s: s.t_i))
    return MissionSummary(MissionHeader("micro-t", "orders", "nearest", 2, 0),
                          ("3,10,E", "4,10,E"), end_time_s=28.0, all_parked_s=38.0,
                          decision_failures=0, wait_s={}, busy_s={},
                          stacks_done=(StackRecord("s-4-2", 3, 23.0),
                                       StackRecord("s-3-2", 7, 28.0)),
                          failures=(), subtasks=subtasks)


# ------------------------------------------------------------------ the timeline


def test_shelves_stations_and_orders_follow_the_trips():
    tl = timeline(MICRO_T, swap_record())
    s32, s42 = (3, 2), (4, 2)
    at = tl.shelves_at
    assert at(4.9).on_agv == {} and at(4.9).in_slot[s42] == "s-4-2"
    # AGV 2 sets off for p1 at 5 s: its shelf rides on it, its slot is empty.
    assert at(5.0).on_agv == {2: "s-4-2"} and s42 not in at(5.0).in_slot
    # AGV 1 waits under s-3-2 for a station until 12 s: the shelf stands in its slot till then.
    assert at(11.9).in_slot[s32] == "s-3-2" and 1 not in at(11.9).on_agv
    assert at(12.0).on_agv == {1: "s-3-2", 2: "s-4-2"} and s32 not in at(12.0).in_slot
    # Put down on arrival: s-4-2 in s-3-2's slot at 23 s, s-3-2 in s-4-2's at 30 s.
    assert at(23.0).in_slot[s32] == "s-4-2" and at(23.0).on_agv == {1: "s-3-2"}
    assert at(30.0).in_slot[s42] == "s-3-2" and at(30.0).on_agv == {}
    assert len(at(30.0).in_slot) == len(MICRO_T.slots)  # every shelf back in a slot
    assert tl.stations_at(5.0) == {"p1": "reserved"}
    assert tl.stations_at(9.0) == {"p1": "packing"}
    assert tl.stations_at(14.0) == {"p1": "packing", "p3": "reserved"}
    assert tl.stations_at(19.0) == {"p3": "packing"} and tl.stations_at(26.0) == {}
    # An order is complete when its shelf is down, after the postponement: 30 s, not 28 s.
    assert [(c.order, c.shelf, c.vehicle, c.t) for c in tl.completions] == [
        (3, "s-4-2", 2, 23.0), (7, "s-3-2", 1, 30.0)]
    assert tl.makespan == 30.0
    assert [tl.completed_by(t) for t in (22.9, 23.0, 29.9, 30.0)] == [0, 1, 1, 2]
    assert [(w.vehicle, w.where, w.t0, w.t1) for w in tl.station_waits] == [
        (1, "s-3-2", 8.0, 12.0)]
    assert [(p.vehicle, p.where, p.t0, p.t1) for p in tl.pile_stays] == [
        (1, "c4", 38.0, math.inf)]
    assert [t.waits for t in tl.trips if t.vehicle == 1] == [(), ((12.0, 13.0),), (), ()]


def test_tracks_follow_the_steps_and_stand_still_between_them():
    track = tracks(swap_record())[1]
    assert track.at(-1.0) == (3.0, 10.0)
    assert track.at(4.0) == pytest.approx((3.0, 6.0))  # halfway from (3, 10) to (3, 2)
    assert track.at(10.0) == (3.0, 2.0)  # waiting for a station
    assert track.at(12.5) == (3.0, 2.0)  # a collision rule's wait
    assert track.at(14.5) == pytest.approx((1.5, 2.0))
    assert track.at(100.0) == (6.0, 10.0)


def test_the_gantt_chart_has_one_bar_per_trip_and_one_per_wait():
    record = swap_record()
    ax = order_plots.gantt(record, timeline(MICRO_T, record)).axes[0]
    bars = {p.get_gid(): p for p in ax.patches if isinstance(p, Rectangle) and p.get_gid()}
    rows = {label.get_text(): y for y, label in zip(ax.get_yticks(), ax.get_yticklabels(),
                                                    strict=True)}
    trips = [gid for gid in bars if gid.startswith("trip/")]
    assert len(trips) == len(record.subtasks) == 7
    for k, s in enumerate(record.subtasks):
        bar = bars[f"trip/{k}"]
        assert (bar.get_x(), bar.get_width()) == pytest.approx((s.t_i, s.t_end - s.t_i))
        assert bar.get_y() + bar.get_height() / 2 == pytest.approx(rows[f"AGV {s.vehicle}"])
    dwells = sorted((b.get_x(), b.get_width()) for g, b in bars.items() if g.startswith("dwell/"))
    assert dwells == [(9.0, 10.0), (16.0, 10.0)]
    assert [(bars[g].get_x(), bars[g].get_width()) for g in bars if g.startswith("wait/")] == [
        (12.0, 1.0)]
    assert (bars["station-wait/0"].get_x(), bars["station-wait/0"].get_width()) == (8.0, 4.0)
    assert bars["pile/0"].get_x() == 38.0  # to the chart's end
    assert ax.get_xlim()[1] >= 38.0


# ------------------------------------------------------------------ a real mission


@pytest.fixture(scope="module")
def mission(tmp_path_factory) -> Path:
    """Twelve orders for six AGVs on micro-t, in process (amended legs and waits included)."""
    out = tmp_path_factory.mktemp("orders") / "run"
    assert main(["run", "--layout", "micro-t", "--orders", "12", "--vehicles", "6",
                 "--inprocess", "--out", str(out), "--quiet"]) == 0
    return out


@pytest.fixture(scope="module")
def read(mission):
    recording, record = read_run(mission)
    states = [(r.envelope.sim_time, m) for r, m in recording.of(VehicleState)]
    return recording, record, states


def test_the_mission_has_what_the_views_must_show(read):
    recording, record, _ = read
    assert recording.of(LegAmended), "no leg postponed: pick a busier mission"
    assert {s.kind for s in record.subtasks} == {"fetch", "pack", "stow"}


def test_plot_of_an_order_mission_writes_its_files(mission, tmp_path, capsys):
    out = tmp_path / "plots"
    assert main(["plot", str(mission), "--out", str(out), "--at", "20", "--frames", "4"]) == 0
    printed = capsys.readouterr().out
    for name in ("orders.png", "gantt.png", "heatmap.png", "snapshot_00020.00.png"):
        assert (out / name).read_bytes()[:4] == b"\x89PNG", name
        assert f"wrote {out / name}" in printed
    with Image.open(out / "run.gif") as gif:
        assert gif.n_frames == 4
    assert "orders completed per quarter of the end time: [" in printed
    assert not (out / "filling.png").exists()


def test_a_snapshot_shows_each_carried_shelf_on_its_agv_and_its_slot_empty(read):
    recording, record, _ = read
    layout = recording.layout()
    tl = timeline(layout, record)
    move = tl.moves[len(tl.moves) // 2]
    t = (move.lifted + move.put) / 2  # on its way to a station or back
    shelves = tl.shelves_at(t)
    assert shelves.on_agv[move.vehicle] == move.shelf and move.slot not in shelves.in_slot
    ax = order_plots.snapshot(layout, record, t, tl).axes[0]
    carried = {p.get_gid(): p for p in ax.patches if (p.get_gid() or "").startswith("carried/")}
    assert set(carried) == {f"carried/{v}" for v in shelves.on_agv}
    body = next(p for p in ax.patches if p.get_gid() == f"agv/{move.vehicle}")
    shelf = carried[f"carried/{move.vehicle}"]
    assert shelf.get_label() == move.shelf
    assert _centre(shelf) == pytest.approx(_centre(body))  # under the AGV that carries it
    x, y = tracks(record)[move.vehicle].at(t)
    assert _centre(body) == pytest.approx(layout.cell_center((0, 0)) + np.array([x, y]))
    (standing,) = [c for c in ax.collections if c.get_gid() == "shelves"]
    centres = {tuple(np.round(p.get_extents().get_points().mean(axis=0), 6))
               for p in standing.get_paths()}
    slots = {tuple(np.round(layout.cell_center(c), 6)) for c in shelves.in_slot}
    assert centres == slots
    assert tuple(np.round(layout.cell_center(move.slot), 6)) not in centres


def _centre(patch: Rectangle) -> np.ndarray:
    return np.array([patch.get_x() + patch.get_width() / 2,
                     patch.get_y() + patch.get_height() / 2])


def test_the_heat_maps_count_every_agv_second_once(read):
    recording, record, states = read
    layout = recording.layout()
    time = cell_seconds(layout, states)
    for v in range(1, len(record.starts) + 1):  # states every 0.5 s: nothing capped
        seen = sorted(t for t, s in states if s.vehicle == v)
        assert time.per_vehicle[v] == pytest.approx(seen[-1] - seen[0])
    assert sum(time.total.values()) == pytest.approx(sum(time.per_vehicle.values()))
    assert all(time.waiting[c] <= time.total[c] + 1e-9 for c in time.waiting)
    waits = [t1 - t0 for s in record.subtasks for label, _, _, t0, t1, *_ in s.steps
             if label == "wait"]
    # States every 0.5 s: each wait is seen to within a state's period.
    assert sum(time.waiting.values()) == pytest.approx(sum(waits), abs=0.5 * len(waits))
    fig = order_plots.heat_map(layout, record, states)
    drawn = [c for ax in fig.axes for c in ax.collections if c.get_gid() == "heat"]
    assert [float(c.get_array().sum()) for c in drawn] == pytest.approx(
        [sum(time.total.values()), sum(time.waiting.values())])


def test_the_orders_curve_steps_at_each_completion(read):
    recording, record, _ = read
    tl = timeline(recording.layout(), record)
    ax = order_plots.orders_over_time(record, tl, recording.info.orders).axes[0]
    (done,) = [line for line in ax.get_lines() if line.get_label().startswith("completed")]
    xs, ys = done.get_data()
    assert list(xs[1:-1]) == [c.t for c in tl.completions]
    assert list(ys[1:-1]) == list(range(1, recording.info.orders + 1))


def test_the_foxglove_scene_shows_the_shelves_where_the_plots_do(read):
    recording, record, _ = read
    layout = recording.layout()
    tl = timeline(layout, record)
    views = SceneViews(layout, BASE, kind="orders", vehicles=recording.info.vehicles)
    start = {topic: decode(message) for topic, message, _ in views.start()}
    (shelves,) = start["/view/goods"].entities
    assert len(shelves.cubes) == len(layout.slots)
    frames = carried_seen = 0
    for r in recording.messages:
        if not r.genuine:
            continue
        out = views.on_message(r.key, r.envelope.message, r.envelope.sim_time)
        agvs = [decode(m) for topic, m, _ in out if topic == "/view/forklifts"]
        if not agvs:
            continue
        t = views.shown_until
        expected = tl.shelves_at(t)
        assert set(views.shelves.in_slot) == set(expected.in_slot), t
        assert views.shelves.carried == expected.on_agv, t
        frames += 1
        for entity in agvs[-1].entities:
            v = int(entity.id.split("/")[1])
            assert len(entity.cubes) == (2 if v in expected.on_agv else 1), (t, v)
            carried_seen += v in expected.on_agv
        goods = [decode(m) for topic, m, _ in out if topic == "/view/goods"]
        if goods:
            cells = {(round(c.pose.position.x - layout.origin[0]),
                      round(c.pose.position.y - layout.origin[1]))
                     for c in goods[-1].entities[0].cubes}
            assert cells == set(expected.in_slot), t
    assert frames > 100 and carried_seen > 0


def test_the_scene_of_a_lane_layout_draws_its_lanes_slots_stations_and_piles():
    views = SceneViews(MICRO_T, BASE, kind="orders", vehicles=2)
    (warehouse,) = [decode(m) for topic, m, _ in views.start() if topic == "/view/warehouse"]
    by_id = {e.id: e for e in warehouse.entities}
    junctions = {c for j in MICRO_T.junctions for c in j.cells}
    arrows = sum(len(d) for c, d in MICRO_T.lane_directions.items() if c not in junctions)
    tiles, heads = by_id["lanes"].triangles
    assert len(heads.points) == 3 * arrows and len(tiles.points) == 6 * len(junctions)
    assert len(by_id["slots"].cubes) == len(MICRO_T.slots)
    assert {i for i in by_id if i.startswith("packing/")} == {f"packing/{p.name}"
                                                              for p in MICRO_T.packing}
    assert {i for i in by_id if i.startswith("pile/")} == {f"pile/{p.name}" for p in MICRO_T.piles}
    # An arrowhead points its lane's way: the tip lies ahead of the cell's centre.
    lane = MICRO_T.lanes[0]
    cell = next(c for c in lane.cells if c not in junctions)
    x, y = MICRO_T.cell_center(cell)
    tips = [p for p in heads.points if abs(p.x - x) < 0.5 and abs(p.y - y) < 0.5]
    ahead = {"E": (1, 0), "W": (-1, 0), "N": (0, 1), "S": (0, -1)}[lane.direction]
    assert max((p.x - x) * ahead[0] + (p.y - y) * ahead[1] for p in tips) == pytest.approx(0.3)


def test_a_stow_postponed_puts_its_shelf_down_later():
    views = SceneViews(MICRO_T, BASE, kind="orders", vehicles=1)
    tracker = views.shelves
    stand = VehicleState(1, "3,2,E", 0, "", True, 3.5, 2.5, 0.0)
    assert tracker.on_state(VehicleState(1, "3,2,E", 0, "", False, 3.5, 2.5, 0.0), 0.0) is False
    assert tracker.on_state(stand, 0.5) is True and tracker.carried == {1: "s-3-2"}
    views.on_message("k", SubtaskEvent(1, "stow", "s-3-2", None, 1.0, 5.0, 5.0, False, [], []),
                     1.0)
    views.on_message("k", LegAmended(1, 1.0, 7.0, 7.0, [], []), 2.0)
    assert tracker.on_state(stand, 6.0) is False and tracker.carried == {1: "s-3-2"}
    assert tracker.on_state(stand, 7.0) is True and tracker.in_slot[3, 2] == "s-3-2"
    assert tracker.on_state(stand, 7.5) is False  # still "loaded" until its next trip


CELLS = st.tuples(st.integers(-1, MICRO_T.cols), st.integers(-1, MICRO_T.rows))
TIMES = st.floats(allow_nan=True, allow_infinity=True)
NAMES = st.sampled_from([s.name for s in MICRO_T.slots[:4]] + ["p1", "c2", "nowhere"])
MESSAGES = st.one_of(
    st.builds(lambda v, cell, loaded, x: VehicleState(v, f"{cell[0]},{cell[1]},E", 0, "",
                                                      loaded, x, cell[1] + 0.5, 0.0),
              st.integers(1, 3), CELLS, st.booleans(), TIMES),
    st.builds(lambda v, kind, target, t: SubtaskEvent(v, kind, target, None, 0.0, t, t, False,
                                                      [], []),
              st.integers(1, 3), st.sampled_from(["fetch", "pack", "stow", "charge"]), NAMES,
              TIMES),
    st.builds(lambda v, t: LegAmended(v, 0.0, t, t, [], []), st.integers(1, 3), TIMES))


def replay(messages) -> ShelfTracker:
    """The scene's shelves after these messages, one every 0.5 s of sim time."""
    views = SceneViews(MICRO_T, BASE, kind="orders", vehicles=1)  # each state a frame
    for k, message in enumerate(messages):
        views.on_message("k", message, 0.5 * k)
    return views.shelves


@settings(max_examples=150, deadline=None, derandomize=True)
@given(st.lists(MESSAGES, max_size=40))
def test_whatever_the_messages_say_no_shelf_is_lost_or_doubled(messages):
    """The scene survives any sequence of states and trips (a forged one included) and every
    shelf stays in exactly one place: a slot or one AGV."""
    tracker = replay(messages)
    where = list(tracker.in_slot.values()) + list(tracker.carried.values())
    assert sorted(where) == sorted(s.name for s in MICRO_T.slots)
    assert set(tracker.in_slot) <= {s.cell for s in MICRO_T.slots}


def test_replayed_states_do_move_shelves():
    standing, lifting = (VehicleState(2, "3,2,E", 0, "", loaded, 3.5, 2.5, 0.0)
                         for loaded in (False, True))
    assert replay([standing, lifting]).carried == {2: "s-3-2"}


# ------------------------------------------------------------------ makespan curves


def point(orders, agvs, bi, uni, bi_sd=5.0, uni_sd=8.0):
    return {"orders": orders, "agvs": agvs, "bi_s": bi, "uni_s": uni, "bi_sd": bi_sd,
            "uni_sd": uni_sd, "saving": 1 - bi / uni}


def bench_result() -> dict:
    return {"seeds": 3,
            "fig17": [point(50, 10, 400.0, 520.0), point(100, 10, 700.0, 950.0, 12.0, 20.0)],
            "fig18": [point(50, 5, 800.0, 990.0), point(50, 10, 400.0, 520.0),
                      point(50, 15, 330.0, 450.0), point(50, 20, 300.0, 420.0)],
            "fig19": [point(10, 10, 150.0, 190.0), point(20, 10, 260.0, 380.0)],
            "checks": {"fig17_rises_with_orders": True}}


def test_a_makespan_figure_has_the_points_of_the_result():
    result = bench_result()
    by_name = {c.name: c for c in curves(result, "r.json")}
    assert [by_name[n].varies for n in ("fig17", "fig18", "fig19")] == ["orders", "agvs",
                                                                        "orders"]
    ax = figure(by_name["fig18"], 3).axes[0]
    bars = {c.get_label(): c for c in ax.containers if isinstance(c, ErrorbarContainer)}
    assert len(bars) == 2
    for key, container in bars.items():
        which = "bi" if key.startswith("bidirectional") else "uni"
        line, _, (spread,) = container
        xs, ys = line.get_data()
        assert list(xs) == [5, 10, 15, 20]
        assert list(ys) == [p[f"{which}_s"] for p in result["fig18"]]
        lows_highs = [tuple(sorted(seg[:, 1])) for seg in spread.get_segments()]
        assert lows_highs == pytest.approx([(p[f"{which}_s"] - p[f"{which}_sd"],
                                             p[f"{which}_s"] + p[f"{which}_sd"])
                                            for p in result["fig18"]])
    savings = [t.get_text() for t in ax.texts]
    assert savings == [f"{p['saving']:.0%}" for p in result["fig18"]]
    assert "3 order seeds" in ax.get_title()


def test_plot_of_a_bench_result_writes_one_figure_per_experiment(tmp_path, capsys):
    path = tmp_path / "seed002.json"
    path.write_text(json.dumps(bench_result()))
    assert main(["plot", str(path), "--out", str(tmp_path / "figs")]) == 0
    printed = capsys.readouterr().out
    for name in ("fig17.png", "fig18.png", "fig19.png"):
        assert (tmp_path / "figs" / name).read_bytes()[:4] == b"\x89PNG"
        assert f"wrote {tmp_path / 'figs' / name}" in printed


@pytest.mark.parametrize("change, says", [
    (lambda r: r["fig17"][1].pop("uni_s"), "fig17[1].uni_s: missing; it must be a finite"),
    (lambda r: r["fig19"][0].update(bi_sd=-1.0), "fig19[0].bi_sd: -1.0 must not be negative"),
    (lambda r: r["fig18"][2].update(orders=60), "fig18: both orders and AGVs vary"),
    (lambda r: r.update(fig17=[]), "fig17 must be a non-empty list of points"),
    (lambda r: r["fig17"][0].update(agvs="ten"), "fig17[0].agvs: 'ten'"),
])
def test_a_bad_bench_result_is_refused_in_one_line(tmp_path, capsys, change, says):
    result = bench_result()
    change(result)
    path = tmp_path / "seed002.json"
    path.write_text(json.dumps(result))
    assert main(["plot", str(path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err and says in err, err
    assert err.startswith(f"fleet plot: error: {path}: ")


def test_snapshots_of_the_bench_result_are_refused(tmp_path, capsys):
    path = tmp_path / "seed002.json"
    path.write_text(json.dumps(bench_result()))
    assert main(["plot", str(path), "--at", "5"]) == 2
    assert "it has no instants to draw a snapshot at" in capsys.readouterr().err

