"""Zenoh plumbing shared by every process: session configuration, numbered publishers and a
request helper (the keys they use are fleet.wire.topics). Processes are clients of one router
(`fleet run` starts it; in compose it is the `router` service); tests may connect peers
directly."""

from __future__ import annotations

import itertools
import json
import logging
import re
import socket
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

import zenoh

from fleet.errors import UserError
from fleet.runtime.access import TlsFiles, configure_client, configure_router, configure_tls
from fleet.wire.protocol import Envelope, Message, ProtocolError, RecorderStatus, decode, encode
from fleet.wire.topics import Keys

DEFAULT_ROUTER = "tcp/127.0.0.1:7447"
# Congestion control for streams that must not lose a message (table changes, the clock, the
# mission result): the publisher waits rather than drop. Their receivers only enqueue, so
# they drain. State streams keep zenoh's default (drop), so a stalled reader stalls no one.
RELIABLE = zenoh.CongestionControl.BLOCK
log = logging.getLogger("fleet.runtime.bus")


LEASE_MS = 1000  # a lost peer is noticed after this (measured: docs/reliability.md)
CONNECT_RETRY = {"period_init_ms": 100, "period_max_ms": 500, "period_increase_factor": 1.5}


@dataclass(frozen=True)
class BusConfig:
    mode: str = "client"  # "client", "peer" or "router"
    connect: tuple[str, ...] = (DEFAULT_ROUTER,)
    listen: tuple[str, ...] = ()
    lease_ms: int = LEASE_MS
    connect_timeout_ms: int = -1  # -1: wait for the router however long it takes to start
    user: str = ""  # log in to the router as this principal (fleet/runtime/access.py)
    password: str = ""
    acl: dict | None = None  # a router: enforce this access control ...
    users_file: str = ""  # ... and authenticate sessions against this dictionary
    tls: TlsFiles | None = None  # its tls/ links: certificates both ways (routers' links)

    def zenoh_config(self) -> zenoh.Config:
        config = zenoh.Config()
        config.insert_json5("mode", json.dumps(self.mode))
        config.insert_json5("scouting/multicast/enabled", "false")  # loopback and named hosts
        config.insert_json5("connect/endpoints", json.dumps(list(self.connect)))
        config.insert_json5("listen/endpoints", json.dumps(list(self.listen)))
        config.insert_json5("connect/timeout_ms", str(self.connect_timeout_ms))
        # A process started with its router, or cut off from it, tries again soon after the
        # router listens (zenoh's default waits 1 s, then 2 s, ... between attempts).
        config.insert_json5("connect/retry", json.dumps(CONNECT_RETRY))
        config.insert_json5("transport/link/tx/lease", str(self.lease_ms))
        if self.user:
            configure_client(config, self.user, self.password)
        if self.acl is not None:
            configure_router(config, self.acl, self.users_file)
        if self.tls is not None:
            configure_tls(config, self.tls)
        return config


class BusError(UserError, zenoh.ZError):
    """A session that could not be opened: no router at the endpoints, a busy listen port, a
    refused login. The message names the endpoint; still a zenoh.ZError to whoever catches
    those."""


SLOW_CONNECT_S = 1.0  # a connect that takes longer says what it waits for


def zenoh_message(exc: BaseException) -> str:
    """A zenoh error's text without the Rust source locations it carries."""
    text = re.sub(r" at /\S+?\.rs:\d+\.?", "", str(exc))
    return " ".join(text.split())


def open_session(config: BusConfig, say: Callable[[str], None] | None = None) -> zenoh.Session:
    """A zenoh session. A client waits for its router up to `connect_timeout_ms`, says
    through `say` (default: the log) what it is waiting for once that takes a while, and
    fails with a BusError naming the endpoints."""
    endpoints = ", ".join(config.connect) or "no endpoint"
    waiting = f"waiting for a zenoh router at {endpoints}" + (
        f" (up to {config.connect_timeout_ms / 1000:g} s)" if config.connect_timeout_ms >= 0
        else "")
    note = threading.Timer(SLOW_CONNECT_S, say or log.warning, (waiting,))
    note.daemon = True
    if config.mode != "router" and config.connect:
        note.start()
    try:
        return zenoh.open(config.zenoh_config())
    except zenoh.ZError as exc:
        raise BusError(_open_failure(config, zenoh_message(exc))) from None
    finally:
        note.cancel()


