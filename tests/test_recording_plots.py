"""Plots, the animation and the comparison of recorded runs (MCAP), on small synthetic
recordings written with RecordingWriter."""

import dataclasses
import json
import math
import tomllib
from collections import Counter
from importlib import resources
from pathlib import Path

import pytest
from matplotlib.colors import to_rgb
from matplotlib.patches import Rectangle
from PIL import Image

from fleet.cli import main
from fleet.commands.plot import read_run
from fleet.errors import UserError
from fleet.mission.record import MissionHeader, MissionSummary, StackRecord, SubtaskRecord
from fleet.planning.planner import HybridAStar
from fleet.planning.reservations import ReservationTable
from fleet.planning.trajectory import Trajectory
from fleet.recording.writer import RecordingWriter
from fleet.views.drawing import draw_layout, map_figure, plan_figure
from fleet.views.palette import forklift_color
from fleet.views.plots import (
    animate,
    filling_sequence,
    gantt,
    heat_map,
    occupancy_seconds,
    pose_at,
    snapshot,
)
from fleet.wire.protocol import MissionInfo, StackDone, SubtaskEvent, VehicleState, encode
from fleet.wire.topics import expected_sender
from fleet.world.layout import Layout
from fleet.world.layout_file import load_layout, parse_layout
from fleet.world.places import resolve

STATE_PERIOD_S = 0.5  # the fast clock's state grid (fleet/mission/driving.py)


def layout_source(name: str) -> str:
    return resources.files("fleet.world.layouts").joinpath(f"{name}.toml").read_text()


def small_record(end: float = 40.0, kind: str = "fill", strategy: str = "ann") -> MissionSummary:
    """A record on `small`: forklift 1 drives two cells west, waits, fills stack a#1 at
    `end`; forklift 2 never moves."""
    steps = (("turn-right", "4,6,S", "3,5,W", 5.0, 10.0, 0, 1),
             ("forward", "3,5,W", "2,5,W", 10.0, 11.25, 1, 1),
             ("stop", "2,5,W", "2,5,W", 11.25, end - 5.0, 0, 0))
    intervals = ((2, 5, 10.0, math.inf), (3, 5, 5.0, 11.25), (4, 6, 5.0, 10.0))
    subtask = SubtaskRecord(1, "deliver", "a", 1, 5.0, end - 5.0, end, False, steps, intervals)
    return MissionSummary(MissionHeader("small", kind, strategy, 2, 0), ("4,6,S", "5,6,S"),
                          end_time_s=end, all_parked_s=end - 5.0, decision_failures=0,
                          wait_s={}, busy_s={}, stacks_done=(StackRecord("a", 1, end),),
                          failures=(), subtasks=(subtask,))


def two_forklift_record(end: float = 40.0, kind: str = "fill") -> MissionSummary:
    """small_record, and forklift 2 has a subtask for stack a#2 from 10 s until the end, in
    which it waits at its start: both forklifts have a row of bars up to the end."""
    record = small_record(end, kind)
    second = SubtaskRecord(2, "deliver", "a", 2, 10.0, end - 2.0, end, False,
                           (("stop", "5,6,S", "5,6,S", 10.0, end - 10.0, 0, 0),),
                           ((5, 6, 10.0, math.inf), (5, 5, 10.0, math.inf)))
    return dataclasses.replace(record, subtasks=(*record.subtasks, second),
                               stacks_done=(StackRecord("a", 2, end - 1.0),
                                            *record.stacks_done))


def write_recording(path: Path, record: MissionSummary, clock: str = "fast") -> Path:
    """A recording of `record` as a run would leave it: the mission message, every subtask
    and stack, and each forklift's state on the shared grid of sim times."""
    m = record.mission
    source = layout_source(m.layout)
    layout = parse_layout(source, m.layout)
    info = MissionInfo(layout=m.layout, layout_toml=source, kind=m.kind, strategy=m.strategy,
                       vehicles=m.vehicles, seed=m.seed, clock=clock, speed=1.0,
                       starts=list(record.starts))
    events: list[tuple[float, str, object]] = [(0.0, "dispatch/mission", info)]
    for s in record.subtasks:
        body = dataclasses.asdict(s) | {"steps": list(s.steps), "intervals": list(s.intervals)}
        events.append((s.t_i, "dispatch/subtask", SubtaskEvent(**body)))
    for stack in record.stacks_done:
        events.append((stack.t, "dispatch/stack", StackDone(stack.cluster, stack.index, 0,
                                                            stack.t)))
    end = max([s.t for s in record.stacks_done] + [s.t_done for s in record.subtasks])
    for k in range(int(end / STATE_PERIOD_S) + 1):
        t = k * STATE_PERIOD_S
        for v in range(1, m.vehicles + 1):
            x, y, th = pose_at(record, v, t, layout)
            state = VehicleState(v, "0,0,E", 0, "", False, x, y, th)
            events.append((t, f"vehicle/{v}/state", state))
    events.sort(key=lambda e: e[0])
    writer = RecordingWriter(path)
    writer.describe(info)
    numbers: Counter = Counter()
    for k, (t, key, message) in enumerate(events):
        key = f"fleet/test/{key}"
        numbers[key] += 1  # each key's one sender numbers its stream
        writer.write(key, encode(message, expected_sender(key), numbers[key], t), k * 1000, t)
    writer.close()
    return path


