"""What the 2D LiDAR drivers share: the scan, the settings, the counters and the serial-port plumbing.

A :class:`LaserScan` is one revolution of the head, as ROS's
``sensor_msgs/LaserScan`` would carry it but with the measured angles kept
(the LD19 and the RPLIDAR A1 do not sample at fixed increments): angles in
radians counterclockwise in the LiDAR's frame (REP 103; both vendors count
clockwise, the drivers turn that round), ranges in metres with NaN for "no
return" (no echo, outside ``range_m``, or in an ``ignore_deg`` sector).

:class:`SerialLidar` is the part both drivers (:mod:`beastbt.devices.ld19`,
:mod:`beastbt.devices.rplidar`) inherit: it reads a :class:`SerialLike`
without blocking, reopens a port that failed, assembles points into one scan
per revolution (:class:`RevolutionAssembler`), masks them, keeps
:class:`LidarStats` and tells when the LiDAR has gone silent. Time comes from
the injected clock only.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Callable, Optional, Sequence

import numpy as np
import serial

from beastbt.core.clock import Clock
from beastbt.core.config import check_config_keys
from beastbt.core.config import require_number as _require_number
from beastbt.blackboard.types import LaserScan
from beastbt.core.schema_defaults import schema_defaults
from beastbt.devices.interfaces import EventSink, SerialLike, ignore_events
from beastbt.devices.reopening_port import PortReopener

LIDAR_MODELS: dict[str, dict[str, Any]] = {
    "ld19": {"name": "LDRobot LD19", "baud": 230400, "range_m": (0.02, 12.0), "min_rate_hz": 5.0},
    "rplidar_a1": {"name": "Slamtec RPLIDAR A1", "baud": 115200, "range_m": (0.15, 12.0), "min_rate_hz": 2.0},
}
"""Each model's port speed, the ranges it measures (metres, datasheets: LD19 0.02-12 m, A1 0.15-12 m) and the
rotation rate below which its motor counts as spinning up (Hz)."""

STARTUP_GRACE_S = 3.0
"""No "silent" event before the first scan within this long of start (an A1 takes 1-2 s to spin up), s."""

MAX_READ_BYTES = 65536
"""Most bytes taken from the port in one poll (230400 baud is 23 kB/s: a 20 Hz poll sees ~1.2 kB)."""


@dataclass(frozen=True)
@schema_defaults("parts/lidar.schema.json#/properties/mounting")
class LidarMounting:
    """Where the LiDAR sits on the robot (base_link: x forward, y left, z up), metres, and its yaw, degrees."""

    x_m: float
    y_m: float
    z_m: float
    yaw_deg: float
    """Its 0 degree mark, counterclockwise from the robot's forward."""


@dataclass
@schema_defaults("parts/lidar.schema.json", required=("type",),
                 computed={"mounting": "a nested config with its own schema (LidarMounting)"})
