"""Plots of an order mission (seed 002): the orders completed over time, a Gantt chart of each
AGV's trips, where the AGVs spent their time and where they were held up (heat maps over
the lanes), the warehouse at one instant, and an animation of the run.

They read the mission record and the layout through fleet/views/order_timeline.py (the heat
maps also the recorded states) and return their figures, so what a reader sees can be checked
on the figure itself; fleet/views/drawing.save_figure writes them.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.axes import Axes
from matplotlib.collections import PatchCollection
from matplotlib.colors import LogNorm, to_rgba
from matplotlib.figure import Figure
from matplotlib.font_manager import FontProperties
from matplotlib.lines import Line2D
from matplotlib.patches import Patch, PathPatch, Rectangle
from matplotlib.path import Path
from matplotlib.textpath import TextPath
from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter
from matplotlib.transforms import Affine2D

from fleet.mission.record import MissionSummary
from fleet.planning.geometry import Cell
from fleet.views.drawing import (
    Z_FORKLIFT,
    Z_FORKLIFT_TEXT,
    inches_per_metre,
    legend_below,
    map_figure,
)
from fleet.views.lane_drawing import (
    CARRIED_SIDE,
    SHELF_SIDE,
    STATION_FREE,
    STATION_PACKING,
    STATION_RESERVED,
    Z_HEAT,
    Z_SHELF,
    agv_handles,
    agv_label,
    agv_patches,
    agv_side,
    draw_lane_floor,
    shelf_handles,
    shelf_patches,
    square,
    station_handles,
    station_patches,
)
from fleet.views.order_timeline import (
    CHARGE,
    FETCH,
    PACK,
    STOW,
    OrderTimeline,
    Track,
    cell_seconds,
    timeline,
    tracks,
)
from fleet.views.palette import (
    PACKING_COLOR,
    PILE_COLOR,
    SHELF_COLOR,
    forklift_color,
    lighter,
)
from fleet.views.plots import (
    FPS,
    FRAMES,
    GIF_DPI,
    check_movie,
    movie_writer,
    vehicle_rows,
    write_frames,
)
from fleet.wire.protocol import VehicleState
from fleet.world.layout import Layout

# A trip's colour says what it is: empty to a shelf, with a shelf (brown, as shelves are
# drawn) to a station and back, to a pile (green, as piles are drawn).
TRIP_COLORS = {FETCH: (0.55, 0.70, 0.88), PACK: SHELF_COLOR, STOW: lighter(SHELF_COLOR, 0.45),
               CHARGE: PILE_COLOR}
OTHER_TRIP = (0.6, 0.6, 0.6)  # out of another's way (a deadlock broken)
TRIP_NAMES = {FETCH: "to a shelf (fetch)", PACK: "with the shelf to a station (pack)",
              STOW: "with the shelf back to a slot (stow)", CHARGE: "to a pile (charge)"}
DWELL_COLOR = PACKING_COLOR
STATION_WAIT = {"facecolor": (1.0, 0.88, 0.88), "edgecolor": "tab:red", "hatch": "////",
                "lw": 0.0}
ON_PILE = {"facecolor": lighter(PILE_COLOR, 0.5), "edgecolor": "none"}


def heading(record: MissionSummary, orders: int | None = None) -> str:
    """Which run a plot is of, for its title."""
    m = record.mission
    count = f"{orders} orders" if orders else "orders"
    return (f"order mission of {count} on {m.layout}, {len(record.starts)} AGVs, "
            f"order seed {m.seed}, {m.strategy} dispatching")


def agvs(record: MissionSummary) -> list[int]:
    return sorted(set(range(1, len(record.starts) + 1)) | {s.vehicle for s in record.subtasks})


def quarters(tl: OrderTimeline, end: float) -> list[int]:
    """Orders completed in each quarter of `end`."""
    end = end or 1.0
    counts = [0, 0, 0, 0]
    for c in tl.completions:
        counts[min(3, int(4 * c.t / end))] += 1
    return counts


# ------------------------------------------------------------------ orders over time


def orders_over_time(record: MissionSummary, tl: OrderTimeline, orders: int) -> Figure:
    """Orders completed (shelf back in a slot) and packed (the station's dwell over) against
    time, as steps; the released orders as a line. Instead of seed 000's filling sequence."""
    fig, ax = plt.subplots(figsize=(10, 5), layout="constrained")
    done = [c.t for c in tl.completions]
    packed = sorted(p.t_done for p in tl.packings)
    end = max([tl.makespan, *packed, 1.0])
    for times, style, label in (
            (packed, {"color": DWELL_COLOR, "ls": "--"}, "packed (the station's dwell over)"),
            (done, {"color": SHELF_COLOR, "lw": 2}, "completed (its shelf back in a slot)")):
        ax.step([0.0, *times, end], [0, *range(1, len(times) + 1), len(times)], where="post",
                label=f"{label}: {len(times)}", **style)
    total = max(orders, len(done))
    ax.axhline(total, color="0.5", lw=0.8, ls=":", label=f"orders released at t = 0: {total}")
    ax.set_xlim(0, 1.02 * end)
    ax.set_ylim(0, 1.05 * total or 1)
    ax.set_xlabel("simulated time [s]")
    ax.set_ylabel("orders")
    ax.grid(alpha=0.3)
    last = f"the last shelf put down at {tl.makespan:.1f} s" if done else "none complete"
    rate = f"; {3600 * len(done) / tl.makespan:.0f} orders an hour" if done else ""
    ax.set_title(f"Orders completed over time: {len(done)} of {total}, {last}{rate}\n"
                 f"{heading(record, orders)}", fontsize=10)
    legend_below(ax, ax.get_legend_handles_labels()[0], ncols=3)
    return fig


# ------------------------------------------------------------------ Gantt chart


def gantt(record: MissionSummary, tl: OrderTimeline, orders: int | None = None) -> Figure:
    """One row per AGV, its trips along time: one bar per trip coloured by its kind, the
    packing dwell in orange, a collision rule's waits as black bars inside the trip, waits
    under a slot for a free station hatched red, time on a pile in light green, failed
    plans as crosses above the row. Bars carry gids: trip/K (K the subtask's index),
    dwell/K, wait/K, station-wait/N, pile/N."""
    vehicles = agvs(record)
    fig, ax = plt.subplots(figsize=(14, 1.9 + 0.55 * len(vehicles)), layout="constrained")
    row = {v: k for k, v in enumerate(vehicles)}
    last = max([tl.makespan, record.end_time_s, *(t.t_done for t in tl.trips), 1.0])
    for trip in tl.trips:
        y = row[trip.vehicle]
        ax.add_patch(_bar(y, trip.t_i, trip.t_end, 0.6, f"trip/{trip.index}",
                          facecolor=TRIP_COLORS.get(trip.kind, OTHER_TRIP), edgecolor="white",
                          lw=0.4))  # a white edge tells two trips of a kind apart
        if trip.t_done > trip.t_end:
            ax.add_patch(_bar(y, trip.t_end, trip.t_done, 0.6, f"dwell/{trip.index}",
                              color=DWELL_COLOR))
        for t0, t1 in trip.waits:
            ax.add_patch(_bar(y, t0, t1, 0.25, f"wait/{trip.index}", color="black"))
    for k, stay in enumerate(tl.station_waits):
        ax.add_patch(_bar(row[stay.vehicle], stay.t0, stay.t1, 0.6, f"station-wait/{k}",
                          **STATION_WAIT))
    for k, stay in enumerate(tl.pile_stays):
        ax.add_patch(_bar(row[stay.vehicle], stay.t0, min(stay.t1, last), 0.3, f"pile/{k}",
                          **ON_PILE))
    vehicle_rows(ax, record, row, vehicles, "AGV")
    ax.set_xlim(0, 1.01 * last)
    ax.set_xlabel("simulated time [s]")
    handles = [Patch(color=c, label=TRIP_NAMES[k]) for k, c in TRIP_COLORS.items()]
    if any(t.kind not in TRIP_COLORS for t in tl.trips):
        handles.append(Patch(color=OTHER_TRIP, label="out of another AGV's way (aside)"))
    handles += [Patch(color=DWELL_COLOR, label="packing (the station's dwell)"),
                Patch(color="black", label="waiting: a collision rule"),
                Patch(label="waiting loaded under the slot for a free station", **STATION_WAIT),
                Patch(label="standing on a pile (charging, then idle)", **ON_PILE),
                Line2D([], [], ls="none", marker="x", color="black", ms=4, mew=0.8,
                       label="plan failed")]
    legend_below(ax, handles, ncols=5)
    waited = sum(t1 - t0 for trip in tl.trips for t0, t1 in trip.waits)
    ax.set_title(f"What each AGV did over time, trip by trip: {len(tl.trips)} trips, "
                 f"{len(tl.completions)} orders complete, {waited:.0f} s waiting for other "
                 f"AGVs\n{heading(record, orders)}", fontsize=10)
    return fig


def _bar(y: float, t0: float, t1: float, height: float, gid: str, **style) -> Rectangle:
    return Rectangle((t0, y - height / 2), t1 - t0, height, gid=gid, **style)


# ------------------------------------------------------------------ heat maps

HEAT_WIDTH_IN, HEAT_HEIGHT_IN = 7.0, 7.5  # the largest of each heat map: two side by side


def heat_map(layout: Layout, record: MissionSummary,
             states: Iterable[tuple[float, VehicleState]], orders: int | None = None) -> Figure:
    """Two maps over the lanes from the recorded states: the AGV-seconds spent on each cell
    (driving, waiting or parked), and the seconds AGVs stood in a collision rule's wait on
    each (congestion), each on a log colour scale."""
    time = cell_seconds(layout, states)
    width_m, height_m = layout.cols * layout.cell_size, layout.rows * layout.cell_size
    scale = min(HEAT_WIDTH_IN / width_m, HEAT_HEIGHT_IN / height_m)
    width, height = width_m * scale, height_m * scale
    fig, axes = plt.subplots(1, 2, figsize=(2 * width + 3.5, height + 1.6), layout="constrained")
    total, held = sum(time.total.values()), sum(time.waiting.values())
    panels = ((axes[0], time.total, "YlOrRd",
               f"Time on each cell: {total:.0f} AGV-seconds in all"),
              (axes[1], time.waiting, "Purples",
               f"Congestion: waiting for another AGV, {held:.0f} s in all"))
    for ax, seconds, cmap, title in panels:
        draw_lane_floor(ax, layout, labels=False, scale=scale)
        busiest = _heat(ax, layout, seconds, cmap)
        ax.set_title(title + busiest, fontsize=9)
    fig.suptitle(f"Where the AGVs were, from their recorded states (each state counts until "
                 f"the next, 2 s at most, on the cell nearest its centre)\n"
                 f"{heading(record, orders)}", fontsize=10)
    return fig



def _heat(ax: Axes, layout: Layout, seconds: dict[Cell, float], cmap: str) -> str:
    """Colour each cell with time on it (log scale: parked AGVs hold a cell for hundreds of
    seconds, a lane sees seconds); returns where the most was, for the title."""
    cells = {c: s for c, s in seconds.items()
             if 0 <= c[0] < layout.cols and 0 <= c[1] < layout.rows and s > 0}
    if not cells:
        return "; none"
    values = np.array(list(cells.values()))
    lo, hi = float(values.min()), float(values.max())
    squares = PatchCollection([square(layout, c, 1.0) for c in cells], cmap=cmap,
                              norm=LogNorm(vmin=lo, vmax=max(hi, 2 * lo)), alpha=0.9,
                              edgecolor="none", zorder=Z_HEAT, gid="heat")
    squares.set_array(values)
    ax.add_collection(squares)
    # At the side: under a map of fixed aspect, constrained layout lets titles overlap.
    bar = ax.figure.colorbar(squares, ax=ax, shrink=0.7, pad=0.02, label="seconds (log scale)")
    bar.ax.yaxis.set_major_locator(LogLocator(subs=(1.0, 2.0, 5.0)))
    bar.ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))  # 2, not 2 x 10^0
    bar.ax.yaxis.set_minor_formatter(NullFormatter())
    top = max(cells, key=lambda c: (cells[c], c))
    return f";\nthe most on cell ({top[0]}, {top[1]}): {cells[top]:.0f} s, {len(cells)} cells"


