"""A TCP forwarder between one process and its zenoh router, so a fault can cut that process's
link silently and later restore it (the `cut_link` fault).

A cut behaves like a network link going down: nothing is forwarded any more, but no socket is
closed, so neither end gets a FIN or a reset and each only notices by its zenoh lease
expiring. Connections opened during the cut are accepted and held without an answer (as if
the SYN had gone through but nothing came back). A restore closes everything held since the
cut (by then both ends have given those connections up) and forwards new connections again;
a zenoh client reconnects by itself (it retries its connect endpoint after losing its
router) and re-declares its liveliness tokens and subscriptions.

One thread per proxy multiplexes every connection with a selector; the public methods hand
their work to that thread and wait for it, so only that thread ever touches a socket."""

from __future__ import annotations

import contextlib
import errno
import logging
import queue
import selectors
import socket
import struct
import threading
from dataclasses import dataclass, field

log = logging.getLogger("fleet.runtime.linkproxy")

CHUNK = 65536  # bytes read per recv
BUFFER_LIMIT = 1 << 20  # per direction: stop reading a side whose peer does not keep up
COMMAND_TIMEOUT_S = 10.0  # how long cut(), restore() and close() wait for the proxy thread


@dataclass(eq=False)
class _Pipe:
    """One direction of a connection: bytes read from `src` wait in `buf` to go to `dst`."""

    src: socket.socket
    dst: socket.socket
    buf: bytearray = field(default_factory=bytearray)
    eof: bool = False  # src has closed its sending side
    shut: bool = False  # ... and that has been passed on to dst (after buf drained)

    @property
    def done(self) -> bool:
        return self.shut


@dataclass(eq=False)
class _Link:
    """A connection accepted from the process, and its own connection to the target (None
    when accepted during a cut: a link that is down reaches nobody)."""

    client: socket.socket
    upstream: socket.socket | None
    connecting: bool = False  # the upstream connect is still in progress
    held: bool = False  # open when a cut began, or accepted during one: forwards nothing
    closed: bool = False
    pipes: tuple[_Pipe, ...] = ()

    def sockets(self) -> list[socket.socket]:
        return [s for s in (self.client, self.upstream) if s is not None and s.fileno() != -1]


@dataclass(frozen=True)
class _Command:
    name: str  # "cut", "restore" or "close"
    done: threading.Event = field(default_factory=threading.Event)


