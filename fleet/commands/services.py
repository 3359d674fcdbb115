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


def run_reservation(args: argparse.Namespace) -> int:
    from reservation import service

    logging.basicConfig(level=logging.INFO, format="%(name)s: %(message)s", stream=sys.stderr)
    return service.serve(args)
