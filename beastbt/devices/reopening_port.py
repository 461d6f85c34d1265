"""How a driver loses a serial port and gets it back: closed on failure, reopened at a pace, said once each way.

A USB GPS or LiDAR that is unplugged, or a UART that errors, must not end the
run: the driver drops the port, its readings go stale (the consumers judge
that), and it tries to open the port again every ``reopen_interval_s``. The
operator hears of it once when it goes and once when it is back, not every
tick. Time comes from the caller (``now_s``, the injected clock).
"""

from __future__ import annotations

import math
from typing import Callable, Optional

import serial

from beastbt.devices.interfaces import EventSink, SerialLike


class PortReopener:
    """The lose-and-reopen policy of one driver's serial port, and its two events.

    ``kind`` prefixes the event kinds (``{kind}_port_lost``, ``{kind}_port_reopened``);
    ``label`` starts their texts (``GPS``, ``LiDAR (LD19)``); ``path`` is the port's name;
    ``open_port`` opens it again (None: it cannot be reopened); ``reopen_interval_s`` is the
    pace of the tries (s). ``lost_reported``: the driver starts without a port and has
    already said so (its first failed try stays quiet).
    """

    def __init__(self, events: EventSink, kind: str, label: str, path: str,
                 open_port: Optional[Callable[[], SerialLike]], reopen_interval_s: float,
                 lost_reported: bool = False) -> None:
        self._events = events
        self.kind = kind
        self.label = label
        self.path = path
        self._open_port = open_port
        self.reopen_interval_s = reopen_interval_s
        self._lost_reported = lost_reported
        self._next_open_s = -math.inf

    def lost(self, now_s: float, port: Optional[SerialLike], exc: BaseException, consequence: str) -> None:
        """Close ``port`` after ``exc`` at ``now_s`` (s), say so with ``consequence``, and schedule the next try."""
        if port is not None:
            try:
                port.close()
            except Exception:  # noqa: BLE001 - a vanished device may fail to close; it is gone anyway
                pass
        self._next_open_s = now_s + self.reopen_interval_s
        how = (f"retrying every {self.reopen_interval_s:g} s" if self._open_port is not None
               else "no way to reopen it was given")
        self._events(f"{self.kind}_port_lost", f"{self.label}: serial port {self.path} failed ({exc}); "
                                               f"{consequence}; {how}")
        self._lost_reported = True

    def reopen(self, now_s: float) -> Optional[SerialLike]:
        """A freshly opened port when a try is due at ``now_s`` (s) and succeeds; else None (said once)."""
        if self._open_port is None:
            if not self._lost_reported:
                self._events(f"{self.kind}_port_lost", f"{self.label}: no serial port for {self.path} "
                                                       f"and no way to open one")
                self._lost_reported = True
            return None
        if now_s < self._next_open_s:
            return None
        try:
            port = self._open_port()
        except (serial.SerialException, OSError) as exc:
            self._next_open_s = now_s + self.reopen_interval_s
            if not self._lost_reported:
                self._events(f"{self.kind}_port_lost", f"{self.label}: cannot open serial port {self.path} ({exc}); "
                                                       f"retrying every {self.reopen_interval_s:g} s")
                self._lost_reported = True
            return None
        if self._lost_reported:
            self._events(f"{self.kind}_port_reopened", f"{self.label}: serial port {self.path} is back")
        self._lost_reported = False
        return port
