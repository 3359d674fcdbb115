"""`fleet run`: run a whole mission (as processes on zenoh, or in one process) and print its
summary."""

from __future__ import annotations

import argparse
import signal
import sys
import time
from pathlib import Path
from typing import Any

from fleet.bus import free_port
from fleet.cli_help import strategies_epilog
from fleet.cli_types import (
    integer,
    layout_arg,
    port,
    port_problem,
    positive_float,
    positive_int,
    scenario_arg,
    text_file,
    writable_dir,
)
from fleet.distributed import RunSpec, run_processes
from fleet.engine import EngineOptions
from fleet.errors import UserError
from fleet.faults import Scenario, check_against, load_scenario
from fleet.layout import Layout, load_layout
from fleet.layout_check import fleet_size
from fleet.mission import Mission, MissionKind, Strategy
from fleet.progress import ProgressBar
from fleet.record_inprocess import recorded_run, write_recording
from fleet.record_io import digest_of
from fleet.recording import read_recording


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("run", help="run a whole fill or empty mission",
                       description="Run a mission: a zenoh router, the reservation service, "
                       "one agent process per forklift and the dispatcher, on this machine. "
                       "The dispatcher assigns subtasks; every forklift plans with the "
                       "improved hybrid A* against the shared reservation table.",
                       epilog=strategies_epilog())
    add_mission_args(p)
    p.add_argument("--clock", choices=["fast", "realtime"], default="fast",
                   help="fast: discrete events, deterministic (default); realtime: sim time "
                   "= speed x wall time")
    p.add_argument("--speed", type=positive_float, default=1.0,
                   help="sim seconds per wall second with --clock realtime (default 1)")
    p.add_argument("--inprocess", action="store_true",
                   help="run the in-process reference engine instead (one process, no "
                   "zenoh); fast mode gives the same record bit for bit")
    p.add_argument("--port", type=port, help="router port on 127.0.0.1 (default: a free one)")
    p.add_argument("--out", type=writable_dir, metavar="DIR",
                   help="directory for the recording (run.mcap), the "
                   "reservation journal and each process's log (default: "
                   "runs/DATE-TIME-LAYOUT-STRATEGY)")
    p.add_argument("--foxglove", type=port, metavar="PORT", nargs="?", const=8765,
                   help="serve the live view over the Foxglove WebSocket protocol on "
                   "127.0.0.1:PORT (default port 8765)")
    p.add_argument("--secure", action="store_true",
                   help="the router runs zenoh access control and every process logs in with "
                   "credentials made for this run (kept in OUT/secrets): a forklift may "
                   "publish only as itself and commit only its own reservations, only the "
                   "dispatcher assigns tasks, the recorder only reads (docs/faults.md)")
    p.add_argument("--faults", metavar="SCENARIO", type=scenario_arg,
                   help="inject the faults of a scenario: a shipped one by name (see fleet "
                   "faults list) or a TOML file (docs/faults.md; default: no faults)")
    p.set_defaults(handler=run)


def add_mission_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--layout", default="paper", type=layout_arg,
                   help="layout name or TOML file (default paper)")
    p.add_argument("--mission", choices=[k.value for k in MissionKind], default="fill",
                   help="fill: goods from the stations to the stacks, in each cluster's fill "
                   "order; empty: from the stacks back to the stations, in reverse (default "
                   "fill)")
    p.add_argument("--strategy", choices=[s.value for s in Strategy], default="ann",
                   help="how the dispatcher picks each forklift's next goal (default ann; "
                   "each is described below)")
    p.add_argument("--vehicles", type=positive_int, default=None,
                   help="fleet size (default: every start pose of the layout)")
    p.add_argument("--seed", type=integer, default=0,
                   help="the mission's seed, kept in its record (the dispatching itself "
                   "draws no random numbers: a mission gives the same record every time; "
                   "default 0)")
    p.add_argument("--weights", type=text_file, metavar="FILE",
                   help="MLP weights for --strategy ann (default: the weights shipped for the "
                   "layout)")


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


def summary_lines(rec: dict[str, Any], wall_s: float, digest: str) -> list[str]:
    """The summary of a mission record (record_io.record_to_dict)."""
    m = rec["mission"]
    end = rec["end_time_s"]
    lines = [
        f"mission {m['kind']} on {m['layout']} with {m['vehicles']} forklifts, "
        f"strategy {m['strategy']}",
        f"  end time           {end:.2f} s (last stack done); every forklift parked at "
        f"{rec['all_parked_s']:.2f} s",
        f"  stacks             {len(rec['stacks_done'])}",
        f"  subtasks           {len(rec['subtasks'])}",
        f"  decision failures  {rec['decision_failures']}",
        f"  waiting time       {sum(rec['wait_s'].values()):.2f} s in all",
        f"  wall time          {wall_s:.1f} s",
        f"  record digest      {digest[:16]}",
        "  forklift  busy s   wait s   utilisation",
    ]
    for v in sorted(rec["busy_s"], key=int):
        busy = rec["busy_s"][v]
        lines.append(f"  {v:>8} {busy:8.1f} {rec['wait_s'].get(v, 0.0):8.1f}   "
                     f"{busy / end if end else 0:.0%}")
    return lines


