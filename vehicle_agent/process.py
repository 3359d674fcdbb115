"""`fleet agent` / `python -m vehicle_agent`: start one forklift's agent process."""

from __future__ import annotations

import argparse
import dataclasses
import logging
import socket
from pathlib import Path

import zenoh

from fleet.errors import UserError
from fleet.runtime.access import read_dictionary
from fleet.runtime.argtypes import layout_arg, pose, positive_float
from fleet.runtime.bus import (
    Requester,
    RequestFailed,
    add_bus_arguments,
    bus_config,
    open_session,
    stop_on_signals,
)
from fleet.wire.protocol import ClaimReply, VehicleClaim
from fleet.wire.topics import Keys, vehicle_sender
from fleet.world.layout_file import load_layout
from vehicle_agent.agent import Agent, Stopped

log = logging.getLogger("fleet.agent")


def forklift_id(text: str) -> int | None:
    if text == "auto":
        return None
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is neither a number nor 'auto'") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"forklift ids start at 1, not {value}")
    return value


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_bus_arguments(p)
    p.add_argument("--id", type=forklift_id, required=True,
                   help="forklift id (1, 2, ...), or 'auto': claim one from the dispatcher "
                   "(started with --claims) under this host's name")
    p.add_argument("--claim-as", default=socket.gethostname(),
                   help="--id auto: the name to claim under (default: the host name, which "
                   "a restarted container keeps, so it gets its forklift back)")
    p.add_argument("--claim-timeout", type=positive_float, default=120.0, metavar="SECONDS",
                   help="--id auto: seconds to keep asking for an id (default 120)")
    p.add_argument("--layout", default="paper", type=layout_arg,
                   help="layout name or TOML file (default paper)")
    p.add_argument("--start", type=pose, metavar="POSE",
                   help="start pose 'col,row,H' (default: the layout's start pose for --id)")
    p.add_argument("--logins", type=Path, metavar="FILE",
                   help="the forklifts' logins, a 'user:password' line each (the compose "
                   "deployment's secret): claim an id logged in as any of them, then run as "
                   "vehicle-ID (instead of --user and --password-file; default none)")
    p.add_argument("--id-file", type=Path, metavar="FILE",
                   help="write the forklift's id here once it is known (a container's health "
                   "check reads it; default: nowhere)")
    p.add_argument("--exit-when-done", action="store_true",
                   help="exit once the dispatcher publishes the mission's result")


def serve(args: argparse.Namespace) -> int:
    layout = load_layout(args.layout)
    keys = Keys(args.run)
    config = bus_config(args)
    logins = read_dictionary(args.logins) if args.logins else {}
    vehicle = args.id
    if vehicle is None:  # in a session of its own, logged in as any forklift
        claimant = config
        if logins:
            user, password = next(iter(logins.items()))
            claimant = dataclasses.replace(config, user=user, password=password)
        claiming = open_session(claimant)
        try:
            vehicle = claim(claiming, keys, args.claim_as, args.claim_timeout)
        finally:
            claiming.close()
    if logins:
        user = vehicle_sender(vehicle)
        if user not in logins:
            raise UserError(f"--logins {args.logins} has no login for {user}")
        config = dataclasses.replace(config, user=user, password=logins[user])
    session = open_session(config)
    try:
        start = args.start
        if start is None:
            if not 1 <= vehicle <= len(layout.vehicle_starts):
                raise UserError(f"forklift {vehicle}: layout {layout.name} has start poses for "
                                f"forklifts 1 to {len(layout.vehicle_starts)}; give --start")
            start = layout.vehicle_starts[vehicle - 1]
        if args.id_file is not None:
            args.id_file.parent.mkdir(parents=True, exist_ok=True)
            args.id_file.write_text(f"{vehicle}\n")
        agent = Agent(session, keys, vehicle, layout, start)
        stop_on_signals(agent.stop)
        agent.run(exit_when_done=args.exit_when_done)
    except Stopped:
        pass  # a clean stop: the session is closed below
    finally:
        session.close()
    return 0


def claim(session: zenoh.Session, keys: Keys, name: str, timeout_s: float) -> int:
    """A forklift id from the dispatcher (dispatcher/claims.py), asked for until one
    answers; a refusal is final (the fleet is complete, or the mission has started)."""
    requester = Requester(session, f"claim:{name}", timeout_s=5.0, retry_s=timeout_s)
    try:
        reply = requester.request(keys.dispatch_claim,
                                  VehicleClaim(requester.next_id(), name)).message
    except RequestFailed as exc:
        raise UserError(f"no forklift id for {name}: {exc}") from None
    if not isinstance(reply, ClaimReply):
        raise UserError(f"no forklift id for {name}: the answer was a {reply.TYPE}")
    if not reply.ok:
        raise UserError(f"no forklift id for {name}: {reply.reason}")
    log.info("%s is forklift %d", name, reply.vehicle)
    return reply.vehicle

