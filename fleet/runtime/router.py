"""`fleet router`: a zenoh router in a Python process (there is no zenohd to install). The
other processes connect to it as clients; `fleet run` starts one on a loopback port (one
per host with --hosts, linked to the first host's), the compose deployment runs it as the
`router` service."""

from __future__ import annotations

import json
import logging
import threading
import time

import zenoh

from fleet.errors import UserError
from fleet.runtime.args import read_login
from fleet.runtime.bus import BusConfig, open_session
from fleet.runtime.lifecycle import stop_on_signals
from fleet.runtime.process_configs import RouterConfig

log = logging.getLogger("fleet.runtime.router")
LAST_OUT_S = 5.0  # how long a stopping router waits for its clients to leave


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


def serve(config: RouterConfig) -> int:
    # zenoh's own errors, to this router's log: a link refused in its TLS or login handshake
    # (a certificate of another run, a clock far off, a wrong address) shows nowhere else.
    zenoh.init_log_from_env_or("error")
    stop = threading.Event()
    stop_on_signals(stop.set)
    acl = None
    if config.acl is not None or config.users is not None:
        if config.acl is None or config.users is None:
            raise UserError("--acl and --users go together: access control names the users "
                            "the dictionary authenticates")
        try:
            acl = json.loads(config.acl.read_text())
        except (OSError, ValueError) as exc:
            raise UserError(f"--acl {config.acl}: {exc}") from None
    user, password = read_login(config.user, config.password_file)
    with open_session(BusConfig("router", config.connect, config.endpoints, acl=acl,
                                users_file=str(config.users or ""), tls=config.tls,
                                user=user, password=password)) as session:
        clients = Clients(session)
        token = session.liveliness().declare_token(config.announce) if config.announce \
            else None
        with clients.listener:
            log.info("routing on %s", ", ".join(config.endpoints))
            if config.exit_when_idle_s is not None:
                clients.wait_idle(config.exit_when_idle_s, stop)
            stop.wait()
            # Told to stop, the router goes last: a process closing its session after its
            # router is gone can hang, and when `fleet run` dies every child stops at once.
            if not clients.none.wait(LAST_OUT_S):
                log.warning("stopping with %d sessions still connected",
                            len(clients.connected))
        if token is not None:
            token.undeclare()
    return 0
