"""A seed-004 floor at one instant (`fleet plot RUN --at T`: snapshot_T.png), in the seed's
coordinates as its heat maps are drawn (heat004.py: x a column, y a row from the top): the
cells (walls, aisles, slots, each station's queue, work cell and worker, its entrance E and
exit point X, charging piles, parking places), the shelves standing home and the slots whose
shelf is away, closed zones, and every lifting AGV where it is (between two cells while it
moves) with its number and heading, carrying its shelf or empty. What is drawn is
state004.floor_at's; colours are fleet/views/palette.py's (an AGV has one colour everywhere).
"""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.artist import Artist
from matplotlib.axes import Axes
from matplotlib.collections import PatchCollection
from matplotlib.colors import ListedColormap
from matplotlib.figure import Figure
from matplotlib.patches import Patch, Polygon, Rectangle

from fleet.planning.rules004 import STEP, XY, Kind
from fleet.views.drawing import Z_FORKLIFT, Z_FORKLIFT_TEXT, Z_LABEL, legend_below
from fleet.views.heat004 import FLOOR_COLOURS
from fleet.views.palette import PILE_COLOR, SHELF_COLOR, STATION_COLOR, forklift_color, lighter
from fleet.views.state004 import AgvAt, FloorAt
from fleet.world.floor004 import Floor004

CELL_IN = 0.19  # a cell's side in inches: paper004 (100 x 50 cells) is 19 x 9.5 inches
MIN_WIDTH_IN = 8.0
SHELF_SIDE, CARRIED_SIDE = 0.8, 0.96  # in cells
# An AGV's body points where it heads: (along its heading, across it) in cells, back first.
BODY = ((-0.36, -0.36), (0.14, -0.36), (0.46, 0.0), (0.14, 0.36), (-0.36, 0.36))
NUMBER_BACK = 0.07  # its number sits this far behind the body's middle, off the point
PARKING_COLOR = "#e4def2"
PILE = {"facecolor": lighter(PILE_COLOR, 0.3), "edgecolor": "0.3", "lw": 0.4}
WORK = {"facecolor": STATION_COLOR, "edgecolor": "0.3", "lw": 0.4}
SHELF = {"facecolor": SHELF_COLOR, "edgecolor": "white", "lw": 0.3}
AWAY = {"facecolor": "white", "edgecolor": SHELF_COLOR, "lw": 0.8, "linestyle": (0, (2, 1))}
CLOSED = {"facecolor": (0.85, 0.1, 0.1, 0.35), "edgecolor": (0.85, 0.1, 0.1), "lw": 0.5,
          "hatch": "xxx"}
DOWN_EDGE = "red"
Z_CELLS, Z_SHELF, Z_CLOSED = 1.0, 1.1, 1.2


def square(xy: tuple[float, float], side: float, **style) -> Rectangle:
    """A square of `side` cells centred on a (possibly fractional) cell."""
    return Rectangle((xy[0] - side / 2, xy[1] - side / 2), side, side, **style)


def base_image(floor: Floor004) -> np.ndarray:
    """Each cell's static kind, as an index into FLOOR_COLOURS, row by row from the top."""
    kinds = list(FLOOR_COLOURS)
    return np.array([[kinds.index(floor.kind((x, y))) for x in range(floor.width)]
                     for y in range(floor.height)])


def draw_floor(ax: Axes, floor: Floor004, away: frozenset[XY]) -> list[Artist]:
    """What stands on the floor at an instant: the cells, the shelves home and the slots whose
    shelf is away. Returns the legend entries."""
    kinds = list(FLOOR_COLOURS)
    ax.imshow(base_image(floor), cmap=ListedColormap([FLOOR_COLOURS[k] for k in kinds]),
              vmin=0, vmax=len(kinds) - 1, interpolation="nearest", zorder=0)
    ax.add_collection(PatchCollection([square(xy, 1.0) for xy in floor.parking],
                                      facecolor=PARKING_COLOR, edgecolor="none",
                                      zorder=Z_CELLS))
    ax.add_collection(PatchCollection([square(xy, 0.9) for xy in floor.piles], zorder=Z_CELLS,
                                      **PILE))
    ax.add_collection(PatchCollection([square(s.work, 0.9) for s in floor.stations],
                                      zorder=Z_CELLS, **WORK))
    for s in floor.stations:
        ax.text(*s.worker, s.name.rsplit("-", 1)[-1], ha="center", va="center", fontsize=6,
                color="white", weight="bold", zorder=Z_LABEL)
        for xy, mark in ((s.entrance, "E"), (s.exit_point, "X")):
            ax.text(*xy, mark, ha="center", va="center", fontsize=5, color="0.45",
                    zorder=Z_CELLS)
    home = [s.xy for s in floor.slots if s.xy not in away]
    ax.add_collection(PatchCollection([square(xy, SHELF_SIDE) for xy in home],
                                      zorder=Z_SHELF, gid="shelves", **SHELF))
    if away:
        ax.add_collection(PatchCollection([square(xy, SHELF_SIDE) for xy in sorted(away)],
                                          zorder=Z_SHELF, gid="away", **AWAY))
    ax.set_xlim(-0.5, floor.width - 0.5)
    ax.set_ylim(floor.height - 0.5, -0.5)  # the seed's rows count from the top
    ax.set_aspect("equal")
    ax.set_xticks(range(0, floor.width, 10))
    ax.set_yticks(range(0, floor.height, 10))
    ax.tick_params(labelsize=6, length=2)
    return [Patch(facecolor=FLOOR_COLOURS[Kind.WALL], label="wall"),
            Patch(facecolor=FLOOR_COLOURS[Kind.FLOOR], edgecolor="0.8", label="aisle"),
            Patch(label="shelf at home", **SHELF),
            Patch(label="slot, its shelf away (on an AGV)", **AWAY),
            Patch(facecolor=FLOOR_COLOURS[Kind.LANE], label="station queue and exit cells"),
            Patch(label="station work cell", **WORK),
            Patch(facecolor=FLOOR_COLOURS[Kind.STRUCTURE],
                  label="station structure, worker (its number); E entrance, X exit"),
            Patch(label="charging pile", **PILE),
            Patch(facecolor=PARKING_COLOR, label="parking place")]


