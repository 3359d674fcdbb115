"""The link proxy (fleet/runtime/linkproxy.py): plain TCP forwarding, a silent cut, a restore; then
between a zenoh client and a real router, where a cut is noticed only by lease expiry and a
restore lets the client reconnect and re-declare by itself."""

import os
import signal
import socket
import struct
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
import zenoh

from fleet.runtime.bus import BusConfig, free_port, open_session
from fleet.runtime.linkproxy import LinkProxy
from fleet.wire.topics import Keys

ROOT = Path(__file__).resolve().parent.parent
QUIET_S = 0.3  # how long a silent connection must stay silent to pass


class EchoServer:
    """Echoes every byte back, and passes an end of stream back too."""

    def __init__(self) -> None:
        self.listener = socket.create_server(("127.0.0.1", 0))
        self.port = self.listener.getsockname()[1]
        self.accepted = 0
        self.connections: list[socket.socket] = []
        self.thread = threading.Thread(target=self._serve, daemon=True)
        self.thread.start()

    def _serve(self) -> None:
        while True:
            try:
                conn, _ = self.listener.accept()
            except OSError:
                return
            self.accepted += 1
            self.connections.append(conn)
            threading.Thread(target=self._echo, args=(conn,), daemon=True).start()

    @staticmethod
    def _echo(conn: socket.socket) -> None:
        try:
            while data := conn.recv(65536):
                conn.sendall(data)
            conn.shutdown(socket.SHUT_WR)
        except OSError:
            pass

    def close(self) -> None:
        self.listener.shutdown(socket.SHUT_RDWR)  # wakes the accept
        self.listener.close()
        for conn in self.connections:
            conn.close()


@pytest.fixture
def echo():
    server = EchoServer()
    yield server
    server.close()


def connect(port: int) -> socket.socket:
    return socket.create_connection(("127.0.0.1", port), timeout=10)


def silent(conn: socket.socket) -> bool:
    """Nothing arrives, not even an end of stream, for QUIET_S."""
    conn.settimeout(QUIET_S)
    try:
        conn.recv(100)
    except TimeoutError:
        return True
    finally:
        conn.settimeout(10)
    return False


def receive(conn: socket.socket, size: int) -> bytes:
    data = bytearray()
    while len(data) < size:
        chunk = conn.recv(size - len(data))
        if not chunk:
            break
        data += chunk
    return bytes(data)


def test_forwards_both_ways_and_passes_the_end_of_stream_on(echo):
    with LinkProxy("127.0.0.1", echo.port) as proxy:
        conn = connect(proxy.port)
        payload = os.urandom(3 << 20)  # more than the proxy buffers: flow control works
        sender = threading.Thread(target=conn.sendall, args=(payload,))
        sender.start()
        assert receive(conn, len(payload)) == payload
        sender.join()
        conn.shutdown(socket.SHUT_WR)
        assert conn.recv(100) == b""  # the server's end of stream came back through
        conn.close()


def test_a_cut_is_silent_and_a_restore_closes_what_it_held(echo):
    with LinkProxy("127.0.0.1", echo.port) as proxy:
        before = connect(proxy.port)
        before.sendall(b"ping")
        assert receive(before, 4) == b"ping"
        proxy.cut()
        assert proxy.cut_active
        before.sendall(b"lost")
        assert silent(before)  # neither forwarded nor closed
        during = connect(proxy.port)  # accepted, never answered
        during.sendall(b"hello?")
        assert silent(during)
        assert echo.accepted == 1  # the cut link reached nobody
        proxy.restore()
        assert not proxy.cut_active
        assert before.recv(100) == b""  # both held connections are closed now
        assert during.recv(100) == b""
        after = connect(proxy.port)
        after.sendall(b"back")
        assert receive(after, 4) == b"back"
        for conn in (before, during, after):
            conn.close()


