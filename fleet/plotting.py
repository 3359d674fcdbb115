"""Matplotlib drawings of layouts and trajectories (imported only by commands that draw)."""

from __future__ import annotations

from collections.abc import Iterable, Sequence

import matplotlib

matplotlib.use("Agg")  # files only; no display needed
import matplotlib.pyplot as plt
from matplotlib.patches import Polygon, Rectangle

from fleet.geometry import Cell, body_corners
from fleet.layout import Layout
from fleet.maneuvers import world_pose
from fleet.reservations import Reservation
from fleet.trajectory import Pose, Trajectory

COLORS = ["tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple", "tab:brown"]


def _cell_square(layout: Layout, cell: Cell, **style) -> Rectangle:
    x, y = layout.cell_center(cell)
    half = layout.cell_size / 2
    return Rectangle((x - half, y - half), layout.cell_size, layout.cell_size, **style)


def draw_layout(ax, layout: Layout, filled: Iterable[Cell] = ()) -> None:
    filled = set(filled)
    grid = layout.grid_map(filled)
    for c in range(layout.cols):
        for r in range(layout.rows):
            cell = (c, r)
            if cell in filled:
                ax.add_patch(_cell_square(layout, cell, color="0.35"))
            elif not grid.free(cell):
                ax.add_patch(_cell_square(layout, cell, color="0.75"))
            else:
                ax.add_patch(_cell_square(layout, cell, fill=False, lw=0.3, ls="--",
                                          edgecolor="0.8"))
    for stack in layout.stacks:
        x, y = layout.cell_center(stack.cell)
        ax.text(x, y, str(stack.index), ha="center", va="center", fontsize=5, color="0.2")
    for station in layout.stations:
        x, y = layout.cell_center(station.cell)
        ax.add_patch(_cell_square(layout, station.cell, color="gold"))
        ax.text(x, y, station.name, ha="center", va="center", fontsize=7)
    for cluster in layout.clusters:
        cells = [s.cell for s in layout.stacks if s.cluster == cluster.name]
        if cells:
            xs, ys = zip(*(layout.cell_center(c) for c in cells), strict=True)
            ax.text(sum(xs) / len(xs), sum(ys) / len(ys), cluster.name, ha="center",
                    va="center", fontsize=11, color="tab:blue", alpha=0.6, weight="bold")
    x0, y0 = layout.cell_center((0, 0))
    half = layout.cell_size / 2
    ax.set_xlim(x0 - half, x0 - half + layout.cols * layout.cell_size)
    ax.set_ylim(y0 - half, y0 - half + layout.rows * layout.cell_size)
    ax.set_aspect("equal")


def _body(layout: Layout, x: float, y: float, theta: float, **style) -> Polygon:
    return Polygon(body_corners(x, y, theta, layout.vehicle.dims), closed=True, **style)


def draw_trajectory(ax, layout: Layout, traj: Trajectory, color: str = "tab:red",
                    label: str | None = None) -> None:
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
                           alpha=0.5))
    ax.plot(xs, ys, color=color, lw=1.5, label=label)
    _draw_pose(ax, layout, traj.start, color, alpha=0.9)
    _draw_pose(ax, layout, traj.goal, color, alpha=0.9, hatch="//")
    for step in traj.steps[:: max(1, len(traj.steps) // 8)]:
        x, y = layout.cell_center(step.start.cell)
        ax.text(x, y + 0.3, f"{step.t0:g}", fontsize=5, color=color)


def _draw_pose(ax, layout: Layout, pose: Pose, color: str, **style) -> None:
    x, y = layout.cell_center(pose.cell)
    ax.add_patch(_body(layout, x, y, pose.heading * 3.141592653589793 / 2, facecolor=color,
                       edgecolor="black", lw=0.6, **style))


def draw_reservations(ax, layout: Layout, reservations: Sequence[Reservation]) -> None:
    vehicles = sorted({r.vehicle for r in reservations})
    for r in reservations:
        color = COLORS[vehicles.index(r.vehicle) % len(COLORS)]
        ax.add_patch(_cell_square(layout, r.cell, color=color, alpha=0.12))


def save_plan_figure(path: str, layout: Layout, traj: Trajectory | None,
                     others: Sequence[Trajectory], reservations: Sequence[Reservation],
                     filled: Iterable[Cell], title: str) -> None:
    fig, ax = plt.subplots(figsize=(12, 8.5))
    draw_layout(ax, layout, filled)
    draw_reservations(ax, layout, reservations)
    for i, other in enumerate(others):
        draw_trajectory(ax, layout, other, COLORS[(i + 1) % len(COLORS)],
                        f"vehicle {other.vehicle}")
    if traj is not None:
        draw_trajectory(ax, layout, traj, COLORS[0], f"vehicle {traj.vehicle} (planned)")
    ax.set_title(title, fontsize=10)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.legend(loc="upper right", fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    plt.close(fig)
