"""`fleet run --dispatch external`: the fleet with no mission, for a VDA 5050 master. The
vehicles (forklifts, or a lane layout's AGVs) park at their start poses and take the orders a
master sends over MQTT through the gateway (docs/vda5050.md), on the real-time clock, until
Ctrl-C; everything is recorded as in any run."""

from __future__ import annotations

import argparse
import json
import signal
import sys
from pathlib import Path

from fleet.commands.runs import write_summary
from fleet.errors import UserError
from fleet.mission.spec import ClockMode
from fleet.recording.reader import read_recording
from fleet.recording.rundir import choose
from fleet.runtime.args import fleet_of, mission_from_args
from fleet.runtime.bus import free_port
from fleet.runtime.hosts import hosts_for
from fleet.runtime.local_run import RunSpec, run_processes
from fleet.runtime.mqtt_broker import mosquitto_binary
from fleet.runtime.process_configs import GatewayConfig
from fleet.vda5050.messages import serial_number
from fleet.world.layout import Layout


def check_vda5050_run(args: argparse.Namespace, layout: Layout) -> None:
    """What a run through the VDA 5050 gateway (--dispatch external or vda5050) refuses."""
    refused = [flag for flag, given in (
        ("--inprocess", args.inprocess), ("--faults", args.faults is not None),
        ("--clock fast", args.clock == ClockMode.FAST.value)) if given]
    if refused:
        raise UserError(f"--dispatch {args.dispatch} takes no {' and no '.join(refused)} (it "
                        "runs on the real-time clock; the rest is not built yet: "
                        "docs/vda5050.md)")
    if layout.floor is not None:
        raise UserError(f"--dispatch {args.dispatch}: layout {layout.name} is a seed-004 "
                        "floor; its lifting AGVs do not speak VDA 5050 yet (docs/vda5050.md)")
    if args.dispatch == "vda5050" and layout.has_lanes:
        raise UserError(f"--dispatch vda5050 runs our fill and empty missions through the "
                        f"gateway; layout {layout.name} is a lane layout, whose order missions "
                        "do not go through it yet: its AGVs take a master's orders with "
                        "--dispatch external (docs/vda5050.md)")
    if args.dispatch == "external" and layout.has_lanes and args.mission not in (None, "orders"):
        raise UserError(f"--dispatch external --mission {args.mission}: the AGVs of lane layout "
                        f"{layout.name} park on their piles as an order mission starts them, "
                        "and take a master's orders; give no --mission")


def broker_of(args: argparse.Namespace) -> tuple[str, bool]:
    """The run's MQTT broker (--mqtt, or a mosquitto of its own on a free port) and whether
    the run starts it; a mosquitto that is not installed is said before anything starts."""
    if args.mqtt is not None:
        return args.mqtt, False
    mosquitto_binary()
    return f"mqtt://127.0.0.1:{free_port()}", True


def run_external(args: argparse.Namespace, layout: Layout, command: str) -> int:
    check_vda5050_run(args, layout)
    mission = mission_from_args(args, layout)
    n = fleet_of(layout, mission.vehicles)
    say = (lambda line: None) if args.quiet or args.json else \
        (lambda line: print(f"fleet run: {line}", file=sys.stderr, flush=True))
    out = choose(args.out, args.force, layout.name, "external", say).path

    def interrupted(*_) -> None:
        raise KeyboardInterrupt  # SIGTERM ends the session like Ctrl-C

    signal.signal(signal.SIGTERM, interrupted)
    url, own_broker = broker_of(args)
    spec = RunSpec(mission, n, out, ClockMode.REALTIME, args.speed,
                   port=args.port or free_port(), command=command, foxglove=args.foxglove,
                   dispatch="external", mqtt=url, own_broker=own_broker, secure=args.secure,
                   hosts=hosts_for(args.hosts, n, args.secure))
    g, kind = GatewayConfig, layout.vehicle_kind
    say(f"{n} {kind.noun}s as VDA 5050 2.0.0 AGVs on {url}, topics "
        f"{g.interface}/v2/{g.manufacturer}/{serial_number(kind.name, 1)} .. "
        f"{serial_number(kind.name, n)}; their map: fleet vda5050 map {layout.name}; Ctrl-C "
        "ends the session")
    try:
        outcome = run_processes(spec, on_ready=lambda *_: say(
            "started the router, recorder, reservation service, agents, clock and gateway"))
    except KeyboardInterrupt:
        return _session_summary(out, args.json)
    # only a process that died ends a session by itself
    print(f"fleet run: the session ended: {outcome.error}; logs in {out}", file=sys.stderr)
    return 1


def _session_summary(out: Path, as_json: bool) -> int:
    """What the session's recording says (safety, the VDA 5050 verdict, messages), kept for
    `fleet runs`; exit 1 if a verdict failed."""
    from fleet.analysis.analyze import analyze

    report = analyze(read_recording(out))
    write_summary(out, report)
    if as_json:
        print(json.dumps({"dispatch": "external", "out": str(out), **report.to_json()}))
    else:
        print("\n".join([f"session on {report.mission['layout']} with "
                         f"{report.mission['vehicles']} vehicles, ended at "
                         f"{report.recovered_sim_s:.1f} s of sim time; recording and logs in "
                         f"{out}", *report.verdict_lines()]))
    return 0 if report.passed else 1
