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
``jsonschema`` schemas as in the file. Messages sent once or on change
(:data:`LATCHED`: /scene, /route, /map, ...) are sent again when a client
subscribes to them, so a client that connects mid-run still sees the world
and the map (:meth:`LiveServer.take_resend`).

The SDK logs what clients do wrong (an unknown channel id, a message that is
not JSON, an unknown op) through Python's ``logging``, one record per fault:
a client could flood the run's terminal with them (a subscribe with 5,000
unknown ids made 5,000 lines). :class:`SdkLogLimiter` takes those records
instead: the first of each kind per client is shown, the rest are counted and
said in one summary line per interval (and at the end), within a cap on lines
per interval over all clients. The client still gets a status message for
each fault from the SDK.
"""

from __future__ import annotations

import logging
import re
import sys
import threading
import time
from typing import Any, Callable, Optional

LATCHED = ("/scene", "/route", "/collision_monitor/zones", "/map", "/global_costmap", "/plan")
"""Topics whose last message a newly subscribed client needs (they are sent at the start and on change): a
subscription to any of them has the writer send them all again (ROS 2's transient-local durability). Each must be
one the writer keeps to send again (``/scene``, ``/route`` and its ``_latched_views``)."""


SDK_LOGGER = "foxglove"
"""The logger under which the SDK's Rust side logs (``foxglove.websocket.connected_client``, ...)."""

_CLIENT = re.compile(r"(?:\d{1,3}(?:\.\d{1,3}){3}|\[[0-9A-Fa-f:.%\w]*\]):\d+")
_QUOTED = re.compile(r"`[^`]*`")
_NUMBER = re.compile(r"\d+")
_UNPRINTABLE = re.compile(r"[^\x20-\x7e]")


def _printable(text: str, limit: int) -> str:
    """``text`` made safe for a terminal (no escape sequences, no line breaks) and at most ``limit`` characters."""
    if len(text) > limit:
        text = text[:limit] + "..."
    return _UNPRINTABLE.sub(lambda m: m.group().encode("unicode_escape").decode("ascii"), text)


class SdkLogLimiter(logging.Handler):
    """The Foxglove SDK's log records on the run's terminal, rate-limited so no client can flood it.

    Within each window of ``window_s`` (wall seconds) a record is shown only if
    no record of the same kind (its text with numbers and quoted words taken
    out) came from the same client in that window, that client has had fewer
    than ``per_client`` lines, and all clients together fewer than ``total``.
    The others are counted; when the window ends (on a timer, on the next
    record, or at :meth:`close`) one line says how many were not shown, from
    whom and like what. So at most ``total + 1`` lines per window, whatever
    the clients send. ``write`` takes a line (default: standard error, which
    the writer process shares with the run's terminal); ``clock`` gives wall
    seconds; ``timer`` False leaves the summaries to the next record and
    :meth:`close` (tests).
    """

    MAX_TEXT_CHARS = 1000
    """The start of a record's text that is looked at and kept (characters)."""

    MAX_GROUPS = 1000
    """Distinct (client, kind) groups counted per window; more are counted together (bounds memory)."""

    def __init__(self, write: Optional[Callable[[str], None]] = None, clock: Callable[[], float] = time.monotonic,
                 window_s: float = 10.0, per_client: int = 2, total: int = 6, timer: bool = True) -> None:
        super().__init__(level=logging.WARNING)
        self._write = write or (lambda line: print(line, file=sys.stderr, flush=True))
        self._clock = clock
        self.window_s = window_s
        self.per_client = per_client
        self.total = total
        self._timer_enabled = timer
        self._timer: Optional[threading.Timer] = None
        self._guard = threading.Lock()  # the SDK logs from several of its threads
        self._window_end = -1.0
        self._shown: set[tuple[str, str]] = set()
        self._lines_by_client: dict[str, int] = {}
        self._lines = 0
        self._hidden: dict[tuple[str, str], list] = {}  # (client, kind) -> [count, last text]
        self._hidden_other = 0

    def emit(self, record: logging.LogRecord) -> None:
        """Show ``record`` or count it (see the class)."""
        try:
            text = record.getMessage()
        except Exception:  # a record the SDK formatted badly: say that much, not a traceback
            text = f"{record.msg!r}"
        # A client's text can be echoed in the record (an unknown op's name, up to the SDK's 16 MB message
        # limit): keep only its start, so neither the regular expressions nor the counts grow with it.
        text = text[:self.MAX_TEXT_CHARS]
        match = _CLIENT.search(text)
        client = match.group() if match else ""
        kind = _NUMBER.sub("N", _QUOTED.sub("`...`", text.replace(client, "CLIENT") if client else text))[:120]
        lines: list[str] = []
        with self._guard:
            now = self._clock()
            if now >= self._window_end:
                lines += self._summary_locked()
                self._window_end = now + self.window_s
            key = (client, kind)
            if (key not in self._shown and self._lines_by_client.get(client, 0) < self.per_client
                    and self._lines < self.total):
                self._shown.add(key)
                self._lines_by_client[client] = self._lines_by_client.get(client, 0) + 1
                self._lines += 1
                lines.append(f"beastbt: foxglove: {_printable(text, 300)}")
            else:
                group = self._hidden.get(key)
                if group is not None:
                    group[0] += 1
                    group[1] = text
                elif len(self._hidden) < self.MAX_GROUPS:
                    self._hidden[key] = [1, text]
                else:
                    self._hidden_other += 1
                self._arm_locked(now)
        for line in lines:
            self._write(line)

    def _arm_locked(self, now: float) -> None:
        """Start the timer that says the window's summary when it ends (once per window)."""
        if self._timer_enabled and self._timer is None:
            self._timer = threading.Timer(max(0.0, self._window_end - now), self.flush_summary)
            self._timer.daemon = True
            self._timer.start()

    def _summary_locked(self) -> list[str]:
        """The line (if any) for what this window did not show; starts a new window's counts."""
        hidden = sum(count for count, _ in self._hidden.values()) + self._hidden_other
        lines: list[str] = []
        if hidden:
            by_client: dict[str, int] = {}
            for (client, _), (count, _) in self._hidden.items():
                by_client[client] = by_client.get(client, 0) + count
            top = sorted(self._hidden.items(), key=lambda item: -item[1][0])[:3]
            parts = [f"{count:,} from {client or 'the server'} (like: {_printable(last, 120)})"
                     for (client, _), (count, last) in top]
            others = hidden - sum(count for _, (count, _) in top)
            if others:
                parts.append(f"{others:,} more (from {len(by_client):,} client(s) in all)")
            lines.append(f"beastbt: foxglove: {hidden:,} more messages of the live server not shown "
                         f"(at most {self.total} lines per {self.window_s:g} s): " + "; ".join(parts))
        self._shown.clear()
        self._lines_by_client.clear()
        self._lines = 0
        self._hidden.clear()
        self._hidden_other = 0
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None
        return lines

    def flush_summary(self) -> None:
        """Say what was not shown, if anything, and start a new window (the timer calls this)."""
        with self._guard:
            lines = self._summary_locked()
            self._window_end = -1.0
        for line in lines:
            self._write(line)

    def close(self) -> None:
        """Say what was not shown, and stop the timer."""
        self.flush_summary()
        super().close()


class LiveServer:
    """A Foxglove WebSocket server on ``host:port`` (port 0: any free port) with beastbt's channels.

    Raises whatever ``foxglove.start_server`` raises when it cannot listen
    (the port is taken, the host is not this machine's).
    """

    def __init__(self, host: str, port: int, name: str = "beastbt") -> None:
        import foxglove  # the official SDK; imported only by a run that serves live
        from foxglove.websocket import ServerListener

        self._foxglove = foxglove
        # The SDK's records go to the limiter only, not to the root logger (whose last-resort handler
        # would print each one on standard error).
        self._log_limiter = SdkLogLimiter()
        self._sdk_logger = logging.getLogger(SDK_LOGGER)
        self._sdk_logger.addHandler(self._log_limiter)
        self._sdk_logger.propagate = False
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
        """Stop serving: clients see the server go away; what the log limiter held back is said."""
        self.server.stop()
        self._sdk_logger.removeHandler(self._log_limiter)
        self._sdk_logger.propagate = True
        self._log_limiter.close()


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


__all__ = ["LiveServer", "SdkLogLimiter", "start_live", "LATCHED", "SDK_LOGGER"]
