"""`fleet router`: a zenoh router in a Python process (there is no zenohd to install). The
other processes connect to it as clients; `fleet run` starts one on a loopback port, the
compose deployment runs it as the `router` service."""

from __future__ import annotations

import argparse
import json
import logging
import threading
import time
from pathlib import Path

import zenoh

from fleet.errors import UserError
from fleet.runtime.argtypes import endpoint, positive_float
from fleet.runtime.bus import BusConfig, open_session, stop_on_signals

log = logging.getLogger("fleet.runtime.router")
DEFAULT_LISTEN = "tcp/0.0.0.0:7447"
LAST_OUT_S = 5.0  # how long a stopping router waits for its clients to leave


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--listen", action="append", default=[], type=endpoint, metavar="ENDPOINT",
                   help=f"endpoint to listen on (default {DEFAULT_LISTEN}; repeatable)")
    p.add_argument("--connect", action="append", default=[], type=endpoint, metavar="ENDPOINT",
                   help="another router to connect to (default none; repeatable)")
    p.add_argument("--acl", type=Path, metavar="FILE",
                   help="enforce this access control (a JSON file: the access_control "
                   "section fleet/runtime/access.py writes); needs --users (default: none, "
                   "everyone "
                   "may do everything)")
    p.add_argument("--users", type=Path, metavar="FILE",
                   help="authenticate every session against this user:password dictionary "
                   "(default: no logins)")
    p.add_argument("--exit-when-idle", type=positive_float, metavar="SECONDS",
                   help="exit once sessions have come and every one has gone for this long "
                   "(a deployment whose processes exit when the mission ends; default: run "
                   "until stopped)")


class Clients:
    """The sessions connected to this router, followed by zenoh's transport events."""

    def __init__(self, session: zenoh.Session) -> None:
        self.connected: set[str] = set()
        self.lock = threading.Lock()
        self.none = threading.Event()
        self.none.set()
        self.changed = threading.Condition(self.lock)
        self.came = False  # some session has connected
        self.idle_since = time.monotonic()
        self.listener = session.info.declare_transport_events_listener(self._on_event,
                                                                      history=True)

    def wait_idle(self, quiet_s: float, stop: threading.Event) -> None:
        """Set `stop` once sessions came and none has been connected for `quiet_s`; return
        then, or when `stop` is set otherwise."""
        with self.changed:
            while not stop.is_set():
                left = self.idle_since + quiet_s - time.monotonic() \
                    if self.came and not self.connected else quiet_s
                if left <= 0:
                    log.info("no session for %g s: stopping", quiet_s)
                    stop.set()
                    return
                self.changed.wait(min(left, 0.5))  # events notify; the cap re-checks stop

    def _on_event(self, event) -> None:
        with self.lock:
            zid = str(event.transport.zid)
            if event.kind == zenoh.SampleKind.PUT:
                self.connected.add(zid)
                self.came = True
            else:
                self.connected.discard(zid)
            if self.connected:
                self.none.clear()
            elif not self.none.is_set():
                self.none.set()
                self.idle_since = time.monotonic()
            self.changed.notify_all()


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
        if args.exit_when_idle is not None:
            clients.wait_idle(args.exit_when_idle, stop)
        stop.wait()
        # Told to stop, the router goes last: a process closing its session after its router
        # is gone can hang, and when `fleet run` dies every child stops at once.
        if not clients.none.wait(LAST_OUT_S):
            log.warning("stopping with %d sessions still connected", len(clients.connected))
        clients.listener.undeclare()
    finally:
        session.close()
    return 0

