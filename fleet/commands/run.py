"""`fleet run`: run a whole mission (as processes on zenoh, or in one process) and print its
summary."""

from __future__ import annotations

import argparse
import contextlib
import json
import re
import signal
import sys
import threading
import time
from collections.abc import Iterator
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from fleet.commands.analyze import stopped_lines
from fleet.commands.progress import MissionProgress, ProgressBar
from fleet.commands.run004 import run004
from fleet.commands.run_external import broker_of, check_vda5050_run, run_external
from fleet.commands.runs import write_summary
from fleet.dispatching.decision import Strategy
from fleet.dispatching.scorer import layout_weights
from fleet.errors import UserError
from fleet.mission.engine import engine_options
from fleet.mission.faults import Scenario, check_against, load_scenario
from fleet.mission.order_work import OrderWork, order_fleet
from fleet.mission.record import digest_of
from fleet.mission.spec import ClockMode, Mission, MissionKind
from fleet.mission.standstill import Standstill
from fleet.recording.inprocess import recorded_run, write_recording
from fleet.recording.mission_record import recorded_standstill
from fleet.recording.reader import Recording, read_recording
from fleet.recording.rundir import choose
from fleet.runtime.args import add_mission_args, mission_from_args
from fleet.runtime.argtypes import (
    mqtt_url,
    port,
    port_problem,
    positive_float,
    scenario_arg,
    writable_dir,
)
from fleet.runtime.bus import free_port
from fleet.runtime.helptext import strategies_epilog
from fleet.runtime.hosts import Hosts, cut_links, hosts_for
from fleet.runtime.local_run import RunSpec, run_processes
from fleet.runtime.process_configs import DISPATCH_MODES
from fleet.vehicles import registry
from fleet.wire.protocol import MissionDone
from fleet.world.layout import Layout
from fleet.world.layout_file import load_layout
from fleet.world.reachability import fleet_size

if TYPE_CHECKING:
    from fleet.analysis.report import Report


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("run", help="run a whole fill or empty mission",
                       description="Run a mission: a zenoh router, the reservation service, "
                       "one agent process per forklift and the dispatcher, on this machine. "
                       "The dispatcher assigns subtasks; every forklift plans with the "
                       "improved hybrid A* against the shared reservation table.",
                       epilog=strategies_epilog())
    add_mission_args(p)
    p.add_argument("--clock", choices=[m.value for m in ClockMode],
                   help="fast: discrete events, deterministic (default); realtime: sim time "
                   "= speed x wall time (the default, and the only clock, of --dispatch "
                   "vda5050 and external)")
    p.add_argument("--speed", type=positive_float, default=1.0,
                   help="sim seconds per wall second with --clock realtime (default 1)")
    p.add_argument("--inprocess", action="store_true",
                   help="run the in-process reference engine instead (one process, no "
                   "zenoh); fast mode gives the same record bit for bit")
    p.add_argument("--port", type=port, help="router port on 127.0.0.1 (default: a free one)")
    p.add_argument("--out", type=writable_dir, metavar="DIR", help="a new or empty directory "
                   "for the recording (run.mcap), the reservation journal and each process's "
                   "log (default: runs/DATE-TIME-LAYOUT-STRATEGY, -2 after it if taken)")
    p.add_argument("--force", action="store_true",
                   help="with --out: an earlier run's directory there is replaced whole: "
                   "everything in it is deleted, files of your own put there too (only a "
                   "directory a fleet run made, never another)")
    p.add_argument("--foxglove", type=port, metavar="PORT", nargs="?", const=8765,
                   help="serve the live view over the Foxglove WebSocket protocol on "
                   "127.0.0.1:PORT (default port 8765)")
    p.add_argument("--secure", action="store_true",
                   help="the router (each host's, with --hosts) runs zenoh access control "
                   "and every process logs in with credentials made for this run (kept in "
                   "OUT/secrets/HOST): a forklift may publish only as itself and commit only its "
                   "own reservations, only the dispatcher assigns tasks, the recorder only "
                   "reads; the routers of several hosts link over TLS with certificates made "
                   "for this run (docs/faults.md, docs/deployment.md)")
    p.add_argument("--hosts", type=Path, metavar="FILE",
                   help="spread the processes over several hosts, a zenoh router on each, "
                   "linked: a TOML file naming each host's address, how a process is started "
                   "there and what it runs (docs/deployment.md; default: this machine alone)")
    p.add_argument("--faults", metavar="SCENARIO", type=scenario_arg,
                   help="inject the faults of a scenario: a shipped one by name (see fleet "
                   "faults list) or a TOML file (docs/faults.md; default: no faults)")
    p.add_argument("--dispatch", choices=DISPATCH_MODES, default="internal",
                   help="internal: the dispatcher runs the mission (default); vda5050: it "
                   "runs it as VDA 5050 orders over MQTT, through the gateway; external: no "
                   "mission, the forklifts park and take a VDA 5050 master's orders over MQTT "
                   "through the gateway until Ctrl-C; both on the real-time clock "
                   "(docs/vda5050.md)")
    p.add_argument("--mqtt", type=mqtt_url, metavar="URL",
                   help="--dispatch vda5050 or external: the MQTT broker, mqtt://HOST[:PORT] "
                   "(default: a mosquitto started for the run on a free port of 127.0.0.1)")
    p.add_argument("--quiet", action="store_true",
                   help="no progress: only the summary and errors")
    p.add_argument("--json", action="store_true",
                   help="no progress; print the summary as one JSON object (docs/metrics.md)")
    p.set_defaults(handler=run)


