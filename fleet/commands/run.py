"""`fleet run`: run a whole mission and print its summary."""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from fleet.engine import EngineOptions, MissionRecord, run_mission
from fleet.layout import Layout, load_layout
from fleet.mission import Mission, MissionKind, Strategy
from fleet.progress import ProgressBar


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("run", help="run a whole fill or empty mission",
                       description="Run a mission: the dispatcher assigns subtasks, every "
                       "forklift plans with the improved hybrid A* against the shared "
                       "reservation table.")
    add_mission_args(p)
    p.add_argument("--inprocess", action="store_true",
                   help="run the in-process reference engine (one process, deterministic); "
                   "for now this is also what runs without the flag, until the distributed "
                   "runtime lands")
    p.add_argument("--out", type=Path, help="directory to write the mission record into")
    p.set_defaults(handler=run)


def add_mission_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--layout", default="paper", help="layout name or TOML file (default paper)")
    p.add_argument("--mission", choices=[k.value for k in MissionKind], default="fill")
    p.add_argument("--strategy", choices=[s.value for s in Strategy], default="ann")
    p.add_argument("--vehicles", type=int, default=None,
                   help="fleet size (default: every start pose of the layout)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--weights", type=Path, help="MLP weights for --strategy ann "
                   "(default: the weights shipped for the layout)")


def mission_from_args(args: argparse.Namespace) -> Mission:
    return Mission(layout=args.layout, kind=MissionKind(args.mission),
                   strategy=Strategy(args.strategy), vehicles=args.vehicles, seed=args.seed)


def engine_options(mission: Mission, layout: Layout, weights: Path | None,
                   progress=None) -> EngineOptions:
    mlp = None
    if mission.strategy is Strategy.ANN:
        from fleet.ann import load_scorer

        mlp = load_scorer(layout, weights)
    return EngineOptions(mlp=mlp, progress=progress)


def summary_lines(rec: MissionRecord, wall_s: float) -> list[str]:
    end = rec.end_time
    lines = [
        f"mission {rec.mission.kind.value} on {rec.layout} with {len(rec.vehicles)} forklifts, "
        f"strategy {rec.mission.strategy.value}",
        f"  end time           {end:.2f} s (last stack done); every forklift parked at "
        f"{rec.all_parked_time:.2f} s",
        f"  stacks             {len(rec.stacks_done)}",
        f"  subtasks           {len(rec.subtasks)}",
        f"  decision failures  {rec.decision_failures}",
        f"  waiting time       {rec.total_wait_s:.2f} s in all",
        f"  wall time          {wall_s:.1f} s",
        "  forklift  busy s   wait s   utilisation",
    ]
    for v in rec.vehicles:
        busy = rec.busy_s.get(v, 0.0)
        lines.append(f"  {v:>8} {busy:8.1f} {rec.wait_s.get(v, 0.0):8.1f}   "
                     f"{busy / end if end else 0:.0%}")
    return lines


def run(args: argparse.Namespace) -> int:
    mission = mission_from_args(args)
    layout = load_layout(mission.layout)
    options = engine_options(mission, layout, args.weights)
    bar = ProgressBar(len(layout.stacks), f"{mission.kind.value} {mission.strategy.value}")

    def progress(done: int, total: int, t: float, failures: int) -> None:
        bar.update(done, f"stacks  t={t:7.1f} s  failures {failures}")

    t0 = time.perf_counter()
    options.progress = progress
    rec = run_mission(mission, options, layout)
    bar.close()
    wall = time.perf_counter() - t0
    print("\n".join(summary_lines(rec, wall)))
    if args.out:
        from fleet.record_io import record_to_dict

        args.out.mkdir(parents=True, exist_ok=True)
        path = args.out / "mission.json"
        path.write_text(json.dumps(record_to_dict(rec)))
        print(f"wrote {path}")
    return 0
