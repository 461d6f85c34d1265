"""An emulated MTK3339 GPS (Adafruit Ultimate GPS HAT) behind a simulated serial port.

:class:`SimGps` turns the simulated robot's true position into the NMEA
sentences the real receiver would send (GGA, GSA, RMC by default; VTG, GLL,
ZDA on request), with the errors a real one makes: white noise, a slowly
wandering bias (first-order Gauss-Markov), occasional multipath jumps,
dropout windows and a cold start without a fix. It answers the PMTK
configuration commands (``PMTK220`` rate, ``PMTK251`` baud, ``PMTK314``
sentence selection) with ``$PMTK001,<cmd>,<flag>`` like the real firmware.
The driver reads it through :attr:`SimGps.port`, exactly as it reads pyserial.

All randomness comes from the ``numpy.random.Generator`` given; times are the
simulated ``truth.t_s`` seconds; positions metres in the world's ENU frame.
"""

from __future__ import annotations

import datetime as _dt
import math
from dataclasses import dataclass, fields
from typing import Any, Optional

import numpy as np

from beastbt.core.schema_defaults import schema_defaults
from beastbt.core.config import require_number as _number
import pynmea2

from beastbt.devices.nmea_gps import (
    KNOTS_TO_MPS,
    MTK_BAUD_RATES,
    MTK_FACTORY_BAUD,
    MTK_RATE_LIMITS_HZ,
    PMTK314_FIELD_COUNT,
    PMTK314_SLOTS,
    pmtk_sentence,
)
from beastbt.estimation.geodesy import LocalFrame
from beastbt.sim.serial_port import SimSerialPort
from beastbt.sim.truth import RobotTruth

DEFAULT_START_UTC = _dt.datetime(2024, 6, 1, 12, 0, 0, tzinfo=_dt.timezone.utc)
"""UTC at simulated time 0 when none is given (fixed, so runs are reproducible)."""

EMITTABLE_SENTENCES = ("GGA", "GSA", "RMC", "VTG", "GLL", "ZDA")
"""What the emulator can send, in the order an MTK3339 sends them within an epoch."""

_EPS_S = 1e-6
"""Tolerance when comparing simulated times to the output schedule (float ticks), seconds."""




