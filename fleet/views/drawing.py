"""Matplotlib drawings of layouts and trajectories (imported only by commands that draw).

A map is drawn in the layout's world coordinates (metres, as in the layout file and in
Foxglove), with its legend below the axes so it covers nothing. Colours come from
fleet/views/palette.py, shared with the Foxglove scene.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence

import matplotlib

matplotlib.use("Agg")  # files only; no display needed
import matplotlib.pyplot as plt
from matplotlib.artist import Artist
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.legend import Legend
from matplotlib.lines import Line2D
from matplotlib.patches import Patch, Polygon, Rectangle
from matplotlib.text import Text
from matplotlib.transforms import ScaledTranslation

from fleet.planning.geometry import Cell, body_corners
from fleet.planning.maneuvers import world_pose
from fleet.planning.reservations import Reservation
from fleet.planning.trajectory import Pose, Trajectory
from fleet.views.palette import GOODS_COLOR, RACK_COLOR, STATION_COLOR, forklift_color, lighter
from fleet.world.layout import Layout, Stack, Station

DPI = 130  # PNG resolution: a paper map is about 1600 x 1200 pixels

# Map styles, each with its legend entry's look.
FILLED_STACK = {"facecolor": GOODS_COLOR, "edgecolor": "white", "lw": 0.4}
EMPTY_STACK = {"facecolor": lighter(RACK_COLOR, 0.8), "edgecolor": lighter(RACK_COLOR, 0.4),
               "lw": 0.4}
OBSTACLE = {"facecolor": "0.62", "edgecolor": "0.62"}
STATION = {"facecolor": STATION_COLOR, "edgecolor": "0.3", "lw": 0.6}
FLOOR = {"fill": False, "lw": 0.3, "ls": "--", "edgecolor": "0.85"}
CLUSTER_LABEL = {"fontsize": 11, "weight": "bold", "color": "0.1", "ha": "center",
                 "va": "center", "bbox": {"boxstyle": "round,pad=0.25", "facecolor": "white",
                                          "edgecolor": "0.4", "lw": 0.6, "alpha": 0.9}}

# Drawing order: the floor and stacks, reserved cells over them, the names of clusters and
# stations over those, forklifts and trajectories on top (a forklift passing a name hides
# it, not the reverse).
Z_STACK_TEXT, Z_RESERVED, Z_LABEL, Z_FORKLIFT, Z_FORKLIFT_TEXT = 1.1, 1.2, 1.5, 2.0, 2.1

MAP_WIDTH_IN, MAP_HEIGHT_IN = 11.0, 7.5  # the largest map area; figures fit the layout
LEGEND_DROP_IN = 0.42  # the tick labels' and x label's height: the legend goes under them
STACK_NUMBER_PT = 5
CHAR_WIDTH = 0.62  # a bold character's mean width, in font sizes



def frame_floor(ax: Axes, layout: Layout) -> None:
    """The axes fitted to the floor, to scale, in metres."""
    x0 = layout.origin[0] - layout.cell_size / 2
    y0 = layout.origin[1] - layout.cell_size / 2
    ax.set_xlim(x0, x0 + layout.cols * layout.cell_size)
    ax.set_ylim(y0, y0 + layout.rows * layout.cell_size)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")

def inches_per_metre(layout: Layout) -> float:
    """The scale of a map of the layout (map_figure())."""
    return min(MAP_WIDTH_IN / (layout.cols * layout.cell_size),
               MAP_HEIGHT_IN / (layout.rows * layout.cell_size))


def map_figure(layout: Layout, extra_width_in: float = 0.0,
               dpi: float | None = None) -> tuple[Figure, Axes]:
    """A figure sized to the layout's shape, room for the title above and the legend below
    (and `extra_width_in` at the side, for a colour bar)."""
    width_m, height_m = layout.cols * layout.cell_size, layout.rows * layout.cell_size
    scale = inches_per_metre(layout)
    size = (max(width_m * scale + 1.0 + extra_width_in, 7.0), height_m * scale + 2.0)
    fig = plt.figure(figsize=size, dpi=dpi, layout="constrained")
    return fig, fig.add_subplot()


def legend_below(ax: Axes, handles: Sequence[Artist], ncols: int = 5, **style) -> Legend:
    """The axes' legend under them, below the x label, outside the axes: it covers no data.
    It moves with the axes (a map's shrinks to its aspect), so no gap opens between them.
    At most `ncols` columns, fewer if it would be wider than the figure (a narrow map)."""
    fig = ax.figure
    below = ax.transAxes + ScaledTranslation(0, -LEGEND_DROP_IN, fig.dpi_scale_trans)
    renderer = fig.canvas.get_renderer()
    for n in range(min(ncols, len(handles)), 0, -1):
        legend = ax.legend(handles=list(handles), loc="upper center", bbox_to_anchor=(0.5, 0),
                           bbox_transform=below, ncols=n, fontsize=8, frameon=False, **style)
        if legend.get_window_extent(renderer).width <= 0.95 * fig.bbox.width:
            break
    return legend


def save_figure(fig: Figure, path: str, dpi: float = DPI) -> None:
    """Write the figure (cut to what is drawn) and free it."""
    fig.savefig(path, dpi=dpi, bbox_inches="tight", pad_inches=0.15)
    plt.close(fig)


def cell_square(layout: Layout, cell: Cell, **style) -> Rectangle:
    """The square of a cell on a map, in world coordinates, styled by `style`."""
    x, y = layout.cell_center(cell)
    half = layout.cell_size / 2
    return Rectangle((x - half, y - half), layout.cell_size, layout.cell_size, **style)


def draw_layout(ax: Axes, layout: Layout, filled: Iterable[Cell] | None = None,
                stacks_label: str | None = "stack, empty") -> list[Artist]:
    """The map: floor, stacks (filled or empty, with their numbers), obstacles, stations and
    cluster names, in metres. `filled=None` draws every stack empty and leaves "filled" out
    of the legend; `stacks_label=None` leaves the empty stacks out too. Returns the legend
    entries for what it drew."""
    filled_cells = set(filled or ())
    stack_cells = {s.cell for s in layout.stacks}
    obstacle_cells = {c for o in layout.obstacles for c in o.cells}
    taken = stack_cells | obstacle_cells | {s.cell for s in layout.stations}
    for c in range(layout.cols):
        for r in range(layout.rows):
            if (c, r) not in taken:
                ax.add_patch(cell_square(layout, (c, r), **FLOOR))
    for cell in obstacle_cells:
        ax.add_patch(cell_square(layout, cell, **OBSTACLE))
    for stack in layout.stacks:
        full = stack.cell in filled_cells
        ax.add_patch(cell_square(layout, stack.cell, gid=f"stack/{stack.cluster}#{stack.index}",
                                  **(FILLED_STACK if full else EMPTY_STACK)))
        stack_number(ax, layout, stack, "white" if full else "0.3")
    for station in layout.stations:
        ax.add_patch(cell_square(layout, station.cell, **STATION))
        x, y, style = station_label_spot(layout, station)
        ax.text(x, y, station.name, fontsize=7, weight="bold", rotation_mode="anchor",
                zorder=Z_LABEL, **style)
    for cluster in layout.clusters:
        if layout.cluster_stacks(cluster.name):
            x, y, rotation = cluster_label_spot(layout, cluster.name)
            ax.text(x, y, cluster.name, rotation=rotation, zorder=Z_LABEL,
                    gid=f"cluster/{cluster.name}", **CLUSTER_LABEL)
    frame_floor(ax, layout)
    handles: list[Artist] = []
    if filled is not None:
        handles.append(Patch(label="stack, filled", **FILLED_STACK))
    if stacks_label is not None:
        handles.append(Patch(label=stacks_label, **EMPTY_STACK))
    kinds = sorted({o.kind for o in layout.obstacles})
    if kinds:
        handles.append(Patch(label=f"obstacle ({', '.join(kinds)})", **OBSTACLE))
    if layout.stations:
        handles.append(Patch(label="station", **STATION))
    return handles


def stack_number_spot(layout: Layout, stack: Stack) -> tuple[float, float]:
    """Where a stack's number is centred: in the upper part of its cell."""
    x, y = layout.cell_center(stack.cell)
    return x, y + 0.25 * layout.cell_size


def stack_number(ax: Axes, layout: Layout, stack: Stack, color) -> Text:
    """A stack's place in its cluster's fill order, small."""
    return ax.text(*stack_number_spot(layout, stack), str(stack.index), ha="center",
                   va="center", fontsize=STACK_NUMBER_PT, color=color, zorder=Z_STACK_TEXT)


def station_label_spot(layout: Layout, station: Station) -> tuple[float, float, dict]:
    """Where a station's name goes: (x, y, text style). In its cell if it fits; a longer one
    starts at the cell's edge and runs across it into free floor, upright if that floor is
    above or below (a name that spilled both ways would cover its neighbour's)."""
    x, y = layout.cell_center(station.cell)
    cell_pt = layout.cell_size * inches_per_metre(layout) * 72
    if CHAR_WIDTH * 7 * len(station.name) <= 0.9 * cell_pt:
        return x, y, {"ha": "center", "va": "center"}
    taken = layout.static_blocked | {s.cell for s in layout.stacks}
    half = 0.45 * layout.cell_size
    c, r = station.cell
    for dc, dr, rotation, ha in ((1, 0, 0, "left"), (-1, 0, 0, "right"),
                                 (0, 1, 90, "left"), (0, -1, 90, "right")):
        cell = (c + dc, r + dr)
        if 0 <= cell[0] < layout.cols and 0 <= cell[1] < layout.rows and cell not in taken:
            return x - dc * half, y - dr * half, {"ha": ha, "va": "center", "rotation": rotation}
    return x, y, {"ha": "center", "va": "center"}


def cluster_label_spot(layout: Layout, name: str) -> tuple[float, float, float]:
    """Where a cluster's name goes, (x, y, rotation in degrees), so it hides no stack: on the
    free floor along one side of the cluster, centred on that side; below or above first
    (the name runs along the strip), then left or right (turned upright); over the middle
    of the cluster when no side has free floor there."""
    cells = [s.cell for s in layout.cluster_stacks(name)]
    cols, rows = [c for c, _ in cells], [r for _, r in cells]
    c0, c1, r0, r1 = min(cols), max(cols), min(rows), max(rows)
    mid_c, mid_r = (c0 + c1) / 2, (r0 + r1) / 2
    taken = layout.static_blocked | {s.cell for s in layout.stacks}

    def free(cell: Cell) -> bool:
        return 0 <= cell[0] < layout.cols and 0 <= cell[1] < layout.rows and cell not in taken

    sides = [([(c, r0 - 1) for c in range(c0, c1 + 1)], (mid_c, r0 - 1), 0.0),
             ([(c, r1 + 1) for c in range(c0, c1 + 1)], (mid_c, r1 + 1), 0.0),
             ([(c0 - 1, r) for r in range(r0, r1 + 1)], (c0 - 1, mid_r), 90.0),
             ([(c1 + 1, r) for r in range(r0, r1 + 1)], (c1 + 1, mid_r), 90.0)]
    for strip, (c, r), rotation in sides:
        # The cells the name covers: those within a cell of the middle of the side.
        middle = [cell for cell in strip if abs(cell[0] - c) <= 1 and abs(cell[1] - r) <= 1]
        if all(free(cell) for cell in middle):
            return (layout.origin[0] + c * layout.cell_size,
                    layout.origin[1] + r * layout.cell_size, rotation)
    return (layout.origin[0] + mid_c * layout.cell_size,
            layout.origin[1] + mid_r * layout.cell_size, 0.0)


def _body(layout: Layout, x: float, y: float, theta: float, **style) -> Polygon:
    return Polygon(body_corners(x, y, theta, layout.vehicle.dims), closed=True, **style)


def forklift_patch(layout: Layout, vehicle: int, x: float, y: float, theta: float) -> Polygon:
    """Forklift `vehicle`'s body at a pose, in its colour; its gid is Foxglove's entity id."""
    return _body(layout, x, y, theta, facecolor=forklift_color(vehicle), edgecolor="black",
                 lw=0.8, zorder=Z_FORKLIFT, gid=f"forklift/{vehicle}")


def forklift_handles(vehicles: Iterable[int]) -> list[Artist]:
    return [Patch(facecolor=forklift_color(v), edgecolor="black", lw=0.8, label=f"forklift {v}")
            for v in vehicles]


def draw_trajectory(ax: Axes, layout: Layout, traj: Trajectory, label: str | None = None) -> None:
    """A trajectory in its forklift's colour: the path, the body after each maneuver, the
    start pose (solid) and the goal pose (hatched), and some maneuvers' start times."""
    color = forklift_color(traj.vehicle)
    ox, oy = layout.cell_center((0, 0))
    size = layout.cell_size
    xs, ys = [], []
    for step in traj.steps:
        for i in range(21):
            x, y, th = world_pose(step.start.cell, step.start.heading, step.manner, i / 20, size)
            xs.append(ox + x)
            ys.append(oy + y)
        x, y, th = world_pose(step.start.cell, step.start.heading, step.manner, 1.0, size)
        ax.add_patch(_body(layout, ox + x, oy + y, th, fill=False, edgecolor=color, lw=0.5,
                           alpha=0.5, zorder=Z_FORKLIFT))
    ax.plot(xs, ys, color=color, lw=1.5, label=label, zorder=Z_FORKLIFT)
    _draw_pose(ax, layout, traj.start, color, alpha=0.9)
    _draw_pose(ax, layout, traj.goal, color, alpha=0.9, hatch="//")
    for step in traj.steps[:: max(1, len(traj.steps) // 8)]:
        x, y = layout.cell_center(step.start.cell)
        ax.text(x, y + 0.3, f"{step.t0:g}", fontsize=6, color=color, weight="bold",
                zorder=Z_FORKLIFT_TEXT)


def _draw_pose(ax: Axes, layout: Layout, pose: Pose, color, **style) -> None:
    x, y = layout.cell_center(pose.cell)
    ax.add_patch(_body(layout, x, y, pose.heading * math.pi / 2, facecolor=color,
                       edgecolor="black", lw=0.6, zorder=Z_FORKLIFT, **style))


RESERVED_ALPHA = 0.15


def draw_reservations(ax: Axes, layout: Layout, reservations: Sequence[Reservation]) -> None:
    for r in reservations:
        ax.add_patch(cell_square(layout, r.cell, color=forklift_color(r.vehicle),
                                  alpha=RESERVED_ALPHA, zorder=Z_RESERVED))


def plan_figure(layout: Layout, traj: Trajectory | None, others: Sequence[Trajectory],
                reservations: Sequence[Reservation], filled: Iterable[Cell],
                title: str) -> Figure:
    """`fleet plan --png`: the planned trajectory and the other vehicles' plans and
    reservations over the layout, each vehicle in its forklift colour."""
    fig, ax = map_figure(layout)
    handles = draw_layout(ax, layout, filled)
    draw_reservations(ax, layout, reservations)
    for other in others:
        draw_trajectory(ax, layout, other)
        handles.append(Line2D([], [], color=forklift_color(other.vehicle), lw=1.5,
                              label=f"vehicle {other.vehicle}"))
    if traj is not None:
        draw_trajectory(ax, layout, traj)
        handles.append(Line2D([], [], color=forklift_color(traj.vehicle), lw=2.5,
                              label=f"vehicle {traj.vehicle} (planned)"))
    handles += [Patch(facecolor="0.5", edgecolor="black", lw=0.6, label="start pose"),
                Patch(facecolor="0.5", edgecolor="black", lw=0.6, hatch="//",
                      label="goal pose"),
                Patch(facecolor="0.5", alpha=RESERVED_ALPHA * 2,
                      label="reserved cells (vehicle's colour)"),
                Line2D([], [], ls="none", marker="$12$", ms=9, color="0.3",
                       label="a maneuver's start time [s]")]
    ax.set_title(title, fontsize=10)
    legend_below(ax, handles)
    return fig
