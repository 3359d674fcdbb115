"""Matplotlib drawings of seed 002's lane layouts (docs/layouts.md, "Lane layouts"): lanes
with their direction, junctions, slots with or without their shelf, packing stations (free,
reserved or packing), charging piles, and AGVs as unit squares with their id, carrying a shelf
or not.

In the layout's metres like every map (fleet/views/drawing.py), colours from
fleet/views/palette.py (an AGV has the colour of the same number everywhere).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping

from matplotlib.artist import Artist
from matplotlib.axes import Axes
from matplotlib.collections import PatchCollection
from matplotlib.legend_handler import HandlerTuple
from matplotlib.lines import Line2D
from matplotlib.patches import Patch, Rectangle
from matplotlib.text import Text

from fleet.planning.geometry import Cell
from fleet.views.drawing import (
    OBSTACLE,
    Z_FORKLIFT,
    Z_FORKLIFT_TEXT,
    Z_LABEL,
    cell_square,
    frame_floor,
    inches_per_metre,
)
from fleet.views.palette import (
    PACKING_COLOR,
    PILE_COLOR,
    RACK_COLOR,
    SHELF_COLOR,
    STATION_COLOR,
    forklift_color,
    lighter,
)
from fleet.world.layout import Layout

LANE_COLOR, JUNCTION_COLOR, ACCESS_COLOR = "0.90", "0.80", "0.96"
ARROW_COLOR = "0.45"
MARKERS = {"E": ">", "W": "<", "N": "^", "S": "v"}  # a lane's direction, as its drawing shows
SLOT = {"facecolor": lighter(RACK_COLOR, 0.8), "edgecolor": lighter(RACK_COLOR, 0.3),
        "lw": 0.5}
SHELF = {"facecolor": SHELF_COLOR, "edgecolor": "white", "lw": 0.4}
STATION_FREE = {"facecolor": STATION_COLOR, "edgecolor": "0.3", "lw": 0.5}
STATION_RESERVED = {"facecolor": STATION_COLOR, "edgecolor": PACKING_COLOR, "lw": 1.6}
STATION_PACKING = {"facecolor": PACKING_COLOR, "edgecolor": "0.3", "lw": 0.5}
PILE = {"facecolor": lighter(PILE_COLOR, 0.3), "edgecolor": "0.3", "lw": 0.5}
SHELF_SIDE, CARRIED_SIDE = 0.8, 0.92  # a shelf's side in a slot and on an AGV, in cells
# Drawing order: floor, slots and places, heat over them, the lanes' arrows, shelves, labels,
# AGVs on top (as drawing.py's).
Z_HEAT, Z_ARROW, Z_SHELF = 1.05, 1.1, 1.15
LABEL_PT = 5


def square(layout: Layout, cell: Cell, side: float, **style) -> Rectangle:
    """A square of `side` cells centred on a cell."""
    x, y = layout.cell_center(cell)
    half = side * layout.cell_size / 2
    return Rectangle((x - half, y - half), 2 * half, 2 * half, **style)


def junction_cells(layout: Layout) -> frozenset[Cell]:
    return frozenset(c for j in layout.junctions for c in j.cells)


def draw_lane_floor(ax: Axes, layout: Layout, labels: bool = True,
                    scale: float | None = None) -> list[Artist]:
    """What does not change: the lanes (an arrow on each cell outside junctions shows its
    direction), junctions, access cells, empty slots, packing stations as free, piles and
    obstacles, with station and pile names. `scale`: the map's inches a metre (default a
    map_figure()'s), for the arrows' size. Returns the legend entries."""
    junctions = junction_cells(layout)
    lanes = [c for c in layout.lane_directions if c not in junctions]
    ax.add_collection(PatchCollection(
        [cell_square(layout, c) for c in lanes], facecolor=LANE_COLOR, edgecolor="none"))
    ax.add_collection(PatchCollection(
        [cell_square(layout, c) for c in sorted(junctions)], facecolor=JUNCTION_COLOR,
        edgecolor="none"))
    if layout.access_cells:
        ax.add_collection(PatchCollection(
            [cell_square(layout, c) for c in sorted(layout.access_cells)],
            facecolor=ACCESS_COLOR, edgecolor=LANE_COLOR, lw=0.5, linestyle=":"))
    for direction, marker in MARKERS.items():
        cells = [c for c in lanes if direction in layout.lane_directions[c]]
        if cells:
            xs, ys = zip(*(layout.cell_center(c) for c in cells), strict=True)
            ax.scatter(xs, ys, marker=marker, s=_marker_area(layout, scale), color=ARROW_COLOR,
                       linewidths=0, zorder=Z_ARROW, gid=f"lanes/{direction}")
    ax.add_collection(PatchCollection([cell_square(layout, s.cell) for s in layout.slots],
                                      **SLOT))
    ax.add_collection(PatchCollection([cell_square(layout, p.cell) for p in layout.piles],
                                      **PILE))
    ax.add_collection(PatchCollection([cell_square(layout, p.cell) for p in layout.packing],
                                      **STATION_FREE))
    obstacles = [c for o in layout.obstacles for c in o.cells]
    if obstacles:
        ax.add_collection(PatchCollection([cell_square(layout, c) for c in obstacles],
                                          **OBSTACLE))
    if labels:
        for place in (*layout.packing, *layout.piles):
            place_label(ax, layout, place.cell, place.name)
    frame_floor(ax, layout)
    handles: list[Artist] = [
        Line2D([], [], ls="none", marker=">", color=ARROW_COLOR, ms=5,
               label="lane and its direction"),
        Patch(facecolor=JUNCTION_COLOR, label="junction (turns only here)")]
    if layout.access_cells:
        handles.append(Patch(facecolor=ACCESS_COLOR, edgecolor=LANE_COLOR, ls=":",
                             label="access cell"))
    handles.append(Patch(label="slot, empty", **SLOT))
    if layout.piles:
        handles.append(Patch(label="charging pile (c)", **PILE))
    if obstacles:
        handles.append(Patch(label="wall", **OBSTACLE))
    return handles


def _marker_area(layout: Layout, scale: float | None) -> float:
    """A direction marker's area in points², about half a cell across on the map."""
    side_pt = 0.45 * layout.cell_size * (scale or inches_per_metre(layout)) * 72
    return side_pt ** 2


