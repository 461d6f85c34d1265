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
"""

from __future__ import annotations

import struct
from typing import Optional

from beastbt.devices.lidar_scan import LaserScan, SerialLidar

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
_PACKET = struct.Struct("<BBHH" + "HB" * POINTS_PER_PACKET + "HHB")
_HEADER_BYTES = bytes((HEADER, VER_LEN))


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
        self._speeds: list[int] = []
        self._spinning_up_reported = False

    @property
    def spinning_up(self) -> bool:
        """True while the latest packet's speed is below ``min_rate_hz`` (no scans are given then)."""
        return self.last_speed_dps is not None and self.last_speed_dps < self.config.spinning_below_hz * 360.0

    def _decode(self, now_s: float) -> list[LaserScan]:
        buf = self._rx
        scans: list[LaserScan] = []
        pos = 0
        while True:
            start = buf.find(_HEADER_BYTES, pos)
            if start < 0:
                # Keep a last 0x54: it may be the first half of a header.
                keep = len(buf) - 1 if buf and buf[-1] == HEADER else len(buf)
                self.stats.garbage_bytes += keep - pos
                pos = keep
                break
            self.stats.garbage_bytes += start - pos
            if len(buf) - start < PACKET_BYTES:
                pos = start  # half a packet: wait for the rest
                break
            packet = bytes(buf[start:start + PACKET_BYTES])
            if crc8(packet[:-1]) != packet[-1]:
                self.stats.crc_failures += 1
                self._bad.report("lidar_crc", f"dropped a packet with a bad CRC "
                                              f"({self.stats.crc_failures} so far)", now_s)
                # The header may have been garbage that looked like one: look again one byte on.
                self.stats.garbage_bytes += 1
                pos = start + 1
                continue
            pos = start + PACKET_BYTES
            scan = self._packet(packet, now_s)
            if scan is not None:
                scans.append(scan)
        del buf[:pos]
        return scans

    def _packet(self, packet: bytes, now_s: float) -> Optional[LaserScan]:
        fields = _PACKET.unpack(packet)
        speed, start_cdeg = fields[2], fields[3]
        end_cdeg, stamp_ms = fields[4 + 2 * POINTS_PER_PACKET], fields[5 + 2 * POINTS_PER_PACKET]
        self.stats.packets += 1
        self.last_speed_dps, self.last_timestamp_ms = speed, stamp_ms
        if self.spinning_up:
            self.stats.spinup_packets += 1
            self._assembler.reset()
            self._speeds.clear()
            if not self._spinning_up_reported:
                self._events("lidar_spinning_up", f"{self.label}: the head turns at {speed / 360.0:.1f} Hz, below "
                                                  f"{self.config.spinning_below_hz:g} Hz: no scans until it is "
                                                  f"at speed")
                self._spinning_up_reported = True
            return None
        self._spinning_up_reported = False
        degs = packet_angles_deg(start_cdeg, end_cdeg)
        distances = fields[4:4 + 2 * POINTS_PER_PACKET:2]
        intensities = fields[5:5 + 2 * POINTS_PER_PACKET:2]
        # Where a new revolution starts in this packet: the angle falls back by more than half a turn
        # (at most once per packet: 12 points span a few degrees).
        assembler = self._assembler
        prev = assembler.last_deg
        cut = -1
        for i, deg in enumerate(degs):
            if deg + 180.0 < prev:  # False while prev is NaN (nothing seen yet)
                cut = i
                break
            prev = deg
        scan = None
        if cut >= 0:
            assembler.extend(degs[:cut], distances[:cut], intensities[:cut])
            rate = sum(self._speeds) / len(self._speeds) / 360.0 if self._speeds else speed / 360.0
            scan = assembler.take(now_s, rate)
            self._speeds.clear()
            assembler.extend(degs[cut:], distances[cut:], intensities[cut:])
        else:
            assembler.extend(degs, distances, intensities)
        self._speeds.append(speed)
        return scan


__all__ = ["Ld19Lidar", "crc8", "CRC_TABLE", "packet_angles_deg", "PACKET_BYTES", "HEADER", "VER_LEN"]
