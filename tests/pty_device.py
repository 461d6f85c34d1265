"""A fake serial device on a pseudo-terminal, the base of the tests' fakes of vendor firmware.

The fake holds the pty's master end and runs ``_run`` on a thread of its own while
it is used as a context manager; the code under test opens ``port`` (the slave
end) with pyserial, as it would open the real device's /dev/tty*.
"""

from __future__ import annotations

import math
import os
import threading
import tty
from typing import Any


class PtyDevice:
    """A device on a raw pty: ``port`` to open, ``_run`` on a daemon thread between ``__enter__`` and ``__exit__``."""

    thread_name = "fake-device"

    def __init__(self, nonblocking: bool = False) -> None:
        self.master, self.slave = os.openpty()
        tty.setraw(self.master)
        tty.setraw(self.slave)
        if nonblocking:
            os.set_blocking(self.master, False)  # a reader that does not read makes the device drop, not block
        self.port = os.ttyname(self.slave)
        self._stop = threading.Event()
        self._lock = threading.Lock()
        self._thread = threading.Thread(target=self._run, name=self.thread_name, daemon=True)

    def __enter__(self) -> Any:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)
        os.close(self.master)
        os.close(self.slave)

    def _write(self, data: bytes) -> None:
        try:
            os.write(self.master, data)
        except (BlockingIOError, OSError):
            pass  # nobody reads: a real UART overruns the same way

    def _run(self) -> None:
        raise NotImplementedError


class RoomLidar(PtyDevice):
    """A LiDAR on a pty that sees a synthetic room: the truth to check ranges against, and garbage on demand."""

    def __init__(self, room: Any, max_range_m: float) -> None:
        super().__init__(nonblocking=True)
        self.room = room
        self.max_range_m = max_range_m
        self._garbage = bytearray()

    def inject(self, garbage: bytes) -> None:
        """Send ``garbage`` before the next packet or samples."""
        with self._lock:
            self._garbage += garbage

    def truth_m(self, ccw_rad: float) -> float:
        """The true range in direction ``ccw_rad`` (NaN beyond the maximum range)."""
        r = self.room.range_m(ccw_rad)
        return r if r <= self.max_range_m else math.nan
