"""Seed 002's Figures 17-19 from a `fleet bench seed002` result: the makespan of the
bidirectional warehouse (paper002) against the unidirectional one (paper002-uni), the mean
over order seeds with one standard deviation either side as error bars, and the saving
1 - bi / uni written above each point.

`curves` checks the result's shape (a file a user hands `fleet plot`) and says in one line
what is wrong; `figure` draws one experiment.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
from matplotlib.figure import Figure
from matplotlib.transforms import ScaledTranslation

from fleet.errors import UserError
from fleet.views.drawing import legend_below

FIGURES = ("fig17", "fig18", "fig19")
FIELDS = ("orders", "agvs", "bi_s", "uni_s", "bi_sd", "uni_sd", "saving")
BI_COLOR, UNI_COLOR = "tab:blue", "tab:orange"
DODGE_IN = 0.04  # inches each curve is drawn aside


@dataclass(frozen=True)
class MakespanPoint:
    orders: int
    agvs: int
    bi_s: float  # mean makespan, bidirectional (paper002), seconds
    uni_s: float  # unidirectional (paper002-uni)
    bi_sd: float  # sample standard deviation over the seeds
    uni_sd: float
    saving: float  # 1 - bi_s / uni_s


@dataclass(frozen=True)
class Curve:
    """One experiment: its points along what varies ("orders" or "agvs")."""

    name: str  # fig17, fig18, fig19
    varies: str
    points: tuple[MakespanPoint, ...]

    @property
    def fixed(self) -> str:
        """What the experiment holds fixed, for its title."""
        first = self.points[0]
        return f"{first.agvs} AGVs" if self.varies == "orders" else f"{first.orders} orders"


TITLES = {"fig17": "Figure 17: orders on every shelf",
          "fig18": "Figure 18: the fleet varies",
          "fig19": "Figure 19: orders on the lower-left shelf area"}


def is_result(data: Any) -> bool:
    """Whether parsed JSON looks like a `fleet bench seed002` result."""
    return isinstance(data, dict) and any(name in data for name in FIGURES)


def curves(data: Any, source: str) -> list[Curve]:
    """The experiments of a `fleet bench seed002` result, checked: UserError naming the first
    field that is missing or wrong (`source` names the file)."""
    if not is_result(data):
        raise UserError(f"{source}: not a fleet bench seed002 result (no fig17, fig18 or fig19)")
    out = []
    for name in FIGURES:
        if name not in data:
            continue
        rows = data[name]
        if not isinstance(rows, list) or not rows:
            raise UserError(f"{source}: {name} must be a non-empty list of points")
        points = [_point(row, f"{source}: {name}[{k}]") for k, row in enumerate(rows)]
        orders, fleets = {p.orders for p in points}, {p.agvs for p in points}
        if len(orders) > 1 and len(fleets) > 1:
            raise UserError(f"{source}: {name}: both orders and AGVs vary between its points; "
                            f"a curve varies one of them")
        varies = "agvs" if len(fleets) > 1 else "orders"
        out.append(Curve(name, varies, tuple(sorted(points, key=lambda p: getattr(p, varies)))))
    return out


def _point(row: Any, where: str) -> MakespanPoint:
    if not isinstance(row, dict):
        raise UserError(f"{where}: a point must be an object with {', '.join(FIELDS)}")
    values = {}
    for field in FIELDS:
        value = row.get(field)
        if isinstance(value, bool) or not isinstance(value, int | float) \
                or not math.isfinite(value):
            raise UserError(f"{where}.{field}: {'missing' if value is None else repr(value)}; "
                            f"it must be a finite number")
        values[field] = value
    for field in ("orders", "agvs"):
        if values[field] != int(values[field]) or values[field] < 1:
            raise UserError(f"{where}.{field}: {values[field]!r} must be a whole number >= 1")
    for field in ("bi_s", "uni_s", "bi_sd", "uni_sd"):
        if values[field] < 0:
            raise UserError(f"{where}.{field}: {values[field]!r} must not be negative")
    return MakespanPoint(int(values["orders"]), int(values["agvs"]), *(
        float(values[f]) for f in FIELDS[2:]))


def figure(curve: Curve, seeds: int | None = None) -> Figure:
    """The makespan of both warehouses along what the experiment varies: mean with error bars
    of one standard deviation, the saving above each pair of points."""
    fig, ax = plt.subplots(figsize=(7.5, 5), layout="constrained")
    xs = [getattr(p, curve.varies) for p in curve.points]
    for key, color, marker, label, dodge in (
            ("uni", UNI_COLOR, "s", "unidirectional lanes (paper002-uni)", DODGE_IN),
            ("bi", BI_COLOR, "o", "bidirectional channels (paper002)", -DODGE_IN)):
        # Each curve a little aside on the page (the data stay exact): overlapping error
        # bars stay apart.
        aside = ax.transData + ScaledTranslation(dodge, 0, fig.dpi_scale_trans)
        ax.errorbar(xs, [getattr(p, f"{key}_s") for p in curve.points],
                    yerr=[getattr(p, f"{key}_sd") for p in curve.points], color=color,
                    marker=marker, ms=5, capsize=4, lw=1.5, label=label, gid=key,
                    transform=aside)
    top = max(max(p.uni_s + p.uni_sd, p.bi_s + p.bi_sd) for p in curve.points)
    for x, p in zip(xs, curve.points, strict=True):
        ax.annotate(f"{p.saving:.0%}",
                    (x, max(p.uni_s + p.uni_sd, p.bi_s + p.bi_sd)), xytext=(0, 6),
                    textcoords="offset points", ha="center", fontsize=8, color="0.25")
    ax.set_xticks(xs)
    margin = 0.06 * (xs[-1] - xs[0]) or 1.0  # set by hand: the curves aside escape autoscale
    ax.set_xlim(xs[0] - margin, xs[-1] + margin)
    ax.set_xlabel("orders released at t = 0" if curve.varies == "orders" else "AGVs")
    ax.set_ylabel("makespan [s] (the last shelf put down)")
    ax.set_ylim(0, 1.12 * top or 1)
    ax.grid(alpha=0.3)
    if seeds == 1:
        spread = "one order seed (no spread)"
    else:
        spread = f"mean ± one standard deviation over {seeds or 'the'} order seeds"
    mean = sum(p.saving for p in curve.points) / len(curve.points)
    ax.set_title(f"Seed 002, {TITLES.get(curve.name, curve.name)}, {curve.fixed}\n{spread};\n"
                 f"above each point the saving 1 - bi / uni, {mean:.0%} on average",
                 fontsize=9)
    legend_below(ax, ax.get_legend_handles_labels()[0][::-1], ncols=2)  # bidirectional first
    return fig
