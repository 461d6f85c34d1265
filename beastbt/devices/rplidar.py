"""The Slamtec RPLIDAR A1 2D LiDAR: its request/response protocol and its 5-byte scan samples.

The protocol, as Slamtec documents it ("RPLIDAR Interface Protocol and
Application Notes", and the SDK's headers, Slamtec/rplidar_sdk
``sdk/include/sl_lidar_protocol.h`` and ``sdk/include/sl_lidar_cmd.h``):
115200 baud, 8N1. A request is ``0xA5 <cmd>`` (STOP 0x25, RESET 0x40,
SCAN 0x20, GET_INFO 0x50, GET_HEALTH 0x52; none of these carry a payload).
An answer starts with a descriptor ``0xA5 0x5A``, a 32-bit little-endian word
of 30 bits of length and 2 bits of mode (0 single answer, 1 a stream), and a
type byte: INFO (type 0x04, 20 bytes: model, firmware minor, firmware major,
hardware, 16 bytes of serial number), HEALTH (type 0x06, 3 bytes: status
0 good / 1 warning / 2 error, error code u16), SCAN (type 0x81, mode 1, then
5-byte samples until STOP)::

    byte 0: quality(6 bits) << 2 | !S << 1 | S     S = first sample of a new revolution
    byte 1: angle_q6[6:0] << 1 | C                  C = 1 always (check bit)
    byte 2: angle_q6[14:7]                          angle = angle_q6 / 64 degrees, clockwise
    byte 3-4: distance_q2 (u16 LE)                  distance = distance_q2 / 4 mm, 0 = no return

STOP needs no answer; the device wants a moment before the next request
(the SDK waits 1 ms; here the next request goes out on the next poll).
RESET reboots it (it then prints a text banner, skipped here).

The A1 has no motor command: its USB adapter drives the motor from the
port's DTR line, and DTR *low* (cleared) makes it spin. Where this comes
from: the SDK's serial port opens by clearing DTR "to let the motor spin"
(``sdk/src/arch/linux/net_serial.cpp``, ``raw_serial::open``), and its
``setMotorSpeed`` for models without motor control sets DTR for speed 0
and clears it otherwise (``sdk/src/sl_lidar_driver.cpp``). A port that
cannot drive DTR (a pseudo-terminal, some adapters) is reported once; the
motor then runs as the adapter wires it.

:class:`RplidarA1` runs the sequence itself, one step per :meth:`poll`
(never blocking): motor on, STOP, GET_HEALTH, GET_INFO, SCAN, then decodes
samples. It resynchronises after garbage (a sample is taken only when it and
the next one pass their start/check bits; after a failure the next two
must), counts check-bit failures, drops samples until the motor is at speed
(quality-0 samples before the first S bit, revolutions slower than
``min_rate_hz``), re-asks a device that stops answering or goes silent, and
gives one :class:`LaserScan` per revolution with the rate measured on the
clock.
"""

from __future__ import annotations

import collections
import struct
from dataclasses import dataclass
from typing import Optional

import numpy as np
import serial

from beastbt.devices.lidar_scan import LaserScan, SerialLidar

SYNC = 0xA5
"""First byte of every request and of every answer descriptor."""
ANSWER_SYNC = 0x5A
"""Second byte of an answer descriptor."""
CMD_STOP, CMD_RESET, CMD_SCAN, CMD_GET_INFO, CMD_GET_HEALTH = 0x25, 0x40, 0x20, 0x50, 0x52
TYPE_INFO, TYPE_HEALTH, TYPE_SCAN = 0x04, 0x06, 0x81
"""Answer types (the descriptor's last byte)."""
INFO_BYTES, HEALTH_BYTES, SAMPLE_BYTES = 20, 3, 5
DESCRIPTOR_BYTES = 7
HEALTH_STATUS = {0: "good", 1: "warning", 2: "error"}
"""Meaning of the health answer's status byte."""
MODEL_NAMES = {0x18: "A1M8"}
"""Model bytes we can name (the A1M8 answers 0x18; the major model is the byte >> 4)."""
SETTLE_AFTER_STOP_S = 0.002
"""Quiet time after STOP before the next request (the SDK waits 1 ms)."""
SETTLE_AFTER_RESET_S = 1.0
"""Quiet time after RESET (the A1 reboots and prints its banner)."""
MAX_STEP_DEG = 20.0
"""Largest angle step between consecutive samples taken as aligned, degrees (an A1 at 10 Hz and 2000
samples/s steps 1.8 degrees; a misaligned read gives random angles)."""
RATE_WINDOW = 6
"""Revolution starts over which the scan rate is averaged."""