class LidarConfig:
    """Settings of a 2D LiDAR driver (the ``lidar`` section of a robot profile); see the schema for each knob."""

    type: str
    """``ld19`` or ``rplidar_a1`` (no default: the profile says which is fitted)."""
    port: str
    """Serial device of the LiDAR."""
    baud: Optional[int]
    """Baud rate; None = the model's."""
    mounting: LidarMounting = field(default_factory=LidarMounting)
    """Where it sits on the robot."""
    range_m: Optional[tuple[float, float]]
    """[min, max] kept, metres; None = the model's."""
    ignore_deg: list[list[float]]
    """Sectors masked out, degrees counterclockwise in the LiDAR's frame, [from, to] counterclockwise."""
    min_rate_hz: Optional[float]
    """Below this rotation rate the motor is spinning up and no scan is given, Hz; None = the model's."""
    stale_after_s: float
    """No scan for longer than this is a silent LiDAR, seconds."""
    reopen_interval_s: float
    """How often to reopen a failed port (and re-ask a silent RPLIDAR to scan), seconds."""
    answer_timeout_s: float
    """RPLIDAR: how long to wait for an answer before asking again, seconds."""
    bad_data_event_interval_s: float
    """Bad-data events at most this often after the first, seconds."""

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "LidarConfig":
        """Build a config from a profile dict; unknown keys or bad values raise ``ValueError``."""
        check_config_keys(d, cls, "lidar")
        if "type" not in d:
            raise ValueError(f"lidar needs a type: one of {', '.join(LIDAR_MODELS)}")
        cfg = cls(type=d["type"])
        for name, value in d.items():
            if name == "mounting":
                if not isinstance(value, dict):
                    raise ValueError("mounting must be a mapping {x_m, y_m, z_m, yaw_deg}")
                bad = sorted(set(value) - {"x_m", "y_m", "z_m", "yaw_deg"})
                if bad:
                    raise ValueError(f"unknown mounting key(s): {', '.join(map(str, bad))} "
                                     f"(known: x_m, y_m, z_m, yaw_deg)")
                for key, number in value.items():
                    _require_number(f"mounting.{key}", number)
                value = LidarMounting(**value)
            elif name == "range_m" and value is not None:
                if not isinstance(value, (list, tuple)) or len(value) != 2:
                    raise ValueError(f"range_m must be [min, max] in metres, got {value!r}")
                value = (float(_require_number("range_m[0]", value[0], minimum=0.0)),
                         float(_require_number("range_m[1]", value[1], positive=True)))
            setattr(cfg, name, value)
        cfg.validate()
        return cfg

    def validate(self) -> None:
        """Check every value; raise ``ValueError`` naming the first bad one."""
        if self.type not in LIDAR_MODELS:
            raise ValueError(f"type must be one of {', '.join(LIDAR_MODELS)}, got {self.type!r}")
        if not isinstance(self.port, str) or not self.port:
            raise ValueError(f"port must be a device path, got {self.port!r}")
        if self.baud is not None and (isinstance(self.baud, bool) or not isinstance(self.baud, int) or self.baud <= 0):
            raise ValueError(f"baud must be a positive integer or null, got {self.baud!r}")
        lo, hi = self.limits_m
        if not lo < hi:
            raise ValueError(f"range_m must be [min, max] with min < max, got [{lo}, {hi}]")
        if not isinstance(self.ignore_deg, list):
            raise ValueError("ignore_deg must be a list of [from, to] sectors in degrees")
        for i, sector in enumerate(self.ignore_deg):
            if not isinstance(sector, (list, tuple)) or len(sector) != 2:
                raise ValueError(f"ignore_deg[{i}] must be [from, to] in degrees, got {sector!r}")
            for j, value in enumerate(sector):
                _require_number(f"ignore_deg[{i}][{j}]", value)
        if self.min_rate_hz is not None:
            _require_number("min_rate_hz", self.min_rate_hz, positive=True)
        for name in ("stale_after_s", "reopen_interval_s", "answer_timeout_s"):
            _require_number(name, getattr(self, name), positive=True)
        _require_number("bad_data_event_interval_s", self.bad_data_event_interval_s, minimum=0.0)

    @property
    def model(self) -> dict[str, Any]:
        """The model's constants (:data:`LIDAR_MODELS`)."""
        return LIDAR_MODELS[self.type]

    @property
    def port_baud(self) -> int:
        """The baud rate the port is opened at (bits/s)."""
        return int(self.baud) if self.baud is not None else int(self.model["baud"])

    @property
    def limits_m(self) -> tuple[float, float]:
        """[min, max] distances kept, metres."""
        lo, hi = self.range_m if self.range_m is not None else self.model["range_m"]
        return float(lo), float(hi)

    @property
    def spinning_below_hz(self) -> float:
        """The rotation rate below which the motor counts as spinning up, Hz."""
        return float(self.min_rate_hz if self.min_rate_hz is not None else self.model["min_rate_hz"])


