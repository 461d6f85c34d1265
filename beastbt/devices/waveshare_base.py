"""The Waveshare UGV base (ESP32 sub-controller): serial JSON, one object per line.

Commands (``HARDWARE.md``): ``{"T":13,"X":v,"Z":w}`` body velocity,
``{"T":0}`` emergency stop, ``{"T":133,"X":pan,"Y":tilt,"SPD":s,"ACC":a}`` the
pan/tilt gimbal, ``{"T":132,"IO4":a,"IO5":b}`` lights, start-up
``{"T":142,"cmd":ms}``, ``{"T":131,"cmd":1}``, ``{"T":143,"cmd":0}``. Feedback
``{"T":1001,...}`` carries wheel speeds, raw IMU, odometry in centimetres and
the battery in hundredths of a volt. Lines can arrive broken or interleaved:
the parser resynchronises on the next newline and never raises.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from typing import Any, Optional

from beastbt.core.schema_defaults import schema_defaults
from beastbt.blackboard.types import BatteryState, Feedback, ImuSample, ServoCommand, VelocityCommand, WheelOdometry
from beastbt.core.config import dataclass_from_dict
from beastbt.devices.interfaces import EventSink, SerialLike, ignore_events

ACCEL_LSB_PER_G = 8192.0
"""Raw accelerometer counts per g in T:1001 feedback."""
GYRO_LSB_PER_DPS = 16.4
"""Raw gyro counts per deg/s in T:1001 feedback."""
MAG_UT_PER_LSB = 0.15
"""Microtesla per raw magnetometer count in T:1001 feedback."""
STANDARD_GRAVITY = 9.80665
"""m/s^2 per g."""
MAX_LINE_BYTES = 1024
"""A 'line' longer than this without a newline is garbage and is dropped."""


@dataclass
@schema_defaults("parts/waveshare_base.schema.json", computed={"type": "the base type this config is for, not a knob"})
class WaveshareConfig:
    """Settings of the Waveshare serial base (a robot profile's ``base:`` section).

    ``port``: serial device (``/dev/serial0`` on a Pi 4, ``/dev/ttyAMA0`` on a Pi 5).
    ``baud``: 115200. ``feedback_interval_s``: how often the base reports (T:142), s.
    ``min_turn_rate_in_place_rps``: a non-zero |w| below this is raised to it
    when v is 0, as Waveshare's ROS driver does: the tracks do not turn slower (rad/s).
    ``gimbal``: whether a pan/tilt gimbal is on the base. ``pan_min_deg``..``tilt_max_deg``:
    its range (pan -180..180, negative looks left in the base's own convention;
    tilt -30..90, positive up). ``gimbal_speed``/``gimbal_accel``: the SPD/ACC
    values sent with T:133 (0 = the firmware's fastest).
    """

    port: str
    baud: int
    feedback_interval_s: float
    min_turn_rate_in_place_rps: float
    gimbal: bool
    pan_min_deg: float
    pan_max_deg: float
    tilt_min_deg: float
    tilt_max_deg: float
    gimbal_speed: int
    gimbal_accel: int
    type: str = "waveshare_serial"

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "WaveshareConfig":
        """Build from a profile mapping; unknown keys are a ValueError."""
        return dataclass_from_dict(cls, d, "base")


@dataclass
class FeedbackStats:
    """Counts of what the feedback parser saw."""

    lines: int = 0
    feedback: int = 0
    other_json: int = 0
    garbage: int = 0


class WaveshareBase:
    """Adapter for the Waveshare base: velocity and gimbal commands out, feedback in.

    Implements :class:`~beastbt.actuation.adapter.BaseAdapter` and
    :class:`~beastbt.actuation.adapter.ServoAdapter` (servos ``pan`` and ``tilt``
    when the gimbal is present; angles positive left/up in beastbt's convention).
    """

    name = "waveshare_serial"

    def __init__(self, port: SerialLike, config: Optional[WaveshareConfig] = None, events: EventSink = ignore_events) -> None:
        self.port = port
        self.config = config or WaveshareConfig()
        self.events = events
        self.stats = FeedbackStats()
        self._buf = bytearray()
        self._pan_deg = 0.0
        self._tilt_deg = 0.0
        self._port_ok = True
        self.last_sent: Optional[dict] = None

    # -- sending ------------------------------------------------------------
    def _send(self, obj: dict) -> bool:
        line = json.dumps(obj, separators=(",", ":")) + "\n"
        try:
            self.port.write(line.encode("ascii"))
            self.last_sent = obj
            if not self._port_ok:
                self._port_ok = True
                self.events("base_port_back", "the base's serial port answers again")
            return True
        except Exception as exc:  # pyserial raises SerialException/OSError; never let it kill the loop
            if self._port_ok:
                self._port_ok = False
                self.events("base_port_error", f"cannot write to the base: {exc}")
            return False

    def start(self, now_s: float) -> None:
        """Send Waveshare's start-up sequence: feedback interval, continuous feedback on, echo off."""
        self._send({"T": 142, "cmd": int(round(self.config.feedback_interval_s * 1000))})
        self._send({"T": 131, "cmd": 1})
        self._send({"T": 143, "cmd": 0})

    def send_velocity(self, cmd: VelocityCommand, now_s: float) -> None:
        """Send ``{"T":13,"X":v,"Z":w}`` (m/s, rad/s), raising tiny in-place turn rates to the minimum."""
        v, w = cmd.linear_mps, cmd.angular_rps
        floor = self.config.min_turn_rate_in_place_rps
        if v == 0.0 and w != 0.0 and abs(w) < floor:
            w = math.copysign(floor, w)
        self._send({"T": 13, "X": round(v, 4), "Z": round(w, 4)})

    def emergency_stop(self, now_s: float) -> None:
        """Send the base's own emergency stop ``{"T":0}``."""
        self._send({"T": 0})

    def set_lights(self, io4: int, io5: int) -> None:
        """Set the two light outputs (PWM 0-255)."""
        self._send({"T": 132, "IO4": max(0, min(255, int(io4))), "IO5": max(0, min(255, int(io5)))})

    def show_text(self, line: int, text: str) -> None:
        """Write one line of the OLED."""
        self._send({"T": 3, "lineNum": int(line), "Text": text[:20]})

    # -- servos (the gimbal) ------------------------------------------------
    def servo_names(self) -> list[str]:
        """``pan`` and ``tilt`` when the gimbal is present."""
        return ["pan", "tilt"] if self.config.gimbal else []

    def set_servo(self, cmd: ServoCommand, now_s: float) -> bool:
        """Point the gimbal; beastbt's pan is positive left, the base's is negative left."""
        if not self.config.gimbal or cmd.name not in ("pan", "tilt") or cmd.angle_rad is None:
            return False
        c = self.config
        deg = math.degrees(cmd.angle_rad)
        if cmd.name == "pan":
            self._pan_deg = max(c.pan_min_deg, min(c.pan_max_deg, -deg))
        else:
            self._tilt_deg = max(c.tilt_min_deg, min(c.tilt_max_deg, deg))
        return self._send({"T": 133, "X": round(self._pan_deg, 2), "Y": round(self._tilt_deg, 2),
                           "SPD": c.gimbal_speed, "ACC": c.gimbal_accel})

    # -- feedback -----------------------------------------------------------
    def poll(self, now_s: float) -> list[Feedback]:
        """Parse every complete line that arrived; return odometry, IMU and battery readings."""
        try:
            n = self.port.in_waiting
            if n:
                self._buf += self.port.read(n)
        except Exception as exc:
            if self._port_ok:
                self._port_ok = False
                self.events("base_port_error", f"cannot read from the base: {exc}")
            return []
        out: list[Feedback] = []
        while True:
            i = self._buf.find(b"\n")
            if i < 0:
                if len(self._buf) > MAX_LINE_BYTES:
                    self.stats.garbage += 1
                    self._buf.clear()
                break
            line = bytes(self._buf[:i])
            del self._buf[: i + 1]
            out.extend(self.parse_line(line, now_s))
        return out

    def parse_line(self, line: bytes, now_s: float) -> list[Feedback]:
        """Readings from one line of feedback; garbage is counted, never raised."""
        self.stats.lines += 1
        line = line.strip()
        if not line:
            return []
        # A broken line may carry the start of a good object after junk: resynchronise on '{'.
        start = line.rfind(b'{"T"')
        if start > 0:
            line = line[start:]
        try:
            obj = json.loads(line)
        except (ValueError, UnicodeDecodeError):
            self.stats.garbage += 1
            return []
        if not isinstance(obj, dict) or obj.get("T") != 1001:
            self.stats.other_json += 1
            return []
        try:
            return self._readings(obj, now_s)
        except (TypeError, ValueError, KeyError):
            self.stats.garbage += 1
            return []

    @staticmethod
    def _num(obj: dict, key: str) -> Optional[float]:
        v = obj.get(key)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            return None
        return float(v)

    def _readings(self, obj: dict, now_s: float) -> list[Feedback]:
        self.stats.feedback += 1
        out: list[Feedback] = []
        num = self._num
        odl, odr = num(obj, "odl"), num(obj, "odr")
        if odl is not None and odr is not None:
            out.append(WheelOdometry(now_s, odl / 100.0, odr / 100.0, num(obj, "L") or 0.0, num(obj, "R") or 0.0))
        g = [num(obj, k) for k in ("gx", "gy", "gz")]
        a = [num(obj, k) for k in ("ax", "ay", "az")]
        if None not in g and None not in a:
            m = [num(obj, k) for k in ("mx", "my", "mz")]
            gyro = tuple(math.radians(x / GYRO_LSB_PER_DPS) for x in g)  # type: ignore[operator]
            acc = tuple(x / ACCEL_LSB_PER_G * STANDARD_GRAVITY for x in a)  # type: ignore[operator]
            mag = tuple(x * MAG_UT_PER_LSB * 1e-6 for x in m) if None not in m else None  # type: ignore[operator]
            out.append(ImuSample(now_s, gyro, acc, mag))  # type: ignore[arg-type]
        v = num(obj, "v")
        if v is not None:
            out.append(BatteryState(now_s, v / 100.0))
        return out

    def close(self) -> None:
        """Send a stop, then close the port."""
        self._send({"T": 13, "X": 0, "Z": 0})
        try:
            self.port.close()
        except Exception:
            pass