def _open_failure(config: BusConfig, text: str) -> str:
    if "Unable to connect" in text or "Timeout" in text:
        waited = f"{config.connect_timeout_ms / 1000:g} s"
        if config.user:
            return (f"no zenoh router at {', '.join(config.connect)} let {config.user} in "
                    f"within {waited} (none is there, or it refused the login)")
        return f"no zenoh router answers at {', '.join(config.connect)} (waited {waited})"
    if "Address already in use" in text:
        where = re.search(r"bound to (\S+?):? ", text)
        return (f"cannot listen on {where[1] if where else ', '.join(config.listen)}: the "
                f"address is in use (another process listens there)")
    return f"zenoh: {text}"


class Stream:
    """A publisher with its own sequence numbers (1, 2, ...), so whoever records the key can
    count the messages it missed."""

    def __init__(self, session: zenoh.Session, key: str, sender: str,
                 reliable: bool = False, keep: bool = False) -> None:
        options = {"congestion_control": RELIABLE} if reliable else {}
        self.publisher = session.declare_publisher(key, **options)
        self.sender = sender
        self.seq = itertools.count(1)  # next() is atomic: threads may share a stream
        # keep: every message put, as sent (message n at n - 1), for whoever missed some
        self.kept: list[bytes] | None = [] if keep else None
        self.lock = threading.Lock()  # numbers and keeps in one order

    def put(self, message: Message, sim_time: float) -> None:
        self.publisher.put(self.number(message, sim_time))

    def number(self, message: Message, sim_time: float) -> bytes:
        """The message numbered (and kept) as sent; alone, not sent: what a restarted
        sender's predecessor sent already, so that what it sends next goes on from its
        numbers."""
        if self.kept is None:
            return encode(message, self.sender, next(self.seq), sim_time)
        with self.lock:
            payload = encode(message, self.sender, next(self.seq), sim_time)
            self.kept.append(payload)
        return payload

    def since(self, after: int) -> list[bytes]:
        """The messages kept that are numbered after `after`, in order."""
        with self.lock:
            return list((self.kept or [])[max(0, after):])

    def undeclare(self) -> None:
        self.publisher.undeclare()

    def __enter__(self) -> Stream:
        return self

    def __exit__(self, *_) -> None:
        self.undeclare()


class RequestFailed(RuntimeError):
    """No valid answer came back (nobody answered in time, or the answer was malformed)."""


