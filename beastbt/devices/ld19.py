"""The LDRobot LD19 (sold by Waveshare as the D500) 2D LiDAR: its one-way packet stream, decoded.

The protocol, as LDRobot documents it (LD19 development manual, "communication
protocol"; and its reference driver, ldrobotSensorTeam/ldlidar_stl_ros2,
``ldlidar_driver/include/dataprocess/lipkg.h`` and ``src/dataprocess/lipkg.cpp``):
230400 baud, 8N1, the device talks as soon as it has power and never listens.
Each 47-byte packet, little-endian::

    0x54  0x2C  speed(u16, deg/s)  start_angle(u16, 0.01 deg)
    12 x [distance(u16, mm)  intensity(u8)]
    end_angle(u16, 0.01 deg)  timestamp(u16, ms, wraps at 30000)  crc8

The CRC-8 covers the first 46 bytes: polynomial 0x4D, initial value 0, no
reflection, no final XOR (LDRobot's 256-entry ``CrcTable`` is that
polynomial's table; :data:`CRC_TABLE` is generated from it and the tests
check it against entries of LDRobot's table). The 12 points' angles are
spread evenly from the start to the end angle, across 360 when the packet
wraps; angles are clockwise seen from above, a distance of 0 is no return.

:class:`Ld19Lidar` finds packets by their two header bytes, drops and counts
those whose CRC fails (then looks for the next header one byte further on,
so garbage and cut packets cost only themselves), keeps a half packet for the
next read, drops packets while the head spins slower than ``min_rate_hz``
(spinning up or stalling), and gives one :class:`LaserScan` per revolution
with the rate the device reports (speed / 360).

Each read is decoded at once with NumPy (a 20 Hz poll sees ~25 packets):
the headers are found in one pass, the CRCs of all the candidates come from
one table look-up per byte (:func:`crc8_rows`), and only the walk that
decides which candidates are packets (a good CRC skips the 47 bytes it
covers, a bad one only its header byte) runs in Python, once per candidate.
The fields, angles and revolution starts of the packets are then computed
for all of them together (benchmarks/lidar_decode.py).
"""

from __future__ import annotations

import bisect
import struct
from typing import Optional

import numpy as np

from beastbt.devices.lidar_scan import LaserScan, LidarConfig, RevolutionAssembler, SerialLidar

HEADER = 0x54
"""First byte of every packet."""
VER_LEN = 0x2C
"""Second byte: version 1 (top 3 bits) and 12 points per packet (low 5 bits)."""
POINTS_PER_PACKET = 12
PACKET_BYTES = 47
"""Header, VerLen, speed 2, start 2, 12 x 3, end 2, timestamp 2, CRC 1."""
CRC_POLY = 0x4D
"""LDRobot's CRC-8 polynomial (their CrcTable[1])."""
TIMESTAMP_WRAP_MS = 30000
"""The packet timestamp counts milliseconds modulo this."""
_HEADER_BYTES = bytes((HEADER, VER_LEN))
_FIELDS = np.dtype([("header", "u1"), ("verlen", "u1"), ("speed", "<u2"), ("start", "<u2"),
                    ("points", [("mm", "<u2"), ("intensity", "u1")], (POINTS_PER_PACKET,)),
                    ("end", "<u2"), ("stamp", "<u2"), ("crc", "u1")])
"""One packet as a NumPy record (47 bytes, packed): a (k, 47) block of packets viewed as k of these."""
assert _FIELDS.itemsize == PACKET_BYTES
_OFFSETS = np.arange(PACKET_BYTES)
_SCALARS = struct.Struct("<2xHH36xHH")
"""Speed, start angle, end angle and timestamp from a packet's first 46 bytes."""
_POINT_STEPS = np.arange(POINTS_PER_PACKET, dtype=np.float64)


def _crc_table(poly: int) -> tuple[int, ...]:
    table = []
    for byte in range(256):
        crc = byte
        for _ in range(8):
            crc = ((crc << 1) ^ poly) & 0xFF if crc & 0x80 else (crc << 1) & 0xFF
        table.append(crc)
    return tuple(table)


CRC_TABLE = _crc_table(CRC_POLY)
"""The CRC-8 (poly 0x4D) lookup table, equal to LDRobot's ``CrcTable``."""


def crc8(data: bytes) -> int:
    """LDRobot's CRC-8 of ``data`` (table-driven, initial 0)."""
    crc = 0
    for byte in data:
        crc = CRC_TABLE[crc ^ byte]
    return crc


