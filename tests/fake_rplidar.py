"""A fake Slamtec RPLIDAR A1 on a pseudo-terminal, written from Slamtec's protocol document (not from the driver).

It implements the request/response state machine: requests ``0xA5 <cmd>``;
GET_HEALTH and GET_INFO answer a descriptor (``0xA5 0x5A``, 30-bit length |
2-bit mode << 30, type) and their body; SCAN answers the descriptor (length 5,
mode 1, type 0x81) and then streams 5-byte samples of a known synthetic room
until STOP or RESET; RESET stops and prints a text banner as the A1 does.
Samples only come while the motor turns, and until it is at speed they carry
quality 0 and no S bit.

The motor: on the A1 the USB adapter's DTR line drives it (low = spin). A
Linux pseudo-terminal has no modem lines (TIOCMGET/TIOCMBIS fail with ENOTTY
on both ends), so the fake cannot see DTR: a test sets :attr:`motor_on`
itself, and the driver's DTR calls are tested through an in-memory port.
Runs on the wall clock on purpose (test support).
"""

from __future__ import annotations

import math
import os
import struct
import time

from fake_ld19 import SyntheticRoom
from pty_device import RoomLidar

STEP_S = 0.005
BANNER = b"RP LIDAR System.\r\nFirmware Ver 1.29 - rc9, HW Ver 7\r\nModel: 18\r\n"


def descriptor(length: int, mode: int, answer_type: int) -> bytes:
    """An answer descriptor: 0xA5 0x5A, length (30 bits) | mode << 30 as u32 LE, type."""
    return bytes((0xA5, 0x5A)) + struct.pack("<I", (length & 0x3FFFFFFF) | (mode << 30)) + bytes((answer_type,))


def scan_sample(new_revolution: bool, quality: int, angle_deg: float, distance_mm: float,
                check_bit: int = 1) -> bytes:
    """One 5-byte SCAN sample as the protocol document lays it out."""
    s = 1 if new_revolution else 0
    b0 = ((quality & 0x3F) << 2) | ((1 - s) << 1) | s
    angle_q6 = int(round(angle_deg * 64.0)) & 0x7FFF
    b1 = ((angle_q6 & 0x7F) << 1) | check_bit
    b2 = angle_q6 >> 7
    distance_q2 = int(round(distance_mm * 4.0)) & 0xFFFF
    return bytes((b0, b1, b2)) + struct.pack("<H", distance_q2)


class FakeRplidar(RoomLidar):
    """An RPLIDAR A1 on a pty; use as a context manager and open ``port`` at 115200 baud."""

    thread_name = "fake-rplidar"

    def __init__(self, rate_hz: float = 5.5, samples_per_s: float = 2000.0, room: SyntheticRoom | None = None,
                 spinup_s: float = 0.0, health: tuple[int, int] = (0, 0), max_range_m: float = 12.0) -> None:
        super().__init__(room if room is not None else SyntheticRoom(), max_range_m)
        self.rate_hz = rate_hz
        self.samples_per_s = samples_per_s
        self.spinup_s = spinup_s
        """Seconds from motor on to full speed; quality-0 samples without S bit meanwhile."""
        self.health = health
        """(status, error code) GET_HEALTH answers; a RESET clears an error (status 2) once."""
        self.motor_on = True
        """Stands for DTR low (see the module docstring)."""
        self.silent = False
        """While True the device neither answers nor streams."""
        self.bad_samples_next = 0
        """The next this-many samples go out with the check bit C = 0 (and 7.777 m)."""
        self.requests: list[int] = []
        """Every command byte received, in order."""
        self.scanning = False
        self.serial_number = bytes(range(0x10, 0x20))
        self._motor_since: float | None = None
        self._phase_deg = 0.0
        self._last_angle: float | None = None
        self._rx = bytearray()

    def _handle(self, out: bytearray) -> None:
        while len(self._rx) >= 2:
            if self._rx[0] != 0xA5:
                del self._rx[0]
                continue
            cmd = self._rx[1]
            del self._rx[:2]
            self.requests.append(cmd)
            if cmd == 0x25:  # STOP
                self.scanning = False
            elif cmd == 0x40:  # RESET: reboot, banner; a reset clears a protection stop
                self.scanning = False
                if self.health[0] == 2:
                    self.health = (0, 0)
                out += BANNER
            elif cmd == 0x52:  # GET_HEALTH
                out += descriptor(3, 0, 0x06) + struct.pack("<BH", *self.health)
            elif cmd == 0x50:  # GET_INFO: model 0x18 (A1M8), firmware 1.29, hardware 7, serial
                out += descriptor(20, 0, 0x04) + bytes((0x18, 29, 1, 7)) + self.serial_number
            elif cmd == 0x20:  # SCAN
                out += descriptor(5, 1, 0x81)
                self.scanning = True

    def _samples(self, n: int, now: float) -> bytes:
        out = bytearray()
        at_speed = self._motor_since is not None and now - self._motor_since >= self.spinup_s
        speed_hz = self.rate_hz if at_speed else self.rate_hz * 0.3
        step = speed_hz * 360.0 / self.samples_per_s
        for _ in range(n):
            angle = self._phase_deg
            self._phase_deg = (angle + step) % 360.0
            if not at_speed:
                self._last_angle = None
                out += scan_sample(False, 0, angle, 0.0)
                continue
            # S marks the first sample of each turn (after the angle wrapped past 360).
            new_rev = self._last_angle is not None and angle < self._last_angle
            self._last_angle = angle
            if self.bad_samples_next > 0:
                self.bad_samples_next -= 1
                out += scan_sample(new_rev, 15, angle, 7777.0, check_bit=0)
                continue
            r = self.room.range_m(-math.radians(angle))
            if r > self.max_range_m:
                out += scan_sample(new_rev, 0, angle, 0.0)
            else:
                out += scan_sample(new_rev, 47, angle, r * 1000.0)
        return bytes(out)

    def _run(self) -> None:
        due = 0.0
        last = time.monotonic()
        while not self._stop.is_set():
            time.sleep(STEP_S)
            now = time.monotonic()
            out = bytearray()
            with self._lock:
                if self.motor_on and self._motor_since is None:
                    self._motor_since = now
                elif not self.motor_on:
                    self._motor_since = None
                try:
                    data = os.read(self.master, 4096)
                except (BlockingIOError, OSError):
                    data = b""
                if self.silent:
                    due, last = 0.0, now
                    continue
                self._rx += data
                self._handle(out)
                out += self._garbage
                self._garbage.clear()
                if self.scanning and self._motor_since is not None:
                    due += (now - last) * self.samples_per_s
                    n = int(due)
                    due -= n
                    out += self._samples(n, now)
                else:
                    due = 0.0
                last = now
            if out:
                self._write(bytes(out))
