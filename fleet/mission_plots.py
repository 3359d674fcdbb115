"""Plots of a mission record (seed 000, Figures 13 to 18 style): the filling sequence by
quarter, a Gantt chart of the subtasks, and a snapshot of the warehouse at one instant.

They read the record as the plain dict of `fleet.record_io`, so they draw any saved run.
"""

from __future__ import annotations

import math

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
from matplotlib.patches import Patch

from fleet.layout import Layout
from fleet.maneuvers import Manner, world_pose
from fleet.plotting import COLORS, _body, _cell_square, draw_layout
from fleet.record_io import held_intervals
from fleet.trajectory import Pose

QUARTER_COLORS = ["tab:red", "tab:blue", "tab:green", "gold"]  # as in the seed's figures


def _save(fig, ax, path: str, record: dict, what: str) -> None:
    m = record["mission"]
    ax.set_title(f"{m['kind']} with {m['strategy']} on {m['layout']}, {what}", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    plt.close(fig)


def quarters(record: dict) -> list[int]:
    """Stacks done in each quarter of the mission's end time."""
    end = record["end_time_s"] or 1.0
    counts = [0, 0, 0, 0]
    for _, _, t in record["stacks_done"]:
        counts[min(3, int(4 * t / end))] += 1
    return counts


def filling_sequence(path: str, layout: Layout, record: dict) -> None:
    fig, ax = plt.subplots(figsize=(12, 8.5))
    draw_layout(ax, layout)
    end = record["end_time_s"] or 1.0
    cell_of = {(s.cluster, s.index): s.cell for s in layout.stacks}
    for order, (cluster, index, t) in enumerate(record["stacks_done"], start=1):
        cell = cell_of[cluster, index]
        ax.add_patch(_cell_square(layout, cell, color=QUARTER_COLORS[min(3, int(4 * t / end))],
                                  alpha=0.8))
        x, y = layout.cell_center(cell)
        ax.text(x, y - 0.55, str(order), ha="center", va="center", fontsize=5, color="white")
    counts = quarters(record)
    ax.legend(handles=[Patch(color=c, label=f"quarter {q + 1}: {n} stacks")
                       for q, (c, n) in enumerate(zip(QUARTER_COLORS, counts, strict=True))],
              loc="upper right", fontsize=7)
    _save(fig, ax, path, record, f"sequence: end {record['end_time_s']:.2f} s (small "
          f"numbers: order done)")


def gantt(path: str, record: dict) -> None:
    vehicles = sorted({s["vehicle"] for s in record["subtasks"]})
    fig, ax = plt.subplots(figsize=(14, 1 + 0.6 * len(vehicles)))
    for s in record["subtasks"]:
        row = vehicles.index(s["vehicle"])
        color = "tab:blue" if s["kind"] == "deliver" else "tab:orange"
        ax.barh(row, s["t_end"] - s["t_i"], left=s["t_i"], color=color, height=0.6)
        ax.barh(row, s["t_done"] - s["t_end"], left=s["t_end"], color="0.6", height=0.6)
        stops = [st for st in s["steps"] if st[0] == "stop"]
        for st in stops:
            ax.barh(row, st[4] - st[3], left=st[3], color="tab:red", height=0.3)
    for f in record["failures"]:
        if f["vehicle"] is not None and f["vehicle"] in vehicles:
            ax.plot(f["t"], vehicles.index(f["vehicle"]) + 0.4, "kx", ms=3)
    ax.set_yticks(range(len(vehicles)), [f"forklift {v}" for v in vehicles])
    ax.set_xlabel("time [s]")
    ax.legend(handles=[Patch(color="tab:blue", label="to a shelf"),
                       Patch(color="tab:orange", label="to a station"),
                       Patch(color="0.6", label="claim / unload"),
                       Patch(color="tab:red", label="waiting (stop)")],
              loc="upper right", fontsize=7, ncols=4)
    _save(fig, ax, path, record, "subtasks (x: decision failures)")


def pose_at(record: dict, vehicle: int, t: float, layout: Layout) -> tuple[float, float, float]:
    """World pose of a forklift at time t, interpolated within the maneuver it is doing."""
    pose = Pose.parse(record["starts"][vehicle - 1])  # vehicles are numbered from 1
    for s in record["subtasks"]:
        if s["vehicle"] != vehicle:
            continue
        for label, start, end, t0, t1, *_ in s["steps"]:
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


def snapshot(path: str, layout: Layout, record: dict, t: float, ahead: float = 20.0) -> None:
    fill = record["mission"]["kind"] == "fill"
    cell_of = {(s.cluster, s.index): s.cell for s in layout.stacks}
    done = {cell_of[c, i] for c, i, td in record["stacks_done"] if td <= t}
    present = done if fill else {s.cell for s in layout.stacks} - done
    fig, ax = plt.subplots(figsize=(12, 8.5))
    draw_layout(ax, layout, present)
    vehicles = sorted({s["vehicle"] for s in record["subtasks"]})
    held = held_intervals(record)
    for k, v in enumerate(vehicles):
        color = COLORS[k % len(COLORS)]
        for vehicle, cell, t0, t1 in held:
            if vehicle == v and t0 < t + ahead and t1 > t:
                ax.add_patch(_cell_square(layout, cell, color=color,
                                          alpha=0.35 if t0 <= t else 0.12))
        x, y, th = pose_at(record, v, t, layout)
        ax.add_patch(_body(layout, x, y, th, facecolor=color, edgecolor="black", lw=0.8))
        ax.text(x, y, str(v), ha="center", va="center", fontsize=8, color="white")
    _save(fig, ax, path, record, f"t = {t:.2f} s: forklifts and their reserved cells "
          f"(dark: now, light: next {ahead:g} s)")