def _position_tables(n: int) -> np.ndarray:
    # The CRC starts at 0 and has no final XOR, so it is linear over GF(2): the CRC of n bytes is the XOR of
    # the CRCs of each byte alone at its place, zeros elsewhere. A byte v last gives TABLE[v]; each zero byte
    # after it applies TABLE once more. Row i of the (n, 256) result is what byte i contributes.
    out = np.zeros((n, 256), dtype=np.uint8)
    out[n - 1] = CRC_TABLE
    table = np.array(CRC_TABLE, dtype=np.uint8)
    for pos in range(n - 2, -1, -1):
        out[pos] = table[out[pos + 1]]
    return out


_CRC_AT = _position_tables(PACKET_BYTES - 1).ravel()
_CRC_BASE = np.arange(PACKET_BYTES - 1, dtype=np.intp) * 256


def crc8_rows(rows: np.ndarray) -> np.ndarray:
    """LDRobot's CRC-8 of each row of ``rows`` ((k, 46) uint8: packets without their CRC byte), all at once."""
    return np.bitwise_xor.reduce(_CRC_AT[rows + _CRC_BASE], axis=1)


def packet_angles_deg(start_cdeg: int, end_cdeg: int) -> list[float]:
    """The 12 points' angles (degrees clockwise, in [0, 360)) from a packet's start and end (0.01 deg)."""
    span = ((end_cdeg - start_cdeg) % 36000) / 100.0
    step = span / (POINTS_PER_PACKET - 1)
    start = start_cdeg / 100.0
    return [(start + i * step) % 360.0 for i in range(POINTS_PER_PACKET)]


class Ld19Lidar(SerialLidar):
    """LD19 / D500 driver: packets from a serial port in, one :class:`LaserScan` per revolution out.

    Call :meth:`poll` every tick. :attr:`stats` counts packets, CRC failures,
    garbage bytes and packets dropped while spinning up; :meth:`is_stale`
    tells a silent device. ``last_speed_dps`` is the latest packet's speed
    (degrees per second) and ``last_timestamp_ms`` its timestamp.
    """

    label = "LiDAR (LD19)"
    model_type = "ld19"

    last_speed_dps: Optional[int] = None
    last_timestamp_ms: Optional[int] = None

    def __init__(self, *args, **kwargs) -> None:  # type: ignore[no-untyped-def]
        super().__init__(*args, **kwargs)
        self._assembler: _PacketRevolution = _PacketRevolution(self.config)
        self._speeds: list[int] = []
        self._spinning_up_reported = False

    @property
    def spinning_up(self) -> bool:
        """True while the latest packet's speed is below ``min_rate_hz`` (no scans are given then)."""
        return self.last_speed_dps is not None and self.last_speed_dps < self.config.spinning_below_hz * 360.0

    def _decode(self, now_s: float) -> list[LaserScan]:
        buf = self._rx
        n = len(buf)
        data = bytes(buf)  # a copy: a NumPy view would pin the bytearray, which is cut below
        heads = []
        at = data.find(_HEADER_BYTES)
        while at >= 0:
            heads.append(at)
            at = data.find(_HEADER_BYTES, at + 1)
        full = bisect.bisect_right(heads, n - PACKET_BYTES)  # the candidates with all their 47 bytes here
        if full:
            rows = np.frombuffer(data, dtype=np.uint8)[np.array(heads[:full])[:, None] + _OFFSETS]
            good = (crc8_rows(rows[:, :-1]) == rows[:, -1]).tolist()
        # Which candidates are packets, in stream order: a good CRC takes its 47 bytes (headers seen inside
        # them are data), a bad one only its header byte (it may have been garbage that looked like one).
        stats = self.stats
        pos = 0
        taken: list[int] = []
        half = False
        for i, start in enumerate(heads):
            if start < pos:
                continue
            stats.garbage_bytes += start - pos
            if i >= full:
                pos = start  # half a packet: wait for the rest
                half = True
                break
            if not good[i]:
                stats.crc_failures += 1
                self._bad.report("lidar_crc", f"dropped a packet with a bad CRC ({stats.crc_failures} so far)", now_s)
                stats.garbage_bytes += 1
                pos = start + 1
                continue
            taken.append(i)
            pos = start + PACKET_BYTES
        if not half:
            # Keep a last 0x54: it may be the first half of a header.
            keep = max(pos, n - 1) if n and data[-1] == HEADER else n
            stats.garbage_bytes += keep - pos
            pos = keep
        del buf[:pos]
        if not taken:
            return []
        return self._packets(data, [heads[i] for i in taken], now_s)

    def _packets(self, data: bytes, starts: list[int], now_s: float) -> list[LaserScan]:
        """Good packets (at ``starts`` in ``data``, stream order) into revolutions: spin-up, where each
        revolution starts, and the scans they complete."""
        stats = self.stats
        stats.packets += len(starts)
        slow_below = self.config.spinning_below_hz * 360.0
        assembler = self._assembler
        speeds = self._speeds
        unpack = _SCALARS.unpack_from
        scans: list[LaserScan] = []
        segment: list[int] = []  # where this read's packets of the revolution in progress start in data
        # The loop runs for every packet (375 a second): state in locals, written back once after it.
        last_deg = assembler.last_deg  # the latest point's angle; NaN after a reset: no comparison holds
        reported = self._spinning_up_reported
        speed = stamp_ms = 0
        for at in starts:
            speed, start_cdeg, end_cdeg, stamp_ms = unpack(data, at)
            if speed < slow_below:
                stats.spinup_packets += 1
                assembler.reset()
                last_deg = assembler.last_deg
                speeds.clear()
                segment.clear()
                if not reported:
                    self._events("lidar_spinning_up", f"{self.label}: the head turns at {speed / 360.0:.1f} Hz, "
                                                      f"below {self.config.spinning_below_hz:g} Hz: no scans until "
                                                      f"it is at speed")
                    reported = True
                continue
            reported = False
            # Where a new revolution starts in this packet: the angle falls back by more than half a turn (at
            # most once per packet: 12 points span a few degrees). The angles are packet_angles_deg's; a packet
            # that does not pass 360 has them rising from its start, so only its first point can fall back.
            first = start_cdeg / 100.0
            last = first + (POINTS_PER_PACKET - 1) * ((((end_cdeg - start_cdeg) % 36000) / 100.0)
                                                      / (POINTS_PER_PACKET - 1))
            cut = -1
            if last < 360.0:
                if first + 180.0 < last_deg:
                    cut = 0
            else:
                prev = last_deg
                for k, deg in enumerate(packet_angles_deg(start_cdeg, end_cdeg)):
                    if deg + 180.0 < prev:
                        cut = k
                        break
                    prev = deg
                last %= 360.0
            segment.append(at)
            if cut >= 0:
                rate = sum(speeds) / len(speeds) / 360.0 if speeds else speed / 360.0
                assembler.keep(data, segment)
                scan = assembler.close(cut, now_s, rate)
                if scan is not None:
                    scans.append(scan)
                speeds.clear()
                segment = [at]
            last_deg = last
            speeds.append(speed)
        assembler.keep(data, segment)
        assembler.last_deg = last_deg
        self._spinning_up_reported = reported
        self.last_speed_dps, self.last_timestamp_ms = speed, stamp_ms
        return scans


