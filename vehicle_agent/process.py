"""`fleet agent` / `python -m vehicle_agent`: start one forklift's agent process."""

from __future__ import annotations

import argparse

from fleet.bus import (
    Keys,
    add_bus_arguments,
    bus_config,
    open_session,
    stop_on_signals,
)
from fleet.errors import UserError
from fleet.layout import load_layout
from fleet.trajectory import Pose
from vehicle_agent.agent import Agent, Stopped


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_bus_arguments(p)
    p.add_argument("--id", type=int, required=True, help="forklift id (1, 2, ...)")
    p.add_argument("--layout", default="paper", help="layout name or TOML file (default paper)")
    p.add_argument("--start", type=Pose.parse,
                   help="start pose 'col,row,H' (default: the layout's start pose for --id)")


def serve(args: argparse.Namespace) -> int:
    layout = load_layout(args.layout)
    start = args.start
    if start is None:
        if not 1 <= args.id <= len(layout.vehicle_starts):
            raise UserError(f"--id {args.id}: layout {layout.name} has start poses for "
                            f"forklifts 1 to {len(layout.vehicle_starts)}; give --start")
        start = layout.vehicle_starts[args.id - 1]
    session = open_session(bus_config(args))
    try:
        agent = Agent(session, Keys(args.run), args.id, layout, start)
        stop_on_signals(agent.stop)
        agent.run()
    except Stopped:
        pass  # a clean stop: the session is closed below
    finally:
        session.close()
    return 0

