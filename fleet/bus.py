"""Zenoh plumbing shared by every process: the key space (docs/protocol.md), session
configuration, and a request helper. Processes are clients of one router (`fleet run` starts
it; in compose it is the `router` service); tests may connect peers directly."""

from __future__ import annotations

import json
import socket
import threading
from dataclasses import dataclass

import zenoh

from fleet.protocol import Envelope, Message, ProtocolError, decode, encode

DEFAULT_ROUTER = "tcp/127.0.0.1:7447"


@dataclass(frozen=True)
class Keys:
    """Every key expression of one run, under fleet/<run>/."""

    run: str = "default"

    @property
    def root(self) -> str:
        return f"fleet/{self.run}"

    @property
    def everything(self) -> str:
        return f"{self.root}/**"

    @property
    def reservation_request(self) -> str:
        return f"{self.root}/reservation/request"

    @property
    def reservation_change(self) -> str:
        return f"{self.root}/reservation/change"

    @property
    def reservation_alive(self) -> str:
        return f"{self.root}/reservation/alive"

    def vehicle_state(self, vehicle: int) -> str:
        return f"{self.root}/vehicle/{vehicle}/state"

    def vehicle_alive(self, vehicle: int) -> str:
        return f"{self.root}/vehicle/{vehicle}/alive"


@dataclass(frozen=True)
class BusConfig:
    mode: str = "client"  # "client", "peer" or "router"
    connect: tuple[str, ...] = (DEFAULT_ROUTER,)
    listen: tuple[str, ...] = ()
    lease_ms: int = 1000  # a lost peer is noticed after about 3/4 of this

    def zenoh_config(self) -> zenoh.Config:
        config = zenoh.Config()
        config.insert_json5("mode", json.dumps(self.mode))
        config.insert_json5("scouting/multicast/enabled", "false")  # loopback and named hosts
        config.insert_json5("connect/endpoints", json.dumps(list(self.connect)))
        config.insert_json5("listen/endpoints", json.dumps(list(self.listen)))
        config.insert_json5("connect/timeout_ms", "-1")  # wait for the router to come up
        config.insert_json5("transport/link/tx/lease", str(self.lease_ms))
        return config


def open_session(config: BusConfig) -> zenoh.Session:
    return zenoh.open(config.zenoh_config())


class RequestFailed(RuntimeError):
    """No valid answer came back (nobody answered in time, or the answer was malformed)."""


class Requester:
    """Sends requests with a per-sender sequence number and decodes the single reply."""

    def __init__(self, session: zenoh.Session, sender: str, timeout_s: float = 5.0) -> None:
        self.session = session
        self.sender = sender
        self.timeout_s = timeout_s
        self.seq = 0

    def next_id(self) -> str:
        self.seq += 1
        return f"{self.sender}:{self.seq}"

    def request(self, key: str, message: Message, sim_time: float = 0.0) -> Envelope:
        payload = encode(message, self.sender, self.seq, sim_time)
        for reply in self.session.get(key, payload=payload, timeout=self.timeout_s):
            if reply.ok is None:
                raise RequestFailed(f"{key}: error reply: "
                                    f"{reply.err.payload.to_bytes().decode(errors='replace')}")
            try:
                return decode(reply.ok.payload.to_bytes())
            except ProtocolError as exc:
                raise RequestFailed(f"{key}: malformed reply: {exc}") from None
        raise RequestFailed(f"{key}: no reply within {self.timeout_s:g} s")


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
