"""The colours every view of a run shares: the plots (fleet/views/drawing.py, fleet/views/plots.py)
and the Foxglove scene (fleet/views/scene.py). A forklift has one colour everywhere, so a reader
can follow forklift 3 from the Gantt chart to a snapshot to Foxglove.

Colours are RGB triples in [0, 1], which matplotlib and foxglove.messages.Color both take.
Pure data: no plotting library is imported here (the recorder uses it too).
"""

from __future__ import annotations

RGB = tuple[float, float, float]

# Matplotlib's tab10 without its brown (the goods' colour) and grey (stacks, obstacles):
# eight hues that stay apart on white paper and on the dark Foxglove floor.
FORKLIFT_COLORS: tuple[RGB, ...] = (
    (0.12, 0.47, 0.71), (1.0, 0.50, 0.05), (0.17, 0.63, 0.17), (0.84, 0.15, 0.16),
    (0.58, 0.40, 0.74), (0.09, 0.75, 0.81), (0.89, 0.47, 0.76), (0.74, 0.74, 0.13))

GOODS_COLOR: RGB = (0.60, 0.40, 0.20)  # goods on a stack, or on a forklift's forks
RACK_COLOR: RGB = (0.45, 0.50, 0.60)  # an empty stack's rack
STATION_COLOR: RGB = (0.95, 0.80, 0.10)

# Seed 002's lane layouts: a shelf is goods on legs (GOODS_COLOR, in a slot or on an AGV);
# a packing station is a station (STATION_COLOR) and turns orange while an AGV packs at it.
SHELF_COLOR: RGB = GOODS_COLOR
PACKING_COLOR: RGB = (0.93, 0.45, 0.10)  # a packing station with an AGV dwelling on it
PILE_COLOR: RGB = (0.35, 0.70, 0.35)  # a charging pile


def forklift_color(vehicle: int) -> RGB:
    """Forklift `vehicle`'s colour (forklifts are numbered from 1): its body, its reserved
    cells and its row of the Gantt chart. Ids past the palette's length reuse it in turn."""
    return FORKLIFT_COLORS[(vehicle - 1) % len(FORKLIFT_COLORS)]


def lighter(rgb: RGB, amount: float = 0.5) -> RGB:
    """`rgb` mixed with white: `amount` 0 keeps it, 1 gives white."""
    return (rgb[0] + (1 - rgb[0]) * amount, rgb[1] + (1 - rgb[1]) * amount,
            rgb[2] + (1 - rgb[2]) * amount)