def test_resets_and_unreachable_targets_do_not_stop_the_proxy(echo):
    with LinkProxy("127.0.0.1", echo.port) as proxy:
        reset = connect(proxy.port)
        reset.sendall(b"x")
        assert receive(reset, 1) == b"x"
        reset.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
        reset.close()  # a reset, passed on to the server
        conn = connect(proxy.port)
        conn.sendall(b"still here")
        assert receive(conn, 10) == b"still here"
        conn.close()
    with LinkProxy("127.0.0.1", free_port()) as proxy:  # nobody listens there
        conn = socket.socket()
        conn.settimeout(10)
        with conn, pytest.raises(ConnectionResetError):  # refused upstream: reset here
            conn.connect(("127.0.0.1", proxy.port))  # (before connect returns, or after)
            conn.recv(100)


def test_close_stops_its_thread_and_is_idempotent(echo):
    proxy = LinkProxy("127.0.0.1", echo.port)
    port = proxy.start()
    conn = connect(port)
    proxy.cut()
    held = connect(port)
    proxy.close()
    proxy.close()
    assert f"linkproxy-{port}" not in {t.name for t in threading.enumerate()}
    assert conn.recv(100) == b"" and held.recv(100) == b""
    with pytest.raises(RuntimeError):
        proxy.cut()
    conn.close()
    held.close()


# -- a zenoh client behind the proxy ----------------------------------------------------------

@pytest.fixture
def router_port(tmp_path):
    """A `fleet router` on a free loopback port (its clients connect with a timeout that
    waits for it to come up)."""
    port = free_port()
    with open(tmp_path / "router.log", "wb") as log:
        proc = subprocess.Popen([sys.executable, "-m", "fleet", "router", "--listen",
                                 f"tcp/127.0.0.1:{port}"], cwd=ROOT, stderr=log,
                                env={**os.environ, "PYTHONUNBUFFERED": "1"})
    yield port
    proc.send_signal(signal.SIGTERM)
    try:
        proc.wait(30)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()


class Liveliness:
    """When the observer last saw the token appear and vanish."""

    def __init__(self) -> None:
        self.appeared = threading.Event()
        self.vanished = threading.Event()
        self.at: dict[str, float] = {}

    def __call__(self, sample: zenoh.Sample) -> None:
        kind = "appeared" if sample.kind == zenoh.SampleKind.PUT else "vanished"
        self.at[kind] = time.monotonic()
        getattr(self, kind).set()


def delivered(observer: zenoh.Session, key: str, received: threading.Event,
              timeout: float) -> bool:
    """Publishes on `key` until the subscriber says it received one (a subscriber declared
    just now may not have reached the router yet)."""
    received.clear()
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        observer.put(key, b"hello")
        if received.wait(0.1):
            return True
    return False


def test_a_cut_client_is_dropped_by_lease_and_comes_back_by_itself(router_port):
    keys = Keys(f"l{os.getpid()}")
    alive, command = keys.vehicle_alive(1), keys.vehicle_inject(1)
    with LinkProxy("127.0.0.1", router_port) as proxy:
        observer = open_session(BusConfig("client", (f"tcp/127.0.0.1:{router_port}",),
                                          connect_timeout_ms=30_000))
        agent = open_session(BusConfig("client", (proxy.endpoint,), connect_timeout_ms=30_000))
        try:
            seen = Liveliness()
            watcher = observer.liveliness().declare_subscriber(alive, seen, history=True)
            token = agent.liveliness().declare_token(alive)
            received = threading.Event()
            subscriber = agent.declare_subscriber(command, lambda _: received.set())
            assert seen.appeared.wait(10), "the observer never saw the token"
            assert delivered(observer, command, received, 10)

            seen.appeared.clear()
            cut_at = time.monotonic()
            proxy.cut()
            assert seen.vanished.wait(15), "the router never dropped the cut client"
            assert seen.at["vanished"] - cut_at < 2.5  # lease 1000 ms: about 1 s

            restored_at = time.monotonic()
            proxy.restore()
            assert seen.appeared.wait(20), "the client never came back"
            assert seen.at["appeared"] > restored_at
            assert delivered(observer, command, received, 10), \
                "the client's subscriber was not declared again"
            subscriber.undeclare()
            token.undeclare()
            watcher.undeclare()
        finally:
            agent.close()
            observer.close()