class Requester:
    """Sends requests with a per-sender sequence number and decodes the single reply.

    A request nobody answers (no queryable reachable: the server is starting, restarting, or
    its router has not yet propagated it), or whose reply does not come within `timeout_s`,
    is sent again with backoff for up to `retry_s`, and only while `retry_while()` holds;
    every request we send is idempotent (commits carry request ids, tasks task ids)."""

    def __init__(self, session: zenoh.Session, sender: str, timeout_s: float = 5.0,
                 retry_s: float = 15.0) -> None:
        self.session = session
        self.sender = sender
        self.timeout_s = timeout_s
        self.retry_s = retry_s
        # next() is atomic: threads may share a requester, and an id handed out twice would
        # get the store's answer to the other request (it answers a known id again)
        self.seq = itertools.count(1)  # of messages sent
        self.ids = itertools.count(1)  # of request ids handed out
        # Ids must not repeat across a restart of the sender: the store answers a known id
        # with its old reply (idempotent retries), and an agent a known task id likewise.
        self.incarnation = f"{time.time_ns():x}"

    def next_id(self) -> str:
        return f"{self.sender}:{self.incarnation}:{next(self.ids)}"

    def request(self, key: str, message: Message, sim_time: float = 0.0,
                retry_while: Callable[[], bool] = lambda: True) -> Envelope:
        payload = encode(message, self.sender, next(self.seq), sim_time)
        give_up = time.monotonic() + self.retry_s
        backoff = 0.1
        while True:
            start = time.monotonic()
            for reply in self.session.get(key, payload=payload, timeout=self.timeout_s):
                if reply.ok is None:
                    error = reply.err.payload.to_bytes().decode(errors="replace")
                    if error == "Timeout":  # zenoh's own: the server did not answer in time
                        break
                    raise RequestFailed(f"{key}: error reply: {error}")
                try:
                    return decode(reply.ok.payload.to_bytes())
                except ProtocolError as exc:
                    raise RequestFailed(f"{key}: malformed reply: {exc}") from None
            timed_out = time.monotonic() - start >= self.timeout_s
            if time.monotonic() + backoff > give_up or not retry_while():
                raise RequestFailed(f"{key}: no reply within {self.timeout_s:g} s" if timed_out
                                    else f"{key}: nobody answered (no process serves this key)")
            time.sleep(backoff)  # backoff before asking again, not synchronisation
            backoff = min(2 * backoff, 2.0)


def received(sample: zenoh.Sample, expected: type[Message] | tuple[type[Message], ...],
             log: logging.Logger) -> Message | None:
    """The message in a sample if it is valid and of an expected type; otherwise None, with
    the reason logged (a malformed message never takes a process down)."""
    try:
        return _expected(sample.payload.to_bytes(), expected)
    except ProtocolError as exc:
        log.warning("rejected a message on %s: %s", sample.key_expr, exc)
        return None


def asked(query: zenoh.Query, expected: type[Message] | tuple[type[Message], ...],
          log: logging.Logger) -> Message | None:
    """The message a query carries, as `received` has it; the asker is told why not in an
    error reply."""
    try:
        return _expected(query.payload.to_bytes() if query.payload is not None else b"",
                         expected)
    except ProtocolError as exc:
        log.warning("rejected a message on %s: %s", query.key_expr, exc)
        query.reply_err(f"rejected: {exc}".encode())
        return None


def _expected(payload: bytes, expected: type[Message] | tuple[type[Message], ...]) -> Message:
    message = decode(payload).message
    if not isinstance(message, expected):
        raise ProtocolError(f"a {message.TYPE} does not belong here")
    return message


def follow_recorded(session: zenoh.Session, keys: Keys, recorded: threading.Event,
                    log: logging.Logger):
    """Set `recorded` once the recorder says the mission's result is in its file; returns
    the subscriber (undeclare it when done)."""
    def on_status(sample: zenoh.Sample) -> None:
        status = received(sample, RecorderStatus, log)
        if status is not None and status.done_seen:
            recorded.set()

    return session.declare_subscriber(keys.recorder_status, on_status)


def free_port() -> int:
    """A loopback TCP port nobody listens on right now (for tests and benchmarks)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def wait_alive(session: zenoh.Session, key: str, timeout: float) -> bool:
    """Block until a liveliness token matching `key` exists (True) or the timeout passes."""
    seen = threading.Event()
    subscriber = session.liveliness().declare_subscriber(
        key, lambda sample: seen.set() if sample.kind == zenoh.SampleKind.PUT else None,
        history=True)
    try:
        return seen.wait(timeout)
    finally:
        subscriber.undeclare()


def wait_gone(session: zenoh.Session, key: str, timeout: float) -> bool:
    """Block until no liveliness token matches `key` (True) or the timeout passes. Asks the
    network each time (a subscriber's history and a query can cross a token's deletion)."""
    deadline = time.monotonic() + timeout
    while True:
        replies = session.liveliness().get(key, timeout=1.0)
        if not any(reply.ok is not None for reply in replies):
            return True
        if time.monotonic() > deadline:
            return False
        time.sleep(0.05)  # paces the poll
