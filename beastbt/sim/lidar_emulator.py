"""Emulated 2D LiDARs: an LDRobot LD19 and a Slamtec RPLIDAR A1 that ray-cast the simulated world.

Each emulator writes its model's bytes into a :class:`~beastbt.sim.serial_port.SimSerialPort`
that the real driver (:mod:`beastbt.devices.ld19`, :mod:`beastbt.devices.rplidar`)
reads, as the Waveshare and GPS emulators do: one code path from the bytes on.

What a LiDAR sees is cast by :class:`RayCaster` from the LiDAR's pose
(the robot's true pose composed with the profile's ``lidar.mounting``):
walls and box sides as segments, cylinders and persons as circles, persons
where they are at the time of the cast (:attr:`ContactWorld.person_xy`, so a
person stopped by the robot is seen stopped), other robots of a shared world
as circles where the fleet last put them (:attr:`ContactWorld.others_xy`). All of it is vectorised
(rays x segments, rays x circles: one matrix product per cast). Rays are cast in chunks (half a revolution's
points at once, :data:`CHUNKS_PER_REVOLUTION`, with the pose at the chunk's start) and the chunk's bytes are
fed to the port as their points' times come, so the driver reads them at the
model's byte rate and a revolution's points span the revolution's time (the
LD19's port, :class:`PacedPort`, feeds them when the driver reads: the same
bytes, without work at every physics step).

Noise, per point: a Gaussian range error (:attr:`LidarModel.range_sigma_m`
plus a part proportional to range), a dropout probability (no return), and
no return beyond the model's range. Draws come from the emulator's own
generator (see :meth:`beastbt.sim.robot.Simulator.stream_rng`), so adding a
LiDAR shifts no other emulator's noise. Time is the simulator's only.

Protocols, as the vendors document them (and as the drivers' docstrings cite):

* LD19: one-way stream of 47-byte packets ``0x54 0x2C speed start 12x(dist, intensity) end timestamp crc8``,
  angles clockwise in 0.01 degree, CRC-8 poly 0x4D; ~4500 points/s at 10 Hz (0.8 degree steps).
* RPLIDAR A1: requests ``0xA5 cmd``; GET_HEALTH / GET_INFO answer a descriptor (``0xA5 0x5A``, length | mode << 30,
  type) and a body; SCAN answers a descriptor (length 5, mode 1, type 0x81) then 5-byte samples until STOP or
  RESET (which reboots and prints a banner). The motor spins while DTR is low; samples only come at speed.
"""

from __future__ import annotations

import bisect
import math
import struct
from dataclasses import dataclass
from typing import Any, Optional, Sequence

import numpy as np

from beastbt.sim.cpu_account import LIDAR, SIM_CPU
from beastbt.sim.obstacles import BoxObstacle, CylinderObstacle, Person
from beastbt.sim.serial_port import SimSerialPort

CHUNKS_PER_REVOLUTION = 2
"""Casts per revolution: each casts half a turn's points at once, with the poses at that half's start (the robot
moves at most a few centimetres in it: 0.35 m/s x 0.09 s for the A1); more casts cost more NumPy calls."""

NO_HIT = np.inf


@dataclass(frozen=True)
class LidarModel:
    """What an emulated LiDAR measures and how fast: rate (Hz), points per second, range (m) and noise."""

    rate_hz: float
    points_per_s: float
    range_m: tuple[float, float]
    range_sigma_m: float
    """Constant part of the range noise's standard deviation, m."""
    range_sigma_ratio: float
    """Part of the range noise's standard deviation proportional to the range (dimensionless)."""
    dropout: float
    """Probability that a point inside the range has no return."""
    intensity: int
    """The intensity (LD19, 0-255) or quality (A1, 0-63) of a return."""

    @property
    def step_deg(self) -> float:
        """Angle between consecutive points, degrees."""
        return 360.0 * self.rate_hz / self.points_per_s


LD19_MODEL = LidarModel(rate_hz=10.0, points_per_s=4500.0, range_m=(0.02, 12.0), range_sigma_m=0.01,
                        range_sigma_ratio=0.005, dropout=0.01, intensity=200)
