"""Plots of a mission record (seed 000, Figures 13 to 18 style): the filling sequence by
quarter, a Gantt chart of the subtasks, a snapshot of the warehouse at one instant, a heat map
of where the forklifts were, and an animation of the whole run.

They read the mission record (fleet.mission.record.MissionSummary; for a recording, as
rebuilt by fleet.recording.mission_record.summary_of), so they draw any saved run; the heat
map also reads the recorded vehicle states. Each returns its figure
(fleet.views.drawing.save_figure writes it), so what a reader sees can be checked on the
figure itself.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from dataclasses import replace
from itertools import pairwise
from pathlib import Path
from typing import Protocol

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib import animation
from matplotlib.artist import Artist
from matplotlib.axes import Axes
from matplotlib.collections import PatchCollection
from matplotlib.colors import LogNorm, to_rgba
from matplotlib.figure import Figure
from matplotlib.legend_handler import HandlerTuple
from matplotlib.lines import Line2D
from matplotlib.patches import Patch, PathPatch
from matplotlib.textpath import TextPath
from matplotlib.transforms import Affine2D
from PIL import Image

from fleet.errors import UserError
from fleet.mission.record import MissionSummary, held_intervals
from fleet.planning.geometry import Cell, body_corners, cells_under
from fleet.planning.maneuvers import Manner, world_pose
from fleet.planning.trajectory import Pose
from fleet.views.drawing import (
    STACK_NUMBER_PT,
    Z_FORKLIFT_TEXT,
    Z_RESERVED,
    Z_STACK_TEXT,
    cell_square,
    draw_layout,
    forklift_handles,
    forklift_patch,
    inches_per_metre,
    legend_below,
    map_figure,
    stack_number_spot,
)
from fleet.views.palette import GOODS_COLOR, forklift_color, lighter
from fleet.wire.protocol import VehicleState
from fleet.world.layout import Layout

QUARTER_COLORS = ["tab:red", "tab:blue", "tab:green", "gold"]  # as in the seed's figures
CLAIM_COLOR = "0.6"  # the Gantt chart's claiming and unloading
SHOW_AHEAD_S = 20.0  # a snapshot shows reserved cells this far ahead
HELD_NOW_ALPHA, HELD_SOON_ALPHA = 0.35, 0.12  # reserved cells held now, held soon



def vehicle_rows(ax: Axes, record: MissionSummary, row: dict[int, int], vehicles: list[int],
                 noun: str) -> None:
    """A Gantt chart's rows: one a vehicle, named in its colour, the first on top, a cross
    where a plan of its failed."""
    failures = [(f.t, row[f.vehicle] - 0.42) for f in record.failures
                if f.stage == "plan" and f.vehicle in row]
    if failures:
        ax.plot(*zip(*failures, strict=True), "kx", ms=4, mew=0.8)
    ax.set_yticks(range(len(vehicles)), [f"{noun} {v}" for v in vehicles])
    for label, v in zip(ax.get_yticklabels(), vehicles, strict=True):
        label.set_color(forklift_color(v))
        label.set_fontweight("bold")
    ax.set_ylim(len(vehicles) - 0.5, -0.6)  # the first on top, room for its crosses

def heading(record: MissionSummary) -> str:
    """Which run a plot is of, for its title."""
    m = record.mission
    return (f"{m.kind} mission with the {m.strategy} strategy on {m.layout}, "
            f"{len(record.starts)} forklifts")


def forklifts(record: MissionSummary) -> list[int]:
    """Every forklift of the run, numbered from 1, also those that never had a subtask."""
    return sorted(set(range(1, len(record.starts) + 1)) | {s.vehicle for s in record.subtasks})


def quarters(record: MissionSummary) -> list[int]:
    """Stacks done in each quarter of the mission's end time."""
    end = record.end_time_s or 1.0
    counts = [0, 0, 0, 0]
    for stack in record.stacks_done:
        counts[min(3, int(4 * stack.t / end))] += 1
    return counts