SUMMARY_WIDTH = 80  # the summary fits a terminal of 80 columns
VALUE_COLUMN = 21  # where the value of a "  label   value" line starts


def summary_lines(report: Report, wall_s: float, digest: str,
                  ended: Ending | None = None) -> list[str]:
    """The summary of a run: its recording's numbers as `fleet analyze` has them
    (docs/metrics.md), the wall time, the record's digest (of a finished mission) or how far
    an unfinished one got (`ended`), and the verdicts; a line longer than SUMMARY_WIDTH goes
    on under its value (a path is never broken)."""
    m = report.mission
    under = " " * VALUE_COLUMN
    labelled = [
        f"mission {m['kind']} on {m['layout']} with {m['vehicles']} {report.vehicle_noun}s, "
        f"strategy {m['strategy']}",
        *report.numbers_lines(),
        f"  wall time          {wall_s:.1f} s",
        *([f"  record digest      {digest[:16]}"] if ended is None else ended.lines(report)),
    ]
    at = f" --at {ended.t(report):.2f}" if ended is not None else ""
    verdicts = [
        f"  recording          {report.path}",
        *(f"  {line}" for line in report.verdict_lines()),
        f"  look closer        fleet analyze {report.path}",
        f"{under}fleet plot {report.path}{at}",
    ]
    return [*_fitted(labelled, under), *report.vehicle_lines(), *_fitted(verdicts, under)]


@dataclass(frozen=True)
class Ending:
    """How a mission that did not finish ended: the failure `fleet run` heard, and how far
    the mission got as the recording has it (None: its dispatcher said nothing, as when it
    was killed outright)."""

    failure: str
    stopped: Standstill | None

    def t(self, report: Report) -> float:
        """The sim time it reached."""
        return self.stopped.t if self.stopped is not None else report.recovered_sim_s

    def lines(self, report: Report) -> list[str]:
        if self.stopped is None:
            return [f"  stopped            the dispatcher said nothing of how far it got; the "
                    f"recording reaches t={report.recovered_sim_s:.2f} s"]
        return stopped_lines(self.stopped)

    def to_json(self) -> dict[str, Any]:
        return {"finished": False, "error": self.failure,
                "stopped": self.stopped.to_dict() if self.stopped is not None else None}


def _fitted(lines: list[str], indent: str) -> list[str]:
    """Each line, broken after a clause (', ' or '; ') where it would pass SUMMARY_WIDTH and
    continued at `indent`; a clause longer than that (a long path) is left whole."""
    out = []
    for line in lines:
        current = ""
        for clause in re.split(r"(?<=[;,]) ", line):
            if current and len(current) + 1 + len(clause) > SUMMARY_WIDTH:
                out.append(current)
                current = indent + clause
            else:
                current = f"{current} {clause}" if current else clause
        out.append(current)
    return out


def summary_json(report: Report, wall_s: float, digest: str,
                 ended: Ending | None = None) -> dict[str, Any]:
    """The summary as one JSON object (`fleet run --json`)."""
    vehicles = report.vehicles
    return {
        **(ended.to_json() if ended is not None else
           {"finished": True, "error": "", "stopped": None}),
        "mission": report.mission,
        "end_time_s": report.end_time_s,
        "all_parked_s": report.all_parked_s,
        "stacks_done": report.stacks_done,
        "stacks_expected": report.stacks_expected,
        "subtasks": report.subtasks,
        "decision_failures": report.decision_failures,
        "plans_failed": report.plans_failed,
        "undecided": report.undecided,
        "waiting_s": sum(v.waiting_s for v in vehicles),
        "stopped_s": sum(v.stopped_s for v in vehicles),
        "postponed_s": sum(v.postponed_s for v in vehicles),
        "incomplete": report.incomplete,  # why figures miss something; [] when they do not
        "vehicles": [asdict(v) for v in vehicles],
        "wall_s": wall_s,
        "digest": digest,
        "recording": report.path,
        "verdicts": {"safety": report.safe, "work": report.work_done,
                     "messages": report.messages_whole, "passed": report.passed,
                     **({"lanes": report.lanes_kept} if report.lane_layout else {}),
                     **({"battery": report.batteries_kept} if report.battery else {}),
                     **({"vda5050": report.protocol.passed} if report.protocol else {})},
        **({"orders": asdict(report.orders)} if report.orders is not None else {}),
        **({"battery": asdict(report.battery)} if report.battery is not None else {}),
    }