# ------------------------------------------------------------------ snapshot and animation


def snapshot(layout: Layout, record: MissionSummary, t: float,
             tl: OrderTimeline | None = None, orders: int | None = None) -> Figure:
    """The warehouse at instant t: lanes, slots with or without their shelf, packing stations
    free, reserved or packing, piles, and each AGV (a shelf under it when it carries one)."""
    tl = tl or timeline(layout, record)
    fig, ax = map_figure(layout)
    handles = draw_lane_floor(ax, layout)
    shelves = tl.shelves_at(t)
    ax.add_collection(shelf_patches(layout, sorted(shelves.in_slot)))
    used = tl.stations_at(t)
    for patch in station_patches(layout, used):
        ax.add_patch(patch)
    vehicles = agvs(record)
    ox, oy = layout.origin
    size = layout.cell_size
    for v, track in tracks(record).items():
        c, r = track.at(t)
        x, y = ox + c * size, oy + r * size
        for patch in agv_patches(layout, v, x, y, shelves.on_agv.get(v)):
            ax.add_patch(patch)
        agv_label(ax, v, x, y)
    packing = sum(1 for u in used.values() if u == "packing")
    ax.set_title(f"The warehouse at t = {t:.2f} s: {tl.completed_by(t)} orders complete, "
                 f"{len(shelves.on_agv)} shelves on AGVs, {packing} of {len(layout.packing)} "
                 f"stations packing\n{heading(record, orders)}", fontsize=10)
    _map_legend(ax, handles, vehicles)
    return fig


