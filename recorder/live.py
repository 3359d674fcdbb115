"""The live view: a Foxglove WebSocket server carrying the view channels (fleet/views/scene.py) as
they are made, for the Foxglove app to connect to (Open connection > Foxglove WebSocket,
ws://HOST:PORT; this SDK speaks the subprotocol foxglove.sdk.v1).

A channel is created, and advertised, the first time its topic is published. A client that
subscribes later is sent the topic's last message at once: the static warehouse is published
only once, at the start, and would otherwise never reach it.
"""

from __future__ import annotations

from typing import Any

import foxglove
from foxglove.websocket import ChannelView, Client, ServerListener


class _Replay(ServerListener):
    """Sends a topic's last message when a client subscribes to it. The SDK gives no way to
    send to that client alone, so every subscriber gets it again: harmless, since a scene
    entity replaces the one with the same id."""

    def __init__(self, view: LiveView) -> None:
        self.view = view

    def on_subscribe(self, client: Client, channel: ChannelView) -> None:
        self.view._replay(channel.topic)


class LiveView:
    """A Foxglove WebSocket server for the view channels. `port=0` binds a free port (see
    `port`). Publish from one thread; the server answers clients on its own threads."""

    def __init__(self, port: int = 8765, host: str = "127.0.0.1",
                 name: str = "forklift-fleet") -> None:
        # A context of its own: these channels go to this server only, never to another sink
        # (an MCAP writer) of the process. Its Python object must outlive the server.
        self._context = foxglove.Context()
        self._channels: dict[str, foxglove.Channel] = {}
        self._schemas: dict[str, str] = {}  # topic -> schema name
        self._latest: dict[str, bytes] = {}  # topic -> last message, for late subscribers
        self._server = foxglove.start_server(name=name, host=host, port=port,
                                             context=self._context,
                                             server_listener=_Replay(self))
        self.host = host
        self._port = self._server.port
        self.closed = False

    @property
    def port(self) -> int:
        """The port the server listens on (the one picked when asked for 0)."""
        return self._port

    @property
    def url(self) -> str:
        return f"ws://{self.host}:{self._port}"

    def publish(self, topic: str, message: Any, log_ns: int | None = None) -> None:
        """Log a Foxglove message (foxglove.messages.*) on `topic`, at the current time unless
        `log_ns` is given. A topic keeps the message type it was first published with."""
        if self.closed:
            return
        schema = message.get_schema()
        channel = self._channels.get(topic)
        if channel is None:
            channel = foxglove.Channel(topic, schema=schema, message_encoding=schema.encoding,
                                       context=self._context)
            self._channels[topic] = channel
            self._schemas[topic] = schema.name
        elif self._schemas[topic] != schema.name:
            raise ValueError(f"topic {topic} carries {self._schemas[topic]}, not {schema.name}")
        data = message.encode()
        self._latest[topic] = data  # before logging: a subscriber never misses the newest
        channel.log(data, log_time=log_ns)

    def _replay(self, topic: str) -> None:
        # Called on a server thread. Were a publish to race this (read here, logged there,
        # then the older logged here), the topic would show the older message until its next.
        data = self._latest.get(topic)
        channel = self._channels.get(topic)
        if data is not None and channel is not None and not self.closed:
            channel.log(data)

    def close(self) -> None:
        """Stop the server (clients are disconnected). Safe to call twice."""
        if self.closed:
            return
        self.closed = True
        self._server.stop()
        for channel in self._channels.values():
            channel.close()

    def __enter__(self) -> LiveView:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
