"""Live Foxglove: the recording's channels served over the Foxglove WebSocket protocol, from the writer process.

``beastbt run MISSION --foxglove [HOST:]PORT`` gives the recording's writer
process (:mod:`beastbt.recording.writer`) a :class:`LiveServer`: the writer
already turns every tick into the JSON messages of the recording's channels,
and hands the same bytes, with the same log times, to the official
``foxglove-sdk`` server (``foxglove.start_server``), which speaks the
protocol (subprotocol ``foxglove.sdk.v1``) to Foxglove and any other client.
The tick loop does nothing more than when it records; with ``--no-record``
the writer process runs for the live view alone and writes no file.

Channels are advertised as they are declared (all of them when the writer
opens, :data:`beastbt.recording.schemas.CHANNELS`), with the same
``jsonschema`` schemas as in the file. Messages sent once (/scene and
/route) are sent again when a client subscribes to them, so a client that
connects mid-run still sees the world (:meth:`LiveServer.take_resend`).
"""

from __future__ import annotations

import threading
from typing import Any, Optional

LATCHED = ("/scene", "/route")
"""Topics whose last message a newly subscribed client needs (they are sent at the start and on change)."""


class LiveServer:
    """A Foxglove WebSocket server on ``host:port`` (port 0: any free port) with beastbt's channels.

    Raises whatever ``foxglove.start_server`` raises when it cannot listen
    (the port is taken, the host is not this machine's).
    """

    def __init__(self, host: str, port: int, name: str = "beastbt") -> None:
        import foxglove  # the official SDK; imported only by a run that serves live
        from foxglove.websocket import ServerListener

        self._foxglove = foxglove
        self._context = foxglove.Context()
        self._channels: dict[str, Any] = {}
        self._resend = threading.Event()
        server = self

        class Listener(ServerListener):
            """Notes subscriptions to latched topics (called on the SDK's thread); the SDK's defaults for the rest."""

            def on_subscribe(self, client: Any, channel: Any) -> None:
                if channel.topic in LATCHED:
                    server._resend.set()

        self._listener = Listener()  # kept alive: the SDK holds only what it is given
        self.server = foxglove.start_server(name=name, host=host, port=port, context=self._context,
                                            server_listener=self._listener)
        self.port = int(self.server.port)
        """The port it listens on (the one asked for, or the one picked for port 0)."""

    def add_channel(self, topic: str, schema_name: str, schema_data: bytes) -> None:
        """Advertise ``topic`` with its JSON Schema (encoding ``jsonschema``, messages ``json``)."""
        if topic in self._channels:
            return
        schema = self._foxglove.Schema(name=schema_name, encoding="jsonschema", data=schema_data)
        self._channels[topic] = self._foxglove.Channel(topic, schema=schema, message_encoding="json",
                                                       context=self._context)

    def log(self, topic: str, data: bytes, log_time_ns: int) -> None:
        """Send a message (the JSON bytes the file gets) at its log time (Unix epoch ns) to the subscribers."""
        channel = self._channels.get(topic)
        if channel is not None:
            channel.log(data, log_time=log_time_ns)

    def take_resend(self) -> bool:
        """True (once) when a client subscribed to a latched topic since the last call."""
        if self._resend.is_set():
            self._resend.clear()
            return True
        return False

    def close(self) -> None:
        """Stop serving: clients see the server go away."""
        self.server.stop()


def start_live(endpoint: Optional[tuple[str, int]]) -> tuple[Optional[LiveServer], Optional[str]]:
    """A :class:`LiveServer` on ``endpoint`` (host, port), or (None, why not) when it cannot start."""
    if endpoint is None:
        return None, None
    host, port = endpoint
    try:
        return LiveServer(host, int(port)), None
    except ImportError as exc:
        return None, f"--foxglove needs the foxglove-sdk package ({exc}); pip install foxglove-sdk"
    except Exception as exc:  # the SDK raises its own errors for a taken port or a bad host
        return None, f"--foxglove could not listen on {host}:{port}: {exc}"


__all__ = ["LiveServer", "start_live", "LATCHED"]