class _PacketRevolution(RevolutionAssembler):
    """The LD19's revolution in progress, kept as its packets' bytes until it ends, then decoded at once.

    ``packets`` holds the revolution's packets back to back; it starts at
    point ``skip`` of the first one. A reset (spin-up, a lost port) forgets
    them with the rest.
    """

    def __init__(self, config: LidarConfig) -> None:
        super().__init__(config)
        self.packets = bytearray()
        self.skip = 0

    def reset(self) -> None:
        """Forget the revolution in progress, packets included."""
        super().reset()
        self.packets.clear()
        self.skip = 0

    @property
    def last_deg(self) -> float:
        """The angle of the latest point seen (clockwise degrees; NaN after a reset)."""
        return self._last_deg

    @last_deg.setter
    def last_deg(self, deg_cw: float) -> None:
        self._last_deg = deg_cw

    def keep(self, data: bytes, starts: list[int]) -> None:
        """Add the packets at ``starts`` in ``data`` to the revolution (unless it is a partial one)."""
        if self._complete_start:
            self.packets += b"".join([data[at:at + PACKET_BYTES] for at in starts])

    def close(self, cut: int, stamp_s: float, rate_hz: float) -> Optional[LaserScan]:
        """End the revolution at point ``cut`` of its last packet: its scan (None if it was partial); the next
        one starts there, with that packet."""
        scan = None
        if self._complete_start:
            fields = np.frombuffer(bytes(self.packets), dtype=_FIELDS)
            start = fields["start"]
            span = (fields["end"].astype(np.int64) - start) % 36000
            # packet_angles_deg for all the packets at once.
            degs = ((start / 100.0)[:, None] + _POINT_STEPS * (span / 100.0 / (POINTS_PER_PACKET - 1))[:, None])
            end = len(fields) * POINTS_PER_PACKET - POINTS_PER_PACKET + cut
            points = fields["points"]
            self.extend((degs.ravel() % 360.0)[self.skip:end], points["mm"].ravel()[self.skip:end],
                        points["intensity"].ravel()[self.skip:end])
        scan = self.take(stamp_s, rate_hz)
        self.packets.clear()
        self.skip = cut
        return scan


__all__ = ["Ld19Lidar", "crc8", "crc8_rows", "CRC_TABLE", "packet_angles_deg", "PACKET_BYTES", "HEADER", "VER_LEN"]