def filling_sequence(layout: Layout, record: MissionSummary) -> Figure:
    """Each stack coloured by the quarter of the end time it was done in and numbered in the
    order done (the seed's Figure 13)."""
    fill = record.mission.kind == "fill"
    verb = "filled" if fill else "emptied"
    end = record.end_time_s or 1.0
    left = len(layout.stacks) - len(record.stacks_done)
    fig, ax = map_figure(layout)
    handles = draw_layout(ax, layout, stacks_label=f"not {verb}: {left} stacks" if left else None)
    cell_of = {(s.cluster, s.index): s.cell for s in layout.stacks}
    for order, stack in enumerate(record.stacks_done, start=1):
        cell = cell_of[stack.cluster, stack.index]
        ax.add_patch(cell_square(layout, cell, alpha=0.8,
                                 color=QUARTER_COLORS[min(3, int(4 * stack.t / end))]))
        x, y = layout.cell_center(cell)
        ax.text(x, y - 0.12 * layout.cell_size, str(order), ha="center", va="center",
                fontsize=7, weight="bold", color="white", zorder=Z_STACK_TEXT)
    by_quarter = [Patch(color=c, alpha=0.8, label=f"{verb} in quarter {q + 1} "
                        f"({q * end / 4:.0f} to {(q + 1) * end / 4:.0f} s): {n} stacks")
                  for q, (c, n) in enumerate(zip(QUARTER_COLORS, quarters(record), strict=True))]
    ax.set_title(f"{'Filling' if fill else 'Emptying'} sequence: when each stack was {verb}, "
                 f"the last at {record.end_time_s:.2f} s\n{heading(record)}\nbold number: "
                 f"the order {verb}; small number: the stack's place in its cluster",
                 fontsize=10)
    legend_below(ax, by_quarter + handles, ncols=4)
    return fig


def gantt(record: MissionSummary) -> Figure:
    """One row per forklift, its subtasks along time: driving to a shelf in the forklift's
    colour, to a station in a lighter shade, claiming or unloading in grey, waiting (stop
    maneuvers) in black, failed plans as crosses above the row."""
    vehicles = forklifts(record)
    fig, ax = plt.subplots(figsize=(14, 1.9 + 0.55 * len(vehicles)), layout="constrained")
    row = {v: k for k, v in enumerate(vehicles)}
    for s in record.subtasks:
        y, color = row[s.vehicle], forklift_color(s.vehicle)
        ax.barh(y, s.t_end - s.t_i, left=s.t_i, height=0.6,
                color=color if s.kind == "deliver" else lighter(color, 0.55))
        ax.barh(y, s.t_done - s.t_end, left=s.t_end, color=CLAIM_COLOR, height=0.6)
        for st in s.steps:
            if st[0] == "stop":
                ax.barh(y, st[4] - st[3], left=st[3], color="black", height=0.25)
    vehicle_rows(ax, record, row, vehicles, "forklift")
    last = max([record.end_time_s] + [s.t_done for s in record.subtasks])
    ax.set_xlim(0, 1.01 * last or 1.0)
    ax.set_xlabel("simulated time [s]")
    swatches = vehicles or [1]  # the legend's colours: every forklift's
    full = tuple(Patch(color=forklift_color(v)) for v in swatches)
    light = tuple(Patch(color=lighter(forklift_color(v), 0.55)) for v in swatches)
    legend_below(ax, [full, light, Patch(color=CLAIM_COLOR), Patch(color="black"),
                       Line2D([], [], ls="none", marker="x", color="black", ms=4, mew=0.8)],
                 labels=["driving to a shelf (forklift's colour)",
                         "driving to a station (lighter)", "claiming / unloading",
                         "stopped (a stop maneuver)", "plan failed"],
                 handler_map={tuple: HandlerTuple(ndivide=None, pad=0)})
    ax.set_title(f"What each forklift did over time, subtask by subtask\n{heading(record)}",
                 fontsize=10)
    return fig


def pose_at(record: MissionSummary, vehicle: int, t: float,
            layout: Layout) -> tuple[float, float, float]:
    """World pose of a forklift at time t, interpolated within the maneuver it is doing."""
    pose = Pose.parse(record.starts[vehicle - 1])  # vehicles are numbered from 1
    for s in record.subtasks:
        if s.vehicle != vehicle:
            continue
        for label, start, end, t0, t1, *_ in s.steps:
            if t0 <= t < t1:
                p = Pose.parse(start)
                x, y, th = world_pose(p.cell, p.heading, Manner.from_label(label),
                                      (t - t0) / (t1 - t0), layout.cell_size)
                ox, oy = layout.cell_center((0, 0))
                return ox + x, oy + y, th
            if t1 <= t:
                pose = Pose.parse(end)
    x, y = layout.cell_center(pose.cell)
    return x, y, pose.heading * math.pi / 2


