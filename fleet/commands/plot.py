"""`fleet plot RUN.mcap`: the filling sequence, a Gantt chart, a heat map of occupancy and
snapshots as PNG files, and an animation of the run, all from its recording; of an order
mission (seed 002) the orders completed over time instead of the filling sequence, and the
lane layout with its shelves, stations and piles; of a seed-004 run its heat maps and
snapshots of its floor. `fleet plot RESULT.json` draws the makespan curves of a `fleet bench
seed002` result (seed 002's Figures 17-19)."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from fleet.commands.progress import ProgressBar
from fleet.errors import UserError
from fleet.recording.reader import Recording, read_recording, recording_file
from fleet.recording.segments import RUN_FILE
from fleet.runtime.argtypes import positive_int, sim_seconds, writable_dir
from fleet.world.floor004 import Floor004

if TYPE_CHECKING:
    from collections.abc import Callable

    from fleet.mission.record import MissionSummary
    from fleet.views.makespan import Curve
    from fleet.views.order_timeline import OrderTimeline
    from fleet.wire.protocol import VehicleState

FRAMES = 150
FPS = 10


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("plot", help="draw a recorded run (its MCAP recording)",
                       description="Draw a recorded run from its recording: the filling "
                       "sequence (filling.png), a Gantt chart of every forklift's subtasks "
                       "(gantt.png), a heat map of where the forklifts were (heatmap.png), "
                       "snapshots of the warehouse at some times (snapshot_T.png) and an "
                       "animation of the whole run (run.gif or run.mp4). Of an order mission "
                       "(seed 002): the orders completed over time (orders.png) instead of the "
                       "filling sequence, a Gantt chart of every AGV's trips, the time on "
                       "each cell and the congestion (heatmap.png), and the lanes, shelves, "
                       "packing stations and piles in the snapshots and the animation. Of a "
                       "seed-004 run: its heat maps in the style of the seed's Figures 10-11 "
                       "(heat.png) and snapshots of its floor (snapshot_T.png: the shelves "
                       "home or away, each AGV with its number and heading, loaded or "
                       "empty). Of a "
                       "`fleet bench seed002 --json` result: the makespan curves of seed "
                       "002's Figures 17-19 (fig17.png, fig18.png, fig19.png).")
    p.add_argument("recording", type=Path,
                   help=f"the run's MCAP recording, or the directory holding {RUN_FILE} (and "
                   f"the later segments of a restarted recorder: read as one); or a JSON "
                   f"result of fleet bench seed002")
    p.add_argument("--out", type=writable_dir, metavar="DIR",
                   help="directory for the files (default: beside the recording)")
    p.add_argument("--at", type=sim_seconds, action="append", default=[],
                   metavar="SECONDS",
                   help="also draw a snapshot at this time in seconds (repeatable; default: "
                   "at a quarter, half and three quarters of the end time)")
    p.add_argument("--gif", action=argparse.BooleanOptionalAction, default=True,
                   help="animate the run into run.gif (default; a few seconds for a paper "
                   "mission); --no-gif skips it")
    p.add_argument("--mp4", action="store_true",
                   help="write the animation as run.mp4 instead (needs ffmpeg)")
    p.add_argument("--frames", type=positive_int, default=FRAMES,
                   help=f"frames of the animation, spread evenly over the run (default "
                   f"{FRAMES})")
    p.add_argument("--fps", type=positive_int, default=FPS,
                   help=f"frames per second of the animation (default {FPS})")
    p.set_defaults(handler=run)


def read_run(path: Path, recording: Recording | None = None
             ) -> tuple[Recording, MissionSummary]:
    """A run's recording (every segment of it; `recording` if read already) and its mission
    record (fleet.recording.mission_record.summary_of). A truncated recording (a killed
    recorder) is read as far as it goes, and windows without a recorder are skipped, each
    with a note."""
    from fleet.recording.mission_record import summary_of

    file = recording_file(path)
    recording = recording or read_recording(path)
    record = summary_of(recording)
    if not recording.complete:
        print(f"note: {file if len(recording.segments) < 2 else path} is incomplete "
              f"({recording.problem}); using what it holds", file=sys.stderr)
    for gap in recording.gaps:
        print(f"note: no recorder ran for {gap.duration_s:.1f} s between {gap.after.name} and "
              f"{gap.before.name}; what happened then is missing", file=sys.stderr)
    return recording, record


def bench_result(path: Path) -> dict | None:
    """The parsed `fleet bench seed002` result a path names, or None when it names none (a
    recording, or a file the recording reader will name and refuse)."""
    try:
        if not path.is_file():
            return None
        with open(path, "rb") as stream:
            looks_json = stream.read(64).lstrip()[:1] == b"{"
        if not (looks_json or path.suffix.lower() == ".json"):
            return None
        data = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, ValueError):
        return None
    from fleet.views.makespan import is_result

    return data if is_result(data) else None


def plot_bench(args: argparse.Namespace, result: dict) -> int:
    """The makespan figures of a `fleet bench seed002` result, beside it or in --out."""
    from fleet.views.makespan import curves

    if args.at:
        raise UserError(f"--at: {args.recording} is a fleet bench seed002 result (makespan "
                        f"curves); it has no instants to draw a snapshot at")
    out = args.out or args.recording.parent
    out.mkdir(parents=True, exist_ok=True)
    for path in write_makespan(curves(result, str(args.recording)), result.get("seeds"), out):
        print(f"wrote {path}")
    return 0


def write_makespan(found: list[Curve], seeds: object, out: Path) -> list[Path]:
    """One PNG per experiment of a seed 002 result: OUT/fig17.png, fig18.png, fig19.png."""
    from fleet.views.drawing import save_figure
    from fleet.views.makespan import figure

    count = seeds if isinstance(seeds, int) and not isinstance(seeds, bool) else None
    written = []
    for curve in found:
        written.append(out / f"{curve.name}.png")
        save_figure(figure(curve, count), str(written[-1]))
    return written


def run(args: argparse.Namespace) -> int:
    from fleet.wire.protocol import MissionDone

    result = bench_result(args.recording)
    if result is not None:
        return plot_bench(args, result)
    recording = read_recording(args.recording)
    floor = recording.layout().floor if recording.info is not None else None
    if floor is not None:
        return plot004(args, recording, floor)
    recording, record = read_run(args.recording, recording)
    layout = recording.layout()
    tl = None
    if record.mission.kind == "orders":
        from fleet.views.order_timeline import timeline

        tl = timeline(layout, record)
    finished = any(m.ok for _, m in recording.of(MissionDone))
    # An amended stow puts its shelf down later than its order was announced done.
    last = max(record.end_time_s, tl.makespan if tl is not None else 0.0)
    # A mission that did not finish is drawn up to where its recording ends: the wedge.
    end = last if finished else max(last, record.all_parked_s, recording.last_sim_time)
    refuse_late(args.at, end, finished)
    out = args.out or recording.path.parent
    out.mkdir(parents=True, exist_ok=True)
    if tl is not None:
        written, summary = plot_orders(args, recording, record, tl, end, out)
    else:
        written, summary = plot_stacks(args, recording, record, end, out)
    print(summary)
    for path in written:
        print(f"wrote {path}")
    return 0


def refuse_late(at: list[float], end: float, finished: bool) -> None:
    """A snapshot after the end would show the end under another time's name: refused."""
    late = [t for t in at if t > end]
    if late:
        ended = "the run ended" if finished else \
            "the mission did not finish; its recording ends"
        raise UserError(f"--at {late[0]:.10g}: {ended} at {end:.2f} s; snapshots are drawn "
                        f"from 0 to {end:.2f} s")


