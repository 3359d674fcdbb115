"""`fleet router`: a zenoh router in a Python process (there is no zenohd to install). The
other processes connect to it as clients; `fleet run` starts one on a loopback port, the
compose deployment runs it as the `router` service."""

from __future__ import annotations

import argparse
import json
import logging
import threading
from pathlib import Path

import zenoh

from fleet.bus import BusConfig, open_session, stop_on_signals
from fleet.errors import UserError

log = logging.getLogger("fleet.router")
DEFAULT_LISTEN = "tcp/0.0.0.0:7447"
LAST_OUT_S = 5.0  # how long a stopping router waits for its clients to leave


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--listen", action="append", default=[],
                   help=f"endpoint to listen on (default {DEFAULT_LISTEN}; repeatable)")
    p.add_argument("--connect", action="append", default=[],
                   help="another router to connect to (repeatable)")
    p.add_argument("--acl", type=Path, help="enforce this access control (a JSON file: the "
                   "access_control section fleet/access.py writes); needs --users")
    p.add_argument("--users", type=Path, help="authenticate every session against this "
                   "user:password dictionary")


class Clients:
    """The sessions connected to this router, followed by zenoh's transport events."""

    def __init__(self, session: zenoh.Session) -> None:
        self.connected: set[str] = set()
        self.lock = threading.Lock()
        self.none = threading.Event()
        self.none.set()
        self.listener = session.info.declare_transport_events_listener(self._on_event,
                                                                      history=True)

    def _on_event(self, event) -> None:
        with self.lock:
            zid = str(event.transport.zid)
            if event.kind == zenoh.SampleKind.PUT:
                self.connected.add(zid)
            else:
                self.connected.discard(zid)
            if self.connected:
                self.none.clear()
            else:
                self.none.set()


def serve(args: argparse.Namespace) -> int:
    listen = tuple(args.listen) or (DEFAULT_LISTEN,)
    stop = threading.Event()
    stop_on_signals(stop.set)
    acl = None
    if args.acl is not None or args.users is not None:
        if args.acl is None or args.users is None:
            raise UserError("--acl and --users go together: access control names the users "
                            "the dictionary authenticates")
        try:
            acl = json.loads(args.acl.read_text())
        except (OSError, ValueError) as exc:
            raise UserError(f"--acl {args.acl}: {exc}") from None
    session = open_session(BusConfig("router", tuple(args.connect), listen, acl=acl,
                                     users_file=str(args.users or "")))
    try:
        clients = Clients(session)
        log.info("routing on %s", ", ".join(listen))
        stop.wait()
        # Told to stop, the router goes last: a process closing its session after its router
        # is gone can hang, and when `fleet run` dies every child stops at once.
        if not clients.none.wait(LAST_OUT_S):
            log.warning("stopping with %d sessions still connected", len(clients.connected))
        clients.listener.undeclare()
    finally:
        session.close()
    return 0

