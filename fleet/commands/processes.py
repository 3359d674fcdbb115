"""The service processes, each startable alone (`fleet run` starts them all; the compose
deployment starts one per container): `fleet router`, `fleet reservation`, `fleet agent`,
`fleet dispatcher`, `fleet recorder`; and `fleet table` to look at the reservation service."""

from __future__ import annotations

import argparse
import sys

from fleet.commands.helptext import strategies_epilog
from fleet.errors import UserError

# What each process is for, as its user reads it (its module's docstring is its design).
PROCESSES = {
    "router": ("run a zenoh router for the other processes",
               "Run a zenoh router (in Python: there is no zenohd to install). Every other "
               "process of a run connects to it as a client. `fleet run` starts one on a "
               "free loopback port; the compose deployment runs it as its router service."),
    "reservation": ("run the reservation service process",
                    "Run the reservation service: the run's authoritative space-time "
                    "reservation table. Forklifts commit the cells their plans need through "
                    "it; it journals every change (and replays the journal when it starts "
                    "again) and publishes each one."),
    "agent": ("run one forklift's agent process",
              "Run one forklift: it plans every subtask the dispatcher hands it with the "
              "improved hybrid A* against its copy of the reservation table, commits the "
              "plan through the reservation service, drives it and publishes its state. "
              "Give it its id, or `--id auto` to claim one from a dispatcher started with "
              "--claims."),
    "dispatcher": ("run the dispatcher process",
                   "Run the dispatcher: it waits for the reservation service and the "
                   "forklifts, then runs the mission, picking each forklift's next goal by "
                   "the strategy and handing it over, and publishes the progress and, at the "
                   "end, the mission's record."),
    "recorder": ("record a run to an MCAP file",
                 "Record everything a run publishes (its keys under fleet/RUN/) to an MCAP "
                 "file that fleet analyze, fleet plot and Foxglove read; with --foxglove, "
                 "also serve a live view of the run. Start it before the mission's other "
                 "processes, so it hears everything."),
}
TABLE_CONNECT_TIMEOUT_S = 5.0
SERVICE_WAIT_S = 3.0  # for the reservation service's token, once connected


def register(sub: argparse._SubParsersAction) -> None:
    from dispatcher import process as dispatcher_process
    from fleet.runtime import router
    from fleet.runtime.bus import add_bus_arguments
    from recorder import process as recorder_process
    from reservation import service
    from vehicle_agent import process as agent_process

    for name, module in (("router", router), ("reservation", service),
                         ("agent", agent_process), ("dispatcher", dispatcher_process),
                         ("recorder", recorder_process)):
        summary, description = PROCESSES[name]
        p = sub.add_parser(name, help=summary, description=description,
                           epilog=strategies_epilog() if name == "dispatcher" else None)
        module.add_arguments(p)
        p.set_defaults(handler=_serve(module))
    t = sub.add_parser("table", help="show the reservation service's table, or follow it",
                       description="Load the table from a running reservation service and "
                       "print who holds how many cells; with --follow, print every change "
                       "as it is published until Ctrl-C. Fails within --connect-timeout "
                       "when no router answers, and names the runs there when none of them "
                       "is --run.")
    add_bus_arguments(t, connect_timeout_s=TABLE_CONNECT_TIMEOUT_S)
    t.add_argument("--follow", action="store_true", help="keep printing changes")
    t.set_defaults(handler=run_table)


def _serve(module):
    def handler(args: argparse.Namespace) -> int:
        from fleet.runtime.bus import setup_logging

        setup_logging()
        return module.serve(args)

    return handler


def run_table(args: argparse.Namespace) -> int:
    from fleet.runtime.bus import Requester, bus_config, open_session, wait_alive
    from fleet.wire.topics import Keys
    from reservation.client import ReservationClient
    from reservation.mirror import TableMirror

    keys = Keys(args.run)
    config = bus_config(args)
    session = open_session(config, say=lambda line: print(f"fleet table: {line}",
                                                          file=sys.stderr))
    try:
        if not wait_alive(session, keys.reservation_alive, SERVICE_WAIT_S):
            raise UserError(no_service(session, args.run, config.connect))
        mirror = TableMirror()
        subscriber = ReservationClient(
            session, keys, Requester(session, "fleet-table", retry_s=SERVICE_WAIT_S)
        ).follow(mirror)
        held: dict[int, int] = {}
        for r in mirror.table.reservations():
            held[r.vehicle] = held.get(r.vehicle, 0) + 1
        print(f"{keys.root}: revision {mirror.revision}, {sum(held.values())} reserved "
              f"intervals")
        for vehicle, n in sorted(held.items()):
            print(f"  vehicle {vehicle}: {n}")
        seen = mirror.revision
        while args.follow:  # until Ctrl-C
            mirror.wait_for(seen + 1, timeout=3600)
            for change in mirror.table.diff(seen):
                what = (f"{len(change.intervals)} intervals" if change.intervals
                        else f"released from t={change.release_from}")
                print(f"revision {change.revision}: vehicle {change.vehicle} {what}",
                      flush=True)
            seen = mirror.revision
        subscriber.undeclare()
    finally:
        session.close()
    return 0


def no_service(session, run: str, endpoints: tuple[str, ...]) -> str:
    """Why `fleet table` has nothing to show: no service for that run, and which runs have
    one on this bus (a mistyped --run is the usual cause)."""
    from fleet.wire.topics import Keys

    replies = session.liveliness().get(Keys("*").reservation_alive, timeout=1.0)
    runs = sorted({str(r.ok.key_expr).split("/")[1] for r in replies if r.ok is not None})
    where = f" at {', '.join(endpoints)}" if endpoints else ""
    others = f"runs with one there: {', '.join(runs)}" if runs else "no run has one there"
    return f"no reservation service answers for run {run!r}{where} ({others})"