def snapshot_times(at: list[float], end: float) -> list[float]:
    """The instants given, or a quarter, half and three quarters of the end time."""
    return at or [end / 4, end / 2, 3 * end / 4]


def snapshot_path(out: Path, t: float) -> Path:
    return out / f"snapshot_{t:08.2f}.png"


def plot004(args: argparse.Namespace, recording: Recording, floor: Floor004) -> int:
    """A seed-004 run: its heat in the style of the seed's Figures 10-11 (heat.png) and its
    floor at some instants (snapshot_T.png), from its tracking events."""
    from fleet.analysis.analyze004 import (
        end_time_s,
        mission_finished,
        recorded_events,
        recorded_starts,
    )
    from fleet.mission.heat004 import heat_counts, t_values
    from fleet.views.drawing import save_figure
    from fleet.views.heat004 import heat_maps
    from fleet.views.snapshot004 import snapshot
    from fleet.views.state004 import floor_at

    events, _ = recorded_events(recording, floor)
    finished = mission_finished(recording)
    # A mission that did not finish is drawn up to where its recording ends.
    end = end_time_s(events) if finished else \
        max(end_time_s(events), recording.last_sim_time)
    refuse_late(args.at, end, finished)
    counts = heat_counts(events)
    info = recording.info
    out = args.out or recording.path.parent
    out.mkdir(parents=True, exist_ok=True)
    heading = f"{info.layout}: {info.orders} orders, {info.vehicles} lifting AGVs, seed " \
        f"{info.seed}"
    written = [out / "heat.png"]
    save_figure(heat_maps(floor, [
        ("T_value of this run (Equation 6, scaled to 0..1)", t_values(counts.heat())),
        ("cells entered", {xy: float(n) for xy, n in counts.passes.items()})],
        f"{heading}; the brighter, the hotter"), str(written[0]))
    starts = recorded_starts(recording, floor)
    for t in snapshot_times(args.at, end):
        written.append(snapshot_path(out, t))
        save_figure(snapshot(floor, floor_at(events, starts, t), heading), str(written[-1]))
    print(f"{sum(counts.passes.values())} cells entered, {len(counts.passes)} cells used")
    for path in written:
        print(f"wrote {path}")
    return 0


