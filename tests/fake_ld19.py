"""A fake LDRobot LD19 on a pseudo-terminal, written from LDRobot's protocol description (not from the driver).

The device is one-way: it streams 47-byte packets (0x54, 0x2C, speed deg/s,
start angle 0.01 deg, 12 x (distance mm, intensity), end angle, timestamp ms
mod 30000, CRC-8 poly 0x4D over the first 46 bytes; all little-endian) for a
head turning clockwise at ``rate_hz`` in a known synthetic room
(:class:`SyntheticRoom`), so a test can check decoded ranges against the
truth. The CRC here is computed bit by bit, independently of the driver's
table. Faults on demand: garbage bytes, packets with a wrong CRC, a packet
split across two writes, a slow (spinning-up) head, silence. Runs on the wall
clock on purpose (test support).
"""

from __future__ import annotations

import math
import struct
import time
from dataclasses import dataclass, field

from pty_device import RoomLidar

STEP_S = 0.005


@dataclass
class SyntheticRoom:
    """A rectangular room around the LiDAR (at the origin, its 0 mark along +x) with round pillars.

    Walls at x = -back_m and x = front_m, y = -right_m and y = left_m; pillars (x, y, radius) in metres.
    """

    front_m: float = 3.0
    back_m: float = 2.0
    left_m: float = 2.5
    right_m: float = 1.5
    pillars: list[tuple[float, float, float]] = field(default_factory=lambda: [(1.0, 1.0, 0.2)])

    def range_m(self, ccw_rad: float) -> float:
        """Distance from the origin along direction ``ccw_rad`` (counterclockwise from +x) to the first surface."""
        dx, dy = math.cos(ccw_rad), math.sin(ccw_rad)
        best = math.inf
        if dx > 1e-12:
            best = min(best, self.front_m / dx)
        if dx < -1e-12:
            best = min(best, -self.back_m / dx)
        if dy > 1e-12:
            best = min(best, self.left_m / dy)
        if dy < -1e-12:
            best = min(best, -self.right_m / dy)
        for px, py, radius in self.pillars:
            along = px * dx + py * dy
            miss2 = px * px + py * py - along * along
            if along > 0 and miss2 <= radius * radius:
                best = min(best, along - math.sqrt(radius * radius - miss2))
        return best


def crc8_bitwise(data: bytes) -> int:
    """CRC-8, polynomial 0x4D, init 0, MSB first, as LDRobot specifies (computed bit by bit)."""
    crc = 0
    for byte in data:
        crc ^= byte
        for _ in range(8):
            crc = ((crc << 1) ^ 0x4D) & 0xFF if crc & 0x80 else (crc << 1) & 0xFF
    return crc


def ld19_packet(speed_dps: int, start_cdeg: int, points: list[tuple[int, int]], end_cdeg: int, stamp_ms: int,
                good_crc: bool = True) -> bytes:
    """One 47-byte LD19 packet."""
    body = struct.pack("<BBHH", 0x54, 0x2C, speed_dps, start_cdeg)
    for distance_mm, intensity in points:
        body += struct.pack("<HB", distance_mm, intensity)
    body += struct.pack("<HH", end_cdeg, stamp_ms % 30000)
    crc = crc8_bitwise(body)
    return body + bytes([crc if good_crc else crc ^ 0x5A])


class FakeLd19(RoomLidar):
    """An LD19 streaming a synthetic room on a pty; use as a context manager, open ``port`` at 230400."""

    thread_name = "fake-ld19"

    def __init__(self, rate_hz: float = 10.0, points_per_s: float = 4500.0, room: SyntheticRoom | None = None,
                 max_range_m: float = 12.0) -> None:
        super().__init__(room if room is not None else SyntheticRoom(), max_range_m)
        self.rate_hz = rate_hz
        """Rotation rate of the head, Hz (also what the speed field says)."""
        self.points_per_s = points_per_s
        self.silent = False
        """While True nothing is sent (an unplugged or dead device)."""
        self.bad_crc_next = 0
        """The next this-many packets go out with a wrong CRC."""
        self.split_next = 0
        """The next this-many packets go out in two writes, 30 ms apart."""
        self.packets_sent = 0
        self.bad_crc_sent = 0
        self._phase_deg = 0.0

    def _packet(self, stamp_ms: int) -> bytes:
        speed = int(round(self.rate_hz * 360.0))
        step = self.rate_hz * 360.0 / self.points_per_s
        start = self._phase_deg
        points = []
        for i in range(12):
            cw = (start + i * step) % 360.0
            r = self.room.range_m(-math.radians(cw))
            distance = 0 if r > self.max_range_m else int(round(r * 1000.0))
            points.append((distance, 200 if distance else 0))
        end = (start + 11 * step) % 360.0
        self._phase_deg = (start + 12 * step) % 360.0
        good = self.bad_crc_next <= 0
        if not good:
            # A corrupted packet's points read 7.777 m, so a test sees it if the driver let it through.
            points = [(7777, 99)] * 12
            self.bad_crc_next -= 1
            self.bad_crc_sent += 1
        return ld19_packet(speed, int(round(start * 100)) % 36000, points, int(round(end * 100)) % 36000,
                           stamp_ms, good_crc=good)

    def _run(self) -> None:
        t0 = time.monotonic()
        due = 0.0
        last = t0
        while not self._stop.is_set():
            time.sleep(STEP_S)
            now = time.monotonic()
            due += (now - last) * self.points_per_s / 12.0
            last = now
            out = bytearray()
            with self._lock:
                if self.silent:
                    due = 0.0
                    continue
                out += self._garbage
                self._garbage.clear()
                split = None
                while due >= 1.0:
                    due -= 1.0
                    packet = self._packet(int((now - t0) * 1000.0))
                    self.packets_sent += 1
                    if self.split_next > 0 and split is None:
                        self.split_next -= 1
                        split = len(out) + 20
                    out += packet
            if split is not None:
                self._write(bytes(out[:split]))
                time.sleep(0.03)
                self._write(bytes(out[split:]))
            elif out:
                self._write(bytes(out))