def _map_legend(ax: Axes, floor: list, vehicles: Iterable[int]) -> None:
    """Under a map: the floor's entries, shelves, stations and AGVs."""
    agv, agv_labels, style = agv_handles(vehicles)
    entries = floor + shelf_handles() + station_handles()
    legend_below(ax, entries + agv, labels=[h.get_label() for h in entries] + agv_labels,
                 ncols=4, **style)


BOLD = FontProperties(weight="bold")


def _centred(path: Path) -> Path:
    """A glyph path moved so its box is centred on the origin."""
    (x0, y0), (x1, y1) = path.get_extents().get_points()
    return path.transformed(Affine2D().translate(-(x0 + x1) / 2, -(y0 + y1) / 2))


class _OrderArtists:
    """The moving parts of an order mission's animation over the lane floor drawn once:
    shelves in slots, stations in use, AGVs with the shelves they carry, their ids and the
    title. `show(t)` updates them in place; `artists` lists them in drawing order."""

    def __init__(self, ax: Axes, layout: Layout, record: MissionSummary, tl: OrderTimeline,
                 orders: int | None) -> None:
        self.layout, self.tl, self.orders, self.ax = layout, tl, orders, ax
        self.heading = heading(record, orders)
        self.slots = [s.cell for s in layout.slots]
        self.shelves = ax.add_collection(PatchCollection(
            [square(layout, c, SHELF_SIDE) for c in self.slots], edgecolor="white", lw=0.4,
            zorder=Z_SHELF))
        self.shelf_rgba = np.tile(to_rgba(SHELF_COLOR), (len(self.slots), 1))
        self.stations = ax.add_collection(PatchCollection(
            [square(layout, p.cell, 1.0) for p in layout.packing], zorder=Z_SHELF))
        self.station_styles = {name: (to_rgba(style["facecolor"]), to_rgba(style["edgecolor"]),
                                      style["lw"])
                               for name, style in (("free", STATION_FREE),
                                                   ("reserved", STATION_RESERVED),
                                                   ("packing", STATION_PACKING))}
        self.tracks: dict[int, Track] = tracks(record)
        side, big = agv_side(layout) * layout.cell_size, CARRIED_SIDE * layout.cell_size
        self.carried = {v: ax.add_patch(Rectangle((0, 0), big, big, facecolor=SHELF_COLOR,
                                                  edgecolor="black", lw=0.5,
                                                  zorder=Z_FORKLIFT - 0.01))
                        for v in self.tracks}
        self.bodies = {v: ax.add_patch(Rectangle((0, 0), side, side,
                                                 facecolor=forklift_color(v),
                                                 edgecolor="black", lw=0.6, zorder=Z_FORKLIFT))
                       for v in self.tracks}
        # Ids as glyph outlines moved by a transform: a frame draws them as paths, far
        # faster than laying out a text per AGV per frame.
        size = 6 / 72 / inches_per_metre(layout)  # 6 pt on a map_figure(), in metres
        self.labels = {v: ax.add_patch(PathPatch(_centred(TextPath((0, 0), str(v), size=size,
                                                                   prop=BOLD)),
                                                 facecolor="white", edgecolor="none",
                                                 zorder=Z_FORKLIFT_TEXT))
                       for v in self.tracks}
        self.title = ax.set_title("", fontsize=10)
        self.artists = [self.shelves, self.stations, *self.carried.values(),
                        *self.bodies.values(), *self.labels.values(), *ax.spines.values(),
                        self.title]
        for artist in self.artists:
            artist.set_animated(True)

    def show(self, t: float) -> None:
        layout, tl = self.layout, self.tl
        shelves = tl.shelves_at(t)
        self.shelf_rgba[:, 3] = [c in shelves.in_slot for c in self.slots]
        self.shelves.set_facecolor(self.shelf_rgba)
        used = tl.stations_at(t)
        styles = [self.station_styles[used.get(p.name, "free")] for p in layout.packing]
        self.stations.set_facecolor([s[0] for s in styles])
        self.stations.set_edgecolor([s[1] for s in styles])
        self.stations.set_linewidth([s[2] for s in styles])
        ox, oy = layout.origin
        size = layout.cell_size
        for v, track in self.tracks.items():
            c, r = track.at(t)
            x, y = ox + c * size, oy + r * size
            body, carried = self.bodies[v], self.carried[v]
            body.set_xy((x - body.get_width() / 2, y - body.get_height() / 2))
            carried.set_xy((x - carried.get_width() / 2, y - carried.get_height() / 2))
            carried.set_visible(v in shelves.on_agv)
            self.labels[v].set_transform(Affine2D().translate(x, y) + self.ax.transData)
        self.title.set_text(f"The warehouse at t = {t:.1f} s: {tl.completed_by(t)} orders "
                            f"complete, {len(shelves.on_agv)} shelves on AGVs\n{self.heading}")


def frame_times(tl: OrderTimeline, record: MissionSummary, frames: int) -> list[float]:
    """`frames` instants from 0 to the last arrival, both ends included."""
    end = max(tl.makespan, record.end_time_s, record.all_parked_s)
    if frames == 1:
        return [end]
    return [end * k / (frames - 1) for k in range(frames)]


def animate(path: str, layout: Layout, record: MissionSummary, orders: int | None = None,
            fps: int = FPS, frames: int = FRAMES, dpi: int = GIF_DPI,
            progress: Callable[[int, int], None] | None = None) -> int:
    """An animation of the order mission (GIF, or MP4 by the path's extension): each frame a
    snapshot() at one of `frames` instants spread over it. Returns the frames written."""
    check_movie(frames, fps)
    writer = movie_writer(path, fps)
    tl = timeline(layout, record)
    fig, ax = map_figure(layout, dpi=dpi)
    try:
        handles = draw_lane_floor(ax, layout)
        artists = _OrderArtists(ax, layout, record, tl, orders)
        _map_legend(ax, handles, artists.tracks)
        return write_frames(writer, path, dpi, ax, artists, frame_times(tl, record, frames),
                            progress)
    finally:
        plt.close(fig)

