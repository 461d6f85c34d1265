"""systemd's notify protocol, spoken by the tick loop: ready, watchdog keep-alives, status and stopping.

Under a ``Type=notify`` unit with ``WatchdogSec=`` (``beastbt service install`` writes one), systemd sets
``NOTIFY_SOCKET`` and restarts the service when no ``WATCHDOG=1`` came for that long. beastbt sends one after
every tick of a run and on every pass of ``serve``'s idle wait: a loop that hangs (a device read that never
returns, a behaviour stuck in a loop) stops feeding it, and systemd kills and restarts the process; the base's own
heartbeat has stopped the wheels by then. The protocol is one datagram per message on a Unix socket
(sd_notify(3)); a path that starts with ``@`` is in the abstract namespace. Outside systemd (no ``NOTIFY_SOCKET``)
every call is a no-op that costs an attribute lookup.
"""

from __future__ import annotations

import os
import socket
from typing import Mapping, Optional


class SystemdNotifier:
    """Sends sd_notify(3) messages to ``NOTIFY_SOCKET``; every method is a no-op when there is none.

    A failed send (systemd gone, the socket full) is dropped, never raised: the watchdog's point is to notice a
    loop that stopped, and a loop must not stop because the notification could not be sent.
    """

    def __init__(self, address: Optional[str]) -> None:
        self.address: Optional[str] = None
        self._sock: Optional[socket.socket] = None
        if address:
            self.address = "\0" + address[1:] if address.startswith("@") else address
            self._sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
            self._sock.setblocking(False)
        self.sent_watchdogs = 0
        """How many ``WATCHDOG=1`` went out (a count, for tests and the status line)."""

    @classmethod
    def from_environment(cls, environ: Mapping[str, str] = os.environ) -> "SystemdNotifier":
        """The notifier for this process: systemd's socket when ``NOTIFY_SOCKET`` is set, else a silent one."""
        return cls(environ.get("NOTIFY_SOCKET") or None)

    @property
    def active(self) -> bool:
        """Whether messages go anywhere (the process runs under a ``Type=notify`` unit)."""
        return self._sock is not None

    def send(self, message: str) -> bool:
        """Send one raw message (``KEY=VALUE`` lines); whether it went out."""
        if self._sock is None or self.address is None:
            return False
        try:
            self._sock.sendto(message.encode("utf-8"), self.address)
            return True
        except OSError:
            return False

    def ready(self, status: str = "") -> None:
        """Tell systemd start-up is done (``READY=1``), with a one-line status."""
        self.send("READY=1" + (f"\nSTATUS={status}" if status else ""))

    def watchdog(self) -> None:
        """Feed the watchdog (``WATCHDOG=1``): called once per tick of the loop."""
        if self._sock is not None and self.send("WATCHDOG=1"):
            self.sent_watchdogs += 1

    def status(self, text: str) -> None:
        """The one-line status ``systemctl status`` shows (``STATUS=``)."""
        self.send(f"STATUS={text}")

    def stopping(self) -> None:
        """Tell systemd the process is shutting down on purpose (``STOPPING=1``)."""
        self.send("STOPPING=1")

    def close(self) -> None:
        """Close the socket (further calls are no-ops)."""
        if self._sock is not None:
            self._sock.close()
            self._sock = None


_PROCESS_NOTIFIER: Optional[SystemdNotifier] = None


def process_notifier() -> SystemdNotifier:
    """The process's one notifier (made from the environment on first use): ``serve`` and its runs share it."""
    global _PROCESS_NOTIFIER
    if _PROCESS_NOTIFIER is None:
        _PROCESS_NOTIFIER = SystemdNotifier.from_environment()
    return _PROCESS_NOTIFIER