def states_of(recording: Recording) -> list[tuple[float, VehicleState]]:
    from fleet.wire.protocol import VehicleState

    states = [(r.envelope.sim_time, m) for r, m in recording.of(VehicleState)]
    if not states:
        print(f"note: {recording.path} holds no vehicle states: no heat map", file=sys.stderr)
    return states


def animated(args: argparse.Namespace, out: Path,
             draw: Callable[[str, Callable[[int, int], None]], int]) -> Path:
    """The animation's file, drawn by `draw(path, progress)` with a progress bar."""
    path = out / ("run.mp4" if args.mp4 else "run.gif")
    bar = ProgressBar(args.frames, path.name, unit="frames")
    try:
        draw(str(path), lambda done, _: bar.update(done))
    finally:
        bar.close()
    return path


def plot_stacks(args: argparse.Namespace, recording: Recording, record: MissionSummary,
                end: float, out: Path) -> tuple[list[Path], str]:
    """A stack mission's plots (seed 000: fleet/views/plots.py)."""
    from fleet.views import plots
    from fleet.views.drawing import save_figure

    layout = recording.layout()
    written = [out / "filling.png", out / "gantt.png"]
    save_figure(plots.filling_sequence(layout, record), str(written[0]))
    save_figure(plots.gantt(record), str(written[1]))
    if states := states_of(recording):
        written.append(out / "heatmap.png")
        save_figure(plots.heat_map(layout, record, states), str(written[-1]))
    for t in snapshot_times(args.at, end):
        path = snapshot_path(out, t)
        save_figure(plots.snapshot(layout, record, t), str(path))
        written.append(path)
    if args.gif or args.mp4:
        written.append(animated(args, out, lambda path, progress: plots.animate(
            path, layout, record, fps=args.fps, frames=args.frames, progress=progress)))
    return written, f"stacks per quarter of the end time: {plots.quarters(record)}"


def plot_orders(args: argparse.Namespace, recording: Recording, record: MissionSummary,
                tl: OrderTimeline, end: float, out: Path) -> tuple[list[Path], str]:
    """An order mission's plots (seed 002: fleet/views/order_plots.py)."""
    from fleet.views import order_plots
    from fleet.views.drawing import save_figure

    layout = recording.layout()
    orders = recording.info.orders if recording.info is not None else None
    written = [out / "orders.png", out / "gantt.png"]
    save_figure(order_plots.orders_over_time(record, tl, orders or 0), str(written[0]))
    save_figure(order_plots.gantt(record, tl, orders), str(written[1]))
    if states := states_of(recording):
        written.append(out / "heatmap.png")
        save_figure(order_plots.heat_map(layout, record, states, orders), str(written[-1]))
    for t in snapshot_times(args.at, end):
        path = snapshot_path(out, t)
        save_figure(order_plots.snapshot(layout, record, t, tl, orders), str(path))
        written.append(path)
    if args.gif or args.mp4:
        written.append(animated(args, out, lambda path, progress: order_plots.animate(
            path, layout, record, orders, fps=args.fps, frames=args.frames,
            progress=progress)))
    return written, (f"orders completed per quarter of the end time: "
                     f"{order_plots.quarters(tl, end)}")