"""LD19 datasheet: 10 Hz, 4500 points/s (0.8 degree), 0.02-12 m, about +-10 mm at short range, worse far."""
A1_MODEL = LidarModel(rate_hz=5.5, points_per_s=2000.0, range_m=(0.15, 12.0), range_sigma_m=0.01,
                      range_sigma_ratio=0.01, dropout=0.02, intensity=47)
"""RPLIDAR A1M8 datasheet: 5.5 Hz, 2000 samples/s (~1 degree), 0.15-12 m, 1 % of the range (2 % below 3 m)."""
MODELS = {"ld19": LD19_MODEL, "rplidar_a1": A1_MODEL}


class RayCaster:
    """Distances from a point along many directions to the nearest wall or obstacle of a world (m).

    Built once per world: walls and box sides become one (m, 4) segment
    array, cylinders a circle array; persons are circles whose centres are
    passed at each cast (where they are then).
    """

    def __init__(self, walls: Sequence[Any], obstacles: Sequence[Any]) -> None:
        segs: list[tuple[float, float, float, float]] = [(w.x1, w.y1, w.x2, w.y2) for w in walls]
        circles: list[tuple[float, float, float]] = []
        radii: list[float] = []
        for o in obstacles:
            if isinstance(o, BoxObstacle):
                c = o.corners()
                segs += [(*c[i], *c[(i + 1) % 4]) for i in range(4)]
            elif isinstance(o, CylinderObstacle):
                circles.append((o.x, o.y, o.radius_m))
            elif isinstance(o, Person):
                radii.append(o.radius_m)
        s = np.array(segs, dtype=float).reshape(-1, 4)
        self._p = s[:, :2]
        self._e = s[:, 2:] - s[:, :2]
        self._ex, self._ey = self._e[:, 0].copy(), self._e[:, 1].copy()
        c = np.array(circles, dtype=float).reshape(-1, 3)
        self._circ_c = c[:, :2]
        self._circ_r = c[:, 2]
        self.person_r = np.array(radii, dtype=float)
        """Each person's radius, in the world's order of persons (m)."""
        m, k = len(s), len(c) + len(radii)
        # One matrix product per cast gives every ray-times-thing term (see cast); its columns: m of (ey, -ex),
        # m of (-wy, wx), then k of (wx, wy) for the circles and the persons. The edges' columns never change.
        self._matrix = np.zeros((2, 2 * m + k))
        self._matrix[0, :m] = self._e[:, 1]
        self._matrix[1, :m] = -self._e[:, 0]
        self._segments = m
        self._radii2 = np.concatenate((self._circ_r, self.person_r)) ** 2
        self._centres = np.vstack((self._circ_c, np.zeros((len(radii), 2))))

    def cast(self, ox: float, oy: float, angles: np.ndarray, person_xy: Optional[np.ndarray] = None) -> np.ndarray:
        """Distance from (``ox``, ``oy``) along each world angle (rad, CCW from east) to the first thing hit; inf
        where nothing is."""
        m = self._segments
        centres = self._centres
        if len(self.person_r):
            if person_xy is None or not len(person_xy):
                centres = self._circ_c  # no persons given: only the fixed circles
            else:
                centres[len(self._circ_c):] = person_xy
        k = len(centres)
        if m + k == 0:
            return np.full(angles.shape, NO_HIT)
        d = np.empty((len(angles), 2))
        np.cos(angles, out=d[:, 0])
        np.sin(angles, out=d[:, 1])
        matrix = self._matrix[:, :2 * m + k]
        w = self._p - (ox, oy)
        matrix[0, m:2 * m] = -w[:, 1]
        matrix[1, m:2 * m] = w[:, 0]
        c = centres - (ox, oy)
        matrix[:, 2 * m:] = c.T
        terms = d @ matrix
        with np.errstate(divide="ignore", invalid="ignore"):
            # Ray o + t d meets segment p + u e where t = (w x e) / (d x e), u = (w x d) / (d x e), w = p - o;
            # d x e and w x d are the product's first 2m columns.
            denom = terms[:, :m]
            t = (w[:, 0] * self._ey - w[:, 1] * self._ex) / denom
            u = terms[:, m:2 * m] / denom
            hit = np.where((u >= 0.0) & (u <= 1.0) & (t > 0.0), t, NO_HIT)
            if k:
                # Circles: b, the distance along the ray to the closest approach, is the last k columns.
                b = terms[:, 2 * m:]
                disc = b * b - ((c * c).sum(axis=1) - self._radii2[:k])
                root = np.sqrt(disc)
                near = b - root
                t = np.where(near > 0.0, near, b + root)  # from inside a circle: its far side
                hit = np.concatenate((hit, np.where((disc >= 0.0) & (t > 0.0), t, NO_HIT)), axis=1)
        return hit.min(axis=1)


