"""An emulated Waveshare ESP32 sub-controller behind a :class:`SimSerialPort`, following its firmware's source.

Either firmware (``ros``: waveshareteam/ugv_base_ros ``ROS_Driver``;
``general``: waveshareteam/ugv_base_general ``General_Driver``), in the
points a driver depends on (sources and lines in ``docs/hardware/waveshare.md``):

* Commands: ``T:1`` wheel speeds (m/s), ``T:11`` PWM, ``T:13`` body velocity
  (with the firmware's own track width for its main type), ``T:0`` (ros:
  zero speed and every bus servo's torque released; general: no such
  command), ``T:210`` torque on/off, ``T:133`` gimbal, ``T:135`` gimbal stop,
  ``T:136`` heartbeat (ms), ``T:900`` main and module type, ``T:4`` module,
  ``T:142`` feedback interval (ms), ``T:131`` feedback flow, ``T:143`` echo.
  A ``T:1`` beyond +-2 m/s is ignored, as ``setGoalSpeed`` does.
* The heartbeat: when no heartbeat-resetting command came for the heartbeat
  delay (3000 ms at boot), the wheels are stopped, once. ``T:1`` and ``T:11``
  reset it on both firmwares; ``T:13`` only on general.
* Start-up state: ros boots as main type 2 (UGV Rover), feedback on every
  50 ms, echo off; general as main type 1 (RaspRover), feedback off, echo on.
  Until ``T:900`` says 3 (UGV Beast) the firmware computes speeds and
  odometry with the wrong wheel and encoder: the emulated board is a Beast's.
* Feedback ``T:1001``: ros has measured wheel speeds, raw IMU (the
  emulator leaves out the compass, ``mx``..``mz``), odometry as
  whole centimetres from the encoder counts, the battery in hundredths of a
  volt, and pan/tilt with the gimbal module; general has wheel speeds,
  roll/pitch/yaw in degrees, the chip temperature and the battery in volts.
  ``T:1005`` when a gimbal servo does not answer (module 2 without a gimbal).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from collections import deque
from typing import Callable, Deque, Optional

import numpy as np

from beastbt.core.bounded import HeadTail
from beastbt.devices.waveshare_base import ACCEL_LSB_PER_G, GYRO_LSB_PER_DPS, STANDARD_GRAVITY
from beastbt.sim.dynamics import DiffDriveSim
from beastbt.sim.serial_port import SimSerialPort

HEARTBEAT_TIMEOUT_S = 3.0
"""``HEART_BEAT_DELAY`` at boot (3000 ms, ugv_config.h): the wheels stop when no heartbeat command came for this long (s)."""
GIMBAL_RATE_DPS = 200.0
"""How fast the emulated gimbal servos move at SPD 0 (deg/s)."""
FIRMWARE_LIMIT_MPS = 2.0
"""``setGoalSpeed`` returns without effect when L or R is beyond this (m/s)."""
MAIN_TYPES = {1: (0.0800, 2100, 0.125), 2: (0.0800, 660, 0.172), 3: (0.0523, 1092, 0.141)}
"""Main type -> (WHEEL_D m, ONE_CIRCLE_PLUSES, TRACK_WIDTH m), as ``mm_settings`` sets them (movtion_module.h)."""
BOARD_MAIN_TYPE = 3
"""The emulated board sits in a UGV Beast: its encoders count with main type 3's wheel."""
BOOT = {"ros": {"main": 2, "feedback": True, "interval_s": 0.05, "echo": False},
        "general": {"main": 1, "feedback": False, "interval_s": 0.0, "echo": True}}
"""Each firmware's state at boot (ugv_config.h): mainType, baseFeedbackFlow, feedbackFlowExtraDelay, uartCmdEcho."""
OPEN_LOOP_PWM_PER_MPS = 512.0
"""general firmware, main type other than 3: ``leftCtrl(L * 512)``, open-loop PWM (of 255) per m/s asked."""
COMMANDS_KEPT = 2000
"""``commands`` keeps the last this many commands: about 100 s of a run at 20 Hz (a run on the simulator
writes to the base at every tick, for as long as it runs). :attr:`SimWaveshareBase.command_listeners` see
every one."""
VISITS_KEPT = 500
"""The gimbal's settled angles kept per servo: the first and the last this many (the summary's ``servos``)."""
GIMBAL_SERVO_IDS = (2, 1)
"""``GIMBAL_PAN_ID``, ``GIMBAL_TILT_ID`` (ugv_config.h)."""