def run(args: argparse.Namespace) -> int:
    layout = load_layout(args.layout)
    _check_run_flags(args)
    if args.dispatch != "internal":
        check_vda5050_run(args, layout)
        args.clock = args.clock or ClockMode.REALTIME.value
    args.clock = args.clock or ClockMode.FAST.value
    if args.dispatch == "external":
        return run_external(args, layout, command_line())
    if args.mqtt is not None and args.dispatch == "internal":
        raise UserError("--mqtt is the broker of --dispatch vda5050 or external; the internal "
                        "dispatcher speaks no MQTT")
    if layout.floor is not None:  # seed 004's lifting AGVs
        return run004(args, layout, command_line())
    mission = mission_from_args(args, layout)
    if args.dispatch == "vda5050" and mission.kind not in (MissionKind.FILL, MissionKind.EMPTY):
        raise UserError(f"--dispatch vda5050 runs fill and empty missions, not "
                        f"{mission.kind.value} (docs/vda5050.md)")
    if not registry.is_built(layout.vehicle.kind):  # a planned kind: nothing drives it yet
        raise UserError(f"layout {layout.name}: {registry.not_built(layout.vehicle.kind)}")
    if mission.kind is MissionKind.ORDERS:
        n = order_fleet(layout, mission.vehicles)
        OrderWork(layout, mission, n)  # its orders and batteries, checked before any start
    else:
        n = fleet_size(layout, mission.vehicles)
    if not args.inprocess and mission.strategy is Strategy.ANN:  # refused before starting;
        layout_weights(layout, args.weights)  # torch is the dispatcher's to import
    hosts = hosts_for(args.hosts, n, args.secure)
    scenario = fault_scenario(args.faults, layout, n, hosts) if args.faults else None
    out = choose(args.out, args.force, layout.name, mission.strategy.value,
                 lambda line: print(f"fleet run: {line}", file=sys.stderr)).path
    orders = mission.kind is MissionKind.ORDERS
    bar = ProgressBar(mission.orders if orders else len(layout.stacks),
                      f"{mission.kind.value} {mission.strategy.value}",
                      unit="orders" if orders else "stacks",
                      enabled=not (args.quiet or args.json))
    progress = MissionProgress(bar)
    t0 = time.perf_counter()
    stop = threading.Event()  # Ctrl-C or SIGTERM asked the mission to stop
    try:
        if args.inprocess:
            with _stop_requests(stop):
                done = _run_inprocess(mission, layout, args.weights, progress, out, scenario,
                                      stop)
        else:
            done = _run_processes(mission, n, args, progress, out, scenario, hosts)
    except KeyboardInterrupt:  # every child stopped, the dispatcher's last word recorded
        stop.set()
        done = MissionDone(False, error="interrupted")
    finally:
        bar.close()  # first: what is said next goes on lines of its own
    wall_s = time.perf_counter() - t0
    if not done.ok:
        _say_failed(out, done.error, wall_s, args.json)
        return 130 if stop.is_set() else 1
    report = _report(out)
    digest = digest_of(done.record)
    if args.json:
        print(json.dumps(summary_json(report, wall_s, digest)))
    else:
        print("\n".join(summary_lines(report, wall_s, digest)))
    return 0 if report.passed else 1  # a failed verdict fails the run


def _check_run_flags(args: argparse.Namespace) -> None:
    """What no mission runs with: --force without --out, a flag of a run of processes with
    --inprocess, a port something already listens on."""
    if args.force and args.out is None:
        raise UserError("--force replaces the directory given with --out DIR; without --out "
                        "a run gets a new directory of its own and replaces nothing")
    process_only = [flag for flag, given in (
        ("--clock realtime", args.clock == ClockMode.REALTIME.value),
        ("--port", args.port is not None),
        ("--foxglove", args.foxglove is not None), ("--secure", args.secure),
        ("--hosts", args.hosts is not None)) if given]
    if args.inprocess and process_only:
        raise UserError(f"--inprocess runs the fast clock in this one process, without a "
                        f"router, a live view or logins: it takes no "
                        f"{' and no '.join(process_only)}")
    if args.hosts is not None and args.port is not None:
        raise UserError(f"--hosts {args.hosts} gives each host's router its port; --port is "
                        f"the router's port of a run on this machine alone")
    for flag, number in (("--port", args.port), ("--foxglove", args.foxglove)):
        busy = port_problem(number) if number is not None else None
        if busy:
            raise UserError(f"{flag} {number}: {busy}")


