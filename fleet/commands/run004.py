"""`fleet run` on a seed-004 floor: lifting AGVs serving orders (fleet/mission/orders004.py),
as one agent process per AGV beside the reservation service, dispatcher and recorder, or in
this one process (`--inprocess`); then the recording judged by analysis/analyze004.py."""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path

from fleet.analysis.analyze004 import analyze004, report_json, report_lines, verdict_lines
from fleet.commands.progress import MissionProgress, ProgressBar
from fleet.commands.runs import write_summary
from fleet.errors import UserError
from fleet.mission.faults import Fault, load_scenario
from fleet.mission.faults004 import check_faults004, injected004
from fleet.mission.orders004 import fleet004, generate_orders
from fleet.mission.record004 import run_mission004, tracking_params
from fleet.mission.spec import ClockMode, Mission, MissionKind
from fleet.mission.tracking004 import Stuck
from fleet.recording.inprocess import Outgoing, outgoing, write_recording
from fleet.recording.reader import read_recording
from fleet.recording.rundir import choose
from fleet.recording.writer import mission_info
from fleet.runtime.args import mission_from_args
from fleet.runtime.hosts import hosts_for
from fleet.runtime.local_run import RunSpec, run_processes
from fleet.wire.protocol import Message, MissionDone, Progress
from fleet.wire.topics import DISPATCHER, Keys, published_by
from fleet.world.layout import Layout

# What runs on seed 000's and 002's missions but not yet on a seed-004 floor, each refused by
# name rather than ignored (docs/agv-004.md, "As processes").
NOT_YET = (("--battery", lambda a: a.battery), ("--order-area", lambda a: a.order_area),
           ("--weights", lambda a: a.weights is not None),
           ("--orders SHELF,...", lambda a: isinstance(a.orders, tuple)))


def run004(args: argparse.Namespace, layout: Layout, command: str) -> int:
    floor = layout.floor
    assert floor is not None
    refused = [flag for flag, given in NOT_YET if given(args)]
    if refused:
        raise UserError(f"layout {layout.name} (seed 004's lifting AGVs) runs order missions "
                        f"without {' or '.join(refused)} yet")
    mission = mission_from_args(args, layout)
    if mission.kind is not MissionKind.ORDERS:
        raise UserError(f"layout {layout.name} runs order missions, not --mission "
                        f"{mission.kind.value}")
    n = fleet004(floor, mission.vehicles)
    mission = dataclasses.replace(mission, vehicles=n)
    generate_orders(floor, mission.orders, mission.seed)  # a bad count: refused at once
    scenario = load_scenario(args.faults, layout.name) if args.faults else None
    if scenario is not None:
        check_faults004(scenario.faults, floor, n, scenario.name)
    faults = scenario.faults if scenario is not None else ()
    hosts = hosts_for(args.hosts, n, args.secure)
    out = choose(args.out, args.force, layout.name, mission.strategy.value,
                 lambda line: print(f"fleet run: {line}", file=sys.stderr)).path
    bar = ProgressBar(mission.orders, f"orders on {layout.name}", unit="orders",
                      enabled=not (args.quiet or args.json))
    progress = MissionProgress(bar)
    t0 = time.perf_counter()
    try:
        if args.inprocess:
            done = _inprocess(mission, layout, n, out, command, progress, faults)
        else:
            spec = RunSpec(mission, n, out, ClockMode(args.clock), args.speed, command=command,
                           port=args.port, foxglove=args.foxglove,
                           faults_source=args.faults or "", secure=args.secure,
                           faults=injected004(scenario) if scenario is not None else None,
                           clocked_agents=False, hosts=hosts)
            progress.status(f"starting the router, recorder, reservation service, {n} AGV "
                            f"agents and the dispatcher")
            outcome = run_processes(spec, lambda p: progress(p.done, p.t, p.failures))
            done = outcome.done if outcome.done is not None else \
                MissionDone(False, error=outcome.error)
    except KeyboardInterrupt:
        done = MissionDone(False, error="interrupted")
    finally:
        bar.close()
    wall_s = time.perf_counter() - t0
    if not done.ok:
        print(f"fleet run: the mission did not finish: {done.error}", file=sys.stderr)
        print(f"fleet run: logs and what was recorded are in {out}", file=sys.stderr)
        return 1
    report = analyze004(read_recording(out))
    write_summary(out, report)  # for `fleet runs`
    if args.json:
        print(json.dumps({"finished": True, **report_json(report), "wall_s": wall_s,
                          "digest": done.digest, "real_time": done.timing or None}))
    else:
        timing = done.timing
        kept = [] if not timing else [
            f"  {'real time':<19}speed {timing['speed']:g}: instants handled late by "
            f"{timing['lateness_p99_s']:.3f} s at p99; {timing['late']} of "
            f"{timing['instants']} over 0.3 s late"
            + (f" (the latest by {timing['worst_late_s']:.2f} s, at "
               f"{timing['worst_late_at_s']:g} s)" if timing["late"] else "")]
        print("\n".join([*report_lines(report), *kept, f"  {'wall time':<19}{wall_s:.1f} s",
                         f"  {'record digest':<19}{done.digest[:16]}",
                         f"  {'recording':<19}{report.path}", *verdict_lines(report),
                         f"  {'look closer':<19}fleet analyze {out}"]))
    return 0 if report.passed else 1


def _inprocess(mission: Mission, layout: Layout, n: int, out: Path, command: str,
               progress: MissionProgress, faults: tuple[Fault, ...]) -> MissionDone:
    """The mission in this process, its messages recorded as a run of processes has them."""
    keys = Keys()
    topics = published_by(DISPATCHER)
    info = mission_info(mission, layout, n, "inprocess", command=command)
    stream: list[Outgoing] = [outgoing(keys, topics[type(info)], info, 0.0)]

    def publish(message: Message, t: float) -> None:
        stream.append(outgoing(keys, topics[type(message)], message, t))
        if isinstance(message, Progress):
            progress(message.done, t, 0)

    assert layout.floor is not None
    try:
        done = run_mission004(mission, layout.floor, n, None, publish,
                              tracking=tracking_params(info), faults=faults)
    except (Stuck, UserError) as exc:
        done = MissionDone(False, error=str(exc))
    stream.append(outgoing(keys, topics[MissionDone], done, stream[-1].sim_time))
    write_recording(out / "run.mcap", stream, layout)
    return done