def fleet_handles(vehicles: Iterable[int], ahead: float) -> list[Artist]:
    """Legend entries of a map with forklifts and their reserved cells."""
    return [*forklift_handles(vehicles),
            Patch(color="0.3", alpha=HELD_NOW_ALPHA, label="reserved now (its colour)"),
            Patch(color="0.3", alpha=HELD_SOON_ALPHA, label=f"reserved in the next {ahead:g} s")]


def snapshot(layout: Layout, record: MissionSummary, t: float,
             ahead: float = SHOW_AHEAD_S) -> Figure:
    """The warehouse at instant t: stacks filled or empty, each forklift and the cells it
    holds now (dark) or will hold within `ahead` seconds (light), in its colour."""
    fill = record.mission.kind == "fill"
    cell_of = {(s.cluster, s.index): s.cell for s in layout.stacks}
    done = {cell_of[s.cluster, s.index] for s in record.stacks_done if s.t <= t}
    present = done if fill else {s.cell for s in layout.stacks} - done
    fig, ax = map_figure(layout)
    handles = draw_layout(ax, layout, present)
    vehicles = forklifts(record)
    held = held_intervals(record)
    for v in vehicles:
        color = forklift_color(v)
        for vehicle, cell, t0, t1 in held:
            if vehicle == v and t0 < t + ahead and t1 > t:
                ax.add_patch(cell_square(
                    layout, cell, color=color, zorder=Z_RESERVED,
                    alpha=HELD_NOW_ALPHA if t0 <= t else HELD_SOON_ALPHA))
        x, y, th = pose_at(record, v, t, layout)
        ax.add_patch(forklift_patch(layout, v, x, y, th))
        ax.text(x, y, str(v), ha="center", va="center", fontsize=8, color="white",
                weight="bold", zorder=Z_FORKLIFT_TEXT)
    ax.set_title(f"The warehouse at t = {t:.2f} s: {len(done)} of {len(layout.stacks)} stacks "
                 f"{'filled' if fill else 'emptied'}\n{heading(record)}", fontsize=10)
    legend_below(ax, handles + fleet_handles(vehicles, ahead), ncols=5)
    return fig


# ----------------------------------------------------------------------------- heat map

# A state stands for at most this long: a gap in the recording (lost messages, a paused
# clock, the end of a run) must not paint the last pose seen as occupied for the whole gap.
STATE_GAP_CAP_S = 2.0


def body_cells(layout: Layout, x: float, y: float, theta: float) -> set[Cell]:
    """Cells under a forklift's body at a recorded pose. States carry world coordinates
    (fleet/mission/driving.py adds `layout.origin`); body_corners and cells_under work in the
    frame where cell (0, 0) is centred at the origin, so the origin comes off first."""
    ox, oy = layout.origin
    return cells_under(body_corners(x - ox, y - oy, theta, layout.vehicle.dims),
                       layout.cell_size)


def occupancy_seconds(layout: Layout, states: Iterable[tuple[float, VehicleState]],
                      cap_s: float = STATE_GAP_CAP_S) -> dict[Cell, float]:
    """Seconds each cell was under some forklift's body. Each (sim time, state) counts for the
    time until the same forklift's next state, at most cap_s; a forklift's last state counts
    for nothing (nothing says how long it held). Cells off the grid are kept; states with a
    non-finite time or pose are skipped."""
    tracks: dict[int, list[tuple[float, VehicleState]]] = {}
    for t, state in states:
        if all(math.isfinite(v) for v in (t, state.x, state.y, state.theta)):
            tracks.setdefault(state.vehicle, []).append((t, state))
    seconds: dict[Cell, float] = {}
    cells_at: dict[tuple[float, float, float], set[Cell]] = {}  # parked forklifts repeat poses
    for track in tracks.values():
        track.sort(key=lambda ts: ts[0])
        for (t, state), (t_next, _) in pairwise(track):
            dt = min(t_next - t, cap_s)
            if dt <= 0:
                continue
            pose = (state.x, state.y, state.theta)
            if pose not in cells_at:
                cells_at[pose] = body_cells(layout, *pose)
            for cell in cells_at[pose]:
                seconds[cell] = seconds.get(cell, 0.0) + dt
    return seconds


