"""The Waveshare UGV base (ESP32 sub-controller): serial JSON, one object per line.

Written against the firmware that ships on the base, not against our own idea
of it (facts, with file and line, in ``docs/hardware/waveshare.md``). Two
firmwares exist: ``ugv_base_ros`` (``ROS_Driver/``) and ``ugv_base_general``
(``General_Driver/``). The driver works with either, told by the profile
(``base.firmware``) or detected from the first ``T:1001`` feedback line.

At start it sends echo off (``T:143``), the robot and module type (``T:900``
main 3 = UGV Beast, module 2 = gimbal, 0 = none; ``T:4``), the base's own
heartbeat (``T:136``, ms), the feedback interval (``T:142``, ms) and
feedback on (``T:131``). It drives with ``{"T":1,"L":l,"R":r}`` (wheel
speeds, m/s), the only motion command that resets the heartbeat on both
firmwares (``T:13`` does not on ugv_base_ros): if beastbt dies, freezes or
loses the cable, the base stops by itself ``heartbeat_s`` later. Its
emergency stop is zero wheel speed plus a gimbal stop (``T:135``); servo
torque is released (``T:210`` cmd 0) only when the profile asks for it
(``{"T":0}`` would release it on ugv_base_ros and does nothing on
ugv_base_general). Feedback: wheel speeds, odometry in whole centimetres,
raw IMU and the battery in hundredths of a volt on ugv_base_ros; wheel
speeds, attitude in degrees and the battery in volts, without odometry, on
ugv_base_general (the driver integrates the wheel speeds instead). ``T:1005``
bus-servo errors become events. Lines can arrive broken or interleaved: the
parser resynchronises on the next newline and never raises.
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
FIRMWARE_MAX_WHEEL_MPS = 2.0
"""Both firmwares ignore (not clamp) a T:1 whose L or R is beyond +-2.0 m/s (``setGoalSpeed``, movtion_module.h)."""
ROS_FIRMWARE = "ros"
"""waveshareteam/ugv_base_ros (``ROS_Driver``): odometry and raw IMU in T:1001, T:13 does not reset the heartbeat."""
GENERAL_FIRMWARE = "general"
"""waveshareteam/ugv_base_general (``General_Driver``): attitude and volts in T:1001, no odometry, no T:0."""
MODULE_NONE, MODULE_ARM, MODULE_GIMBAL = 0, 1, 2
"""``T:4``/``T:900`` module types: nothing, RoArm-M2, pan/tilt gimbal."""
BUS_SERVO_NAMES = {1: "gimbal tilt", 2: "gimbal pan"}
"""Bus servo ids of the gimbal (``GIMBAL_TILT_ID``, ``GIMBAL_PAN_ID`` in ugv_config.h)."""
SERVO_ERROR_REPEAT_S = 10.0
"""A bus servo that keeps failing is reported again at most this often (the firmware reports it every loop), s."""


@dataclass
@schema_defaults("parts/waveshare_base.schema.json", computed={"type": "the base type this config is for, not a knob"})
class WaveshareConfig:
    """Settings of the Waveshare serial base (a robot profile's ``base:`` section).

    ``port``: serial device (``/dev/serial0`` on a Pi 4, ``/dev/ttyAMA0`` on a Pi 5).
    ``baud``: 115200. ``feedback_interval_s``: how often the base reports (T:142), s.
    ``firmware``: ``auto`` (detected from the feedback), ``ros`` or ``general``.
    ``main_type``: the robot type sent with T:900 (1 RaspRover, 2 UGV Rover,
    3 UGV Beast): the firmware's wheel diameter, encoder counts and track width.
    ``heartbeat_s``: the base stops by itself when no T:1 came for this long (T:136), s.
    ``estop_releases_servos``: whether the e-stop also releases bus servo torque (T:210 cmd 0).
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
    firmware: str
    main_type: int
    heartbeat_s: float
    estop_releases_servos: bool
    type: str = "waveshare_serial"

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "WaveshareConfig":
        """Build from a profile mapping; unknown keys are a ValueError."""
        return dataclass_from_dict(cls, d, "base")


DEFAULT_TRACK_WIDTH_M = 0.141
"""The UGV Beast's track width in its firmware (main type 3, movtion_module.h), m: used when no profile says."""


@dataclass
class FeedbackStats:
    """Counts of what the feedback parser saw."""

    lines: int = 0
    feedback: int = 0
    other_json: int = 0
    garbage: int = 0


class WaveshareBase:
    """Adapter for the Waveshare base: wheel speeds and gimbal commands out, feedback in.

    Implements :class:`~beastbt.actuation.adapter.BaseAdapter` and
    :class:`~beastbt.actuation.adapter.ServoAdapter` (servos ``pan`` and ``tilt``
    when the gimbal is present; angles positive left/up in beastbt's convention).
    ``track_width_m`` turns body velocity into the wheel speeds of ``T:1`` (m).
    """

    name = "waveshare_serial"

    def __init__(self, port: SerialLike, config: Optional[WaveshareConfig] = None, events: EventSink = ignore_events,
                 track_width_m: Optional[float] = None) -> None:
        self.port = port
        self.config = config or WaveshareConfig()
        self.events = events
        self.track_width_m = track_width_m if track_width_m is not None else DEFAULT_TRACK_WIDTH_M
        self.stats = FeedbackStats()
        self.firmware: Optional[str] = None if self.config.firmware == "auto" else self.config.firmware
        """The firmware in use (``ros``/``general``), or None until the feedback tells."""
        self._buf = bytearray()
        self._pan_deg = 0.0
        self._tilt_deg = 0.0
        self._port_ok = True
        self._clamp_warned = False
        self._servo_errors: dict[int, tuple[float, int]] = {}
        self._wheel_odom: Optional[list[float]] = None  # [left m, right m, left m/s, right m/s, stamp s] (general)
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

    def start_commands(self) -> list[dict]:
        """The set-up sent at start, in order: echo off, robot and module type, heartbeat, feedback interval and flow."""
        c = self.config
        module = MODULE_GIMBAL if c.gimbal else MODULE_NONE
        return [{"T": 143, "cmd": 0},
                {"T": 900, "main": int(c.main_type), "module": module},
                {"T": 4, "cmd": module},
                {"T": 136, "cmd": int(round(c.heartbeat_s * 1000))},
                {"T": 142, "cmd": int(round(c.feedback_interval_s * 1000))},
                {"T": 131, "cmd": 1}]

    def start(self, now_s: float) -> None:
        """Send the set-up (:meth:`start_commands`) and a first zero wheel speed, which arms the base's heartbeat."""
        for command in self.start_commands():
            self._send(command)
        self._send({"T": 1, "L": 0.0, "R": 0.0})

    def wheel_speeds(self, cmd: VelocityCommand) -> tuple[float, float]:
        """Left and right wheel speeds (m/s) for a body velocity, within the firmware's limit (ratio kept)."""
        v, w = cmd.linear_mps, cmd.angular_rps
        floor = self.config.min_turn_rate_in_place_rps
        if v == 0.0 and w != 0.0 and abs(w) < floor:
            w = math.copysign(floor, w)
        half = w * self.track_width_m / 2.0
        left, right = v - half, v + half
        top = max(abs(left), abs(right))
        if top > FIRMWARE_MAX_WHEEL_MPS:
            # The firmware ignores the whole command beyond its limit: scale both sides, keeping the curvature.
            scale = FIRMWARE_MAX_WHEEL_MPS / top
            left, right = left * scale, right * scale
            if not self._clamp_warned:
                self._clamp_warned = True
                self.events("base_speed_clamped", f"wheel speed {top:.2f} m/s is beyond the firmware's "
                                                  f"{FIRMWARE_MAX_WHEEL_MPS:g} m/s: clamped (warned once)")
        return left, right

    def send_velocity(self, cmd: VelocityCommand, now_s: float) -> None:
        """Send ``{"T":1,"L":l,"R":r}`` (m/s): resets the base's heartbeat; tiny in-place turns raised to the minimum."""
        left, right = self.wheel_speeds(cmd)
        self._send({"T": 1, "L": round(left, 4), "R": round(right, 4)})

    def emergency_stop(self, now_s: float) -> None:
        """Zero wheel speed and a gimbal stop (T:135); servo torque released (T:210 cmd 0) only if the profile asks."""
        self._send({"T": 1, "L": 0.0, "R": 0.0})
        if self.config.gimbal:
            self._send({"T": 135})
        if self.config.estop_releases_servos:
            self._send({"T": 210, "cmd": 0})

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
        kind = obj.get("T") if isinstance(obj, dict) else None
        if kind == 1005:
            self._servo_error(obj, now_s)
            return []
        if kind != 1001:
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

    def _detect(self, obj: dict) -> None:
        if "odl" in obj or "gx" in obj:
            self.firmware = ROS_FIRMWARE
            why = "its feedback carries odometry (odl/odr) and raw IMU"
        elif "r" in obj or "temp" in obj or isinstance(obj.get("v"), float):
            self.firmware = GENERAL_FIRMWARE
            why = ("its feedback carries attitude and volts but no odometry: odometry is integrated from the "
                   "wheel speeds (flash ugv_base_ros for encoder odometry, or set base.firmware)")
        else:
            return
        self.events("base_firmware", f"firmware ugv_base_{self.firmware} detected: {why}")

    def _readings(self, obj: dict, now_s: float) -> list[Feedback]:
        self.stats.feedback += 1
        if self.firmware is None:
            self._detect(obj)
        out: list[Feedback] = []
        num = self._num
        speed_l, speed_r = num(obj, "L"), num(obj, "R")
        odl, odr = num(obj, "odl"), num(obj, "odr")
        if odl is not None and odr is not None:
            out.append(self._refine(now_s, odl, odr, speed_l or 0.0, speed_r or 0.0))
        elif self.firmware == GENERAL_FIRMWARE and speed_l is not None and speed_r is not None:
            out.append(self._integrate(now_s, speed_l, speed_r))
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
            # ugv_base_ros sends hundredths of a volt as an integer, ugv_base_general volts as a float.
            volts = v if self.firmware == GENERAL_FIRMWARE or (self.firmware is None and v < 50.0) else v / 100.0
            out.append(BatteryState(now_s, volts))
        return out

    def _refine(self, now_s: float, odl_cm: float, odr_cm: float, left_mps: float, right_mps: float) -> WheelOdometry:
        """Odometry finer than the firmware's whole centimetres: wheel speeds integrated, kept within each count.

        ugv_base_ros truncates each side's distance to whole centimetres
        (``long int odl_cm``): at 20 Hz that is a 4 deg heading jitter on a
        0.14 m track. The integrated speeds give the fine part; the counts
        bound it, so it cannot drift: a truncated ``n`` means the distance is
        in [n, n+1) cm (n > 0), (n-1, n] (n < 0) or (-1, 1) (n = 0).
        """
        state = self._wheel_odom
        if state is None:
            state = self._wheel_odom = [odl_cm / 100.0, odr_cm / 100.0, left_mps, right_mps, now_s]
        dt = max(0.0, now_s - state[4])
        for i, (count, speed) in enumerate(((odl_cm, left_mps), (odr_cm, right_mps))):
            estimate = state[i] + 0.5 * (state[2 + i] + speed) * dt
            low = count - 1.0 if count <= 0 else count
            high = count + 1.0 if count >= 0 else count
            state[i] = min(max(estimate, low / 100.0), high / 100.0)
        state[2], state[3], state[4] = left_mps, right_mps, now_s
        return WheelOdometry(now_s, state[0], state[1], left_mps, right_mps)

    def _integrate(self, now_s: float, left_mps: float, right_mps: float) -> WheelOdometry:
        """Odometry from the wheel speeds of a firmware that reports none (trapezoids between feedback lines)."""
        state = self._wheel_odom
        if state is None:
            state = self._wheel_odom = [0.0, 0.0, left_mps, right_mps, now_s]
        dt = max(0.0, now_s - state[4])
        state[0] += 0.5 * (state[2] + left_mps) * dt
        state[1] += 0.5 * (state[3] + right_mps) * dt
        state[2], state[3], state[4] = left_mps, right_mps, now_s
        return WheelOdometry(now_s, state[0], state[1], left_mps, right_mps)

    def _servo_error(self, obj: dict, now_s: float) -> None:
        """``{"T":1005,"id":n,"status":0}``: bus servo ``n`` did not answer (the firmware repeats it every loop)."""
        ident = obj.get("id")
        if not isinstance(ident, int) or isinstance(ident, bool):
            self.stats.garbage += 1
            return
        last_s, count = self._servo_errors.get(ident, (-math.inf, 0))
        count += 1
        if now_s - last_s >= SERVO_ERROR_REPEAT_S:
            name = BUS_SERVO_NAMES.get(ident, f"bus servo {ident}")
            again = f" ({count} reports so far)" if count > 1 else ""
            self.events("bus_servo_error", f"{name} (bus servo id {ident}) does not answer (T:1005){again}: "
                                           f"check its cable and that the base's module type is right")
            last_s = now_s
        self._servo_errors[ident] = (last_s, count)

    def close(self) -> None:
        """Send zero wheel speed, then close the port."""
        self._send({"T": 1, "L": 0.0, "R": 0.0})
        try:
            self.port.close()
        except Exception:
            pass
