"""The service processes, each startable alone: `fleet reservation` (more to come)."""

from __future__ import annotations

import argparse
import logging
import sys


def register(sub: argparse._SubParsersAction) -> None:
    from reservation import service

    p = sub.add_parser("reservation", help="run the reservation service process",
                       description=service.__doc__)
    service.add_arguments(p)
    p.set_defaults(handler=run_reservation)
    t = sub.add_parser("table", help="show the reservation service's table, or follow it",
                       description="Load the table from a running reservation service and "
                       "print who holds how many cells; with --follow, print every change "
                       "as it is published until Ctrl-C.")
    t.add_argument("--run", default="default", help="run name: keys live under fleet/RUN/")
    t.add_argument("--mode", choices=["client", "peer"], default="client")
    t.add_argument("--connect", action="append", default=[],
                   help="zenoh endpoint to connect to (default tcp/127.0.0.1:7447)")
    t.add_argument("--follow", action="store_true", help="keep printing changes")
    t.set_defaults(handler=run_table)


def run_reservation(args: argparse.Namespace) -> int:
    from reservation import service

    logging.basicConfig(level=logging.INFO, format="%(name)s: %(message)s", stream=sys.stderr)
    return service.serve(args)


def run_table(args: argparse.Namespace) -> int:
    from fleet.bus import BusConfig, Keys, Requester, open_session
    from reservation.mirror import TableMirror, follow

    keys = Keys(args.run)
    session = open_session(BusConfig(args.mode, tuple(args.connect) or BusConfig().connect))
    try:
        mirror = TableMirror()
        subscriber = follow(session, keys, mirror, Requester(session, "fleet-table"))
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