@dataclass
class LidarStats:
    """What a LiDAR driver has seen since it started (counts, and the latest rate)."""

    bytes_read: int = 0
    packets: int = 0
    """Good packets (LD19) or samples (RPLIDAR) decoded."""
    crc_failures: int = 0
    """LD19 packets dropped for a CRC mismatch; RPLIDAR samples dropped for a bad check/start bit pair."""
    garbage_bytes: int = 0
    """Bytes skipped while looking for the next packet or answer."""
    spinup_packets: int = 0
    """Packets (LD19) or samples (RPLIDAR) dropped because the motor was not at speed yet."""
    scans: int = 0
    """Revolutions given out."""
    points_per_scan: int = 0
    """Points in the latest scan."""
    scan_rate_hz: float = 0.0
    """Rotation rate of the latest scan, Hz."""
    port_errors: int = 0
    reasons: dict[str, int] = field(default_factory=dict)
    """Other counted conditions by name."""


_last_points: tuple = (None, None, None)
"""The last scan :func:`base_points_xy` turned, its mounting and its points: the collision monitor, the
obstacle condition, the local costmap and the console all ask for the same scan in one tick."""


def base_points_xy(scan: LaserScan, mounting: LidarMounting) -> np.ndarray:
    """The returns of ``scan`` as (n, 2) x, y in metres in base_link (x forward, y left), through ``mounting``
    (no-return points left out): what a costmap or a collision monitor works in. Read-only: the same array
    is handed to every reader of the same scan."""
    global _last_points
    last_scan, last_mounting, last = _last_points  # one read: another thread may swap the tuple
    if last_scan is scan and last_mounting == mounting:
        return last
    ok = np.isfinite(scan.ranges_m)
    r = scan.ranges_m[ok]
    a = scan.angles_rad[ok]
    if mounting.yaw_deg:
        a = a + math.radians(mounting.yaw_deg)  # the LiDAR's angles turned into base_link's
    # Filled in place: fewer temporary arrays than a rotation of points_xy (a collision monitor does this at
    # every scan).
    out = np.empty((len(r), 2))
    np.multiply(r, np.cos(a), out=out[:, 0])
    np.multiply(r, np.sin(a), out=out[:, 1])
    if mounting.x_m or mounting.y_m:
        out += (mounting.x_m, mounting.y_m)
    out.setflags(write=False)
    _last_points = (scan, mounting, out)
    return out


def ccw_rad_from_cw_deg(deg_cw: np.ndarray) -> np.ndarray:
    """Vendor angles (degrees clockwise, 0-360) to REP 103 radians counterclockwise in [-pi, pi)."""
    rad = -np.radians(deg_cw)
    return (rad + math.pi) % (2.0 * math.pi) - math.pi


def sector_mask(angles_rad: np.ndarray, sectors_deg: Sequence[Sequence[float]]) -> np.ndarray:
    """True for angles inside any [from, to] sector (degrees counterclockwise, from 'from' to 'to')."""
    mask = np.zeros(angles_rad.shape, dtype=bool)
    deg = np.degrees(angles_rad) % 360.0
    for start, end in sectors_deg:
        a, b = float(start) % 360.0, float(end) % 360.0
        width = (b - a) % 360.0
        mask |= ((deg - a) % 360.0) <= width
    return mask