def body(agv: AgvAt, **style) -> Polygon:
    """The AGV's body where it is, pointing where it heads."""
    dx, dy = STEP[agv.heading]
    return Polygon([(agv.x + dx * f - dy * a, agv.y + dy * f + dx * a) for f, a in BODY],
                   closed=True, **style)


def text_color(rgb: tuple[float, float, float]) -> str:
    """Black on a light colour, white on a dark one."""
    return "black" if 0.299 * rgb[0] + 0.587 * rgb[1] + 0.114 * rgb[2] > 0.6 else "white"


def draw_agv(ax: Axes, agv: AgvAt) -> None:
    """An AGV: its body in its colour, pointing where it heads, with its number; on a
    larger shelf when it carries one; a red edge while it is broken down."""
    at = (agv.x, agv.y)
    if agv.shelf is not None:
        ax.add_patch(square(at, CARRIED_SIDE, facecolor=SHELF_COLOR, edgecolor="black",
                            lw=0.5, zorder=Z_FORKLIFT - 0.01, gid=f"carried/{agv.vehicle}"))
    color = forklift_color(agv.vehicle)
    ax.add_patch(body(agv, facecolor=color, edgecolor=DOWN_EDGE if agv.down else "black",
                      lw=1.6 if agv.down else 0.6, zorder=Z_FORKLIFT, gid=f"agv/{agv.vehicle}"))
    dx, dy = STEP[agv.heading]
    ax.text(agv.x - dx * NUMBER_BACK, agv.y - dy * NUMBER_BACK, str(agv.vehicle),
            ha="center", va="center", color=text_color(color),
            fontsize=6.5 if agv.vehicle < 100 else 4.5, weight="bold", zorder=Z_FORKLIFT_TEXT,
            gid=f"number/{agv.vehicle}")


def agv_handles(state: FloorAt) -> list[Artist]:
    handles: list[Artist] = [
        Patch(facecolor=forklift_color(1), edgecolor="black", lw=0.6,
              label="AGV, empty: its number on it, pointing where it heads"),
        Patch(facecolor=forklift_color(1), edgecolor=SHELF_COLOR, lw=3,
              label="AGV carrying a shelf (under it, brown)")]
    if any(a.down for a in state.agvs):
        handles.append(Patch(facecolor="white", edgecolor=DOWN_EDGE, lw=1.6,
                             label="AGV broken down"))
    if state.closed:
        handles.append(Patch(label="closed zone", **CLOSED))
    return handles


def snapshot(floor: Floor004, state: FloorAt, heading: str) -> Figure:
    """The floor at `state.t`, titled with what is under way and `heading` (the run)."""
    width = max(floor.width * CELL_IN, MIN_WIDTH_IN)
    fig = plt.figure(figsize=(width + 0.6, width * floor.height / floor.width + 1.6),
                     layout="constrained")
    ax = fig.add_subplot()
    handles = draw_floor(ax, floor, state.away)
    if state.closed:
        ax.add_collection(PatchCollection([square(xy, 1.0) for xy in sorted(state.closed)],
                                          zorder=Z_CLOSED, gid="closed", **CLOSED))
    for agv in state.agvs:
        draw_agv(ax, agv)
    moving = sum(a.to is not None for a in state.agvs)
    ax.set_title(f"The floor at t = {state.t:.2f} s: {state.picked} orders picked, "
                 f"{len(state.away)} shelves on AGVs, {moving} of {len(state.agvs)} AGVs "
                 f"moving\n{heading}", fontsize=10)
    legend_below(ax, handles + agv_handles(state), ncols=4)
    return fig
