"""Seed 004's heat maps in the style of its Figures 10-11 ("the brighter, the hotter"): values
per cell of a seed-004 floor drawn over its slots, stations and piles, one panel each, in
the seed's coordinates (origin top left)."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.colors import ListedColormap
from matplotlib.figure import Figure

from fleet.planning.rules004 import XY, Kind
from fleet.world.floor004 import Floor004

PANEL_WIDTH_IN = 9.0
# The floor under the heat: walls, free floor, slots, station lanes and structure.
FLOOR_COLOURS = {Kind.WALL: "#3a3a3a", Kind.FLOOR: "#ffffff", Kind.SLOT: "#d9d9d9",
                 Kind.LANE: "#c6dbef", Kind.STRUCTURE: "#6b6b6b"}


def heat_maps(floor: Floor004, panels: list[tuple[str, dict[XY, float]]],
              title: str) -> Figure:
    """One panel per (title, value per cell); cells without a value show the floor."""
    aspect = floor.height / floor.width
    fig, axes = plt.subplots(len(panels), 1, squeeze=False, layout="constrained",
                             figsize=(PANEL_WIDTH_IN, len(panels) * PANEL_WIDTH_IN * aspect
                                      + 1.2))
    kinds = list(FLOOR_COLOURS)
    base = np.array([[kinds.index(floor.kind((x, y))) for x in range(floor.width)]
                     for y in range(floor.height)])
    for ax, (name, values) in zip(axes[:, 0], panels, strict=True):
        ax.imshow(base, cmap=ListedColormap([FLOOR_COLOURS[k] for k in kinds]),
                  vmin=0, vmax=len(kinds) - 1, interpolation="nearest")
        heat = np.full((floor.height, floor.width), np.nan)
        for (x, y), v in values.items():
            if v > 0:
                heat[y, x] = v
        shown = ax.imshow(heat, cmap="inferno", interpolation="nearest")
        for x, y in floor.piles:
            ax.plot(x, y, marker="s", color="tab:green", markersize=3)
        ax.set_title(f"{name}: {sum(values.values()):.4g} in all, "
                     f"{sum(v > 0 for v in values.values())} cells", fontsize=9)
        ax.set_xticks([])
        ax.set_yticks([])
        fig.colorbar(shown, ax=ax, shrink=0.8, pad=0.01)
    fig.suptitle(title, fontsize=10)
    return fig
