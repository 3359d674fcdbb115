"""The service processes, each startable alone (`fleet run` starts them all; the compose
deployment starts one per container): `fleet router`, `fleet reservation`, `fleet agent`,
`fleet dispatcher`, `fleet recorder`; and `fleet table` to look at the reservation service."""

from __future__ import annotations

import argparse
import functools
import importlib
import sys
from collections.abc import Callable, Sequence

from fleet.errors import UserError
from fleet.runtime.args import BusFlags, add_bus_arguments
from fleet.runtime.lifecycle import process_main, setup_logging, watch_parent
from fleet.runtime.process_configs import (
    KINDS,
    AgentConfig,
    DispatcherConfig,
    GatewayConfig,
    ProcessConfig,
    RecorderConfig,
    ReservationConfig,
    RouterConfig,
)

TABLE_CONNECT_TIMEOUT_S = 5.0
SERVICE_WAIT_S = 3.0  # for the reservation service's token, once connected


def register(sub: argparse._SubParsersAction) -> None:
    for kind in KINDS:
        p = sub.add_parser(kind.COMMAND, help=kind.SUMMARY, description=kind.DESCRIPTION,
                           epilog=kind.EPILOG)
        kind.add_arguments(p)
        p.set_defaults(handler=lambda args, kind=kind: serve(kind.from_args(args)))
    t = sub.add_parser("table", help="show the reservation service's table, or follow it",
                       description="Load the table from a running reservation service and "
                       "print who holds how many cells; with --follow, print every change "
                       "as it is published until Ctrl-C. Fails within --connect-timeout "
                       "when no router answers, and names the runs there when none of them "
                       "is --run.")
    add_bus_arguments(t, connect_timeout_s=TABLE_CONNECT_TIMEOUT_S)
    t.add_argument("--follow", action="store_true", help="keep printing changes")
    t.set_defaults(handler=run_table)


# Where each process's `serve` is: only the one that runs is imported (each imports what
# it needs, a dispatcher torch, a recorder mcap), so a process starts quickly.
SERVERS: dict[type[ProcessConfig], str] = {
    RouterConfig: "fleet.runtime.router", ReservationConfig: "reservation.service",
    AgentConfig: "vehicle_agent.process", DispatcherConfig: "dispatcher.process",
    RecorderConfig: "recorder.process", GatewayConfig: "vda5050.gateway"}


# The words of `fleet` that start each process (the gateway is an action of `fleet vda5050`).
ALONE: dict[tuple[str, ...], type[ProcessConfig]] = {
    **{(kind.COMMAND,): kind for kind in KINDS}, ("vda5050", "gateway"): GatewayConfig}


def alone(argv: Sequence[str]) -> Callable[[], int] | None:
    """`fleet KIND ...` as fleet run and compose start each process of a run, parsed by the
    kind's own parser (the same flags, help and errors as through `fleet`'s) without
    importing any other command: their imports doubled a process's start-up, 1.1 s of CPU
    against 0.55 s, with eight processes starting on two cores (docs/benchmarks.md). None:
    another command."""
    for words, kind in ALONE.items():
        if tuple(argv[:len(words)]) == words:
            prog = " ".join(["fleet", *words])
            return functools.partial(process_main, kind, served, prog, list(argv[len(words):]))
    return None


def serve(config: ProcessConfig) -> int:
    """Run one process of a run as this one, parsed by the CLI's parser (`fleet service
    dispatcher`; `fleet dispatcher` itself goes by `alone`): the same `serve` its package's
    `python -m` runs."""
    setup_logging()
    watch_parent()
    return served(config)


def served(config: ProcessConfig) -> int:
    """The process's own `serve`, its module imported only now."""
    return importlib.import_module(SERVERS[type(config)]).serve(config)


def run_table(args: argparse.Namespace) -> int:
    from fleet.runtime.bus import Requester, open_session, wait_alive
    from fleet.wire.topics import Keys
    from reservation.client import ReservationClient
    from reservation.mirror import TableMirror

    keys = Keys(args.run)
    config = BusFlags.from_args(args).config()
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
