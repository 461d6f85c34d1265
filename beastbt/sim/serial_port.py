"""An emulated serial port: the simulator's stand-in for ``serial.Serial``.

The emulated device (a GPS, the Waveshare base controller...) pushes the bytes
it would send with :meth:`SimSerialPort.feed`; the driver reads them with
``read``/``in_waiting`` exactly as from pyserial. What the driver writes is
handed to the device's ``on_write`` callback; its latest bytes are kept in ``written`` for tests.
A port can be made to vanish (``unplug``) to exercise the drivers' reopen logic.
"""

from __future__ import annotations

from typing import Callable, Optional

import serial

from beastbt.core.bounded import trim_front
from beastbt.sim.cpu_account import SIM_CPU, kind_of

WRITTEN_KEPT_BYTES = 64 * 1024
"""``written`` keeps at least the last this many bytes (at most twice as many): a run on the simulator writes
to the base at every tick, for as long as it runs."""


class SimSerialPort:
    """A non-blocking in-memory serial port with the pyserial API drivers use."""

    def __init__(self, name: str = "sim", on_write: Optional[Callable[[bytes], None]] = None) -> None:
        self.name = name
        self.port = name
        self.is_open = True
        self._rx = bytearray()
        self.written = bytearray()
        """The bytes the driver wrote, in order: all of them until :data:`WRITTEN_KEPT_BYTES` * 2, then the
        latest (at least :data:`WRITTEN_KEPT_BYTES`)."""
        self.written_total = 0
        """How many bytes the driver wrote in all."""
        self.on_write = on_write
        self.unplugged = False
        self._write_kind: tuple[Optional[Callable[[bytes], None]], int] = (None, 0)
        """``on_write`` and the kind its work is charged to (:mod:`beastbt.sim.cpu_account`)."""

    # --- the device side -------------------------------------------------
    def feed(self, data: bytes) -> None:
        """Queue bytes for the driver to read (what the device sends)."""
        if not self.unplugged:
            self._rx += data

    def unplug(self) -> None:
        """Make the port vanish: reads and writes raise ``serial.SerialException``."""
        self.unplugged = True
        self._rx.clear()

    def replug(self) -> None:
        """Bring the port back (a driver must reopen it)."""
        self.unplugged = False

    # --- the pyserial side -------------------------------------------------
    def _check(self) -> None:
        if self.unplugged:
            raise serial.SerialException(f"device reports readiness to read but returned no data ({self.name} vanished)")
        if not self.is_open:
            raise serial.PortNotOpenError()

    @property
    def in_waiting(self) -> int:
        """Bytes available without blocking."""
        self._check()
        return len(self._rx)

    def read(self, size: int = 1) -> bytes:
        """Read up to ``size`` bytes (never blocks)."""
        self._check()
        out = bytes(self._rx[:size])
        del self._rx[:size]
        return out

    def readline(self) -> bytes:
        """Read up to and including the next newline, or what is there."""
        self._check()
        i = self._rx.find(b"\n")
        n = len(self._rx) if i < 0 else i + 1
        return self.read(n)

    def write(self, data: bytes) -> int:
        """Send bytes to the emulated device."""
        self._check()
        self.written += data
        self.written_total += len(data)
        trim_front(self.written, WRITTEN_KEPT_BYTES)
        on_write = self.on_write
        if on_write is None:
            pass
        elif not SIM_CPU.enabled:  # every run but a benchmark's: nothing to work out per write
            on_write(bytes(data))
        else:
            # The device answering is the simulator's work; the driver's writing is the robot's.
            if self._write_kind[0] is not on_write:
                self._write_kind = (on_write, kind_of(on_write))
            SIM_CPU.call(self._write_kind[1], on_write, bytes(data))
        return len(data)

    def flush(self) -> None:
        """Nothing is buffered on the way out."""

    def reset_input_buffer(self) -> None:
        """Drop unread bytes."""
        self._rx.clear()

    def close(self) -> None:
        """Close the port."""
        self.is_open = False

    def open(self) -> None:
        """Reopen the port (fails while unplugged)."""
        if self.unplugged:
            raise serial.SerialException(f"could not open port {self.name}: [Errno 2] No such file or directory")
        self.is_open = True
