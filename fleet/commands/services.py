"""The service processes, each startable alone (`fleet run` starts them all; the compose
deployment starts one per container): `fleet router`, `fleet reservation`, `fleet agent`,
`fleet dispatcher`, `fleet recorder`; and `fleet table` to look at the reservation service."""

from __future__ import annotations

import argparse


def register(sub: argparse._SubParsersAction) -> None:
    from dispatcher import process as dispatcher_process
    from fleet import router
    from fleet.bus import add_bus_arguments
    from recorder import process as recorder_process
    from reservation import service
    from vehicle_agent import process as agent_process

    for name, module, summary in (
            ("router", router, "run a zenoh router for the other processes"),
            ("reservation", service, "run the reservation service process"),
            ("agent", agent_process, "run one forklift's agent process"),
            ("dispatcher", dispatcher_process, "run the dispatcher process"),
            ("recorder", recorder_process, "record a run to an MCAP file")):
        p = sub.add_parser(name, help=summary, description=module.__doc__,
                           formatter_class=argparse.RawDescriptionHelpFormatter)
        module.add_arguments(p)
        p.set_defaults(handler=_serve(module))
    t = sub.add_parser("table", help="show the reservation service's table, or follow it",
                       description="Load the table from a running reservation service and "
                       "print who holds how many cells; with --follow, print every change "
                       "as it is published until Ctrl-C.")
    add_bus_arguments(t)
    t.add_argument("--follow", action="store_true", help="keep printing changes")
    t.set_defaults(handler=run_table)


def _serve(module):
    def handler(args: argparse.Namespace) -> int:
        from fleet.bus import setup_logging

        setup_logging()
        return module.serve(args)

    return handler


def run_table(args: argparse.Namespace) -> int:
    from fleet.bus import Keys, Requester, bus_config, open_session
    from reservation.mirror import TableMirror, follow

    keys = Keys(args.run)
    session = open_session(bus_config(args))
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