@pytest.fixture
def small() -> Layout:
    return parse_layout(layout_source("small"), "small")


def test_a_forklift_standing_still_occupies_exactly_its_body_cells(small):
    # Parked at 4,6 facing south (its start): the body covers 4,6 and 4,5 (front 1.8 m
    # ahead of the rear axle point, rear 1 m behind on 2 m cells).
    x, y = small.cell_center((4, 6))
    still = VehicleState(1, "4,6,S", 0, "", False, x, y, -math.pi / 2)
    states = [(k * 0.5, still) for k in range(21)]  # 0 to 10 s
    seconds = occupancy_seconds(small, states)
    assert set(seconds) == {(4, 6), (4, 5)}
    assert seconds[4, 6] == pytest.approx(10.0) and seconds[4, 5] == pytest.approx(10.0)


def test_occupancy_caps_gaps_and_counts_each_forklift(small):
    x, y = small.cell_center((4, 6))
    first = VehicleState(1, "4,6,S", 0, "", False, x, y, -math.pi / 2)
    x2, y2 = small.cell_center((6, 2))
    other = VehicleState(2, "6,2,E", 0, "", False, x2, y2, 0.0)
    # Forklift 1: a state, then nothing for 60 s (a gap counts 2 s at most); forklift 2's
    # states interleaved with it do not shorten forklift 1's intervals.
    states = [(0.0, first), (0.0, other), (1.0, other), (60.0, first), (3.0, other)]
    seconds = occupancy_seconds(small, states, cap_s=2.0)
    assert seconds[4, 6] == pytest.approx(2.0)
    assert seconds[6, 2] == pytest.approx(3.0)  # 1 s, then 2 s: states sorted per forklift
    assert set(seconds) == {(4, 6), (4, 5), (6, 2), (7, 2)}  # facing east: front is east


def test_plot_writes_the_pngs_and_a_gif_of_the_requested_frames(tmp_path, capsys):
    run = write_recording(tmp_path / "run.mcap", small_record())
    out = tmp_path / "plots"
    assert main(["plot", str(tmp_path), "--out", str(out), "--at", "12", "--frames", "7"]) == 0
    printed = capsys.readouterr().out
    for name in ("filling.png", "gantt.png", "heatmap.png", "snapshot_00012.00.png"):
        assert (out / name).read_bytes()[:4] == b"\x89PNG", name
        assert f"wrote {out / name}" in printed
    with Image.open(out / "run.gif") as gif:
        assert gif.n_frames == 7
    assert f"wrote {out / 'run.gif'}" in printed
    # The file itself works as well as its directory, and --no-gif skips the animation.
    assert main(["plot", str(run), "--out", str(tmp_path / "again"), "--no-gif"]) == 0
    assert not (tmp_path / "again" / "run.gif").exists()
    assert (tmp_path / "again" / "heatmap.png").exists()