class RevolutionAssembler:
    """Collects points (vendor angles, clockwise degrees) and hands out one :class:`LaserScan` per revolution.

    A revolution ends where the next point starts a new one: the angle falls
    back by more than half a turn (LD19) or the device flags it (RPLIDAR's S
    bit). The first revolution is usually partial (the driver started
    mid-turn) and is dropped, as are revolutions cut by :meth:`reset`.
    """

    def __init__(self, config: LidarConfig) -> None:
        self._config = config
        # Points come one by one (append: the RPLIDAR) into lists, or a packet's worth at once (extend: the
        # LD19, NumPy arrays) into chunks; take() joins them in order. Lists stay for append: a NumPy append
        # per point would cost more than the list's.
        self._chunks: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
        self._deg: list[float] = []
        self._mm: list[float] = []
        self._intensity: list[float] = []
        self._last_deg = math.nan
        self._complete_start = False

    def _clear(self) -> None:
        self._chunks.clear()
        self._deg.clear()
        self._mm.clear()
        self._intensity.clear()

    def reset(self) -> None:
        """Forget the revolution in progress (the next one starts clean after a new-revolution mark)."""
        self._clear()
        self._last_deg = math.nan
        self._complete_start = False

    def starts_revolution(self, deg_cw: float, new_revolution: Optional[bool] = None) -> bool:
        """True when a point at ``deg_cw`` starts a new revolution (call :meth:`take` before appending it then).

        ``new_revolution`` None: decided from the angle falling back by more than 180 degrees.
        """
        if new_revolution is None:
            new_revolution = not math.isnan(self._last_deg) and deg_cw + 180.0 < self._last_deg
        self._last_deg = deg_cw
        return bool(new_revolution)

    @property
    def last_deg(self) -> float:
        """The angle of the latest point seen (clockwise degrees; NaN after a reset)."""
        return self._last_deg

    @property
    def collecting(self) -> bool:
        """True when the revolution in progress began at a revolution's start (its scan will be given)."""
        return self._complete_start

    def extend(self, degs_cw: Sequence[float], distances_mm: Sequence[float], intensities: Sequence[float]) -> None:
        """Store points of one revolution at once (the caller split them at the revolution's start); sequences
        or 1-D NumPy arrays of equal length."""
        if len(degs_cw):
            self._flush_points()
            self._chunks.append((np.asarray(degs_cw, dtype=np.float64), np.asarray(distances_mm, dtype=np.float64),
                                 np.asarray(intensities, dtype=np.float64)))
            self._last_deg = float(degs_cw[-1])

    def _flush_points(self) -> None:
        if self._deg:
            self._chunks.append((np.asarray(self._deg, dtype=np.float64), np.asarray(self._mm, dtype=np.float64),
                                 np.asarray(self._intensity, dtype=np.float64)))
            self._deg.clear()
            self._mm.clear()
            self._intensity.clear()

    def append(self, deg_cw: float, distance_mm: float, intensity: float) -> None:
        """Store a point in the revolution in progress."""
        self._deg.append(deg_cw)
        self._mm.append(distance_mm)
        self._intensity.append(intensity)

    def take(self, stamp_s: float, rate_hz: float) -> Optional[LaserScan]:
        """The revolution collected so far as a scan (None if it was partial), and start a new one."""
        scan = None
        if self._complete_start and (self._deg or self._chunks):
            self._flush_points()
            cfg = self._config
            chunks = self._chunks
            if len(chunks) == 1:
                deg, mm, intensity = chunks[0]
            else:
                deg, mm, intensity = (np.concatenate([c[i] for c in chunks]) for i in range(3))
            angles = ccw_rad_from_cw_deg(deg)
            ranges = mm / 1000.0
            lo, hi = cfg.limits_m
            bad = ~((ranges >= lo) & (ranges <= hi))
            if cfg.ignore_deg:
                bad |= sector_mask(angles, cfg.ignore_deg)
            ranges[bad] = np.nan
            # A copy when the chunk's array is the scan's: the scan owns its arrays.
            scan = LaserScan(stamp_s=stamp_s, angles_rad=angles, ranges_m=ranges,
                             intensities=intensity.copy() if len(chunks) == 1 else intensity,
                             scan_rate_hz=rate_hz, model=cfg.type)
        self._clear()
        self._complete_start = True
        return scan