@dataclass(frozen=True)
class RplidarInfo:
    """The GET_INFO answer: model byte, firmware major.minor, hardware revision, serial number (hex)."""

    model: int
    firmware_major: int
    firmware_minor: int
    hardware: int
    serial_hex: str

    @property
    def firmware(self) -> str:
        """``major.minor`` as Slamtec prints it (minor with two digits: 1.29)."""
        return f"{self.firmware_major}.{self.firmware_minor:02d}"

    @property
    def model_name(self) -> str:
        """A readable model (``A1M8``), or the byte in hex."""
        return MODEL_NAMES.get(self.model, f"model 0x{self.model:02x}")


@dataclass(frozen=True)
class RplidarHealth:
    """The GET_HEALTH answer: status 0 good / 1 warning / 2 error, and the device's error code."""

    status: int
    error_code: int

    @property
    def text(self) -> str:
        """``good``, ``warning (code 0x...)`` or ``error (code 0x...)``."""
        name = HEALTH_STATUS.get(self.status, f"unknown status {self.status}")
        return name if self.status == 0 else f"{name} (code 0x{self.error_code:04x})"


def request(cmd: int) -> bytes:
    """A request without payload: ``0xA5 <cmd>``."""
    return bytes((SYNC, cmd))


def sample_ok(b0: int, b1: int) -> bool:
    """True when a sample's start bits differ (S != !S) and its check bit C is 1."""
    return ((b0 ^ (b0 >> 1)) & 1) == 1 and (b1 & 1) == 1