@dataclass
@schema_defaults("parts/gps_sim.schema.json")
class GpsNoiseModel:
    """How the emulated GPS errs and what it sends (the ``gps`` block of a simulated world).

    Defaults are an MTK3339 in open sky at its factory settings: 1 Hz, about
    2.5 m one-sigma per horizontal axis (CEP50 ~3 m, the datasheet's class).
    Errors are per axis (east, north); times are simulated seconds.
    """

    rate_hz: float
    """Output rate at power-on, Hz (MTK3339 factory 1 Hz; PMTK220 can set up to 10)."""
    white_sigma_m: float
    """Independent noise per epoch and horizontal axis, one sigma, metres."""
    bias_sigma_m: float
    """Slowly wandering bias (Gauss-Markov) per horizontal axis, stationary one sigma, metres."""
    bias_tau_s: float
    """Correlation time of the bias, seconds (atmosphere and orbit errors change over minutes)."""
    vertical_factor: float
    """Vertical errors are this many times the horizontal ones."""
    jump_rate_per_s: float
    """Probability per second that a multipath jump starts (0.002 = one every ~8 min)."""
    jump_magnitude_m: float
    """Typical size of a multipath jump, metres (each one is 0.5-1.5x this, random direction)."""
    jump_duration_s: float
    """Typical length of a multipath jump, seconds (each one 0.5-1.5x this)."""
    dropouts_s: list[tuple[float, float]]
    """Windows [start_s, end_s) of simulated time with no fix (tunnel, trees, buildings)."""
    cold_start_s: float
    """Seconds after power-on without a fix (MTK3339: ~35 s cold, ~1 s hot start)."""
    hdop: float
    """Horizontal dilution of precision reported, unitless."""
    sats: int
    """Satellites reported in use."""
    sky: str
    """``open``: fixes as the noise model says; ``none``: indoors, sentences but never a fix."""
    fix_quality: int
    """GGA fix quality reported: 1 GPS, 2 DGPS/SBAS."""
    speed_sigma_mps: float
    """Noise on each horizontal velocity component behind RMC speed and course, m/s."""
    coord_decimals: int
    """Decimals of minutes in the coordinates (MTK3339: 4, ~0.2 m)."""
    sentences: list[str]
    """Sentences sent every epoch at power-on (from GGA, GSA, RMC, VTG, GLL, ZDA)."""
    talker: str
    """Talker id of the sentences (GP for GPS-only receivers like the MTK3339, GN for multi-GNSS)."""

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "GpsNoiseModel":
        """Build a model from a world dict; unknown keys or bad values raise ``ValueError``."""
        if not isinstance(d, dict):
            raise ValueError(f"gps sim model must be a mapping, got {type(d).__name__}")
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(d) - known)
        if unknown:
            raise ValueError(f"unknown gps sim key(s): {', '.join(map(str, unknown))} "
                             f"(known: {', '.join(sorted(known))})")
        model = cls()
        for key, value in d.items():
            if key == "dropouts_s":
                if not isinstance(value, list):
                    raise ValueError("dropouts_s must be a list of [start_s, end_s] pairs")
                windows = []
                for w in value:
                    if not isinstance(w, (list, tuple)) or len(w) != 2:
                        raise ValueError(f"dropouts_s entry {w!r} must be [start_s, end_s]")
                    windows.append((_number("dropouts_s start", w[0]), _number("dropouts_s end", w[1])))
                value = windows
            setattr(model, key, value)
        model.validate()
        return model

    def validate(self) -> None:
        """Check every value; raise ``ValueError`` naming the first bad one."""
        lo, hi = MTK_RATE_LIMITS_HZ
        if not lo <= _number("rate_hz", self.rate_hz, positive=True) <= hi:
            raise ValueError(f"rate_hz must be between {lo} and {hi} Hz, got {self.rate_hz}")
        for name in ("white_sigma_m", "bias_sigma_m", "jump_rate_per_s", "jump_magnitude_m", "cold_start_s",
                     "speed_sigma_mps"):
            _number(name, getattr(self, name), minimum=0.0)
        for name in ("bias_tau_s", "vertical_factor", "jump_duration_s", "hdop"):
            _number(name, getattr(self, name), positive=True)
        for start, end in self.dropouts_s:
            if not end > start:
                raise ValueError(f"dropout window [{start}, {end}] must end after it starts")
        if isinstance(self.sats, bool) or not isinstance(self.sats, int) or not 0 <= self.sats <= 99:
            raise ValueError(f"sats must be an integer 0..99, got {self.sats!r}")
        if self.sky not in ("open", "none"):
            raise ValueError(f"sky must be open or none, got {self.sky!r}")
        if self.fix_quality not in (1, 2, 4, 5, 6, 9):
            raise ValueError(f"fix_quality must be one of 1, 2, 4, 5, 6, 9, got {self.fix_quality!r}")
        decimals = self.coord_decimals
        if isinstance(decimals, bool) or not isinstance(decimals, int) or not 1 <= decimals <= 8:
            raise ValueError(f"coord_decimals must be an integer 1..8, got {self.coord_decimals!r}")
        if not isinstance(self.sentences, list) or any(s not in EMITTABLE_SENTENCES for s in self.sentences):
            raise ValueError(f"sentences must be a list from {list(EMITTABLE_SENTENCES)}, got {self.sentences!r}")
        if not isinstance(self.talker, str) or len(self.talker) != 2 or not self.talker.isalpha():
            raise ValueError(f"talker must be two letters, got {self.talker!r}")


def format_coordinate(value_deg: float, *, is_latitude: bool, decimals: int) -> tuple[str, str]:
    """Encode decimal degrees as NMEA ``(d)ddmm.mmmm`` and its hemisphere letter."""
    hemi = ("N" if value_deg >= 0 else "S") if is_latitude else ("E" if value_deg >= 0 else "W")
    a = abs(value_deg)
    degrees = int(a)
    minutes = round((a - degrees) * 60.0, decimals)
    if minutes >= 60.0:  # rounding carried into the next degree
        degrees += 1
        minutes = 0.0
    width = 3 + decimals  # "mm." plus decimals
    return f"{degrees:0{2 if is_latitude else 3}d}{minutes:0{width}.{decimals}f}", hemi