def heat_map(layout: Layout, record: MissionSummary, states: Iterable[tuple[float, VehicleState]],
             cap_s: float = STATE_GAP_CAP_S) -> Figure:
    """Cell occupancy over the run from the recorded vehicle states, over the layout."""
    seconds = {c: s for c, s in occupancy_seconds(layout, states, cap_s).items()
               if 0 <= c[0] < layout.cols and 0 <= c[1] < layout.rows and s > 0}
    fig, ax = map_figure(layout, extra_width_in=1.5)
    handles = draw_layout(ax, layout, stacks_label="stack, never under a forklift")
    busiest = ""
    if seconds:
        values = np.array(list(seconds.values()))
        lo, hi = float(values.min()), float(values.max())
        # Log scale: parked forklifts hold a few cells for hundreds of seconds while a lane
        # sees seconds to minutes; a linear scale would show little but the parking spots.
        squares = PatchCollection([cell_square(layout, c) for c in seconds], cmap="YlOrRd",
                                  norm=LogNorm(vmin=lo, vmax=max(hi, 2 * lo)), alpha=0.85,
                                  edgecolor="none")
        squares.set_array(values)
        ax.add_collection(squares)
        fig.colorbar(squares, ax=ax, shrink=0.8,
                     label="seconds some forklift's body covered the cell (log scale)")
        busiest = f"; the busiest cell {hi:.0f} s"
    ax.set_title(f"Where the forklifts were: seconds each cell lay under a forklift's body"
                 f"{busiest}\n{heading(record)}", fontsize=10)
    legend_below(ax, handles, ncols=4)
    return fig


# ---------------------------------------------------------------------------- animation

FRAMES = 150
FPS = 10
GIF_DPI = 80  # 960 x 740 pixels for paper: readable, and a paper mission stays a few megabytes


def frame_times(record: MissionSummary, frames: int) -> list[float]:
    """`frames` instants spread evenly from 0 to when the last forklift parked (or the last
    stack was done, if later), both ends included."""
    end = max(record.end_time_s, record.all_parked_s)
    if frames == 1:
        return [end]
    return [end * k / (frames - 1) for k in range(frames)]


def _stack_numbers(layout: Layout) -> PatchCollection:
    """Each stack's number as stack_number() draws it (place and size), as glyph outlines."""
    size = STACK_NUMBER_PT / 72 / inches_per_metre(layout)  # in metres, on a map_figure()
    patches = []
    for stack in layout.stacks:
        x, y = stack_number_spot(layout, stack)
        glyphs = TextPath((0, 0), str(stack.index), size=size)
        (gx0, gy0), (gx1, gy1) = glyphs.get_extents().get_points()
        patches.append(PathPatch(glyphs.transformed(
            Affine2D().translate(x - (gx0 + gx1) / 2, y - (gy0 + gy1) / 2))))
    return PatchCollection(patches, edgecolor="none", zorder=Z_STACK_TEXT)