class RplidarA1(SerialLidar):
    """RPLIDAR A1 driver: requests out, answers and samples in, one :class:`LaserScan` per revolution.

    :attr:`state` is the step of the start-up sequence (``stopping``,
    ``health``, ``info``, ``scan_descriptor``, ``scanning``, ``resetting``,
    ``failed``); :attr:`health` and :attr:`info` hold the device's answers.
    """

    label = "LiDAR (RPLIDAR A1)"
    model_type = "rplidar_a1"

    def __init__(self, *args, **kwargs) -> None:  # type: ignore[no-untyped-def]
        super().__init__(*args, **kwargs)
        self.state = "stopping"
        self.health: Optional[RplidarHealth] = None
        self.info: Optional[RplidarInfo] = None
        self.motor_on: Optional[bool] = None
        """What the driver last asked of the motor (DTR), None before it has."""
        self.dtr_works: Optional[bool] = None
        """Whether the port accepted the DTR change (False on a pseudo-terminal)."""
        self.timeouts = 0
        """Requests that got no answer in ``answer_timeout_s``."""
        self.resets = 0
        self._state_s = self._clock.now()
        self._resync = True
        self._last_deg: Optional[float] = None
        self._synced = False  # an S bit seen since SCAN: the motor is at speed
        self._rev_starts: collections.deque[float] = collections.deque(maxlen=RATE_WINDOW)
        self._last_sample_s = self._state_s
        self._timeout_reported = False

    # --- the motor ----------------------------------------------------------------------------
    def set_motor(self, on: bool) -> None:
        """Spin the motor (DTR cleared) or stop it (DTR set), as the A1's USB adapter wires it."""
        self.motor_on = on
        port = self._port
        if port is None:
            return
        try:
            port.dtr = not on  # type: ignore[attr-defined]
            self.dtr_works = True
        except (serial.SerialException, OSError, AttributeError, ValueError) as exc:
            if self.dtr_works is not False:
                self._events("lidar_no_dtr", f"{self.label}: cannot drive DTR on {self.config.port} ({exc}); "
                                             f"the motor runs only if the adapter powers it")
            self.dtr_works = False

    # --- the sequence -------------------------------------------------------------------------
    def _enter(self, state: str, now_s: float) -> None:
        self.state = state
        self._state_s = now_s

    def _send(self, cmd: int, now_s: float) -> None:
        self._write(request(cmd), now_s)

    def _on_open(self, now_s: float) -> None:
        self.set_motor(True)
        self._restart(now_s)

    def _restart(self, now_s: float) -> None:
        self._send(CMD_STOP, now_s)
        self._rx.clear()
        self._assembler.reset()
        self._synced = False
        self._resync = True
        self._last_deg = None
        self._rev_starts.clear()
        self._enter("stopping", now_s)

    def _on_poll(self, now_s: float) -> None:
        if self._port is None:
            return
        waited = now_s - self._state_s
        if self.state == "stopping" and waited >= SETTLE_AFTER_STOP_S:
            self._rx.clear()  # what the device sent before it stopped
            self._send(CMD_GET_HEALTH, now_s)
            self._enter("health", now_s)
        elif self.state == "resetting" and waited >= SETTLE_AFTER_RESET_S:
            self._restart(now_s)
        elif self.state == "failed" and waited >= self.config.reopen_interval_s:
            self._restart(now_s)
        elif self.state in ("health", "info", "scan_descriptor") and waited > self.config.answer_timeout_s:
            self.timeouts += 1
            if not self._timeout_reported:
                self._events("lidar_no_answer", f"{self.label}: no answer to {self.state.replace('_', ' ')} "
                                                f"in {self.config.answer_timeout_s:g} s; asking again")
                self._timeout_reported = True
            self._restart(now_s)
        elif self.state == "scanning" and now_s - self._last_sample_s > self.config.reopen_interval_s:
            self._restart(now_s)  # silent while scanning: ask again (a device that reset by itself)

    # --- decoding -----------------------------------------------------------------------------
    def _decode(self, now_s: float) -> list[LaserScan]:
        if self.state in ("stopping", "resetting", "failed"):
            self.stats.garbage_bytes += len(self._rx)
            self._rx.clear()
            return []
        if self.state in ("health", "info", "scan_descriptor"):
            self._answer(now_s)
        if self.state == "scanning":
            return self._samples(now_s)
        return []

    def _answer(self, now_s: float) -> None:
        expected = {"health": (TYPE_HEALTH, HEALTH_BYTES), "info": (TYPE_INFO, INFO_BYTES),
                    "scan_descriptor": (TYPE_SCAN, SAMPLE_BYTES)}[self.state]
        buf = self._rx
        while True:
            start = buf.find(bytes((SYNC, ANSWER_SYNC)))
            if start < 0:
                keep = 1 if buf and buf[-1] == SYNC else 0
                self.stats.garbage_bytes += len(buf) - keep
                del buf[:len(buf) - keep]
                return
            self.stats.garbage_bytes += start
            del buf[:start]
            if len(buf) < DESCRIPTOR_BYTES:
                return
            (word,) = struct.unpack_from("<I", buf, 2)
            length, answer_type = word & 0x3FFFFFFF, buf[6]
            if (answer_type, length) != expected:
                self.stats.garbage_bytes += 2
                del buf[:2]
                continue
            if self.state == "scan_descriptor":
                del buf[:DESCRIPTOR_BYTES]
                self._timeout_reported = False
                self._last_sample_s = now_s
                self._enter("scanning", now_s)
                return
            if len(buf) < DESCRIPTOR_BYTES + length:
                return
            body = bytes(buf[DESCRIPTOR_BYTES:DESCRIPTOR_BYTES + length])
            del buf[:DESCRIPTOR_BYTES + length]
            self._timeout_reported = False
            if self.state == "health":
                self._on_health(body, now_s)
            else:
                self.info = RplidarInfo(body[0], body[2], body[1], body[3], body[4:20].hex().upper())
                self._send(CMD_SCAN, now_s)
                self._enter("scan_descriptor", now_s)
            return

    def _on_health(self, body: bytes, now_s: float) -> None:
        status, code = body[0], body[1] | (body[2] << 8)
        previous, self.health = self.health, RplidarHealth(status, code)
        if status == 2:
            # Slamtec's advice for a device in protection: reset it, once; then report and retry now and then.
            self._events("lidar_health_error", f"{self.label}: the device reports an error "
                                               f"(code 0x{code:04x}); " + ("resetting it" if self.resets == 0 else
                                                                            "it stays in error after a reset"))
            if self.resets == 0:
                self.resets += 1
                self._send(CMD_RESET, now_s)
                self._enter("resetting", now_s)
            else:
                self._enter("failed", now_s)
            return
        if status == 1 and (previous is None or previous.status != 1):
            self._events("lidar_health_warning", f"{self.label}: the device reports a warning (code 0x{code:04x})")
        self._send(CMD_GET_INFO, now_s)
        self._enter("info", now_s)

    def _aligned(self, buf: bytearray, pos: int, ahead: int) -> bool:
        # Each of the next `ahead` samples passes its start/check bits, and each angle follows the one before
        # (a misaligned read of random bytes passes the bits one time in four, the angle step rarely).
        prev = self._last_deg
        for k in range(ahead):
            at = pos + k * SAMPLE_BYTES
            if not sample_ok(buf[at], buf[at + 1]):
                return False
            deg = ((buf[at + 1] >> 1) | (buf[at + 2] << 7)) / 64.0
            if prev is not None and (deg - prev) % 360.0 > MAX_STEP_DEG:
                return False
            prev = deg
        return True

    def _samples(self, now_s: float) -> list[LaserScan]:
        buf = self._rx
        scans: list[LaserScan] = []
        pos = 0
        n = len(buf)
        while True:
            if not self._resync:
                pos = self._aligned_run(buf, pos, now_s, scans)
            ahead = 3 if self._resync else 2  # this sample and the next one (two after a failure) must pass
            if n - pos < SAMPLE_BYTES * ahead:
                break
            if not self._aligned(buf, pos, ahead):
                if not self._resync:  # counted once per break of an aligned stream, not per skipped byte
                    self.stats.crc_failures += 1
                    self._bad.report("lidar_check_bit", f"skipped samples with bad check bits "
                                                        f"({self.stats.crc_failures} so far)", now_s)
                    self._last_deg = None  # after a break the angle may jump (bytes lost): judge the next ones alone
                self._resync = True
                self.stats.garbage_bytes += 1
                pos += 1
                continue
            self._resync = False
            b0, b1, b2, b3, b4 = buf[pos:pos + SAMPLE_BYTES]
            pos += SAMPLE_BYTES
            self._last_sample_s = now_s
            self.stats.packets += 1
            new_rev = bool(b0 & 1)
            quality = b0 >> 2
            deg = ((b1 >> 1) | (b2 << 7)) / 64.0
            self._last_deg = deg
            mm = (b3 | (b4 << 8)) / 4.0 if quality > 0 else 0.0
            if new_rev:
                scan = self._revolution(now_s, self._arrival_s(pos))
                if scan is not None:
                    scans.append(scan)
                self._synced = True
            elif not self._synced:
                self.stats.spinup_packets += 1  # no revolution mark yet: the motor is not at speed
                continue
            self._assembler.append(deg, mm, quality)
        del buf[:pos]
        return scans

    def _aligned_run(self, buf: bytearray, pos: int, now_s: float, scans: list[LaserScan]) -> int:
        """Take at once (NumPy) the samples from ``pos`` that the loop of :meth:`_samples` would take one by one
        in an aligned stream, as it would; the position after them (``pos`` when there are none)."""
        m = (len(buf) - pos) // SAMPLE_BYTES
        if m < 2:
            return pos
        raw = np.frombuffer(bytes(buf[pos:pos + m * SAMPLE_BYTES]), dtype=np.uint8).reshape(m, SAMPLE_BYTES)
        b0, b1 = raw[:, 0].astype(np.int64), raw[:, 1].astype(np.int64)
        deg = ((b1 >> 1) | (raw[:, 2].astype(np.int64) << 7)) / 64.0
        # As _aligned for each sample: its bits pass and its angle follows the one before (the sample before it,
        # or the last one taken).
        good = (((b0 ^ (b0 >> 1)) & 1) == 1) & ((b1 & 1) == 1)
        good[1:] &= ((deg[1:] - deg[:-1]) % 360.0) <= MAX_STEP_DEG
        if self._last_deg is not None:
            good[0] &= ((deg[0] - self._last_deg) % 360.0) <= MAX_STEP_DEG
        # A sample is taken when it and the next one pass: the run ends before the first that does not.
        both = good[:-1] & good[1:]
        count = int(np.argmin(both)) if not both.all() else m - 1
        if count == 0:
            return pos
        self._last_sample_s = now_s
        self.stats.packets += count
        self._last_deg = float(deg[count - 1])
        quality = b0[:count] >> 2
        mm = np.where(quality > 0, (raw[:count, 3] | (raw[:count, 4].astype(np.int64) << 8)) / 4.0, 0.0)
        deg = deg[:count]
        marks = np.flatnonzero(b0[:count] & 1).tolist()  # new revolutions (S bit)
        begin = marks[0] if marks else count
        if not self._synced:
            self.stats.spinup_packets += begin  # no revolution mark yet: the motor is not at speed
        elif begin:
            self._assembler.extend(deg[:begin], mm[:begin], quality[:begin])
        for k, mark in enumerate(marks):
            scan = self._revolution(now_s, self._arrival_s(pos + (mark + 1) * SAMPLE_BYTES))
            if scan is not None:
                scans.append(scan)
            self._synced = True
            end = marks[k + 1] if k + 1 < len(marks) else count
            self._assembler.extend(deg[mark:end], mm[mark:end], quality[mark:end])
        return pos + count * SAMPLE_BYTES

    def _revolution(self, now_s: float, mark_s: float) -> Optional[LaserScan]:
        # An S bit closes the revolution in progress (the first one is partial and dropped by the assembler).
        # The rate comes from when the marks arrived (estimated within a read), not when they were read: a
        # late poll does not make a revolution look slow.
        self._rev_starts.append(mark_s)
        starts = self._rev_starts
        rate = (len(starts) - 1) / (starts[-1] - starts[0]) if len(starts) > 1 and starts[-1] > starts[0] else 0.0
        scan = self._assembler.take(now_s, rate)
        if scan is not None and rate < self.config.spinning_below_hz:
            self.stats.spinup_packets += len(scan)  # turning too slowly: still spinning up, or stalling
            return None
        return scan

    def close(self) -> None:
        """Ask the device to stop scanning, stop the motor, and close the port."""
        if self._port is not None:
            self._write(request(CMD_STOP), self._clock.now())
            self.set_motor(False)
        super().close()


__all__ = ["RplidarA1", "RplidarInfo", "RplidarHealth", "request", "sample_ok", "CMD_STOP", "CMD_RESET",
           "CMD_SCAN", "CMD_GET_INFO", "CMD_GET_HEALTH", "TYPE_INFO", "TYPE_HEALTH", "TYPE_SCAN"]