def _encoder_scale(main_type: int) -> float:
    """Reported distance per true distance when the firmware assumes ``main_type`` on a Beast's encoders."""
    d, pulses, _ = MAIN_TYPES.get(main_type, MAIN_TYPES[2])
    d0, pulses0, _ = MAIN_TYPES[BOARD_MAIN_TYPE]
    return (pulses0 / pulses) * (d / d0)


@dataclass
class GimbalState:
    """Pan/tilt of the emulated gimbal in the base's convention (pan negative left), degrees."""

    pan_deg: float = 0.0
    tilt_deg: float = 0.0
    target_pan_deg: float = 0.0
    target_tilt_deg: float = 0.0
    torque_on: bool = True
    """False once torque was released (T:0 on ros, T:210 cmd 0): the servos go limp and ignore positions."""
    visits: dict = field(default_factory=lambda: {"pan": HeadTail(VISITS_KEPT, VISITS_KEPT),
                                                  "tilt": HeadTail(VISITS_KEPT, VISITS_KEPT)})
    """Angles each servo settled at, in beastbt's convention (pan positive left), in order: a
    :class:`~beastbt.core.bounded.HeadTail` per servo, the first and the last :data:`VISITS_KEPT`."""


class SimWaveshareBase:
    """The device side of the Waveshare serial base (``firmware`` ``ros`` or ``general``), driving a :class:`DiffDriveSim`.

    ``gimbal_present``: whether gimbal servos answer on the bus (without them,
    module 2 reports ``T:1005``).
    """

    def __init__(self, drive: DiffDriveSim, rng: np.random.Generator, battery_v: float = 12.3,
                 battery_drain_v_per_s: float = 0.0002, imu_gyro_noise_dps: float = 0.05,
                 imu_accel_noise_g: float = 0.003, firmware: str = "ros", gimbal_present: bool = True) -> None:
        if firmware not in BOOT:
            raise ValueError(f"unknown Waveshare firmware {firmware!r} (ros or general)")
        self.drive = drive
        self.rng = rng
        self.firmware = firmware
        self.gimbal_present = gimbal_present
        self.port = SimSerialPort("sim:waveshare", on_write=self._on_write)
        self._rx = bytearray()
        boot = BOOT[firmware]
        self.main_type: int = boot["main"]
        self.module_type = 0
        self.feedback_interval_s: float = boot["interval_s"]
        self.feedback_on: bool = boot["feedback"]
        self.echo: bool = boot["echo"]
        self.heartbeat_s = HEARTBEAT_TIMEOUT_S
        self.last_heartbeat_s = 0.0
        self.heartbeat_stopped = False
        self.next_feedback_s = 0.0
        self.now_s = 0.0
        self.gimbal = GimbalState()
        self.battery_v = battery_v
        self.battery_drain_v_per_s = battery_drain_v_per_s
        self.gyro_noise_dps = imu_gyro_noise_dps
        self.accel_noise_g = imu_accel_noise_g
        self.commands: Deque[dict] = deque(maxlen=COMMANDS_KEPT)
        """The latest :data:`COMMANDS_KEPT` command objects received, in order (tests pin protocols with it)."""
        self.commands_total = 0
        """How many command objects were received in all."""
        self.command_listeners: list[Callable[[dict], None]] = []
        """Called with every command object received, in order (for a complete log, as the test harness keeps)."""
        self.estops = 0
        """``T:0`` commands obeyed (ros firmware only)."""
        self.heartbeat_stops = 0
        """Times the heartbeat stopped the wheels."""
        self.ignored_speeds = 0
        """``T:1``/``T:13`` ignored for a side beyond +-2 m/s."""
        self._prev_v = 0.0

    @property
    def last_motion_cmd_s(self) -> Optional[float]:
        """When the heartbeat was last reset (s), or None once it has stopped the wheels."""
        return None if self.heartbeat_stopped else self.last_heartbeat_s

    def _on_write(self, data: bytes) -> None:
        self._rx += data
        while True:
            i = self._rx.find(b"\n")
            if i < 0:
                break
            line = bytes(self._rx[:i + 1])
            del self._rx[: i + 1]
            try:
                obj = json.loads(line)
            except ValueError:
                continue  # deserializeJson failed: the firmware ignores the line
            if self.echo:
                self.port.feed(line)  # serialCtrl echoes the raw line before handling it
            if isinstance(obj, dict):
                self._command(obj)

    @staticmethod
    def _float(obj: dict, key: str) -> Optional[float]:
        v = obj.get(key)
        return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) else None

    def _beat(self) -> None:
        self.heartbeat_stopped = False
        self.last_heartbeat_s = self.now_s

    def _set_goal_speed(self, left: float, right: float) -> None:
        """``setGoalSpeed``: closed-loop wheel speeds (m/s, as the firmware measures them), or nothing when beyond 2 m/s."""
        if self.firmware == "general" and self.main_type != 3:
            top = self.drive.model.max_wheel_speed_mps  # open loop: leftCtrl(L * 512), of 255
            self.drive.set_wheel_targets(max(-1.0, min(1.0, left * OPEN_LOOP_PWM_PER_MPS / 255.0)) * top,
                                         max(-1.0, min(1.0, right * OPEN_LOOP_PWM_PER_MPS / 255.0)) * top)
            return
        if abs(left) > FIRMWARE_LIMIT_MPS or abs(right) > FIRMWARE_LIMIT_MPS:
            self.ignored_speeds += 1
            return
        scale = _encoder_scale(self.main_type)  # the PID reaches the speed its encoder arithmetic believes
        self.drive.set_wheel_targets(left / scale, right / scale)

    def _command(self, obj: dict) -> None:
        self.commands.append(obj)
        self.commands_total += 1
        for listener in self.command_listeners:
            listener(obj)
        t = obj.get("T")
        ros = self.firmware == "ros"
        if t == 1:
            left, right = self._float(obj, "L"), self._float(obj, "R")
            if left is not None and right is not None:  # containsKey and is<float>()
                self._beat()
                self._set_goal_speed(left, right)
        elif t == 11:
            self._beat()
            top = self.drive.model.max_wheel_speed_mps
            self.drive.set_wheel_targets(max(-1.0, min(1.0, float(obj.get("L", 0)) / 255.0)) * top,
                                         max(-1.0, min(1.0, float(obj.get("R", 0)) / 255.0)) * top)
        elif t == 13:
            x, z = float(obj.get("X", 0.0)), float(obj.get("Z", 0.0))
            track = MAIN_TYPES.get(self.main_type, MAIN_TYPES[2])[2]
            self._set_goal_speed(x - z * track / 2.0, x + z * track / 2.0)
            if not ros:
                self._beat()  # ugv_base_general resets the heartbeat on T:13; ugv_base_ros does not
        elif t == 0 and ros:
            self.gimbal.torque_on = False  # emergencyStopProcessing: st.EnableTorque(254, 0)
            self._set_goal_speed(0.0, 0.0)
            self.estops += 1
        elif t == 210:
            self.gimbal.torque_on = bool(obj.get("cmd", 0))
        elif t == 133:
            if self.gimbal.torque_on:
                self.gimbal.target_pan_deg = max(-180.0, min(180.0, float(obj.get("X", 0.0))))
                self.gimbal.target_tilt_deg = max(-30.0, min(90.0, float(obj.get("Y", 0.0))))
        elif t == 135:
            # gimbalCtrlStop: torque off for a moment and on again: the servos stop where they are.
            self.gimbal.target_pan_deg, self.gimbal.target_tilt_deg = self.gimbal.pan_deg, self.gimbal.tilt_deg
        elif t == 136:
            self.heartbeat_s = float(obj.get("cmd", 3000)) / 1000.0
        elif t == 900:
            self.main_type = int(obj.get("main", self.main_type))
            self.module_type = int(obj.get("module", self.module_type))
        elif t == 4:
            self.module_type = int(obj.get("cmd", self.module_type))
        elif t == 142:
            self.feedback_interval_s = abs(float(obj.get("cmd", 50))) / 1000.0
        elif t == 131:
            self.feedback_on = obj.get("cmd") == 1 or (obj.get("cmd") != 0 and self.feedback_on)
        elif t == 143:
            self.echo = bool(obj.get("cmd", 0))

    def _move_gimbal(self, dt: float) -> None:
        g = self.gimbal
        if g.pan_deg == g.target_pan_deg and g.tilt_deg == g.target_tilt_deg:
            return  # at rest, as it is between looks (this runs at every physics step)
        step = GIMBAL_RATE_DPS * dt
        for axis in ("pan", "tilt"):
            cur = getattr(g, f"{axis}_deg")
            tgt = getattr(g, f"target_{axis}_deg")
            if cur == tgt:
                continue
            new = tgt if abs(tgt - cur) <= step else cur + math.copysign(step, tgt - cur)
            setattr(g, f"{axis}_deg", new)
            if new == tgt:
                angle = -tgt if axis == "pan" else tgt
                visits = g.visits[axis]
                if not visits or visits[-1] != angle:
                    visits.append(round(angle, 3))

    def update(self, now_s: float, dt: float) -> None:
        """Advance the firmware to ``now_s`` (after the physics step of ``dt``): heartbeat, gimbal, feedback."""
        self.now_s = now_s
        if now_s - self.last_heartbeat_s > self.heartbeat_s and not self.heartbeat_stopped:
            self.heartbeat_stopped = True  # heartBeatCtrl: setGoalSpeed(0, 0), once
            self._set_goal_speed(0.0, 0.0)
            self.heartbeat_stops += 1
        self._move_gimbal(dt)
        truth = self.drive.truth
        truth.pan_rad = math.radians(-self.gimbal.pan_deg)
        truth.tilt_rad = math.radians(self.gimbal.tilt_deg)
        self.battery_v -= self.battery_drain_v_per_s * dt * (1.0 + 2.0 * abs(truth.v_mps))
        truth.battery_v = self.battery_v
        if self.feedback_on and now_s + 1e-9 >= self.next_feedback_s:
            self.next_feedback_s = max(self.next_feedback_s + self.feedback_interval_s, now_s)
            if self.module_type == 2 and not self.gimbal_present:
                for ident in GIMBAL_SERVO_IDS:
                    self.port.feed(json.dumps({"T": 1005, "id": ident, "status": 0}, separators=(",", ":")).encode()
                                   + b"\n")
            self.port.feed(self._feedback_line() if self.firmware == "ros" else self._general_feedback_line())

    def odometry_m(self) -> tuple[float, float]:
        """Left and right distance (m) as the firmware computes it: whole encoder counts through its main type's wheel."""
        d0, pulses0, _ = MAIN_TYPES[BOARD_MAIN_TYPE]
        d, pulses, _ = MAIN_TYPES.get(self.main_type, MAIN_TYPES[2])
        per_count = math.pi * d0 / pulses0
        t = self.drive.truth
        return (int(t.left_m / per_count) / pulses * d * math.pi, int(t.right_m / per_count) / pulses * d * math.pi)

    def _gimbal_fields(self, fb: dict) -> None:
        if self.module_type == 2:
            fb["pan"] = round(self.gimbal.pan_deg, 2)
            fb["tilt"] = round(self.gimbal.tilt_deg, 2)

    def _feedback_line(self) -> bytes:
        t = self.drive.truth
        n = self.rng.standard_normal(6)
        accel_x = (t.v_mps - self._prev_v) / max(self.feedback_interval_s, 1e-3) / STANDARD_GRAVITY
        self._prev_v = t.v_mps
        gz = math.degrees(t.w_rps) + self.gyro_noise_dps * n[2]
        scale = _encoder_scale(self.main_type)
        odl, odr = self.odometry_m()
        fb = {
            "T": 1001,
            "L": round(t.left_mps * scale, 4), "R": round(t.right_mps * scale, 4),
            "ax": int(round((accel_x + self.accel_noise_g * n[3]) * ACCEL_LSB_PER_G)),
            "ay": int(round((t.v_mps * t.w_rps / STANDARD_GRAVITY + self.accel_noise_g * n[4]) * ACCEL_LSB_PER_G)),
            "az": int(round((1.0 + self.accel_noise_g * n[5]) * ACCEL_LSB_PER_G)),
            "gx": int(round(self.gyro_noise_dps * n[0] * GYRO_LSB_PER_DPS)),
            "gy": int(round(self.gyro_noise_dps * n[1] * GYRO_LSB_PER_DPS)),
            "gz": int(round(gz * GYRO_LSB_PER_DPS)),
            "odl": int(odl * 100), "odr": int(odr * 100),  # long int odl_cm = (en_odom_l * 100): truncated
            "v": int(self.battery_v * 100),
        }
        self._gimbal_fields(fb)
        return json.dumps(fb, separators=(",", ":")).encode() + b"\n"

    def _general_feedback_line(self) -> bytes:
        t = self.drive.truth
        scale = _encoder_scale(self.main_type)
        fb = {
            "T": 1001,
            "L": round(t.left_mps * scale, 4), "R": round(t.right_mps * scale, 4),
            "r": 0.0, "p": 0.0, "y": round(math.degrees(t.yaw), 2),
            "temp": 45.0,
            "v": round(self.battery_v, 2),
        }
        self._gimbal_fields(fb)
        return json.dumps(fb, separators=(",", ":")).encode() + b"\n"