class _RunArtists:
    """The moving parts of an animation over a layout drawn once: stacks present (with their
    numbers), reserved cells, the cluster names (kept readable over them), forklift bodies
    and the title. `show(t)` updates them in place for instant t; `artists` lists them
    in drawing order."""

    def __init__(self, ax, layout: Layout, record: MissionSummary, ahead: float) -> None:
        self.layout, self.record, self.ahead = layout, record, ahead
        self.fill = record.mission.kind == "fill"
        done_at = {(s.cluster, s.index): s.t for s in record.stacks_done}
        self.stack_done = np.array([done_at.get((s.cluster, s.index), math.inf)
                                    for s in layout.stacks])
        self.stack_rgba = np.tile(to_rgba(GOODS_COLOR), (len(layout.stacks), 1))
        self.stacks = ax.add_collection(PatchCollection(
            [cell_square(layout, s.cell) for s in layout.stacks], edgecolor="white", lw=0.4))
        # White numbers on present stacks (the background's dark ones show on the others),
        # as glyph outlines in one collection: a frame draws them at once, not as 136 texts.
        self.numbers = ax.add_collection(_stack_numbers(layout))
        self.number_rgba = np.tile(to_rgba("white"), (len(layout.stacks), 1))
        # One square per (forklift, cell) ever held; each frame sets its alpha.
        held = held_intervals(record)
        square: dict[tuple[int, Cell], int] = {}
        for vehicle, cell, _, _ in held:
            square.setdefault((vehicle, tuple(cell)), len(square))
        self.held_square = np.array([square[v, tuple(c)] for v, c, _, _ in held], dtype=int)
        self.held_t0 = np.array([h[2] for h in held], dtype=float)
        self.held_t1 = np.array([h[3] for h in held], dtype=float)
        self.held_rgba = np.array([to_rgba(forklift_color(v)) for v, _ in square]).reshape(-1, 4)
        self.held = ax.add_collection(PatchCollection(
            [cell_square(layout, c) for _, c in square], edgecolor="none", zorder=Z_RESERVED))
        self.cluster_names = [t for t in ax.texts if (t.get_gid() or "").startswith("cluster/")]
        # Per-forklift records: pose_at then scans one forklift's subtasks, not the fleet's.
        self.tracks = {v: replace(record, subtasks=tuple(s for s in record.subtasks
                                                         if s.vehicle == v))
                       for v in range(1, len(record.starts) + 1)}
        self.bodies = [ax.add_patch(forklift_patch(layout, v, 0.0, 0.0, 0.0))
                       for v in self.tracks]
        self.labels = [ax.text(0.0, 0.0, str(v), ha="center", va="center", fontsize=8,
                               color="white", weight="bold", zorder=Z_FORKLIFT_TEXT)
                       for v in self.tracks]
        self.heading = heading(record)
        self.title = ax.set_title("", fontsize=10)
        self.artists = [self.stacks, self.numbers, self.held, *self.cluster_names, *self.bodies,
                        *self.labels, *ax.spines.values(), self.title]
        for artist in self.artists:
            artist.set_animated(True)  # left out of the background, drawn by each frame

    def show(self, t: float) -> None:
        done = self.stack_done <= t
        self.stack_rgba[:, 3] = done if self.fill else ~done
        self.stacks.set_facecolor(self.stack_rgba)
        self.number_rgba[:, 3] = self.stack_rgba[:, 3]
        self.numbers.set_facecolor(self.number_rgba)
        alive = self.held_t1 > t  # as snapshot(): dark while held, light if held soon
        now = alive & (self.held_t0 <= t)
        soon = alive & (self.held_t0 < t + self.ahead)
        alpha = np.zeros(len(self.held_rgba))
        np.maximum.at(alpha, self.held_square[soon], HELD_SOON_ALPHA)
        np.maximum.at(alpha, self.held_square[now], HELD_NOW_ALPHA)
        rgba = self.held_rgba.copy()
        rgba[:, 3] = alpha
        self.held.set_facecolor(rgba)
        for (v, track), body, label in zip(self.tracks.items(), self.bodies, self.labels,
                                           strict=True):
            x, y, th = pose_at(track, v, t, self.layout)
            body.set_xy(body_corners(x, y, th, self.layout.vehicle.dims))
            label.set_position((x, y))
        self.title.set_text(f"The warehouse at t = {t:.1f} s: {int(done.sum())} of "
                            f"{len(done)} stacks {'filled' if self.fill else 'emptied'}\n"
                            f"{self.heading}")


# The writers take each frame from the canvas as blitted, instead of matplotlib's savefig,
# which would redraw the whole figure (every cell and label) twice per frame.


