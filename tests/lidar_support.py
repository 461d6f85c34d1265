"""Shared helpers of the LiDAR driver tests: an in-memory serial port and polling a driver until something holds."""

from __future__ import annotations

import time
from typing import Callable

import numpy as np


class MemorySerial:
    """A :class:`SerialLike` fed by the test: ``feed(bytes)``, reads give back what was fed; writes are kept."""

    def __init__(self) -> None:
        self.is_open = True
        self.rx = bytearray()
        self.written = bytearray()
        self.dtr_changes: list[bool] = []
        self._dtr = True

    @property
    def in_waiting(self) -> int:
        return len(self.rx)

    def read(self, size: int = 1) -> bytes:
        out = bytes(self.rx[:size])
        del self.rx[:size]
        return out

    def write(self, data: bytes) -> int:
        self.written += data
        return len(data)

    def feed(self, data: bytes) -> None:
        self.rx += data

    @property
    def dtr(self) -> bool:
        return self._dtr

    @dtr.setter
    def dtr(self, value: bool) -> None:
        self._dtr = bool(value)
        self.dtr_changes.append(bool(value))

    def reset_input_buffer(self) -> None:
        self.rx.clear()

    def close(self) -> None:
        self.is_open = False


def poll_until(driver, done: Callable[[list], bool], timeout_s: float = 3.0, every_s: float = 0.01) -> list:
    """Poll ``driver`` (wall time, test support) until ``done(scans so far)`` or the timeout; the scans."""
    scans: list = []
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        scans += driver.poll()
        if done(scans):
            break
        time.sleep(every_s)
    return scans


def range_errors(scan, truth: Callable[[float], float]) -> np.ndarray:
    """|decoded - true| per point with a return in both (metres)."""
    true = np.array([truth(a) for a in scan.angles_rad])
    ok = np.isfinite(true) & np.isfinite(scan.ranges_m)
    return np.abs(scan.ranges_m[ok] - true[ok])