class BadDataEvents:
    """Rate-limits bad-data events: the first at once, then at most one summary per interval."""

    def __init__(self, events: EventSink, interval_s: float, label: str) -> None:
        self._events = events
        self._interval_s = interval_s
        self._label = label
        self._last_s: Optional[float] = None
        self._suppressed = 0

    def report(self, kind: str, text: str, stamp_s: float) -> None:
        """Report ``text`` now if it is the first or the interval has passed, else count it."""
        if self._last_s is None:
            self._last_s = stamp_s
            self._events(kind, f"{self._label}: {text}; further ones are counted and reported at most every "
                               f"{self._interval_s:g} s")
        elif stamp_s - self._last_s >= self._interval_s:
            count = self._suppressed + 1
            self._events(kind, f"{self._label}: {count} more in the last {stamp_s - self._last_s:.1f} s ({text})")
            self._last_s = stamp_s
            self._suppressed = 0
        else:
            self._suppressed += 1


class SerialLidar:
    """The serial side every LiDAR driver shares: non-blocking reads, reopening, staleness, stats.

    Subclasses implement :meth:`_decode` (bytes in ``self._rx`` to scans) and
    may override :meth:`_on_open` (what to send to a freshly opened port) and
    :meth:`_on_poll` (timeouts of a request/response protocol). Call
    :meth:`poll` every tick; it never blocks and never raises.
    """

    label = "LiDAR"
    model_type = "ld19"
    """The ``type`` this driver speaks (for a default config)."""

    def __init__(self, port: Optional[SerialLike], clock: Clock, events: EventSink = ignore_events, *,
                 open_port: Optional[Callable[[], SerialLike]] = None,
                 config: Optional[LidarConfig] = None) -> None:
        self.config = config if config is not None else LidarConfig(type=self.model_type)
        self.config.validate()
        self._port = port
        self._clock = clock
        self._events = events
        self.stats = LidarStats()
        """Counts of bytes, packets, failures and scans; the latest rate and points per scan."""
        self._rx = bytearray()
        self._assembler = RevolutionAssembler(self.config)
        self._bad = BadDataEvents(events, self.config.bad_data_event_interval_s, self.label)
        self._latest: Optional[LaserScan] = None
        self._started_s = clock.now()
        self._silent_reported = False
        self._reopener = PortReopener(events, "lidar", self.label, self.config.port, open_port,
                                      self.config.reopen_interval_s, lost_reported=port is None)
        self._opened = False
        self._last_read_s = self._started_s
        self._read_from = 0
        self._read_span = (self._started_s, self._started_s)

    # --- public state -------------------------------------------------------------------------
    @property
    def latest_scan(self) -> Optional[LaserScan]:
        """The most recent revolution, or None before the first."""
        return self._latest

    @property
    def port_open(self) -> bool:
        """True while the driver holds a working port."""
        return self._port is not None

    def silent_for_s(self, now_s: float) -> float:
        """Seconds since the latest scan (since start when there has been none)."""
        last = self._latest.stamp_s if self._latest is not None else self._started_s
        return now_s - last

    def is_stale(self, now_s: float) -> bool:
        """True when no scan came for longer than ``stale_after_s`` (or the port is lost)."""
        return self._port is None or self.silent_for_s(now_s) > self.config.stale_after_s

    # --- the port -----------------------------------------------------------------------------
    def _lose_port(self, now_s: float, exc: BaseException) -> None:
        port, self._port = self._port, None
        self._rx.clear()
        self._assembler.reset()
        self.stats.port_errors += 1
        self._reopener.lost(now_s, port, exc, "scans stop")

    def _try_open(self, now_s: float) -> bool:
        port = self._reopener.reopen(now_s)
        if port is None:
            return False
        self._port = port
        self._rx.clear()
        self._opened = False
        return True

    def _write(self, data: bytes, now_s: float) -> bool:
        port = self._port
        if port is None:
            return False
        try:
            port.write(data)
        except (serial.SerialException, OSError) as exc:
            self._lose_port(now_s, exc)
            return False
        return True

    # --- reading ------------------------------------------------------------------------------
    def poll(self) -> list[LaserScan]:
        """Read what is waiting (non-blocking); return the revolutions completed since the last poll.

        Never raises: port errors close the port (reopened every
        ``reopen_interval_s``), bad bytes are counted and skipped.
        """
        now_s = self._clock.now()
        scans: list[LaserScan] = []
        if self._port is None and not self._try_open(now_s):
            self._check_silence(now_s)
            return scans
        if not self._opened:
            self._opened = True
            self._on_open(now_s)
        port = self._port
        if port is not None:
            try:
                waiting = port.in_waiting
                data = port.read(min(waiting, MAX_READ_BYTES)) if waiting else b""
            except (serial.SerialException, OSError) as exc:
                self._lose_port(now_s, exc)
                data = b""
            if data:
                self.stats.bytes_read += len(data)
                # Where this read's bytes start in the buffer and the span they arrived over (for drivers that
                # time samples within a read: a stream arrives evenly between two reads).
                self._read_from = len(self._rx)
                self._read_span = (self._last_read_s, now_s)
                self._rx += data
                scans = self._decode(now_s)
            self._last_read_s = now_s
        self._on_poll(now_s)
        for scan in scans:
            self._emit(scan)
        self._check_silence(now_s)
        return scans

    def _emit(self, scan: LaserScan) -> None:
        self._latest = scan
        self.stats.scans += 1
        self.stats.points_per_scan = len(scan)
        self.stats.scan_rate_hz = scan.scan_rate_hz
        if self._silent_reported:
            self._events("lidar_back", f"{self.label}: scans again ({scan.scan_rate_hz:.1f} Hz)")
            self._silent_reported = False

    def _check_silence(self, now_s: float) -> None:
        if self._latest is None and self._port is not None and now_s - self._started_s < STARTUP_GRACE_S:
            return  # the first scan takes a spin-up and a revolution: stale, but not worth an event yet
        if not self._silent_reported and self.is_stale(now_s):
            spinning = " (the motor is not at speed)" if self.stats.spinup_packets and self.stats.scans == 0 else ""
            self._events("lidar_silent", f"{self.label}: no scan for {self.silent_for_s(now_s):.1f} s{spinning}")
            self._silent_reported = True

    def _arrival_s(self, end: int) -> float:
        """When the byte before ``end`` (an index in ``self._rx`` during :meth:`_decode`) arrived, estimated
        by spreading the latest read's bytes evenly over the time since the read before."""
        first, (t0, t1) = self._read_from, self._read_span
        n = len(self._rx) - first
        if n <= 0 or end <= first:
            return t0
        return t0 + (t1 - t0) * min(1.0, (end - first) / n)

    def _count(self, reason: str, n: int = 1) -> None:
        self.stats.reasons[reason] = self.stats.reasons.get(reason, 0) + n

    # --- for subclasses -----------------------------------------------------------------------
    def _on_open(self, now_s: float) -> None:
        """Called once for each newly opened port, before its first read."""

    def _on_poll(self, now_s: float) -> None:
        """Called at the end of each poll (timeouts)."""

    def _decode(self, now_s: float) -> list[LaserScan]:
        """Consume ``self._rx``; return completed scans (not yet emitted)."""
        raise NotImplementedError

    def close(self) -> None:
        """Close the port (the subclass may say goodbye to the device first)."""
        port, self._port = self._port, None
        if port is not None:
            try:
                port.close()
            except Exception:  # noqa: BLE001 - closing a vanished port may fail; it is gone anyway
                pass


__all__ = ["LaserScan", "LidarConfig", "LidarMounting", "LidarStats", "LIDAR_MODELS", "RevolutionAssembler",
           "SerialLidar", "BadDataEvents", "base_points_xy", "ccw_rad_from_cw_deg", "sector_mask"]
