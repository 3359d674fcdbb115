"""`fleet agent` / `python -m vehicle_agent`: start one forklift's agent process."""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Sequence
from contextlib import suppress

import zenoh

from fleet.errors import UserError
from fleet.mission.battery import battery_of
from fleet.mission.record004 import tracking_params
from fleet.runtime.access import read_dictionary
from fleet.runtime.bus import Requester, RequestFailed, open_session
from fleet.runtime.lifecycle import Stopped, process_main, stop_on_signals
from fleet.runtime.mission_info import mission_layout
from fleet.runtime.process_configs import AgentConfig
from fleet.wire.protocol import ClaimReply, VehicleClaim
from fleet.wire.topics import Keys, vehicle_sender
from fleet.world.layout_file import load_layout
from vehicle_agent.agent import Agent
from vehicle_agent.lifting import LiftingAgent

log = logging.getLogger("fleet.agent")


def main(argv: Sequence[str] | None = None) -> int:
    return process_main(AgentConfig, serve, "python -m vehicle_agent", argv)


def serve(config: AgentConfig) -> int:
    given = load_layout(config.layout) if config.layout is not None else None  # at once
    keys = Keys(config.bus.run)
    bus = config.bus.config()
    logins = read_dictionary(config.logins) if config.logins else {}
    vehicle = config.vehicle
    if vehicle is None:  # in a session of its own, logged in as any forklift
        claimant = bus
        if logins:
            user, password = next(iter(logins.items()))
            claimant = dataclasses.replace(bus, user=user, password=password)
        with open_session(claimant) as claiming:
            vehicle = claim(claiming, keys, config.claim_as, config.claim_timeout_s)
    if logins:
        user = vehicle_sender(vehicle)
        if user not in logins:
            raise UserError(f"--logins {config.logins} has no login for {user}")
        bus = dataclasses.replace(bus, user=user, password=logins[user])
    with open_session(bus) as session:
        battery = None
        if given is not None and given.floor is None:
            layout, starts, whose = given, given.vehicle_starts, f"layout {given.name}"
        else:  # a seed-004 agent plans with the mission's costs: it asks for them too
            info, layout, starts = mission_layout(session, keys)
            whose = "the mission"
            if layout.floor is None:
                battery = battery_of(info, vehicle, layout)
        if layout.floor is not None:  # seed 004: the tracker places it (dispatcher/remote004)
            lifting = LiftingAgent(session, keys, vehicle, layout.floor, tracking_params(info))
            stop_on_signals(lifting.stop)
            with suppress(Stopped):
                lifting.run(exit_when_done=config.exit_when_done)
            return 0
        start = config.start
        if start is None:
            if not 1 <= vehicle <= len(starts):
                raise UserError(f"forklift {vehicle}: {whose} has start poses for forklifts 1 "
                                f"to {len(starts)}; give --start")
            start = starts[vehicle - 1]
        if config.id_file is not None:
            config.id_file.parent.mkdir(parents=True, exist_ok=True)
            config.id_file.write_text(f"{vehicle}\n")
        agent = Agent(session, keys, vehicle, layout, start, battery)
        stop_on_signals(agent.stop)
        with suppress(Stopped):  # a clean stop: the session is closed on the way out
            agent.run(exit_when_done=config.exit_when_done)
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