def run(args: argparse.Namespace) -> int:
    mission = mission_from_args(args)
    layout = load_layout(mission.layout)
    n = fleet_size(layout, mission.vehicles)
    for flag, number in (("--port", args.port), ("--foxglove", args.foxglove)):
        busy = port_problem(number) if number is not None and not args.inprocess else None
        if busy:
            raise UserError(f"{flag} {number}: {busy}")
    if not args.inprocess:
        engine_options(mission, layout, args.weights)  # bad weights: refused before starting
    if args.inprocess and (args.clock != "fast" or args.foxglove is not None or args.secure):
        raise UserError("--inprocess runs the fast clock without processes: it takes neither "
                        "--clock realtime nor --foxglove nor --secure")
    scenario = fault_scenario(args.faults, mission, layout, n) if args.faults else None
    out = args.out or Path("runs") / (f"{time.strftime('%Y%m%d-%H%M%S')}-{layout.name}-"
                                      f"{mission.strategy.value}")
    out.mkdir(parents=True, exist_ok=True)
    bar = ProgressBar(len(layout.stacks), f"{mission.kind.value} {mission.strategy.value}")

    def progress(done: int, t: float, failures: int) -> None:
        bar.update(done, f"stacks  t={t:7.1f} s  failures {failures}")

    t0 = time.perf_counter()
    try:
        if args.inprocess:
            record = _run_inprocess(mission, layout, args.weights, progress, out, scenario)
        else:
            record = _run_processes(mission, n, args, progress, out, scenario)
    finally:
        bar.close()
    if record is None:
        print(f"fleet run: logs and what was recorded are in {out}", file=sys.stderr)
        return 1
    print("\n".join(summary_lines(record, time.perf_counter() - t0, digest_of(record))))
    return _verdicts(out / "run.mcap")


def command_line() -> str:
    return " ".join(["fleet", *sys.argv[1:]])


def _verdicts(path: Path) -> int:
    """Analyze the recording; a failed verdict fails the run."""
    from fleet.analysis import analyze

    report = analyze(read_recording(path))
    print(f"  recording          {path}")
    for line in report.verdict_lines():
        print(f"  {line}")
    print(f"  look closer: fleet analyze {path} ; fleet plot {path}")
    return 0 if report.passed else 1


def fault_scenario(source: str, mission: Mission, layout: Layout, vehicles: int) -> Scenario:
    """The scenario of --faults, checked against the run before anything starts."""
    scenario = load_scenario(source)
    check_against(scenario, layout, vehicles)
    if mission.kind is not MissionKind.FILL:
        raise UserError("--faults: fault scenarios run on fill missions for now (cancelling "
                        "a claim from a stack is not modelled yet)")
    return scenario


def _run_inprocess(mission: Mission, layout: Layout, weights: Path | None, progress,
                   out: Path, scenario: Scenario | None) -> dict[str, Any]:
    options = engine_options(mission, layout, weights,
                             lambda done, total, t, failures: progress(done, t, failures))
    done, stream = recorded_run(mission, layout, options, command_line(), scenario)
    write_recording(out / "run.mcap", stream, layout)
    return done.record


def _run_processes(mission: Mission, n: int, args: argparse.Namespace,
                   progress, out: Path, scenario: Scenario | None) -> dict[str, Any] | None:
    def interrupted(*_) -> None:
        raise KeyboardInterrupt  # SIGTERM stops the run like Ctrl-C: every child stopped

    signal.signal(signal.SIGTERM, interrupted)
    port = args.port or free_port()
    print(f"fleet run: router on tcp/127.0.0.1:{port}; watch the table with: fleet table "
          f"--connect tcp/127.0.0.1:{port} --follow", file=sys.stderr)
    if args.foxglove is not None:
        print(f"fleet run: live view for Foxglove on ws://localhost:{args.foxglove}",
              file=sys.stderr)
    spec = RunSpec(mission, n, out, args.clock, args.speed, args.weights, port,
                   foxglove=args.foxglove, command=command_line(), faults=scenario,
                   faults_source=args.faults or "", secure=args.secure)
    outcome = run_processes(spec, lambda p: progress(p.done, p.t, p.failures))
    if outcome.done is None or not outcome.done.ok:
        print(f"fleet run: the mission failed: {outcome.error}", file=sys.stderr)
        return None
    return outcome.done.record
