"""`fleet train`'s picture: per cycle, the fit's loss before and after Levenberg-Marquardt and
the end time (and decision failures) of the cycle's filling mission."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # files only; no display needed
import matplotlib.pyplot as plt

from fleet.mission.training import CycleReport
from fleet.views.drawing import save_figure


def training_figure(reports: Sequence[CycleReport], layout: str, seed: int, path: Path) -> None:
    cycles = [r.cycle for r in reports]
    fig, (loss, end) = plt.subplots(1, 2, figsize=(9.0, 3.4))
    loss.plot(cycles, [r.loss_before for r in reports], "o--", label="before the fit")
    loss.plot(cycles, [r.loss_after for r in reports], "o-", label="after the fit")
    loss.set_yscale("log")
    loss.set_xlabel("cycle")
    loss.set_ylabel("mean squared error (standardised)")
    loss.set_title("loss of the cluster networks, on every sample so far", fontsize=9)
    loss.legend(fontsize=8)
    end.plot(cycles, [r.end_time for r in reports], "o-", color="black")
    for r in reports:
        end.annotate(f"{r.strategy}\n{r.decision_failures} failures", (r.cycle, r.end_time),
                     textcoords="offset points", xytext=(0, 8), ha="center", fontsize=7)
    end.set_xlabel("cycle (its fill uses the networks of the fit before it)")
    end.set_ylabel("end time of the fill, s")
    end.set_title("the cycle's filling mission", fontsize=9)
    end.margins(x=0.15, y=0.3)
    for ax in (loss, end):
        ax.set_xticks(cycles)
    fig.suptitle(f"fleet train --layout {layout} --seed {seed}", fontsize=10)
    fig.tight_layout()
    save_figure(fig, str(path))