def place_label(ax: Axes, layout: Layout, cell: Cell, name: str) -> Text:
    x, y = layout.cell_center(cell)
    return ax.text(x, y, name, ha="center", va="center", fontsize=LABEL_PT, color="0.15",
                   zorder=Z_LABEL)


def shelf_patches(layout: Layout, cells: Iterable[Cell]) -> PatchCollection:
    """The shelves standing in these slots."""
    return PatchCollection([square(layout, c, SHELF_SIDE) for c in cells], zorder=Z_SHELF,
                           gid="shelves", **SHELF)


def station_patches(layout: Layout, used: Mapping[str, str]) -> list[Rectangle]:
    """The packing stations in use: "reserved" (an AGV on its way: an orange frame) or
    "packing" (an AGV dwelling: orange)."""
    style = {"reserved": STATION_RESERVED, "packing": STATION_PACKING}
    return [cell_square(layout, p.cell, zorder=Z_SHELF, gid=f"station/{p.name}",
                        **style[used[p.name]])
            for p in layout.packing if p.name in used]


def station_handles() -> list[Artist]:
    return [Patch(label="packing station, free (p)", **STATION_FREE),
            Patch(label="station reserved: an AGV on its way", **STATION_RESERVED),
            Patch(label="station packing: an AGV dwelling", **STATION_PACKING)]


def shelf_handles() -> list[Artist]:
    return [Patch(label="slot with a shelf", **SHELF)]


def agv_side(layout: Layout) -> float:
    """An AGV body's side, in cells (the kind's outline)."""
    return layout.vehicle_kind.outline.width / layout.cell_size


def agv_patches(layout: Layout, vehicle: int, x: float, y: float,
                shelf: str | None) -> list[Artist]:
    """AGV `vehicle` centred at (x, y) in metres: a square in its colour, on a shelf (drawn
    under it, larger) when it carries one. Gids: "agv/N" and "carried/N"."""
    side = agv_side(layout) * layout.cell_size
    out: list[Artist] = []
    if shelf is not None:
        big = CARRIED_SIDE * layout.cell_size
        out.append(Rectangle((x - big / 2, y - big / 2), big, big, facecolor=SHELF_COLOR,
                             edgecolor="black", lw=0.5, zorder=Z_FORKLIFT - 0.01,
                             gid=f"carried/{vehicle}", label=shelf))
    out.append(Rectangle((x - side / 2, y - side / 2), side, side,
                         facecolor=forklift_color(vehicle), edgecolor="black", lw=0.6,
                         zorder=Z_FORKLIFT, gid=f"agv/{vehicle}"))
    return out


def agv_label(ax: Axes, vehicle: int, x: float, y: float) -> Text:
    return ax.text(x, y, str(vehicle), ha="center", va="center", fontsize=6, color="white",
                   weight="bold", zorder=Z_FORKLIFT_TEXT)


def agv_handles(vehicles: Iterable[int]) -> tuple[list, list[str], dict]:
    """Legend entries for AGVs: (handles, labels, legend style). One entry shows every AGV's
    colour side by side (each wears its id, so one entry an AGV would say nothing more)."""
    swatches = tuple(Patch(facecolor=forklift_color(v), edgecolor="black", lw=0.6)
                     for v in (list(vehicles) or [1]))
    carrying = Patch(facecolor=SHELF_COLOR, edgecolor="black", lw=0.5)
    return ([swatches, carrying], ["AGV, its id on it (its colour: its Gantt row's)",
                                   "AGV carrying a shelf (brown frame)"],
            {"handler_map": {tuple: HandlerTuple(ndivide=None, pad=0)}})
