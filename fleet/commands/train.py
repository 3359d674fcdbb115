"""`fleet train`: warehouse-filling cycles that train the MLP correction, then save it."""

from __future__ import annotations

import argparse
from pathlib import Path

from fleet.commands.progress import ProgressBar
from fleet.runtime.argtypes import integer, layout_arg, png_file, positive_int, writable_file
from fleet.world.layout_file import load_layout


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("train", help="train the ANN strategy's MLP over filling cycles",
                       description="Cycle 1 fills with the comprehensive strategy, later "
                       "cycles with the ANN strategy; after each, the per-cluster networks are "
                       "refitted by Levenberg-Marquardt on every sample so far; the networks "
                       "of the last fit are written (a rule fixed before any mission judges "
                       "them, docs/dispatching.md).")
    p.add_argument("--layout", default="paper", type=layout_arg,
                   help="layout name or TOML file (default paper)")
    p.add_argument("--cycles", type=positive_int, default=3, help="filling cycles (default 3)")
    p.add_argument("--seed", type=integer, default=0,
                   help="seed of the initial weights (default 0)")
    p.add_argument("--lm-steps", type=positive_int, default=50,
                   help="Levenberg-Marquardt steps per fit (default 50)")
    p.add_argument("--out", type=writable_file, metavar="FILE", help="weights file to write "
                   "(default LAYOUT.weights.json in the current directory)")
    p.add_argument("--plot", type=png_file, metavar="FILE.png", help="the loss and end time "
                   "per cycle (default: beside the weights, NAME.training.png)")
    p.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    from fleet.mission.training import train
    from fleet.views.training_plot import training_figure

    layout = load_layout(args.layout)
    out = args.out or Path(f"{layout.name}.weights.json")
    bars: dict[int, ProgressBar] = {}

    def progress(cycle: int, cycles: int, done: int, total: int) -> None:
        bar = bars.get(cycle)
        if bar is None:
            for old in bars.values():
                old.close()
            bar = bars[cycle] = ProgressBar(total, f"cycle {cycle}/{cycles}", unit="stacks")
        bar.update(done)

    mlps, reports = train(layout, args.cycles, args.seed, args.lm_steps, progress)
    for bar in bars.values():
        bar.close()
    print(f"{'cycle':>5} {'strategy':<14} {'end time s':>10} {'failures':>8} {'samples':>7} "
          f"{'loss before':>11} {'after':>8}")
    for r in reports:
        print(f"{r.cycle:>5} {r.strategy:<14} {r.end_time:>10.2f} {r.decision_failures:>8} "
              f"{r.samples:>7} {r.loss_before:>11.4f} {r.loss_after:>8.4f}")
    mlps.save(out)
    plot = args.plot or out.with_name(f"{out.stem}.training.png")
    training_figure(reports, layout.name, args.seed, plot)
    print(f"wrote {out} (the networks of the last fit) and {plot}; use them with: "
          f"fleet run --layout {args.layout} --strategy ann --weights {out}")
    return 0