def _say_failed(out: Path, failure: str, wall_s: float, as_json: bool) -> None:
    """A mission that did not finish: why, then the summary of what its recording holds (how
    far it got, the verdicts), when there is one to read."""
    print(f"fleet run: the mission did not finish: {failure}", file=sys.stderr)
    try:
        recording = read_recording(out)
        report = _report(out, recording)
    except UserError as exc:  # nothing readable was recorded (a run that never started)
        print(f"fleet run: no summary: {exc}", file=sys.stderr)
    else:
        ended = Ending(failure, recorded_standstill(recording))
        if as_json:
            print(json.dumps(summary_json(report, wall_s, "", ended)))
        else:
            print("\n".join(summary_lines(report, wall_s, "", ended)))
    print(f"fleet run: logs and what was recorded are in {out}", file=sys.stderr)


@contextlib.contextmanager
def _stop_requests(stop: threading.Event) -> Iterator[None]:
    """While the in-process mission runs, the first Ctrl-C or SIGTERM asks it to stop before
    its next decision (`stop`), so what it did is recorded whole; a second Ctrl-C interrupts
    at once. A signal this process ignores stays ignored."""
    def ask(*_) -> None:
        stop.set()
        signal.signal(signal.SIGINT, signal.default_int_handler)

    previous = {sig: signal.signal(sig, ask) for sig in (signal.SIGINT, signal.SIGTERM)
                if signal.getsignal(sig) is not signal.SIG_IGN}  # as `nohup` left it
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


def command_line() -> str:
    return " ".join(["fleet", *sys.argv[1:]])


def _report(out: Path, recording: Recording | None = None) -> Report:
    """The analysis of the run's recording (every segment in its directory `out`): its
    numbers and verdicts, kept in the directory for `fleet runs`."""
    from fleet.analysis.analyze import analyze

    recording = recording or read_recording(out)
    report = analyze(recording)
    write_summary(out, report, recorded_standstill(recording))
    return report


def fault_scenario(source: str, layout: Layout, vehicles: int,
                   hosts: Hosts | None = None) -> Scenario:
    """The scenario of --faults (a shipped one in the layout's own version, where it ships
    one), checked against the run before anything starts (a host it cuts among `hosts`)."""
    scenario = load_scenario(source, layout.name)
    check_against(scenario, layout, vehicles)
    cut_links(scenario, hosts)
    return scenario


def _run_inprocess(mission: Mission, layout: Layout, weights: Path | None,
                   progress: MissionProgress, out: Path, scenario: Scenario | None,
                   stop: threading.Event) -> MissionDone:
    """The mission's result; its recording, up to where it ended, in `out`."""
    options = engine_options(mission, layout, weights,
                             lambda done, total, t, failures: progress(done, t, failures))
    progress.status("planning the first subtask")
    done, stream = recorded_run(mission, layout, options, command_line(), scenario, stop)
    write_recording(out / "run.mcap", stream, layout)
    return done


def _run_processes(mission: Mission, n: int, args: argparse.Namespace,
                   progress: MissionProgress, out: Path,
                   scenario: Scenario | None, hosts: Hosts | None) -> MissionDone:
    """The mission's result (not ok: why it failed, the dispatcher's or a dead child's)."""
    def interrupted(*_) -> None:
        raise KeyboardInterrupt  # SIGTERM stops the run like Ctrl-C: every child stopped

    signal.signal(signal.SIGTERM, interrupted)
    port = args.port or free_port()
    router = hosts.first.endpoint if hosts else f"tcp/127.0.0.1:{port}"
    if not (args.quiet or args.json):
        print(f"fleet run: router on {router}; watch the table with\n"
              f"  fleet table --connect {router} --follow", file=sys.stderr)
        if args.foxglove is not None:
            print(f"fleet run: live view for Foxglove on ws://localhost:{args.foxglove}",
                  file=sys.stderr)
    url, own_broker = broker_of(args) if args.dispatch == "vda5050" else ("", False)
    spec = RunSpec(mission, n, out, ClockMode(args.clock), args.speed, args.weights, port,
                   foxglove=args.foxglove, command=command_line(), faults=scenario,
                   faults_source=args.faults or "", secure=args.secure,
                   dispatch=args.dispatch, mqtt=url, own_broker=own_broker, hosts=hosts)
    forklifts = f"{n} forklift agent{'s' if n > 1 else ''}"
    progress.status(f"starting the router, recorder, reservation service, {forklifts} and "
                    "dispatcher")
    outcome = run_processes(spec, lambda p: progress(p.done, p.t, p.failures),
                            lambda *_: progress.status("all started; waiting for the first "
                                                       "subtask"))
    return outcome.done if outcome.done is not None else MissionDone(False, error=outcome.error)
