"""`fleet router`: a zenoh router in a Python process (there is no zenohd to install). The
other processes connect to it as clients; `fleet run` starts one on a loopback port, the
compose deployment runs it as the `router` service."""

from __future__ import annotations

import argparse
import logging
import threading

from fleet.bus import BusConfig, open_session, stop_on_signals

log = logging.getLogger("fleet.router")
DEFAULT_LISTEN = "tcp/0.0.0.0:7447"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--listen", action="append", default=[],
                   help=f"endpoint to listen on (default {DEFAULT_LISTEN}; repeatable)")
    p.add_argument("--connect", action="append", default=[],
                   help="another router to connect to (repeatable)")


def serve(args: argparse.Namespace) -> int:
    listen = tuple(args.listen) or (DEFAULT_LISTEN,)
    stop = threading.Event()
    stop_on_signals(stop.set)
    session = open_session(BusConfig("router", tuple(args.connect), listen))
    try:
        log.info("routing on %s", ", ".join(listen))
        stop.wait()
    finally:
        session.close()
    return 0