def _sentence(talker: str, kind: str, data: list[str]) -> bytes:
    msg = pynmea2.TalkerSentence.sentence_types[kind](talker, kind, data)
    return (str(msg) + "\r\n").encode("ascii")


class SimGps:
    """An emulated MTK3339: call :meth:`update` every simulation step; read :attr:`port`.

    Sends one epoch of sentences whenever ``1 / rate_hz`` seconds of simulated
    time have passed (on a fixed grid), encoding the true position
    (``truth.x`` east, ``truth.y`` north, metres in ``frame``) plus noise.
    ``last_reported_enu`` is the (noisy, as encoded) position last sent with a
    fix and ``last_true_enu`` the truth at that moment, both (east, north, up) metres.
    """

    def __init__(self, frame: LocalFrame, model: GpsNoiseModel, rng: np.random.Generator,
                 start_utc: Optional[_dt.datetime] = None) -> None:
        model.validate()
        self.frame = frame
        self.model = model
        self._rng = rng
        start = start_utc if start_utc is not None else DEFAULT_START_UTC
        self.start_utc = start if start.tzinfo is not None else start.replace(tzinfo=_dt.timezone.utc)
        self.port = SimSerialPort("sim-gps", on_write=self._on_write)
        """The receiver's serial port, as the driver sees it."""
        self.rate_hz = float(model.rate_hz)
        """Current output rate, Hz (changed by PMTK220)."""
        self.baud = MTK_FACTORY_BAUD
        """Current baud rate (changed by PMTK251; the in-memory port carries any rate)."""
        self.answer_pmtk = True
        """Set False to emulate firmware that never acknowledges commands (tests)."""
        self.every_n: dict[str, int] = {s: 1 for s in model.sentences}
        """Sentence -> output every N epochs (PMTK314 sets it; 0 or absent = off)."""
        self.epochs = 0
        """Epochs sent so far."""
        self.last_reported_enu: Optional[tuple[float, float, float]] = None
        self.last_true_enu: Optional[tuple[float, float, float]] = None
        self.last_had_fix = False
        """Whether the last epoch sent carried a fix."""
        self._next_due_s: Optional[float] = None
        self._t_power_on: Optional[float] = None
        self._t_last_epoch: Optional[float] = None
        v = model.vertical_factor
        self._axis_scale = np.array([1.0, 1.0, v])
        self._bias = rng.normal(0.0, model.bias_sigma_m, 3) * self._axis_scale
        self._jump: Optional[tuple[float, float, float]] = None  # (east_m, north_m, end_s)
        self._injected: list[tuple[float, float, float, float]] = []  # (start_s, end_s, east_m, north_m)
        self._rx = bytearray()

    # --- test and benchmark hooks ----------------------------------------------------------------
    def inject_jump(self, east_m: float, north_m: float, start_s: float, duration_s: float) -> None:
        """Add a position jump of (east_m, north_m) metres from ``start_s`` for ``duration_s`` seconds."""
        self._injected.append((float(start_s), float(start_s) + float(duration_s), float(east_m), float(north_m)))

    def has_fix_at(self, t_s: float) -> bool:
        """Whether the receiver has a fix at simulated time ``t_s`` (the sky, cold start and dropouts)."""
        if self.model.sky == "none":
            return False
        # Boundaries are widened by _EPS_S so that a clock summed from float ticks (4.9999999...)
        # lands on the side of the boundary it means.
        if self.model.cold_start_s > 0:
            if self._t_power_on is None or t_s - self._t_power_on < self.model.cold_start_s - _EPS_S:
                return False
        return not any(start - _EPS_S <= t_s < end - _EPS_S for start, end in self.model.dropouts_s)

    # --- simulation step ------------------------------------------------------------------------
    def update(self, truth: RobotTruth) -> None:
        """Advance to ``truth.t_s``; send an epoch of sentences when one is due (cheap otherwise)."""
        t = truth.t_s
        if self._next_due_s is not None and t < self._next_due_s - _EPS_S:
            return
        if self._t_power_on is None:
            self._t_power_on = t
        self._emit(truth)
        period = 1.0 / self.rate_hz
        self._next_due_s = (math.floor((t + _EPS_S) / period) + 1) * period

    def _evolve_errors(self, t: float) -> np.ndarray:
        """Advance bias and jump processes to ``t``; return this epoch's total (e, n, u) error, metres."""
        m, rng = self.model, self._rng
        dt = 0.0 if self._t_last_epoch is None else max(0.0, t - self._t_last_epoch)
        self._t_last_epoch = t
        if dt > 0.0:
            a = math.exp(-dt / m.bias_tau_s)
            drive = m.bias_sigma_m * math.sqrt(1.0 - a * a) * rng.normal(0.0, 1.0, 3) * self._axis_scale
            self._bias = a * self._bias + drive
        if self._jump is not None and t >= self._jump[2]:
            self._jump = None
        p_start = -math.expm1(-m.jump_rate_per_s * dt)  # probability a jump starts within dt
        if self._jump is None and p_start > 0.0 and rng.random() < p_start:
            angle = rng.uniform(0.0, 2.0 * math.pi)
            size = m.jump_magnitude_m * rng.uniform(0.5, 1.5)
            self._jump = (size * math.cos(angle), size * math.sin(angle), t + m.jump_duration_s * rng.uniform(0.5, 1.5))
        error = self._bias + rng.normal(0.0, m.white_sigma_m, 3) * self._axis_scale
        if self._jump is not None:
            error[0] += self._jump[0]
            error[1] += self._jump[1]
        for start, end, east, north in self._injected:
            if start - _EPS_S <= t < end - _EPS_S:
                error[0] += east
                error[1] += north
        return error

    def _emit(self, truth: RobotTruth) -> None:
        m = self.model
        t = truth.t_s
        error = self._evolve_errors(t)
        # Velocity noise is drawn every epoch, fix or not, so the random stream does not depend on dropouts.
        vel_noise = self._rng.normal(0.0, m.speed_sigma_mps, 2)
        fix = self.has_fix_at(t)
        utc = self.start_utc + _dt.timedelta(milliseconds=round(t * 1000.0))
        tod = f"{utc.hour:02d}{utc.minute:02d}{utc.second:02d}.{utc.microsecond // 1000:03d}"
        date = f"{utc.day:02d}{utc.month:02d}{utc.year % 100:02d}"
        self.epochs += 1
        self.last_had_fix = fix
        want = [s for s in EMITTABLE_SENTENCES
                if self.every_n.get(s, 0) > 0 and (self.epochs - 1) % self.every_n[s] == 0]
        out = bytearray()
        talker = m.talker
        if not fix:
            for s in want:
                out += _sentence(talker, s, self._no_fix_fields(s, tod, date, utc))
            self.port.feed(bytes(out))
            return
        east, north, up = truth.x + error[0], truth.y + error[1], error[2]
        lat, lon, h = self.frame.to_geodetic(east, north, up)
        lat_s, ns = format_coordinate(lat, is_latitude=True, decimals=m.coord_decimals)
        lon_s, ew = format_coordinate(lon, is_latitude=False, decimals=m.coord_decimals)
        alt_s = f"{h:.1f}"
        # What was actually sent, after rounding: the reference for truth metrics of the driver.
        lat_q = (1 if ns == "N" else -1) * (int(lat_s[:2]) + float(lat_s[2:]) / 60.0)
        lon_q = (1 if ew == "E" else -1) * (int(lon_s[:3]) + float(lon_s[3:]) / 60.0)
        self.last_reported_enu = self.frame.to_enu(lat_q, lon_q, float(alt_s))
        self.last_true_enu = (truth.x, truth.y, 0.0)
        ve = truth.v_mps * math.cos(truth.yaw) + vel_noise[0]
        vn = truth.v_mps * math.sin(truth.yaw) + vel_noise[1]
        speed_kn = math.hypot(ve, vn) / KNOTS_TO_MPS
        course = math.degrees(math.atan2(ve, vn)) % 360.0
        mode = "D" if m.fix_quality == 2 else "A"
        hdop = m.hdop
        for s in want:
            if s == "GGA":
                data = [tod, lat_s, ns, lon_s, ew, str(m.fix_quality), f"{m.sats:02d}", f"{hdop:.2f}", alt_s, "M",
                        "0.0", "M", "", ""]
            elif s == "GSA":
                prns = [f"{p:02d}" for p in range(1, min(m.sats, 12) + 1)] + [""] * (12 - min(m.sats, 12))
                data = ["A", "3", *prns, f"{1.6 * hdop:.2f}", f"{hdop:.2f}", f"{1.3 * hdop:.2f}"]
            elif s == "RMC":
                data = [tod, "A", lat_s, ns, lon_s, ew, f"{speed_kn:.2f}", f"{course:.2f}", date, "", "", mode]
            elif s == "VTG":
                kmh = speed_kn * KNOTS_TO_MPS * 3.6
                data = [f"{course:.2f}", "T", "", "M", f"{speed_kn:.2f}", "N", f"{kmh:.2f}", "K", mode]
            elif s == "GLL":
                data = [lat_s, ns, lon_s, ew, tod, "A", mode]
            else:  # ZDA
                data = [tod, f"{utc.day:02d}", f"{utc.month:02d}", f"{utc.year:04d}", "", ""]
            out += _sentence(talker, s, data)
        self.port.feed(bytes(out))

    @staticmethod
    def _no_fix_fields(s: str, tod: str, date: str, utc: _dt.datetime) -> list[str]:
        """Fields of each sentence when the receiver has no fix (what an MTK3339 sends then)."""
        if s == "GGA":
            return [tod, "", "", "", "", "0", "00", "", "", "M", "", "M", "", ""]
        if s == "GSA":
            return ["A", "1", *([""] * 12), "", "", ""]
        if s == "RMC":
            return [tod, "V", "", "", "", "", "0.00", "0.00", date, "", "", "N"]
        if s == "VTG":
            return ["0.00", "T", "", "M", "0.00", "N", "0.00", "K", "N"]
        if s == "GLL":
            return ["", "", "", "", tod, "V", "N"]
        return [tod, f"{utc.day:02d}", f"{utc.month:02d}", f"{utc.year:04d}", "", ""]

    # --- commands from the driver -----------------------------------------------------------------
    def _on_write(self, data: bytes) -> None:
        self._rx += data
        *lines, tail = self._rx.split(b"\n")
        self._rx = bytearray(tail)
        for raw in lines:
            line = raw.decode("latin-1").strip()
            if not line.startswith("$PMTK"):
                continue
            try:
                msg = pynmea2.parse(line, check=True)
            except pynmea2.ParseError:
                continue  # a corrupted command is ignored by the firmware, no answer
            data_fields = [str(x) for x in msg.data]
            if not data_fields:
                continue
            flag = self._execute(data_fields[0], data_fields[1:])
            if self.answer_pmtk:
                self.port.feed((pmtk_sentence("001", data_fields[0], flag) + "\r\n").encode("ascii"))

    def _execute(self, command: str, args: list[str]) -> str:
        """Apply one PMTK command; return the PMTK001 flag (3 ok, 2 failed, 1 unsupported, 0 invalid)."""
        if command == "220":
            if len(args) != 1 or not args[0].isdigit():
                return "0"
            period_ms = int(args[0])
            if not 100 <= period_ms <= 10000:
                return "2"
            self.rate_hz = 1000.0 / period_ms
            if self._t_last_epoch is not None:
                period = 1.0 / self.rate_hz
                self._next_due_s = (math.floor((self._t_last_epoch + _EPS_S) / period) + 1) * period
            return "3"
        if command == "251":
            if len(args) != 1 or not args[0].isdigit():
                return "0"
            if int(args[0]) not in MTK_BAUD_RATES:
                return "2"
            self.baud = int(args[0])
            return "3"
        if command == "314":
            if args == ["-1"]:
                self.every_n = {s: 1 for s in ("GGA", "GSA", "RMC", "VTG", "GLL")}  # firmware default set
                return "3"
            if len(args) != PMTK314_FIELD_COUNT or not all(a.isdigit() and int(a) <= 5 for a in args):
                return "0"
            self.every_n = {name: int(args[slot]) for name, slot in PMTK314_SLOTS.items()
                            if name in EMITTABLE_SENTENCES and int(args[slot]) > 0}
            return "3"
        return "1"