class _GifWriter(animation.PillowWriter):
    """Frames palettised as they come, to one palette made from sample frames (`sample()`
    before the first frame): no colour flicker, a third of the memory of RGB frames, and
    far faster than an adaptive palette per frame."""

    def setup(self, fig, outfile, dpi=None) -> None:
        super().setup(fig, outfile, dpi)
        self._samples: list[np.ndarray] = []
        self._palette: Image.Image | None = None

    def _canvas(self) -> np.ndarray:
        return np.asarray(self.fig.canvas.buffer_rgba())[..., :3]

    def sample(self) -> None:
        """Let the canvas as it is now contribute to the palette."""
        self._samples.append(self._canvas().copy())

    def grab_frame(self, **savefig_kwargs) -> None:
        frame = self._canvas()
        if self._palette is None:
            montage = np.concatenate([*self._samples, frame])
            self._palette = Image.fromarray(montage).quantize(
                colors=255, method=Image.Quantize.MEDIANCUT)
        self._frames.append(Image.fromarray(frame).quantize(palette=self._palette,
                                                            dither=Image.Dither.NONE))


class _Mp4Writer(animation.FFMpegWriter):
    def grab_frame(self, **savefig_kwargs) -> None:
        self._proc.stdin.write(bytes(self.fig.canvas.buffer_rgba()))


def movie_writer(path: str, fps: int) -> animation.AbstractMovieWriter:
    """The writer for an animation file: GIF with Pillow, MP4 with ffmpeg if installed."""
    suffix = Path(path).suffix.lower()
    if suffix == ".gif":
        return _GifWriter(fps=fps)
    if suffix == ".mp4":
        if not animation.FFMpegWriter.isAvailable():
            raise UserError(f"{path}: an MP4 needs ffmpeg, which is not on the PATH; install "
                            f"it or write a .gif instead")
        return _Mp4Writer(fps=fps, codec="h264")
    raise UserError(f"{path}: an animation is a .gif or an .mp4 file, not "
                    f"{suffix or 'a name without extension'}")


def check_movie(frames: int, fps: int) -> None:
    if frames < 1 or fps < 1:
        raise UserError(f"an animation needs at least one frame and one frame per second, "
                        f"not {frames} frames at {fps} fps")


def animate(path: str, layout: Layout, record: MissionSummary, fps: int = FPS, frames: int = FRAMES,
            ahead: float = SHOW_AHEAD_S, dpi: int = GIF_DPI,
            progress: Callable[[int, int], None] | None = None) -> int:
    """An animation of the run (GIF, or MP4 by the path's extension): each frame a snapshot()
    at one of `frames` instants spread over the mission. The layout is drawn once as the
    background; each frame restores it and draws the moving artists on it. Returns the
    frames written; `progress(done, total)` is told after each."""
    check_movie(frames, fps)
    writer = movie_writer(path, fps)
    fig, ax = map_figure(layout, dpi=dpi)
    try:
        handles = draw_layout(ax, layout, filled=())
        artists = _RunArtists(ax, layout, record, ahead)
        legend_below(ax, handles + fleet_handles(artists.tracks, ahead), ncols=5)
        return write_frames(writer, path, dpi, ax, artists, frame_times(record, frames),
                            progress)
    finally:
        plt.close(fig)


class MovingArtists(Protocol):
    """What changes between an animation's frames: `show(t)` sets it to instant t, and
    `artists` are drawn over the background, in order."""

    artists: list[Artist]

    def show(self, t: float) -> None: ...


def write_frames(writer: animation.AbstractMovieWriter, path: str, dpi: int, ax: Axes,
                 artists: MovingArtists, times: list[float],
                 progress: Callable[[int, int], None] | None = None) -> int:
    """Each instant of `times` as a frame: the figure drawn once as the background, then
    for each frame `artists.show(t)` and the moving `artists.artists` drawn over it."""
    fig = ax.figure
    artists.show(times[-1])  # the longest title, for the layout to make room
    # Setting up may resize the figure (even pixel sizes for h264): background after it,
    # drawn once, which also fixes the layout for every frame.
    with writer.saving(fig, path, dpi):
        canvas = fig.canvas
        canvas.draw()
        background = canvas.copy_from_bbox(fig.bbox)

        def draw(t: float) -> None:
            canvas.restore_region(background)
            artists.show(t)
            for artist in artists.artists:
                ax.draw_artist(artist)

        if isinstance(writer, _GifWriter):  # the palette sees early, busy and late frames
            for t in (times[0], times[len(times) // 2], times[-1]):
                draw(t)
                writer.sample()
        for k, t in enumerate(times, start=1):
            draw(t)
            writer.grab_frame()
            if progress is not None:
                progress(k, len(times))
    return len(times)