@pytest.mark.parametrize("content", ['{"mission": {}}', "not json at all"])
def test_plot_of_a_json_file_is_refused_clearly(tmp_path, capsys, content):
    old = tmp_path / "mission.json"
    old.write_text(content)
    assert main(["plot", str(old)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("fleet plot: error: ")
    assert "mission.json" in err and "MCAP" in err


def test_plot_of_a_file_that_is_not_mcap_is_refused(tmp_path, capsys):
    other = tmp_path / "run.mcap"
    other.write_text("hello")
    assert main(["plot", str(other)]) == 2
    assert "not an MCAP recording" in capsys.readouterr().err
    assert main(["plot", str(tmp_path / "missing")]) == 2
    assert "no such file or directory" in capsys.readouterr().err.lower()


def test_animation_formats_are_checked_before_drawing(tmp_path, small, monkeypatch):
    from matplotlib import animation

    monkeypatch.setattr(animation.FFMpegWriter, "isAvailable", classmethod(lambda cls: False))
    with pytest.raises(UserError, match="an MP4 needs ffmpeg, which is not on the PATH"):
        animate(str(tmp_path / "run.mp4"), small, small_record())
    with pytest.raises(UserError, match=r"a \.gif or an \.mp4 file, not \.avi"):
        animate(str(tmp_path / "run.avi"), small, small_record())
    assert not any(tmp_path.iterdir())


def test_compare_prints_both_runs_and_the_difference(tmp_path, capsys):
    a = write_recording(tmp_path / "a.mcap", small_record(end=40.0))
    b = write_recording(tmp_path / "b.mcap", small_record(end=50.0, strategy="greedy"))
    assert main(["compare", str(a), str(b)]) == 0
    out = capsys.readouterr().out
    line = next(ln for ln in out.splitlines() if ln.startswith("end time"))
    assert line.split()[-4:] == ["40.00", "50.00", "+10.00", "1.250"]
    strategy = next(ln for ln in out.splitlines() if ln.startswith("strategy"))
    assert "ann" in strategy and "greedy" in strategy and "differs" in strategy
    assert "forklift 1 busy" in out and str(a) in out and str(b) in out


def test_compare_json_gives_both_runs_and_the_differences(tmp_path, capsys):
    a = write_recording(tmp_path / "a.mcap", small_record(end=40.0))
    b = write_recording(tmp_path / "b.mcap", small_record(end=50.0))
    assert main(["compare", str(a), str(b), "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["a"]["end_time_s"] == 40.0 and data["b"]["end_time_s"] == 50.0
    assert data["diff"]["end_time_s"] == pytest.approx(10.0)
    assert data["ratio"]["end_time_s"] == pytest.approx(1.25)
    for key in ("mission", "strategy", "layout", "vehicles", "clock", "stacks_done",
                "subtasks", "decision_failures", "plans_failed", "waiting_s", "stopped_s",
                "postponed_s", "mean_utilisation", "busy_s"):
        assert key in data["a"] and key in data["b"], key
    # Stacks as the analysis counts them: served as the forklifts' states show it.
    from fleet.analysis.analyze import analyze
    from fleet.recording.reader import read_recording
    assert data["a"]["clock"] == "fast"
    assert data["a"]["stacks_done"] == analyze(read_recording(a)).stacks_done
    # Forklift 1 waits 10 s longer in B (its stop lasts to end - 5), stopped, not postponed;
    # its busy time is equal.
    assert data["diff"]["waiting_s"] == pytest.approx(10.0)
    assert data["diff"]["stopped_s"] == pytest.approx(10.0)
    assert data["diff"]["postponed_s"] == 0
    assert data["diff"]["busy_s"]["1"] == pytest.approx(0.0)


def test_plot_mp4_needs_ffmpeg_and_says_so(tmp_path, capsys, monkeypatch):
    from matplotlib import animation

    monkeypatch.setattr(animation.FFMpegWriter, "isAvailable", classmethod(lambda cls: False))
    write_recording(tmp_path / "run.mcap", small_record())
    assert main(["plot", str(tmp_path), "--mp4", "--frames", "3"]) == 2
    assert "an MP4 needs ffmpeg" in capsys.readouterr().err


# ------------------------------------------------------------------ what a reader relies on


def recorded(tmp_path: Path, record: MissionSummary) -> tuple[Layout, MissionSummary, list]:
    """The layout, the mission record and the vehicle states of `record` after a trip
    through a recording, as `fleet plot` reads them."""
    recording, rebuilt = read_run(write_recording(tmp_path / "run.mcap", record))
    states = [(r.envelope.sim_time, m) for r, m in recording.of(VehicleState)]
    return recording.layout(), rebuilt, states


def small_plan_figure(small: Layout):
    """`fleet plan --png`'s figure: forklift 1 from its start to stack a#1 on `small`."""
    table = ReservationTable()
    start, goals = resolve(small, "4,6,S", set())[0], resolve(small, "a#1", set())
    traj = HybridAStar(small.grid_map(), small.vehicle.dims).plan(1, start, 0.0, goals, table)
    assert isinstance(traj, Trajectory)
    table.commit(1, traj.intervals, release_from=traj.t_start)
    return plan_figure(small, traj, [], table.reservations(), set(), "plan")


def test_every_map_is_drawn_in_the_layouts_metres(tmp_path, small):
    layout, record, states = recorded(tmp_path, two_forklift_record())
    bounds = tomllib.loads(layout_source("small"))["bounds"]
    figures = {"filling": filling_sequence(layout, record), "heat map":
               heat_map(layout, record, states), "snapshot": snapshot(layout, record, 12.0),
               "plan": small_plan_figure(small)}
    for name, fig in figures.items():
        ax = fig.axes[0]
        assert (ax.get_xlabel(), ax.get_ylabel()) == ("x [m]", "y [m]"), name
        # The axes span the layout's bounds as its file gives them, in metres.
        assert ax.get_xlim() == pytest.approx(bounds["x"]), name
        assert ax.get_ylim() == pytest.approx(bounds["y"]), name
        assert ax.get_title(), name


def test_the_gantt_legend_covers_no_bar(tmp_path):
    # Both forklifts work up to the end: upper right, where the legend used to be, is full.
    _, record, _ = recorded(tmp_path, two_forklift_record())
    fig = gantt(record)
    fig.canvas.draw()
    ax = fig.axes[0]
    legend = ax.get_legend().get_window_extent()
    bars = [p for p in ax.patches if isinstance(p, Rectangle)]
    assert len(bars) >= 4
    assert not [b for b in bars if legend.overlaps(b.get_window_extent())]
    assert ax.get_xlabel() == "simulated time [s]"


@pytest.mark.parametrize("kind", ["fill", "empty"])
def test_a_snapshot_has_legend_entries_for_filled_and_empty_stacks(tmp_path, kind):
    layout, record, _ = recorded(tmp_path, two_forklift_record(kind=kind))
    fig = snapshot(layout, record, 39.5)  # a#2 done at 39, a#1 at 40
    ax = fig.axes[0]
    entries = dict(zip([t.get_text() for t in ax.get_legend().get_texts()],
                       ax.get_legend().legend_handles, strict=True))
    squares = {p.get_gid(): p for p in ax.patches if p.get_gid()}
    done, waiting = ("stack, filled", "stack, empty")[:: 1 if kind == "fill" else -1]
    # A reader matches a stack to its legend entry by colour.
    assert to_rgb(squares["stack/a#2"].get_facecolor()) == to_rgb(
        entries[done].get_facecolor())
    assert to_rgb(squares["stack/a#1"].get_facecolor()) == to_rgb(
        entries[waiting].get_facecolor())
    assert to_rgb(entries["stack, filled"].get_facecolor()) != to_rgb(
        entries["stack, empty"].get_facecolor())
    for v in (1, 2):
        assert to_rgb(entries[f"forklift {v}"].get_facecolor()) == pytest.approx(
            forklift_color(v))


@pytest.mark.parametrize("name", ["small", "paper", "paper-cut", "paper-firewall", "hall"])
def test_cluster_names_hide_no_stack(name):
    layout = load_layout(name)
    fig, ax = map_figure(layout)
    draw_layout(ax, layout, filled=())
    fig.canvas.draw()
    names = {t.get_gid(): t for t in ax.texts if (t.get_gid() or "").startswith("cluster/")}
    assert set(names) == {f"cluster/{c.name}" for c in layout.clusters}
    stacks = [p.get_window_extent() for p in ax.patches
              if (p.get_gid() or "").startswith("stack/")]
    assert len(stacks) == len(layout.stacks)
    for gid, text in names.items():
        box = text.get_bbox_patch().get_window_extent()  # the name with its white box
        assert text.get_fontweight() == "bold"
        # Touching a stack's edge is allowed; covering any of it by more than a pixel is not.
        covered = [s for s in stacks if min(box.x1, s.x1) - max(box.x0, s.x0) > 1
                   and min(box.y1, s.y1) - max(box.y0, s.y0) > 1]
        assert not covered, gid


def test_plan_png_draws_each_vehicle_in_its_forklift_colour(small):
    fig = small_plan_figure(small)
    ax = fig.axes[0]
    (path,) = [line for line in ax.lines if len(line.get_xdata()) > 1]
    assert to_rgb(path.get_color()) == pytest.approx(forklift_color(1))
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert "vehicle 1 (planned)" in labels and "stack, empty" in labels