class LinkProxy:
    """Forwards TCP connections from `listen_host:<free port>` to `target_host:target_port`,
    until cut() makes the link silent and restore() brings it back."""

    def __init__(self, target_host: str, target_port: int,
                 listen_host: str = "127.0.0.1", protocol: str = "tcp") -> None:
        self.target = (target_host, target_port)
        self.listen_host = listen_host
        self.protocol = protocol  # zenoh's over TCP: tcp, or tls (forwarded as it is)
        self._port = 0
        self._cut = False
        self._closed = False
        self._listener: socket.socket | None = None
        self._selector: selectors.BaseSelector | None = None
        self._wake_r: socket.socket | None = None
        self._wake_w: socket.socket | None = None
        self._thread: threading.Thread | None = None
        self._commands: queue.SimpleQueue[_Command] = queue.SimpleQueue()
        self._links: set[_Link] = set()
        self._masks: dict[socket.socket, int] = {}  # what each socket is registered for
        self._start_lock = threading.Lock()
        self._command_lock = threading.Lock()  # commands are queued only while a thread runs
        self._running = False

    # -- public API ------------------------------------------------------------------------

    def start(self) -> int:
        """Listen on a free port of `listen_host` and start forwarding; returns the port."""
        with self._start_lock:
            if self._thread is not None or self._closed:
                raise RuntimeError("a LinkProxy starts once")
            family = socket.getaddrinfo(self.listen_host, 0, type=socket.SOCK_STREAM)[0][0]
            listener = socket.create_server((self.listen_host, 0), family=family, backlog=64)
            try:
                listener.setblocking(False)
                self._wake_r, self._wake_w = socket.socketpair()
                self._wake_r.setblocking(False)
                self._wake_w.setblocking(False)
                self._selector = selectors.DefaultSelector()
                self._selector.register(listener, selectors.EVENT_READ, "accept")
                self._selector.register(self._wake_r, selectors.EVENT_READ, "wake")
            except OSError:
                for sock in (listener, self._wake_r, self._wake_w):
                    if sock is not None:
                        sock.close()
                raise
            self._listener = listener
            self._port = listener.getsockname()[1]
            self._thread = threading.Thread(target=self._run, daemon=True,
                                            name=f"linkproxy-{self._port}")
            self._running = True
            self._thread.start()
            return self._port

    @property
    def port(self) -> int:
        """The port start() chose (0 before start)."""
        return self._port

    @property
    def endpoint(self) -> str:
        """The zenoh endpoint that reaches the target through this proxy."""
        host = f"[{self.listen_host}]" if ":" in self.listen_host else self.listen_host
        return f"{self.protocol}/{host}:{self._port}"

    @property
    def cut_active(self) -> bool:
        return self._cut

    def cut(self) -> None:
        """Stop forwarding in both directions without closing anything; returns once no
        further byte will be forwarded."""
        self._command("cut")

    def restore(self) -> None:
        """Close every connection held since the cut and forward new connections again."""
        self._command("restore")

    def close(self) -> None:
        """Close every connection and the listener, and stop the thread (idempotent)."""
        with self._start_lock:
            if self._closed:
                return
            self._closed = True
            thread = self._thread
        if thread is None:  # never started: nothing runs, nothing is open
            return
        try:
            self._command("close", force=True)
        except RuntimeError as exc:  # the thread is stuck: nothing more to do than say so
            log.error("%s", exc)
        thread.join(COMMAND_TIMEOUT_S)
        if thread.is_alive():
            log.error("link proxy thread %s did not stop", thread.name)

    def __enter__(self) -> LinkProxy:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- commands --------------------------------------------------------------------------

    def _command(self, name: str, force: bool = False) -> None:
        """Runs a command on the proxy thread (the only one touching sockets) and waits."""
        if self._closed and not force:
            raise RuntimeError("the LinkProxy is closed")
        command = _Command(name)
        with self._command_lock:
            if not self._running:  # not started: nothing to forward or hold, just the state
                if name != "close":
                    self._cut = name == "cut"
                return
            self._commands.put(command)
        self._wake()
        if not command.done.wait(COMMAND_TIMEOUT_S):
            raise RuntimeError(f"link proxy thread did not {name} within {COMMAND_TIMEOUT_S} s")

    def _wake(self) -> None:
        with contextlib.suppress(OSError):  # full (already woken) or closed (stopping)
            self._wake_w.send(b"x")

    def _run_commands(self) -> bool:
        """Applies queued commands; False once told to close."""
        with contextlib.suppress(OSError):
            while self._wake_r.recv(4096):
                pass
        keep_running = True
        while True:
            try:
                command = self._commands.get_nowait()
            except queue.Empty:
                return keep_running
            try:
                if command.name == "cut" and not self._cut:
                    self._cut = True
                    for link in self._links:
                        self._hold(link)
                elif command.name == "restore" and self._cut:
                    self._cut = False
                    for link in [link for link in self._links if link.held]:
                        self._close_link(link)
                elif command.name == "close":
                    keep_running = False
            finally:
                command.done.set()

    # -- the proxy thread ------------------------------------------------------------------

    def _run(self) -> None:
        try:
            running = True
            while running:
                try:
                    events = self._selector.select()
                except InterruptedError:
                    continue
                for key, mask in events:
                    try:
                        if key.data == "wake":
                            running = self._run_commands() and running
                        elif key.data == "accept":
                            self._accept()
                        else:
                            self._on_ready(key.data, key.fileobj, mask)
                    except Exception:  # a bug must not stop every other connection
                        log.exception("link proxy %s: unexpected error", self._port)
                        if isinstance(key.data, _Link):
                            self._close_link(key.data)
        except Exception:
            log.exception("link proxy %s stopped on an unexpected error", self._port)
        finally:
            self._shutdown()

    def _shutdown(self) -> None:
        for link in list(self._links):
            self._close_link(link)
        for sock in (self._listener, self._wake_r, self._wake_w):
            if sock is not None:
                with contextlib.suppress(Exception):
                    self._selector.unregister(sock)
                sock.close()
        self._selector.close()
        with self._command_lock:
            self._running = False
            while True:  # nobody waits for ever on a command that came too late
                try:
                    self._commands.get_nowait().done.set()
                except queue.Empty:
                    break

    def _accept(self) -> None:
        while True:
            try:
                client, _ = self._listener.accept()
            except (BlockingIOError, InterruptedError):
                return
            except OSError as exc:  # e.g. out of file descriptors: try again later
                log.warning("link proxy %s: accept failed: %s", self._port, exc)
                return
            client.setblocking(False)
            _nodelay(client)
            if self._cut:  # the link is down: hold the connection, answer nothing
                link = _Link(client, None, held=True)
            else:
                link = self._connect(client)
                if link is None:
                    continue
            self._links.add(link)
            self._update(link)

    def _connect(self, client: socket.socket) -> _Link | None:
        upstream = None
        try:
            family, kind, proto, _, address = socket.getaddrinfo(
                *self.target, type=socket.SOCK_STREAM)[0]
            upstream = socket.socket(family, kind, proto)
            upstream.setblocking(False)
            _nodelay(upstream)
            code = upstream.connect_ex(address)
            if code not in (0, errno.EINPROGRESS, errno.EWOULDBLOCK):
                raise OSError(code, errno.errorcode.get(code, str(code)))
        except OSError as exc:  # the target is not there: the process sees a refusal
            log.info("link proxy %s: cannot reach %s:%s: %s", self._port, *self.target, exc)
            _abort(client)
            if upstream is not None:
                upstream.close()
            return None
        return _Link(client, upstream, connecting=code != 0,
                     pipes=(_Pipe(client, upstream), _Pipe(upstream, client)))

    def _hold(self, link: _Link) -> None:
        """From now on the link forwards nothing; what was in flight is lost, as it would be
        on a wire that goes down."""
        link.held = True
        for pipe in link.pipes:
            pipe.buf.clear()
        self._update(link)

    def _on_ready(self, link: _Link, sock: socket.socket, mask: int) -> None:
        if link.closed or sock.fileno() == -1:  # closed earlier in this round of events
            return
        if link.held:
            self._drain_held(link, sock)
        elif link.connecting:
            self._finish_connect(link)
        else:
            if mask & selectors.EVENT_WRITE:
                self._flush(link, sock)
            if mask & selectors.EVENT_READ and not link.closed:
                self._read(link, sock)
        if not link.closed:
            self._update(link)

    def _drain_held(self, link: _Link, sock: socket.socket) -> None:
        """Reads and drops what a held connection sends, so that a side that gives up (its
        lease expired) is noticed and its socket released; the other side hears nothing."""
        try:
            while sock.recv(CHUNK):
                pass
            gone = True  # end of stream: that side has closed
        except (BlockingIOError, InterruptedError):
            gone = False
        except OSError:  # reset, or a connect that failed
            gone = True
        if gone:
            self._forget(sock)
            sock.close()
            if not link.sockets():
                self._close_link(link)

    def _finish_connect(self, link: _Link) -> None:
        code = link.upstream.getsockopt(socket.SOL_SOCKET, socket.SO_ERROR)
        if code != 0:
            log.info("link proxy %s: cannot reach %s:%s: %s", self._port, *self.target,
                     errno.errorcode.get(code, code))
            self._close_link(link, reset=True)
        else:
            link.connecting = False

    def _read(self, link: _Link, sock: socket.socket) -> None:
        pipe = link.pipes[0] if sock is link.client else link.pipes[1]
        try:
            data = sock.recv(CHUNK)
        except (BlockingIOError, InterruptedError):
            return
        except OSError:  # reset by the peer: pass the reset on
            self._close_link(link, reset=True)
            return
        if data:
            pipe.buf += data
            self._flush(link, pipe.dst)
        else:
            pipe.eof = True
            self._flush(link, pipe.dst)

    def _flush(self, link: _Link, sock: socket.socket) -> None:
        """Sends what waits for `sock`, and passes an end of stream on once all is sent."""
        pipe = link.pipes[1] if sock is link.client else link.pipes[0]
        try:
            while pipe.buf:
                sent = sock.send(pipe.buf)
                del pipe.buf[:sent]
            if pipe.eof and not pipe.shut:
                sock.shutdown(socket.SHUT_WR)
                pipe.shut = True
        except (BlockingIOError, InterruptedError):
            return
        except OSError:  # the receiving side is gone
            self._close_link(link, reset=True)
            return
        if all(p.done for p in link.pipes):
            self._close_link(link)

    def _update(self, link: _Link) -> None:
        """Registers each socket of the link for exactly what it is waiting for now."""
        for sock in link.sockets():
            if link.held:
                mask = selectors.EVENT_READ
            elif link.connecting:
                mask = selectors.EVENT_WRITE if sock is link.upstream else 0
            else:
                mask = 0
                for pipe in link.pipes:
                    if pipe.src is sock and not pipe.eof and len(pipe.buf) < BUFFER_LIMIT:
                        mask |= selectors.EVENT_READ
                    if pipe.dst is sock and pipe.buf:
                        mask |= selectors.EVENT_WRITE
            self._register(sock, mask, link)

    def _register(self, sock: socket.socket, mask: int, link: _Link) -> None:
        old = self._masks.get(sock, 0)
        if mask == old:
            return
        if not mask:
            self._forget(sock)
        elif not old:
            self._selector.register(sock, mask, link)
        else:
            self._selector.modify(sock, mask, link)
        if mask:
            self._masks[sock] = mask

    def _forget(self, sock: socket.socket) -> None:
        if self._masks.pop(sock, 0):
            with contextlib.suppress(KeyError, ValueError, OSError):
                self._selector.unregister(sock)

    def _close_link(self, link: _Link, reset: bool = False) -> None:
        if link.closed:
            return
        link.closed = True
        self._links.discard(link)
        for sock in link.sockets():
            self._forget(sock)
            if reset:
                _abort(sock)
            else:
                sock.close()


def _nodelay(sock: socket.socket) -> None:
    with contextlib.suppress(OSError):
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)


def _abort(sock: socket.socket) -> None:
    """Closes with a reset (what the other side of a reset connection should see too)."""
    with contextlib.suppress(OSError):
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
    sock.close()
