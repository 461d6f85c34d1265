"""Opening a real robot's ports: a missing device stops the run before anything moves, saying which and why.

A device a part cannot open is a :class:`DeviceUnavailable` naming the
device, the path tried and what to check; nothing has moved when it is raised.
"""

from __future__ import annotations

from beastbt.core.errors import plain_reason


class DeviceUnavailable(Exception):
    """A device of the profile could not be opened; the message says which, where, and what to check."""


def open_serial(device: str, path: str, baud: int, hint: str):
    """Open a serial port non-blocking, or raise :class:`DeviceUnavailable`."""
    import serial
    try:
        return serial.Serial(path, baud, timeout=0, write_timeout=0.05)
    except (serial.SerialException, OSError, ValueError) as exc:
        raise DeviceUnavailable(f"{device}: cannot open {path} at {baud} baud ({plain_reason(exc)}); {hint}") from exc


__all__ = ["DeviceUnavailable", "open_serial"]
