"""An emulated Waveshare ESP32 sub-controller behind a :class:`SimSerialPort`.

It parses the same JSON commands the real firmware does (T:13 velocity, T:1
wheel speeds, T:0 stop, T:133 gimbal, T:132 lights, T:142 feedback interval,
T:131 continuous feedback, T:143 echo), drives the simulated motors and gimbal,
and sends ``T:1001`` feedback lines with wheel speeds, raw IMU, odometry in
centimetres and battery voltage, as the real base does. Like the firmware, it
stops the motors when no motion command has come for ``heartbeat_timeout_s``.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from beastbt.devices.waveshare_base import ACCEL_LSB_PER_G, GYRO_LSB_PER_DPS, STANDARD_GRAVITY
from beastbt.sim.dynamics import DiffDriveSim
from beastbt.sim.serial_port import SimSerialPort

HEARTBEAT_TIMEOUT_S = 3.0
"""The firmware stops the motors when no motion command arrived for this long (s)."""
GIMBAL_RATE_DPS = 200.0
"""How fast the emulated gimbal servos move at SPD 0 (deg/s)."""


@dataclass
class GimbalState:
    """Pan/tilt of the emulated gimbal in the base's convention (pan negative left), degrees."""

    pan_deg: float = 0.0
    tilt_deg: float = 0.0
    target_pan_deg: float = 0.0
    target_tilt_deg: float = 0.0
    visits: dict = field(default_factory=lambda: {"pan": [], "tilt": []})
    """Angles each servo settled at, in beastbt's convention (pan positive left), in order."""


class SimWaveshareBase:
    """The device side of the Waveshare serial base, driving a :class:`DiffDriveSim`."""

    def __init__(self, drive: DiffDriveSim, rng: np.random.Generator, battery_v: float = 12.3,
                 battery_drain_v_per_s: float = 0.0002, imu_gyro_noise_dps: float = 0.05,
                 imu_accel_noise_g: float = 0.003) -> None:
        self.drive = drive
        self.rng = rng
        self.port = SimSerialPort("sim:waveshare", on_write=self._on_write)
        self._rx = bytearray()
        self.feedback_interval_s = 0.05
        self.feedback_on = False
        self.echo = False
        self.next_feedback_s = 0.0
        self.last_motion_cmd_s: Optional[float] = None
        self.now_s = 0.0
        self.gimbal = GimbalState()
        self.battery_v = battery_v
        self.battery_drain_v_per_s = battery_drain_v_per_s
        self.gyro_noise_dps = imu_gyro_noise_dps
        self.accel_noise_g = imu_accel_noise_g
        self.commands: list[dict] = []
        """Every command object received, in order (tests pin protocols with it)."""
        self.estops = 0
        self._prev_v = 0.0

    def _on_write(self, data: bytes) -> None:
        self._rx += data
        while True:
            i = self._rx.find(b"\n")
            if i < 0:
                break
            line = bytes(self._rx[:i])
            del self._rx[: i + 1]
            try:
                obj = json.loads(line)
            except ValueError:
                continue  # the firmware ignores what it cannot parse
            if isinstance(obj, dict):
                self._command(obj)

    def _command(self, obj: dict) -> None:
        self.commands.append(obj)
        t = obj.get("T")
        if self.echo:
            self.port.feed(json.dumps(obj, separators=(",", ":")).encode() + b"\n")
        if t == 13:
            self.drive.set_body_targets(float(obj.get("X", 0.0)), float(obj.get("Z", 0.0)))
            self.last_motion_cmd_s = self.now_s
        elif t == 1:
            self.drive.set_wheel_targets(float(obj.get("L", 0.0)), float(obj.get("R", 0.0)))
            self.last_motion_cmd_s = self.now_s
        elif t == 0:
            self.drive.set_wheel_targets(0.0, 0.0)
            self.estops += 1
        elif t == 133:
            self.gimbal.target_pan_deg = max(-180.0, min(180.0, float(obj.get("X", 0.0))))
            self.gimbal.target_tilt_deg = max(-30.0, min(90.0, float(obj.get("Y", 0.0))))
        elif t == 142:
            self.feedback_interval_s = max(0.01, float(obj.get("cmd", 50)) / 1000.0)
        elif t == 131:
            self.feedback_on = bool(obj.get("cmd", 1))
        elif t == 143:
            self.echo = bool(obj.get("cmd", 0))

    def _move_gimbal(self, dt: float) -> None:
        g = self.gimbal
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
        if self.last_motion_cmd_s is not None and now_s - self.last_motion_cmd_s > HEARTBEAT_TIMEOUT_S:
            self.drive.set_wheel_targets(0.0, 0.0)
            self.last_motion_cmd_s = None
        self._move_gimbal(dt)
        truth = self.drive.truth
        truth.pan_rad = math.radians(-self.gimbal.pan_deg)
        truth.tilt_rad = math.radians(self.gimbal.tilt_deg)
        self.battery_v -= self.battery_drain_v_per_s * dt * (1.0 + 2.0 * abs(truth.v_mps))
        truth.battery_v = self.battery_v
        if self.feedback_on and now_s + 1e-9 >= self.next_feedback_s:
            self.next_feedback_s = max(self.next_feedback_s + self.feedback_interval_s, now_s)
            self.port.feed(self._feedback_line(dt))

    def _feedback_line(self, dt: float) -> bytes:
        t = self.drive.truth
        n = self.rng.standard_normal(6)
        accel_x = (t.v_mps - self._prev_v) / max(self.feedback_interval_s, 1e-3) / STANDARD_GRAVITY
        self._prev_v = t.v_mps
        gz = math.degrees(t.w_rps) + self.gyro_noise_dps * n[2]
        fb = {
            "T": 1001,
            "L": round(t.left_mps, 4), "R": round(t.right_mps, 4),
            "ax": int(round((accel_x + self.accel_noise_g * n[3]) * ACCEL_LSB_PER_G)),
            "ay": int(round((t.v_mps * t.w_rps / STANDARD_GRAVITY + self.accel_noise_g * n[4]) * ACCEL_LSB_PER_G)),
            "az": int(round((1.0 + self.accel_noise_g * n[5]) * ACCEL_LSB_PER_G)),
            "gx": int(round(self.gyro_noise_dps * n[0] * GYRO_LSB_PER_DPS)),
            "gy": int(round(self.gyro_noise_dps * n[1] * GYRO_LSB_PER_DPS)),
            "gz": int(round(gz * GYRO_LSB_PER_DPS)),
            "odl": round(t.left_m * 100.0, 2), "odr": round(t.right_m * 100.0, 2),
            "v": int(round(self.battery_v * 100.0)),
            "pan": round(self.gimbal.pan_deg, 2), "tilt": round(self.gimbal.tilt_deg, 2),
        }
        return json.dumps(fb, separators=(",", ":")).encode() + b"\n"
