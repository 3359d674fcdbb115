"""The static pose graph of a map: which moves fit from each pose (Algorithm 3's static check,
gamma = 0: the cells the move ends on and sweeps are on the map and free), and which poses a
vehicle can drive between, whoever else is there.

The cells each move needs are the same for every fill state of a floor, so they are laid out
once per map size and body (`skeleton`): a fill state is then one gather over its free cells
(`fitting`), and its connected components one vectorised union-find over the moves that fit
from poses where the body fits (`components`). Planners are built for hundreds of fill
states a mission (the dispatcher asks, for every cluster, whether a dock is still reachable
once its next stack is filled), so this is what building one costs.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from functools import cache

import numpy as np

from fleet.params import VehicleDims
from fleet.planning.geometry import Cell
from fleet.planning.maneuvers import Manner, Move, move_table

MANNERS = tuple(Manner)
STOP_SLOT = MANNERS.index(Manner.STOP)


@dataclass(frozen=True, eq=False)
class Skeleton:
    """Every move from every pose of a cols x rows map. Poses are numbered
    (x * rows + y) * 4 + heading, and the move of manner m from pose p is p * len(MANNERS) +
    m; cells are numbered x * rows + y, and two more numbers stand for a padding cell that
    is always free and for any cell off the map, which never is."""

    cols: int
    rows: int
    dst: np.ndarray  # (moves,) the pose each move ends at; -1: off the map
    needs: np.ndarray  # (moves, k) the cells each move ends on and sweeps

    @property
    def cells(self) -> int:
        return self.cols * self.rows

    def move(self, x: int, y: int, heading: int) -> int:
        """The number of the first move (MANNERS[0]) from an on-map pose."""
        return ((x * self.rows + y) * 4 + heading) * len(MANNERS)


@dataclass(frozen=True)
class Components:
    labels: list[int]  # by pose number: poses with the same label reach each other
    at_rest: list[bool]  # by pose number: whether the body fits there

    def of(self, graph: Skeleton, cell: Cell, heading: int) -> int | None:
        """The pose's component; None for a pose off the map or whose body does not fit."""
        x, y = cell
        if not (0 <= x < graph.cols and 0 <= y < graph.rows and 0 <= heading < 4):
            return None
        node = (x * graph.rows + y) * 4 + heading
        return self.labels[node] if self.at_rest[node] else None


@cache
def skeleton(dims: VehicleDims, cell_size: float, cols: int, rows: int) -> Skeleton:
    moves = move_table(dims, cell_size)
    xs, ys = (a.ravel() for a in np.meshgrid(np.arange(cols), np.arange(rows), indexing="ij"))
    padding, off_map = cols * rows, cols * rows + 1

    def needed(move: Move) -> np.ndarray:
        """(cells, k) the cell numbers the move needs from every cell of the map."""
        out = []
        for a, b in sorted(frozenset(move.end_cells) | frozenset(move.middle_cells)):
            cx, cy = xs + a, ys + b
            inside = (cx >= 0) & (cx < cols) & (cy >= 0) & (cy < rows)
            out.append(np.where(inside, cx * rows + cy, off_map))
        return np.stack(out, axis=1) if out else np.empty((xs.size, 0), dtype=np.int64)

    per_move = {key: needed(move) for key, move in moves.items()}
    width = max(n.shape[1] for n in per_move.values())
    needs = np.full((cols * rows, 4, len(MANNERS), width), padding, dtype=np.int32)
    dst = np.full((cols * rows, 4, len(MANNERS)), -1, dtype=np.int64)
    for (manner, heading), move in moves.items():
        slot = MANNERS.index(manner)
        cells = per_move[manner, heading]
        needs[:, heading, slot, :cells.shape[1]] = cells
        ex, ey = xs + move.end_delta[0], ys + move.end_delta[1]
        on_map = (ex >= 0) & (ex < cols) & (ey >= 0) & (ey < rows)
        dst[:, heading, slot] = np.where(on_map, (ex * rows + ey) * 4 + move.end_heading, -1)
    return Skeleton(cols, rows, dst.ravel(), needs.reshape(-1, width))


def fitting(graph: Skeleton, blocked: Iterable[Cell]) -> np.ndarray:
    """(moves,) whether each move's cells are on the map and free of `blocked` cells."""
    free = np.ones(graph.cells + 2, dtype=bool)
    free[graph.cells + 1] = False
    free[[x * graph.rows + y for x, y in blocked
          if 0 <= x < graph.cols and 0 <= y < graph.rows]] = False
    return free[graph.needs].all(axis=1)


def components(graph: Skeleton, fits: np.ndarray) -> Components:
    """Label every pose with its connected component: union-find over the moves that fit
    from poses where the body fits (a stop fits), vectorised (hook roots, then jump pointers
    until every move agrees). Moves are reversible, so reachability is symmetric."""
    by_pose = fits.reshape(-1, len(MANNERS))
    at_rest = by_pose[:, STOP_SLOT]
    usable = (by_pose & at_rest[:, None]).ravel() & (graph.dst >= 0)
    usable.reshape(-1, len(MANNERS))[:, STOP_SLOT] = False
    moves = np.flatnonzero(usable)
    u, v = moves // len(MANNERS), graph.dst[moves]
    parent = np.arange(graph.cells * 4)
    while True:
        ru, rv = parent[u], parent[v]
        if np.array_equal(ru, rv):
            break
        np.minimum.at(parent, np.maximum(ru, rv), np.minimum(ru, rv))
        while not np.array_equal(jumped := parent[parent], parent):
            parent = jumped
    return Components(parent.tolist(), at_rest.tolist())
