"""The NMEA 0183 GPS driver: MTK3339 (Adafruit Ultimate GPS HAT) or any NMEA receiver.

:class:`NmeaGps` reads the receiver's byte stream through a :class:`SerialLike`
(pyserial on the robot, :class:`beastbt.sim.serial_port.SimSerialPort` in the
simulator), frames and checksums sentences with pynmea2, and turns GGA, RMC
and GLL sentences that carry a valid fix into :class:`GpsFix` readings
(GSA, VTG and ZDA add DOP, speed/course and the date). Coordinates and times
are converted exactly (decimal arithmetic), not through float minutes.

Bad input (garbage bytes, truncated lines, wrong checksums, unknown
sentences) is counted in :attr:`NmeaGps.stats`, reported through the
:data:`EventSink` (first occurrence, then rate-limited) and skipped; a port
that fails is closed, reported, and reopened with ``open_port`` every
``reopen_interval_s``. Nothing here raises out of :meth:`NmeaGps.poll`.

Optional start-up configuration (``PMTK220`` output rate, ``PMTK251`` baud
rate, ``PMTK314`` sentence selection) is written by :meth:`NmeaGps.configure`
without blocking; :meth:`NmeaGps.poll` watches for the ``$PMTK001`` answers.
"""

from __future__ import annotations

import datetime as _dt
import re
from dataclasses import dataclass, field
from decimal import ROUND_DOWN, Decimal, InvalidOperation
from typing import Any, Callable, Optional

import pynmea2
import serial

from beastbt.core.schema_defaults import schema_defaults
from beastbt.blackboard.types import GpsFix
from beastbt.core.config import check_config_keys
from beastbt.core.config import require_number as _require_number
from beastbt.devices.interfaces import EventSink, SerialLike, ignore_events
from beastbt.devices.reopening_port import PortReopener
from beastbt.core.clock import Clock

KNOTS_TO_MPS = 1852.0 / 3600.0
"""One knot (international nautical mile per hour) in metres per second, exactly."""

MTK_FACTORY_BAUD = 9600
"""Baud rate of an MTK3339 out of the box."""

MAX_LINE_CHARS = 1024
"""A line longer than this without a newline is binary noise, not NMEA (sentences are <= 82
characters; MTK's proprietary channel dumps reach about 250)."""

MAX_READ_BYTES = 65536
"""Most bytes taken from the port in one poll (a 20 Hz poll at 115200 baud sees ~600)."""

PMTK_ACK_FLAGS = {
    "0": "invalid command",
    "1": "unsupported command",
    "2": "valid command, but the action failed",
    "3": "success",
}
"""Meaning of the flag in ``$PMTK001,<cmd>,<flag>`` (MTK NMEA packet manual)."""

PMTK_COMMAND_NAMES = {
    "220": "output period (PMTK220)",
    "251": "baud rate (PMTK251)",
    "314": "sentence selection (PMTK314)",
}
"""The configuration commands this driver sends, for messages."""

PMTK314_SLOTS = {"GLL": 0, "RMC": 1, "VTG": 2, "GGA": 3, "GSA": 4, "GSV": 5, "ZDA": 17}
"""Field index of each sentence in ``PMTK314`` (19 fields; the others are reserved or MTK-private)."""

PMTK314_FIELD_COUNT = 19
"""Number of fields in an MTK3339 ``PMTK314`` command."""

MTK_RATE_LIMITS_HZ = (0.1, 10.0)
"""Output rates an MTK3339 accepts (``PMTK220`` period 100..10000 ms)."""

MTK_BAUD_RATES = (4800, 9600, 14400, 19200, 38400, 57600, 115200)
"""Baud rates ``PMTK251`` accepts."""

DEFAULT_BASE_ERROR_M = {1: 4.0, 2: 0.1, 4: 0.02, 5: 4.0, 9: 3.0}
"""One-sigma horizontal error per unit HDOP, metres, by GGA fix quality (as the ROS NMEA drivers
estimate it): 1 GPS, 2 DGPS, 4 RTK fixed, 5 RTK float, 9 SBAS."""

REJECT_REASONS = ("garbage", "truncated", "no_checksum", "checksum", "malformed", "unknown_type")
"""Why a line can be rejected: binary/non-ASCII bytes or text outside a sentence; a sentence cut
short by the next ``$`` or before its checksum; no ``*hh`` checksum; a checksum that does not
match; a sentence with a valid checksum whose fields make no sense; a sentence type pynmea2
does not know."""

POSITION_SENTENCES = ("GGA", "RMC", "GLL")
"""Sentence types that carry a position."""