def cast_circles(ox: float, oy: float, angles: np.ndarray, centres: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """Distance from (``ox``, ``oy``) along each world angle (rad) to the first of the circles (centres m, radii m)
    hit; inf where none is (from inside a circle: its far side, as :meth:`RayCaster.cast`)."""
    d = np.stack((np.cos(angles), np.sin(angles)), axis=1)
    c = centres - (ox, oy)
    b = d @ c.T
    disc = b * b - ((c * c).sum(axis=1) - radii * radii)
    with np.errstate(invalid="ignore"):
        root = np.sqrt(disc)
    near = b - root
    t = np.where(near > 0.0, near, b + root)
    return np.where((disc >= 0.0) & (t > 0.0), t, NO_HIT).min(axis=1)


class LidarEmulator:
    """What both models share: the world, the mounting, the noise and the chunked casting on the sim clock.

    ``truth`` is the robot's true pose (:class:`~beastbt.sim.truth.RobotTruth`), ``contact`` the world's
    :class:`~beastbt.sim.contact.ContactWorld` (for the persons' positions; None without obstacles), ``mounting``
    the profile's (x_m, y_m, yaw_deg) on base_link.
    """

    def __init__(self, model: LidarModel, caster: RayCaster, truth: Any, contact: Any,
                 mounting: tuple[float, float, float], rng: np.random.Generator) -> None:
        self.model = model
        self.caster = caster
        self.truth = truth
        self.contact = contact
        self.mount_x, self.mount_y = float(mounting[0]), float(mounting[1])
        self.mount_yaw = math.radians(float(mounting[2]))
        self.rng = rng
        self.port = SimSerialPort("sim-lidar", on_write=self.on_write)
        self.next_point = 0
        """Index of the next point to measure since the head started; point k is at k / points_per_s."""
        self.t0_s = 0.0
        """When point 0 was measured (sim s)."""
        self._pending: list[list[Any]] = []
        """Cast chunks not yet all sent: [item times (s), bytes, bytes per item, items sent]."""
        self.casts = 0
        """Chunks cast so far."""
        self.chunk_s = 1.0 / (model.rate_hz * CHUNKS_PER_REVOLUTION)
        """The sampling time one cast covers, s."""
        self.silent_until_s = -math.inf
        """Until this sim time (s) the head sends nothing (a fault a mission test injects): what it measures
        meanwhile is lost, as from a device that went quiet on a live port."""

    def on_write(self, data: bytes) -> None:
        """What the driver writes (the LD19 listens to nothing)."""

    def measure(self, first: int, count: int) -> tuple[np.ndarray, np.ndarray]:
        """The ``count`` points from index ``first``: device angles (degrees clockwise, 0-360) and distances in mm
        (0 = no return), cast now from the LiDAR's true pose."""
        m = self.model
        k = np.arange(first, first + count, dtype=float)
        deg_cw = (k * m.step_deg) % 360.0
        t = self.truth
        c, s = math.cos(t.yaw), math.sin(t.yaw)
        ox = t.x + c * self.mount_x - s * self.mount_y
        oy = t.y + s * self.mount_x + c * self.mount_y
        angles = t.yaw + self.mount_yaw - np.radians(deg_cw)
        persons = self.contact.person_xy if self.contact is not None and len(self.caster.person_r) else None
        r = self.caster.cast(ox, oy, angles, persons)
        others = self.contact.others if self.contact is not None else ()
        if others:  # other robots of a shared world, where the fleet last said they were
            r = np.minimum(r, cast_circles(ox, oy, angles, self.contact.others_xy,
                                           np.array([o.radius_m for o in others])))
        self.casts += 1
        lo, hi = m.range_m
        noise = self.rng.standard_normal(count)
        drop = self.rng.random(count) < m.dropout
        with np.errstate(invalid="ignore"):
            # No hit (inf) stays inf or turns NaN with the noise: either fails the range test below.
            r = r + noise * (m.range_sigma_m + m.range_sigma_ratio * r)
            kept = (r >= lo) & (r <= hi) & ~drop
        return deg_cw, np.round(np.where(kept, r, 0.0) * 1000.0)

    def queue(self, times_s: Any, data: bytes) -> None:
        """Send ``data``, made of ``len(times_s)`` equal items (an array or a list of times, s, rising), each once
        the sim clock reaches its time."""
        # A list for bisect: flush runs often, where np.searchsorted's call costs more.
        times = times_s.tolist() if isinstance(times_s, np.ndarray) else list(times_s)
        self._pending.append([times, data, len(data) // len(times), 0])

    def due(self, now_s: float) -> bool:
        """True when some queued item's time has come by ``now_s`` (what :meth:`flush` would feed)."""
        pending = self._pending
        return bool(pending) and pending[0][0][pending[0][3]] <= now_s + 1e-9

    def flush(self, now_s: float) -> None:
        """Feed the port every queued item whose time has come."""
        pending = self._pending
        if not pending or pending[0][0][pending[0][3]] > now_s + 1e-9:
            return  # nothing due (most physics steps between two packets)
        out = []
        while pending:
            times, data, size, sent = pending[0]
            due = bisect.bisect_right(times, now_s + 1e-9)
            if due > sent:
                out.append(data[sent * size:due * size])
                pending[0][3] = due
            if due < len(times):
                break
            pending.pop(0)
        if out and now_s >= self.silent_until_s:
            self.port.feed(b"".join(out))


# -- LD19 ---------------------------------------------------------------------------------------------------

LD19_POINTS = 12
_LD19_DTYPE = np.dtype([("header", "u1"), ("verlen", "u1"), ("speed", "<u2"), ("start", "<u2"),
                        ("points", [("mm", "<u2"), ("intensity", "u1")], (LD19_POINTS,)),
                        ("end", "<u2"), ("stamp", "<u2"), ("crc", "u1")])
assert _LD19_DTYPE.itemsize == 47


def _crc_table() -> np.ndarray:
    table = []
    for byte in range(256):
        crc = byte
        for _ in range(8):
            crc = ((crc << 1) ^ 0x4D) & 0xFF if crc & 0x80 else (crc << 1) & 0xFF
        table.append(crc)
    return np.array(table, dtype=np.uint8)


_CRC_TABLE = _crc_table()


def _position_tables(n: int) -> np.ndarray:
    # LDRobot's CRC-8 starts at 0 with no final XOR, so it is linear over GF(2): the CRC of a packet is the XOR
    # of the CRCs of each of its bytes alone at its place. A byte v at the last place gives TABLE[v]; each zero
    # byte after it applies TABLE once more. One (n, 256) table then turns a packet's CRC into one look-up per
    # byte and a reduction, for all packets at once.
    out = np.zeros((n, 256), dtype=np.uint8)
    out[n - 1] = _CRC_TABLE
    for pos in range(n - 2, -1, -1):
        out[pos] = _CRC_TABLE[out[pos + 1]]
    return out


_CRC_AT = _position_tables(46)
_CRC_FLAT = _CRC_AT.ravel()
_CRC_BASE = np.arange(46, dtype=np.intp) * 256


def ld19_crc8(packets: np.ndarray) -> np.ndarray:
    """LDRobot's CRC-8 (poly 0x4D, init 0) of each row of ``packets`` ((n, 46) uint8), for all rows at once."""
    if packets.shape[1] == _CRC_AT.shape[0]:
        # Row-major flat table: one gather instead of a two-index one.
        return np.bitwise_xor.reduce(_CRC_FLAT[packets + _CRC_BASE], axis=1)
    table = _position_tables(packets.shape[1])
    return np.bitwise_xor.reduce(table[np.arange(packets.shape[1]), packets], axis=1)


class PacedPort(SimSerialPort):
    """The LD19's port: its bytes are fed when the driver looks (a read, ``in_waiting``), each batch the ones
    whose time has come by the device's latest update, instead of at every physics step.

    What the driver sees is the same (it reads only between steps), for a
    fifth of the work: the physics runs at 100 Hz, the tick loop reads at
    20 Hz. Unplugging and replugging catch up first, so what came before
    stays and what came while unplugged is lost, as on an eagerly fed port.
    """

    def __init__(self, name: str, device: "SimLd19") -> None:
        super().__init__(name, on_write=device.on_write)
        self._device = device

    def _catch_up(self) -> None:
        device = self._device
        if not SIM_CPU.enabled or not device.due(device.now_s):
            device.flush(device.now_s)
            return
        outer = SIM_CPU.enter(LIDAR)  # feeding the port is the emulator's work, done when the driver looks
        try:
            device.flush(device.now_s)
        finally:
            SIM_CPU.leave(outer)

    @property
    def in_waiting(self) -> int:
        """Bytes available without blocking."""
        self._catch_up()
        return len(self._rx) if not self.unplugged and self.is_open else super().in_waiting

    def read(self, size: int = 1) -> bytes:
        """Read up to ``size`` bytes (never blocks)."""
        self._catch_up()
        return super().read(size)

    def readline(self) -> bytes:
        """Read up to and including the next newline, or what is there."""
        self._catch_up()
        return super().readline()

    def reset_input_buffer(self) -> None:
        """Drop unread bytes."""
        self._catch_up()
        super().reset_input_buffer()

    def unplug(self) -> None:
        """Make the port vanish: reads and writes raise ``serial.SerialException``."""
        self._catch_up()
        super().unplug()

    def replug(self) -> None:
        """Bring the port back (a driver must reopen it)."""
        self._catch_up()  # while unplugged: dropped, as an eager feed would have
        super().replug()


class SimLd19(LidarEmulator):
    """An LD19 that starts turning at power-up (t = 0) and streams packets for as long as the run lasts."""

    def __init__(self, caster: RayCaster, truth: Any, contact: Any, mounting: tuple[float, float, float],
                 rng: np.random.Generator, model: LidarModel = LD19_MODEL) -> None:
        super().__init__(model, caster, truth, contact, mounting, rng)
        self.port = PacedPort("sim-lidar", self)
        self.now_s = 0.0
        """The latest update's time (sim s): what the port feeds up to when the driver reads."""
        self.packet_s = LD19_POINTS / model.points_per_s
        self.chunk_packets = max(1, int(round(1.0 / (model.rate_hz * CHUNKS_PER_REVOLUTION * self.packet_s))))
        self.chunk_s = self.chunk_packets * self.packet_s
        self._template = np.zeros(self.chunk_packets, dtype=_LD19_DTYPE)
        self._template["header"], self._template["verlen"] = 0x54, 0x2C
        self._template["speed"] = int(round(model.rate_hz * 360.0))
        self._next_cast_s = self.t0_s
        """When the next chunk's first packet starts (sim s)."""

    def packets(self, first_packet: int, count: int, times_s: Optional[list[float]] = None) -> bytes:
        """``count`` packets from packet index ``first_packet``, cast now; ``times_s`` the packets' end times
        (computed when not given)."""
        m = self.model
        deg, mm = self.measure(first_packet * LD19_POINTS, count * LD19_POINTS)
        deg = deg.reshape(count, LD19_POINTS)
        mm = mm.reshape(count, LD19_POINTS)
        out = self._template[:count].copy() if count <= len(self._template) else np.zeros(count, dtype=_LD19_DTYPE)
        if count > len(self._template):
            out["header"], out["verlen"], out["speed"] = 0x54, 0x2C, int(round(m.rate_hz * 360.0))
        ends = np.round(deg[:, ::LD19_POINTS - 1] * 100.0).astype(np.int64) % 36000  # first and last point
        out["start"] = ends[:, 0]
        out["end"] = ends[:, 1]
        points = out["points"]
        points["mm"] = mm
        points["intensity"] = (mm > 0) * m.intensity
        if times_s is None:
            times_s = [self.t0_s + (j + 1) * self.packet_s for j in range(first_packet, first_packet + count)]
        # round() halves to even as np.round does; a few packets: Python is cheaper than four NumPy calls.
        out["stamp"] = [round(t * 1000.0) % 30000 for t in times_s]
        raw = out.view(np.uint8).reshape(count, 47)
        raw[:, 46] = ld19_crc8(raw[:, :46])
        return raw.tobytes()

    def update(self, now_s: float, dt_s: float) -> None:
        """Cast and queue the packets due by the end of the next chunk; the port feeds those due by ``now_s``
        when the driver reads."""
        self.now_s = now_s
        if self._next_cast_s > now_s + 1e-9:
            return
        while True:
            first = self.next_point // LD19_POINTS
            start_s = self.t0_s + first * self.packet_s
            if start_s > now_s + 1e-9:
                break
            n = self.chunk_packets
            times = [self.t0_s + (j + 1) * self.packet_s for j in range(first, first + n)]
            self.queue(times, self.packets(first, n, times))
            self.next_point += n * LD19_POINTS
        self._next_cast_s = self.t0_s + (self.next_point // LD19_POINTS) * self.packet_s


# -- RPLIDAR A1 ---------------------------------------------------------------------------------------------

A1_INFO = bytes((0x18, 29, 1, 7)) + bytes(range(0x10, 0x20))
"""GET_INFO body: model 0x18 (A1M8), firmware minor 29, major 1 (1.29), hardware 7, a 16-byte serial number."""
A1_BANNER = b"RP LIDAR System.\r\nFirmware Ver 1.29 - rc9, HW Ver 7\r\nModel: 18\r\n"
A1_SPINUP_S = 0.8
"""From DTR low to the motor at speed, s (the A1 takes about a second)."""


def a1_descriptor(length: int, mode: int, answer_type: int) -> bytes:
    """An answer descriptor: 0xA5 0x5A, length (30 bits) | mode << 30 as u32 LE, and the type byte."""
    return bytes((0xA5, 0x5A)) + struct.pack("<I", (length & 0x3FFFFFFF) | (mode << 30)) + bytes((answer_type,))


class A1Port(SimSerialPort):
    """The A1's USB adapter: a serial port whose DTR line drives the motor (low = spin)."""

    def __init__(self, device: "SimRplidarA1") -> None:
        super().__init__("sim-rplidar", on_write=device.on_write)
        self._device = device
        self._dtr = True

    @property
    def dtr(self) -> bool:
        """The DTR line (True = set = motor stopped)."""
        return self._dtr

    @dtr.setter
    def dtr(self, value: bool) -> None:
        self._dtr = bool(value)
        self._device.motor(not self._dtr)


class SimRplidarA1(LidarEmulator):
    """An RPLIDAR A1: idle until asked; answers STOP, RESET, GET_INFO, GET_HEALTH and SCAN as the protocol says.

    :attr:`state` is ``idle``, ``scanning`` or ``resetting``; :attr:`requests` lists the commands received.
    """

    def __init__(self, caster: RayCaster, truth: Any, contact: Any, mounting: tuple[float, float, float],
                 rng: np.random.Generator, model: LidarModel = A1_MODEL, health: tuple[int, int] = (0, 0)) -> None:
        super().__init__(model, caster, truth, contact, mounting, rng)
        self.port = A1Port(self)
        self.state = "idle"
        self.health = health
        self.requests: list[int] = []
        self.motor_since_s: Optional[float] = None
        """When the motor was switched on (sim s), None while it is off."""
        self.now_s = 0.0
        self._rx = bytearray()
        self._scan_from_s = 0.0
        self._reset_until_s = 0.0
        self.chunk_points = max(1, int(round(model.points_per_s / (model.rate_hz * CHUNKS_PER_REVOLUTION))))
        self.chunk_s = self.chunk_points / model.points_per_s

    def motor(self, on: bool) -> None:
        """The adapter's DTR changed: the motor starts (spinning up) or stops."""
        if on and self.motor_since_s is None:
            self.motor_since_s = self.now_s
        elif not on:
            self.motor_since_s = None

    def on_write(self, data: bytes) -> None:
        """Requests from the driver: ``0xA5 <cmd>``; anything else is skipped, as the device does."""
        self._rx += data
        while len(self._rx) >= 2:
            if self._rx[0] != 0xA5:
                del self._rx[0]
                continue
            cmd = self._rx[1]
            del self._rx[:2]
            self.requests.append(cmd)
            self._command(cmd)

    def _command(self, cmd: int) -> None:
        if self.state == "resetting":
            return  # rebooting: deaf
        if cmd == 0x25:  # STOP: no answer
            self._stop()
        elif cmd == 0x40:  # RESET: reboot, then the banner
            self._stop()
            self.state = "resetting"
            self._reset_until_s = self.now_s + 0.5
            self.queue(np.array([self._reset_until_s]), A1_BANNER)
        elif cmd == 0x52:  # GET_HEALTH
            status, code = self.health
            self.port.feed(a1_descriptor(3, 0, 0x06) + bytes((status, code & 0xFF, code >> 8)))
        elif cmd == 0x50:  # GET_INFO
            self.port.feed(a1_descriptor(20, 0, 0x04) + A1_INFO)
        elif cmd == 0x20:  # SCAN
            self._stop()
            self.port.feed(a1_descriptor(5, 1, 0x81))
            self.state = "scanning"
            self._scan_from_s = self.now_s
            self.next_point = -1  # set at the first chunk: the head's angle where sampling starts

    def _stop(self) -> None:
        self.state = "idle"
        self._pending.clear()

    def at_speed_s(self) -> Optional[float]:
        """When the motor is (or will be) at speed, sim s; None while it is off."""
        return None if self.motor_since_s is None else self.motor_since_s + A1_SPINUP_S

    def samples(self, first: int, count: int) -> bytes:
        """``count`` 5-byte scan samples from point index ``first``, cast now (S set where a revolution starts)."""
        m = self.model
        deg, mm = self.measure(first, count)
        k = np.arange(first, first + count)
        per_rev = m.points_per_s / m.rate_hz
        new_rev = np.floor(k / per_rev) != np.floor((k - 1) / per_rev)
        quality = np.where(mm > 0, m.intensity, 0)
        s = new_rev.astype(np.int64)
        out = np.empty((count, 5), dtype=np.uint8)
        out[:, 0] = (quality << 2) | ((1 - s) << 1) | s
        q6 = np.round(deg * 64.0).astype(np.int64) & 0x7FFF
        out[:, 1] = ((q6 & 0x7F) << 1) | 1
        out[:, 2] = q6 >> 7
        q2 = np.clip(mm * 4.0, 0, 0xFFFF).astype(np.int64)
        out[:, 3] = q2 & 0xFF
        out[:, 4] = q2 >> 8
        return out.tobytes()

    def update(self, now_s: float, dt_s: float) -> None:
        """Finish a reset, stream the samples due by ``now_s`` while scanning at speed."""
        self.now_s = now_s
        if self.state == "resetting" and now_s >= self._reset_until_s:
            self.state = "idle"
        if self.state == "scanning":
            ready = self.at_speed_s()
            if ready is not None:
                start = max(ready, self._scan_from_s)
                if self.next_point < 0:
                    self.t0_s = 0.0
                    self.next_point = int(math.ceil(start * self.model.points_per_s))
                point_s = 1.0 / self.model.points_per_s
                while self.next_point * point_s <= now_s + 1e-9:
                    first, n = self.next_point, self.chunk_points
                    self.queue((np.arange(first, first + n) + 1) * point_s, self.samples(first, n))
                    self.next_point += n
            else:  # the motor stopped: nothing more, and sampling starts afresh once it is back at speed
                self._pending.clear()
                self.next_point = -1
        self.flush(now_s)


def make_emulator(kind: str, caster: RayCaster, truth: Any, contact: Any, mounting: tuple[float, float, float],
                  rng: np.random.Generator) -> LidarEmulator:
    """The emulator of LiDAR ``kind`` (``ld19`` or ``rplidar_a1``)."""
    if kind == "rplidar_a1":
        return SimRplidarA1(caster, truth, contact, mounting, rng)
    return SimLd19(caster, truth, contact, mounting, rng)


__all__ = ["RayCaster", "LidarModel", "LidarEmulator", "SimLd19", "PacedPort", "SimRplidarA1", "A1Port",
           "make_emulator", "LD19_MODEL", "A1_MODEL", "MODELS", "ld19_crc8", "a1_descriptor", "CHUNKS_PER_REVOLUTION",
           "cast_circles"]