_USED_SENTENCES = frozenset({"GGA", "RMC", "GLL", "GSA", "VTG", "ZDA"})
_NUMBER_RE = re.compile(r"^[+-]?(\d+(\.\d*)?|\.\d+)$")
_COORD_RE = re.compile(r"^\d{3,}(\.\d*)?$")
_TOD_RE = re.compile(r"^(\d{2})(\d{2})(\d{2}(?:\.\d*)?)$")
_DATE_RE = re.compile(r"^(\d{2})(\d{2})(\d{2})$")
_HEX2_RE = re.compile(r"^[0-9A-Fa-f]{2}\s*$")
_RMC_MODE_QUALITY = {"A": 1, "D": 2, "R": 4, "F": 5, "E": 6, "M": 7, "S": 8, "P": 1}
"""NMEA 2.3 mode indicator (RMC/GLL/VTG) to the equivalent GGA quality; ``N`` means no fix."""


# --------------------------------------------------------------------------------------------
# configuration




@dataclass
@schema_defaults("parts/gps_device.schema.json", convert={"base_error_m": lambda d: {int(k): v for k, v in d.items()}})
class GpsConfig:
    """Settings of the NMEA GPS driver (the ``gps`` device of a robot profile).

    Every time is in seconds of the injected clock; distances in metres.
    """

    port: str
    """Serial device of the receiver (the Pi 4's GPIO UART for the Adafruit HAT)."""
    port_baud: int
    """Baud rate the port is opened at (9600 = MTK3339 factory setting)."""
    baud: Optional[int]
    """Baud rate to switch the receiver to with PMTK251 at start-up; None leaves it. Raise it
    (57600/115200) before asking for 5-10 Hz with many sentences: 9600 baud carries ~960 chars/s."""
    rate_hz: Optional[float]
    """Output rate to set with PMTK220 (0.1-10 Hz); None leaves the receiver's rate (1 Hz default)."""
    sentences: Optional[list[str]]
    """Sentences to enable with PMTK314, e.g. ["RMC", "GGA"] (from GLL, RMC, VTG, GGA, GSA, GSV,
    ZDA); None leaves the receiver's selection."""
    position_sentences: list[str]
    """Which sentence types give positions (GGA, RMC, GLL). A receiver sending GGA and RMC yields
    two fixes per epoch with the same time; set ["GGA"] to get one per epoch."""
    reopen_interval_s: float
    """How often to try to reopen a port that failed, seconds."""
    stale_after_s: float
    """A fix older than this is stale (2.5 s = two missed epochs at 1 Hz), seconds."""
    ack_timeout_s: float
    """How long to wait for a ``$PMTK001`` answer to a configuration command, seconds."""
    base_error_m: dict[int, float]
    """One-sigma horizontal error per unit HDOP by GGA quality, metres (merged over the
    defaults 1: 4.0, 2: 0.1, 4: 0.02, 5: 4.0, 9: 3.0)."""
    other_quality_error_m: float
    """Base error for qualities not in base_error_m (3 PPS, 6 dead reckoning, 7 manual, 8 simulated), metres."""
    hdop_when_unknown: float
    """HDOP assumed when the receiver has not sent one yet (no GGA/GSA), unitless."""
    vertical_error_factor: float
    """Vertical sigma = this x horizontal sigma (GPS height is ~2x worse, as nmea_navsat_driver assumes)."""
    min_sigma_m: float
    """Floor on the horizontal sigma so that the covariance is never zero, metres."""
    bad_data_event_interval_s: float
    """After the first event for a kind of bad data, report that kind at most this often, seconds."""

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "GpsConfig":
        """Build a config from a profile dict; unknown keys or bad values raise ``ValueError``."""
        check_config_keys(d, cls, "gps")
        kw: dict[str, Any] = dict(d)
        cfg = cls()
        if "base_error_m" in kw:
            merged = dict(DEFAULT_BASE_ERROR_M)
            raw = kw["base_error_m"]
            if not isinstance(raw, dict):
                raise ValueError("base_error_m must be a mapping of fix quality to metres")
            for key, value in raw.items():
                try:
                    quality = int(key)
                except (TypeError, ValueError):
                    raise ValueError(f"base_error_m key {key!r} is not a fix quality number") from None
                merged[quality] = _require_number(f"base_error_m[{key}]", value, positive=True)
            kw["base_error_m"] = merged
        for name, value in kw.items():
            setattr(cfg, name, value)
        cfg.validate()
        return cfg

    def validate(self) -> None:
        """Check every value; raise ``ValueError`` naming the first bad one."""
        if not isinstance(self.port, str) or not self.port:
            raise ValueError(f"port must be a device path, got {self.port!r}")
        if self.port_baud not in MTK_BAUD_RATES:
            raise ValueError(f"port_baud must be one of {MTK_BAUD_RATES}, got {self.port_baud!r}")
        if self.baud is not None and self.baud not in MTK_BAUD_RATES:
            raise ValueError(f"baud must be one of {MTK_BAUD_RATES} or null, got {self.baud!r}")
        if self.rate_hz is not None:
            rate = _require_number("rate_hz", self.rate_hz, positive=True)
            lo, hi = MTK_RATE_LIMITS_HZ
            if not lo <= rate <= hi:
                raise ValueError(f"rate_hz must be between {lo} and {hi} Hz, got {rate}")
        if self.sentences is not None:
            if not isinstance(self.sentences, list) or not all(isinstance(s, str) for s in self.sentences):
                raise ValueError("sentences must be a list of sentence names")
            bad = [s for s in self.sentences if s.upper() not in PMTK314_SLOTS]
            if bad:
                raise ValueError(f"sentences: cannot enable {bad} (choose from {sorted(PMTK314_SLOTS)})")
        if not isinstance(self.position_sentences, list) or not all(
            isinstance(s, str) and s.upper() in POSITION_SENTENCES for s in self.position_sentences
        ):
            raise ValueError(f"position_sentences must be a list from {list(POSITION_SENTENCES)}, "
                             f"got {self.position_sentences!r}")
        for name in ("reopen_interval_s", "stale_after_s", "ack_timeout_s", "other_quality_error_m",
                     "hdop_when_unknown", "vertical_error_factor", "min_sigma_m"):
            _require_number(name, getattr(self, name), positive=True)
        _require_number("bad_data_event_interval_s", self.bad_data_event_interval_s, minimum=0.0)
        for quality, err in self.base_error_m.items():
            _require_number(f"base_error_m[{quality}]", err, positive=True)

    def pmtk_commands(self) -> list[str]:
        """The configuration sentences to send, in order (baud first, then sentences, then rate).

        Each is a full ``$PMTK...*CS`` sentence without line ending.
        """
        out: list[str] = []
        if self.baud is not None:
            out.append(pmtk_sentence("251", str(int(self.baud))))
        if self.sentences is not None:
            slots = ["0"] * PMTK314_FIELD_COUNT
            for name in self.sentences:
                slots[PMTK314_SLOTS[name.upper()]] = "1"
            out.append(pmtk_sentence("314", *slots))
        if self.rate_hz is not None:
            out.append(pmtk_sentence("220", str(int(round(1000.0 / float(self.rate_hz))))))
        return out


def pmtk_sentence(command: str, *fields_: str) -> str:
    """Render ``$PMTK<command>,<fields>*CS`` with the NMEA checksum (XOR between ``$`` and ``*``)."""
    return str(pynmea2.ProprietarySentence("MTK", [command, *fields_]))


# --------------------------------------------------------------------------------------------
# exact field conversions


def parse_coordinate(value: str, hemisphere: str, *, is_latitude: bool) -> float:
    """Convert an NMEA ``(d)ddmm.mmmm`` field and its N/S/E/W letter to decimal degrees.

    The conversion is done in decimal arithmetic and rounded once to float, so
    ``4134.49821229`` gives exactly the nearest double to 41 + 34.49821229/60.
    Raises ``ValueError`` for anything that is not a valid coordinate.
    """
    if not _COORD_RE.match(value):
        raise ValueError(f"not a coordinate: {value!r}")
    hemisphere = hemisphere.upper()
    allowed = ("N", "S") if is_latitude else ("E", "W")
    if hemisphere not in allowed:
        raise ValueError(f"bad hemisphere {hemisphere!r} for {'latitude' if is_latitude else 'longitude'}")
    raw = Decimal(value)
    degrees = int(raw // 100)
    minutes = raw - 100 * degrees
    if minutes >= 60:
        raise ValueError(f"minutes >= 60 in {value!r}")
    result = degrees + minutes / Decimal(60)
    limit = 90 if is_latitude else 180
    if result > limit:
        raise ValueError(f"coordinate out of range: {value!r}")
    if hemisphere in ("S", "W"):
        result = -result
    return float(result)


def parse_time_of_day(value: str) -> tuple[int, int, Decimal]:
    """Split an NMEA ``hhmmss.sss`` field into hours, minutes and exact seconds (leap second 60 allowed)."""
    m = _TOD_RE.match(value)
    if not m:
        raise ValueError(f"not a time of day: {value!r}")
    hours, minutes, seconds = int(m.group(1)), int(m.group(2)), Decimal(m.group(3))
    if hours > 23 or minutes > 59 or seconds >= 61:
        raise ValueError(f"time of day out of range: {value!r}")
    return hours, minutes, seconds


def format_utc(date: _dt.date, hours: int, minutes: int, seconds: Decimal) -> str:
    """ISO 8601 UTC with milliseconds, ``2015-04-13T20:26:40.000Z`` (extra digits truncated)."""
    sec = seconds.quantize(Decimal("0.001"), rounding=ROUND_DOWN)
    return f"{date.isoformat()}T{hours:02d}:{minutes:02d}:{sec:06.3f}Z"


def _number(value: str) -> Optional[float]:
    """A numeric NMEA field: None when empty, ``ValueError`` when not a plain decimal number."""
    value = value.strip()
    if value == "":
        return None
    if not _NUMBER_RE.match(value):
        raise ValueError(f"not a number: {value!r}")
    return float(value)


def _field(data: list[str], i: int) -> str:
    return data[i].strip() if i < len(data) else ""


def _two_digit_year(yy: int) -> int:
    # GPS started in 1980, so 80-99 are 19xx and the rest 20xx.
    return 1900 + yy if yy >= 80 else 2000 + yy


# --------------------------------------------------------------------------------------------
# statistics


@dataclass
class GpsStats:
    """What the driver has seen: counts of sentences (``read`` = used + ignored + rejected).

    ``used``: well-formed sentences the driver applied (GGA, RMC, GLL, GSA, VTG, ZDA, PMTK001),
    with or without a fix; ``ignored``: well-formed sentences of other types (GSV, TXT, MTK
    status...); ``rejected``: counts by reason (see :data:`REJECT_REASONS`); ``fixes``:
    positions produced; ``no_fix``: position sentences that said "no fix".
    """

    read: int = 0
    used: int = 0
    ignored: int = 0
    fixes: int = 0
    no_fix: int = 0
    rejected: dict[str, int] = field(default_factory=dict)

    @property
    def rejected_total(self) -> int:
        """All rejected sentences, whatever the reason."""
        return sum(self.rejected.values())

    def summary(self) -> str:
        """One line for people: ``read 145 sentences: used 105, ignored 40, rejected 2 (checksum 2); 60 positions``."""
        reasons = ", ".join(f"{k} {v}" for k, v in sorted(self.rejected.items()))
        rejected = f"rejected {self.rejected_total}" + (f" ({reasons})" if reasons else "")
        return (f"read {self.read} sentences: used {self.used}, ignored {self.ignored}, {rejected}; "
                f"{self.fixes} positions, {self.no_fix} no-fix reports")


@dataclass
class _EpochData:
    """What the receiver said so far about one measurement epoch (one time of day).

    Quality, satellites and HDOP live here, not in the driver: a fix carries
    only what its own epoch said. An epoch whose GGA was lost (an RMC alone)
    has them unknown (None; the quality then from RMC's mode letter), never
    those of an earlier epoch's GGA, which could be minutes old (gpsd, too,
    reports such an epoch without DOPs or an error estimate).
    """

    tod: Optional[tuple[int, int, Decimal]] = None
    alt_msl: Optional[float] = None
    speed_mps: Optional[float] = None
    track_deg: Optional[float] = None
    gga_quality: Optional[int] = None
    sats: Optional[int] = None
    hdop: Optional[float] = None


class _RejectEvents:
    """Rate-limits bad-data events: the first per reason at once, then at most one per interval."""

    def __init__(self, events: EventSink, interval_s: float) -> None:
        self._events = events
        self._interval_s = interval_s
        self._last_s: dict[str, float] = {}
        self._suppressed: dict[str, int] = {}

    def report(self, reason: str, example: str, stamp_s: float) -> None:
        last = self._last_s.get(reason)
        shown = example if len(example) <= 90 else example[:87] + "..."
        if last is None:
            self._last_s[reason] = stamp_s
            self._suppressed[reason] = 0
            self._events(f"gps_{reason}", f"GPS: rejected a sentence ({reason}): {shown!r}; further ones are "
                                          f"counted and reported at most every {self._interval_s:g} s")
        elif stamp_s - last >= self._interval_s:
            count = self._suppressed[reason] + 1
            self._last_s[reason] = stamp_s
            self._suppressed[reason] = 0
            self._events(f"gps_{reason}", f"GPS: {count} sentence(s) rejected ({reason}) in the last "
                                          f"{stamp_s - last:.1f} s, e.g. {shown!r}")
        else:
            self._suppressed[reason] += 1


# --------------------------------------------------------------------------------------------
# the driver


class NmeaGps:
    """NMEA 0183 GPS driver: bytes from a serial port in, :class:`GpsFix` readings out.

    Call :meth:`poll` every tick; it never blocks and never raises. Positions
    are WGS84 decimal degrees, altitude metres above mean sea level, speed m/s,
    course degrees clockwise from true north; ``stamp_s`` is the clock time at
    which the bytes were read.
    """

    def __init__(
        self,
        port: Optional[SerialLike],
        clock: Clock,
        events: EventSink = ignore_events,
        *,
        open_port: Optional[Callable[[], SerialLike]] = None,
        config: Optional[GpsConfig] = None,
    ) -> None:
        self._port = port
        self._clock = clock
        self._events = events
        self.config = config if config is not None else GpsConfig()
        self.config.validate()
        self.stats = GpsStats()
        """Counts of sentences read, used, ignored and rejected (by reason)."""
        self._rejects = _RejectEvents(events, self.config.bad_data_event_interval_s)
        self._rx = bytearray()
        self._port_lost = port is None
        self._reopener = PortReopener(events, "gps", "GPS", self.config.port, open_port, self.config.reopen_interval_s)
        self._latest_fix: Optional[GpsFix] = None
        self._no_fix_reported = False  # receiver said "no fix" after our latest fix
        self._have_fix_state: Optional[bool] = None  # for fix acquired/lost events
        self._date: Optional[_dt.date] = None
        self._date_tod_s = 0.0
        self._epoch = _EpochData()
        self._pending: dict[str, float] = {}
        self._configure_requested = False
        self._positions = frozenset(s.upper() for s in self.config.position_sentences)

    # --- public state ---------------------------------------------------------------------
    @property
    def latest_fix(self) -> Optional[GpsFix]:
        """The most recent position with a valid fix, or None if there has been none."""
        return self._latest_fix

    @property
    def pending_acks(self) -> dict[str, float]:
        """Configuration commands awaiting ``$PMTK001``: command number -> clock time sent (s)."""
        return dict(self._pending)

    @property
    def port_open(self) -> bool:
        """True while the driver holds a working port."""
        return self._port is not None

    def is_stale(self, now_s: float) -> bool:
        """True when there is no usable position at ``now_s`` (seconds, clock time).

        Stale means: no fix yet, the latest fix older than ``stale_after_s``, the
        receiver reporting "no fix" since, or the port lost since.
        """
        fix = self._latest_fix
        if fix is None or self._port_lost or self._no_fix_reported:
            return True
        return now_s - fix.stamp_s > self.config.stale_after_s

    # --- configuration ----------------------------------------------------------------------
    def configure(self) -> None:
        """Write the start-up PMTK commands from the config (nothing if none is set).

        Does not wait: :meth:`poll` matches the ``$PMTK001,<cmd>,<flag>`` answers,
        reports ``gps_config_failed`` for flags 0/1/2 and ``gps_config_unacked``
        when none comes within ``ack_timeout_s``. The commands are sent again
        whenever the port is reopened (a receiver that lost power forgets them).
        """
        self._configure_requested = True
        if self._port is not None:
            self._send_config(self._clock.now())

    def _send_config(self, now_s: float) -> None:
        port = self._port
        if port is None:
            return
        for sentence in self.config.pmtk_commands():
            command = sentence[5:8]
            try:
                port.write((sentence + "\r\n").encode("ascii"))
                if command == "251" and hasattr(port, "baudrate"):
                    # The receiver switches at once: drain what we wrote, then follow it.
                    flush = getattr(port, "flush", None)
                    if callable(flush):
                        flush()
                    port.baudrate = int(self.config.baud)  # type: ignore[attr-defined]
            except (serial.SerialException, OSError) as exc:
                self._lose_port(now_s, exc)
                return
            self._pending[command] = now_s

    def _check_acks(self, now_s: float) -> None:
        for command, sent_s in list(self._pending.items()):
            if now_s - sent_s > self.config.ack_timeout_s:
                del self._pending[command]
                name = PMTK_COMMAND_NAMES.get(command, f"PMTK{command}")
                self._events("gps_config_unacked", f"GPS: the receiver did not acknowledge {name} within "
                                                   f"{self.config.ack_timeout_s:g} s; it keeps its previous setting")

    def _handle_ack(self, data: list[str]) -> None:
        command, flag = _field(data, 1), _field(data, 2)
        if command not in self._pending:
            return
        del self._pending[command]
        if flag != "3":
            name = PMTK_COMMAND_NAMES.get(command, f"PMTK{command}")
            meaning = PMTK_ACK_FLAGS.get(flag, "unknown answer")
            self._events("gps_config_failed", f"GPS: the receiver refused {name}: PMTK001 flag {flag} ({meaning})")

    # --- the port ---------------------------------------------------------------------------
    def _lose_port(self, now_s: float, exc: BaseException) -> None:
        port, self._port = self._port, None
        self._rx.clear()
        self._pending.clear()  # answers cannot come; configure() is repeated on reopen
        self._port_lost = True
        self._reopener.lost(now_s, port, exc, "position goes stale")

    def _try_open(self, now_s: float) -> bool:
        port = self._reopener.reopen(now_s)
        if port is None:
            return False
        self._port = port
        self._rx.clear()
        if self._configure_requested:
            self._send_config(now_s)
        return self._port is not None

    # --- reading ----------------------------------------------------------------------------
    def poll(self) -> list[GpsFix]:
        """Read every byte waiting on the port (non-blocking) and return the new fixes.

        Fixes are stamped with ``clock.now()`` (seconds). Complete lines are
        parsed, a partial last line is kept for the next poll. Port errors close
        the port (reopened later), bad sentences are counted; never raises.
        """
        now_s = self._clock.now()
        fixes: list[GpsFix] = []
        if self._port is None and not self._try_open(now_s):
            return fixes
        port = self._port
        assert port is not None
        try:
            waiting = port.in_waiting
            data = port.read(min(waiting, MAX_READ_BYTES)) if waiting > 0 else b""
        except (serial.SerialException, OSError) as exc:
            self._lose_port(now_s, exc)
            return fixes
        if data:
            self._rx += data
            *lines, tail = self._rx.split(b"\n")
            self._rx = bytearray(tail)
            for raw in lines:
                # latin-1 maps every byte to one character, so garbage survives to be classified.
                fixes.extend(self.feed_sentences(raw.decode("latin-1"), now_s))
            if len(self._rx) > MAX_LINE_CHARS:
                self._count_read()
                self._reject("garbage", self._rx[:40].decode("latin-1"), now_s)
                self._rx.clear()
        self._check_acks(now_s)
        return fixes

    def feed_line(self, line: str, stamp_s: float) -> Optional[GpsFix]:
        """Parse one received line (one NMEA sentence) and return its fix, if it gives one.

        ``stamp_s`` (seconds) stamps the fix and times rate-limited events. A
        line holding several sentences (a lost newline) is split; the last fix is
        returned (:meth:`feed_sentences` returns all).
        """
        fixes = self.feed_sentences(line, stamp_s)
        return fixes[-1] if fixes else None

    def feed_sentences(self, line: str, stamp_s: float) -> list[GpsFix]:
        """Parse one received line that may hold several sentences; return every fix it gives."""
        line = line.rstrip("\r\n")
        if not line.strip():
            return []
        out: list[GpsFix] = []
        start = line.find("$")
        prefix = line if start < 0 else line[:start]
        if prefix.strip():
            # Bytes outside any sentence: binary protocol, line noise, a receiver at another baud.
            self._count_read()
            self._reject("garbage", prefix, stamp_s)
        if start < 0:
            return out
        segments = line[start:].split("$")[1:]
        for i, seg in enumerate(segments):
            fix = self._feed_sentence("$" + seg, stamp_s, last_in_line=i == len(segments) - 1)
            if fix is not None:
                out.append(fix)
        return out

    # --- one sentence -----------------------------------------------------------------------
    def _count_read(self) -> None:
        self.stats.read += 1

    def _reject(self, reason: str, text: str, stamp_s: float) -> None:
        self.stats.rejected[reason] = self.stats.rejected.get(reason, 0) + 1
        self._rejects.report(reason, text, stamp_s)

    def _feed_sentence(self, text: str, stamp_s: float, *, last_in_line: bool) -> Optional[GpsFix]:
        self._count_read()
        body = text.rstrip()
        if any(not (" " <= c <= "~") for c in body):
            self._reject("garbage", body, stamp_s)
            return None
        star = body.rfind("*")
        if star < 0:
            # Cut by the next "$": truncated. At the end of a line: no checksum (cut, or never sent).
            self._reject("no_checksum" if last_in_line else "truncated", body, stamp_s)
            return None
        if not _HEX2_RE.match(body[star + 1:]):
            self._reject("truncated" if len(body) - star - 1 < 2 else "checksum", body, stamp_s)
            return None
        try:
            msg = pynmea2.parse(body, check=True)
        except pynmea2.ChecksumError:
            self._reject("checksum", body, stamp_s)
            return None
        except pynmea2.SentenceTypeError:
            self._reject("unknown_type", body, stamp_s)
            return None
        except pynmea2.ParseError:
            self._reject("malformed", body, stamp_s)
            return None
        try:
            return self._apply(msg, stamp_s)
        except (ValueError, ArithmeticError, InvalidOperation) as exc:
            self._reject("malformed", f"{body} ({exc})", stamp_s)
            return None

    def _apply(self, msg: pynmea2.NMEASentence, stamp_s: float) -> Optional[GpsFix]:
        if isinstance(msg, pynmea2.ProprietarySentence):
            data = list(msg.data)
            if msg.manufacturer == "MTK" and data and data[0] == "001":
                self.stats.used += 1
                self._handle_ack(data)
            else:
                self.stats.ignored += 1
            return None
        kind = getattr(msg, "sentence_type", "")
        if kind not in _USED_SENTENCES:
            self.stats.ignored += 1
            return None
        data = [str(v) for v in msg.data]
        handler = getattr(self, f"_on_{kind.lower()}")
        result = handler(data, stamp_s)
        self.stats.used += 1
        return result

    # --- time and epochs ----------------------------------------------------------------------
    def _start_epoch(self, tod: str) -> None:
        """A sentence with time of day ``tod`` (``''``: none): a new epoch when the time differs."""
        if not tod:
            return
        key = parse_time_of_day(tod)  # "102127.000" and "102127.00" are the same epoch
        if key == self._epoch.tod:
            return
        if self._epoch.tod is None:
            # DOPs a GSA gave before any timed sentence (the driver's first epoch) belong to this one.
            self._epoch = _EpochData(tod=key, hdop=self._epoch.hdop)
        else:
            self._epoch = _EpochData(tod=key)

    def _utc(self, tod: str) -> Optional[str]:
        """ISO time for a time of day, using the tracked date (None while the date is unknown)."""
        if not tod or self._date is None:
            return None
        hours, minutes, seconds = parse_time_of_day(tod)
        tod_s = hours * 3600 + minutes * 60 + float(seconds)
        date = self._date
        # A sentence half a day away from the one that gave the date crossed midnight.
        if tod_s < self._date_tod_s - 43200:
            date += _dt.timedelta(days=1)
        elif tod_s > self._date_tod_s + 43200:
            date -= _dt.timedelta(days=1)
        return format_utc(date, hours, minutes, seconds)

    def _set_date(self, date: _dt.date, tod: str) -> None:
        self._date = date
        if tod:
            hours, minutes, seconds = parse_time_of_day(tod)
            self._date_tod_s = hours * 3600 + minutes * 60 + float(seconds)
        else:
            self._date_tod_s = 0.0

    # --- sentence handlers ----------------------------------------------------------------------
    def _on_gga(self, data: list[str], stamp_s: float) -> Optional[GpsFix]:
        tod = _field(data, 0)
        if tod:
            parse_time_of_day(tod)
        quality_field = _field(data, 5)
        quality = int(quality_field) if quality_field.isdigit() else 0
        sats_field = _field(data, 6)
        sats = int(sats_field) if sats_field.isdigit() else None
        hdop = _number(_field(data, 7))
        alt = _number(_field(data, 8))
        self._start_epoch(tod)
        self._epoch.gga_quality = quality
        if quality == 0:
            return self._no_fix("GGA", stamp_s)
        if sats is not None:
            self._epoch.sats = sats
        if hdop is not None:
            self._epoch.hdop = hdop
        lat = parse_coordinate(_field(data, 1), _field(data, 2), is_latitude=True)
        lon = parse_coordinate(_field(data, 3), _field(data, 4), is_latitude=False)
        self._epoch.alt_msl = alt
        return self._fix("GGA", stamp_s, lat, lon, tod, quality, alt_msl=alt)

    def _on_rmc(self, data: list[str], stamp_s: float) -> Optional[GpsFix]:
        tod, status = _field(data, 0), _field(data, 1).upper()
        mode = _field(data, 11).upper()
        if tod:
            parse_time_of_day(tod)
        speed_kn = _number(_field(data, 6))
        course = _number(_field(data, 7))
        date_field = _field(data, 8)
        self._start_epoch(tod)
        if status != "A" or mode == "N":
            return self._no_fix("RMC", stamp_s)
        if date_field:
            m = _DATE_RE.match(date_field)
            if not m:
                raise ValueError(f"bad date {date_field!r}")
            day, month, yy = (int(g) for g in m.groups())
            self._set_date(_dt.date(_two_digit_year(yy), month, day), tod)
        lat = parse_coordinate(_field(data, 2), _field(data, 3), is_latitude=True)
        lon = parse_coordinate(_field(data, 4), _field(data, 5), is_latitude=False)
        speed = None if speed_kn is None else speed_kn * KNOTS_TO_MPS
        track = None if course is None else course % 360.0
        self._epoch.speed_mps, self._epoch.track_deg = speed, track
        return self._fix("RMC", stamp_s, lat, lon, tod, self._carried_quality(mode),
                         alt_msl=self._epoch.alt_msl, speed_mps=speed, track_deg=track)

    def _on_gll(self, data: list[str], stamp_s: float) -> Optional[GpsFix]:
        tod, status, mode = _field(data, 4), _field(data, 5).upper(), _field(data, 6).upper()
        if tod:
            parse_time_of_day(tod)
        self._start_epoch(tod)
        if status != "A" or mode == "N":
            return self._no_fix("GLL", stamp_s)
        lat = parse_coordinate(_field(data, 0), _field(data, 1), is_latitude=True)
        lon = parse_coordinate(_field(data, 2), _field(data, 3), is_latitude=False)
        return self._fix("GLL", stamp_s, lat, lon, tod, self._carried_quality(mode), alt_msl=self._epoch.alt_msl,
                         speed_mps=self._epoch.speed_mps, track_deg=self._epoch.track_deg)

    def _on_gsa(self, data: list[str], stamp_s: float) -> None:
        fix_type = _field(data, 1)
        hdop = _number(_field(data, 15))
        if fix_type in ("2", "3") and hdop is not None:
            # GSA has no time: it belongs to the epoch in progress (after that epoch's GGA on MTK and u-blox).
            self._epoch.hdop = hdop

    def _on_vtg(self, data: list[str], stamp_s: float) -> None:
        mode = _field(data, 8).upper()
        if mode == "N":
            return
        course = _number(_field(data, 0))
        knots = _number(_field(data, 4))
        kmh = _number(_field(data, 6))
        if knots is not None:
            self._epoch.speed_mps = knots * KNOTS_TO_MPS
        elif kmh is not None:
            self._epoch.speed_mps = kmh / 3.6
        if course is not None:
            self._epoch.track_deg = course % 360.0

    def _on_zda(self, data: list[str], stamp_s: float) -> None:
        tod = _field(data, 0)
        day, month, year = _field(data, 1), _field(data, 2), _field(data, 3)
        if tod:
            parse_time_of_day(tod)
        if day and month and year:
            self._set_date(_dt.date(int(year), int(month), int(day)), tod)

    # --- fixes --------------------------------------------------------------------------------
    def _carried_quality(self, mode: str) -> int:
        # RMC/GLL carry no quality: their epoch's GGA's, else what the mode letter implies, else GPS.
        if self._epoch.gga_quality:
            return self._epoch.gga_quality
        return _RMC_MODE_QUALITY.get(mode, 1)

    def covariance(self, quality: int, hdop: Optional[float]) -> tuple[tuple[float, float, float], ...]:
        """ENU position covariance (m^2) for a fix: sigma = HDOP x base error of its quality.

        The vertical sigma is ``vertical_error_factor`` times larger; the
        horizontal sigma is never below ``min_sigma_m``.
        """
        cfg = self.config
        base = cfg.base_error_m.get(quality, cfg.other_quality_error_m)
        h = hdop if hdop is not None and hdop > 0 else cfg.hdop_when_unknown
        sigma = max(h * base, cfg.min_sigma_m)
        var_h = sigma * sigma
        var_v = (cfg.vertical_error_factor * sigma) ** 2
        return ((var_h, 0.0, 0.0), (0.0, var_h, 0.0), (0.0, 0.0, var_v))

    def _fix(self, sentence: str, stamp_s: float, lat: float, lon: float, tod: str, quality: int, *,
             alt_msl: Optional[float] = None, speed_mps: Optional[float] = None,
             track_deg: Optional[float] = None) -> Optional[GpsFix]:
        # Satellites and HDOP of this fix's own epoch only (None when the epoch gave none).
        sats, hdop = self._epoch.sats, self._epoch.hdop
        fix = GpsFix(
            stamp_s=stamp_s, lat=lat, lon=lon, alt_msl=alt_msl, quality=quality, sats=sats, hdop=hdop,
            speed_mps=speed_mps, track_deg=track_deg, time_utc=self._utc(tod), sentence=sentence,
            covariance_enu=self.covariance(quality, hdop),
        )
        if sentence not in self._positions:
            return None
        self.stats.fixes += 1
        self._latest_fix = fix
        self._no_fix_reported = False
        self._port_lost = False
        if self._have_fix_state is not True:
            n_sats = "?" if sats is None else sats
            self._events("gps_fix_acquired", f"GPS: position fix (quality {quality}, {n_sats} satellites)")
            self._have_fix_state = True
        return fix

    def _no_fix(self, sentence: str, stamp_s: float) -> None:
        self.stats.no_fix += 1
        self._no_fix_reported = True
        if self._have_fix_state is True:
            self._events("gps_fix_lost", f"GPS: the receiver reports no fix ({sentence})")
        self._have_fix_state = False
        return None
