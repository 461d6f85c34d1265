"""Differential-drive dynamics of the simulated robot: motor response, limits, slip, contact.

Each wheel (or track) follows its speed target through a first-order lag
limited in acceleration and speed. The body moves by the wheel speeds each
scaled by a random slip; the encoders count the unslipped wheel travel, so the
odometry drifts the way a real one does.

Contact (:mod:`beastbt.sim.contact`): the footprint cannot pass through a wall
or an obstacle, whatever the speed or the time step (a swept test). A move that
would push into something ends at contact and the forward drive stalls there:
the tracks stop and their encoders stop counting the blocked part, so "blocked"
is visible to odometry. Turning on the spot still works (the tracks skid), and
moving along or away from what it touches is free. The persons of the world
walk first in each step; one that reaches the robot stops at contact.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Optional

if TYPE_CHECKING:  # only for annotations: validating a world (which needs Wall) does not load NumPy
    import numpy as np

    from beastbt.sim.contact import ContactWorld

from beastbt.core.config import dataclass_from_dict
from beastbt.core.schema_defaults import schema_defaults
from beastbt.sim.truth import RobotTruth


@dataclass
@schema_defaults("robot.schema.json#/properties/sim",
                 computed={"track_width_m": "the profile's geometry.track_width_m (set by build_simulator)"})
class DriveModel:
    """Physical parameters of the simulated base (a robot profile's ``sim:`` section, SI units).

    ``track_width_m``: effective distance between the tracks/wheels, m.
    ``max_wheel_speed_mps``: top speed of one side, m/s.
    ``max_wheel_accel_mps2``: top acceleration of one side, m/s^2.
    ``motor_time_constant_s``: first-order lag of the motor speed loop, s.
    ``slip_sigma``: standard deviation of the per-step fractional slip of each side (0.02 = 2 %).
    ``slip_bias``: mean fraction of wheel travel lost to slip (0.01 = 1 %).
    ``footprint_radius_m``: radius of the circle that collides with walls and obstacles, m.
    """

    track_width_m: float = 0.17
    max_wheel_speed_mps: float
    max_wheel_accel_mps2: float
    motor_time_constant_s: float
    slip_sigma: float
    slip_bias: float
    footprint_radius_m: float

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "DriveModel":
        """Build from a mapping of field names; unknown keys are a ValueError."""
        return dataclass_from_dict(cls, d, "sim")


@dataclass
class Wall:
    """A wall segment in the world frame (metres)."""

    x1: float
    y1: float
    x2: float
    y2: float

    def distance_to(self, x: float, y: float) -> float:
        """Shortest distance from point (x, y) to the segment, m."""
        dx, dy = self.x2 - self.x1, self.y2 - self.y1
        L2 = dx * dx + dy * dy
        t = 0.0 if L2 == 0 else max(0.0, min(1.0, ((x - self.x1) * dx + (y - self.y1) * dy) / L2))
        return math.hypot(x - (self.x1 + t * dx), y - (self.y1 + t * dy))


@dataclass
class DiffDriveSim:
    """Integrates the true state of a differential-drive robot.

    ``contact`` is the world it can touch; left out, one is made of ``walls`` (none without walls).
    """

    model: DriveModel
    truth: RobotTruth
    rng: np.random.Generator
    walls: list[Wall] = field(default_factory=list)
    target_left_mps: float = 0.0
    target_right_mps: float = 0.0
    path_length_m: float = 0.0
    max_speed_mps: float = 0.0
    blocked: bool = False
    contact: Optional[ContactWorld] = None

    def __post_init__(self) -> None:
        if self.contact is None and self.walls:
            from beastbt.sim.contact import ContactWorld  # NumPy only where something can be touched
            self.contact = ContactWorld(self.walls, [], self.model.footprint_radius_m)

    def set_wheel_targets(self, left_mps: float, right_mps: float) -> None:
        """Set the speed each side's motor controller aims for (clamped to the top speed)."""
        top = self.model.max_wheel_speed_mps
        self.target_left_mps = max(-top, min(top, left_mps))
        self.target_right_mps = max(-top, min(top, right_mps))

    def set_body_targets(self, v_mps: float, w_rps: float) -> None:
        """Set wheel targets from a body velocity (m/s forward, rad/s CCW)."""
        half = 0.5 * self.model.track_width_m * w_rps
        self.set_wheel_targets(v_mps - half, v_mps + half)

    def _side(self, current: float, target: float, dt: float) -> float:
        m = self.model
        alpha = 1.0 - math.exp(-dt / m.motor_time_constant_s) if m.motor_time_constant_s > 0 else 1.0
        delta = (target - current) * alpha
        limit = m.max_wheel_accel_mps2 * dt
        return current + max(-limit, min(limit, delta))

    def step(self, dt: float) -> None:
        """Advance the true state by ``dt`` seconds."""
        t = self.truth
        m = self.model
        contact = self.contact
        if contact is not None and contact.persons:
            # The persons walk first (knowing where the robot is and where it is going); the robot then meets them.
            contact.advance_persons(t.t_s + dt, dt, t.x, t.y, t.yaw, t.v_mps)
        vl = self._side(t.left_mps, self.target_left_mps, dt)
        vr = self._side(t.right_mps, self.target_right_mps, dt)
        if vl == 0.0 and vr == 0.0:
            t.left_mps = t.right_mps = t.v_mps = t.w_rps = 0.0
            t.t_s += dt
            if contact is not None:
                contact.observe(t.x, t.y)
            return
        sl = 1.0 - m.slip_bias + m.slip_sigma * self.rng.standard_normal()
        sr = 1.0 - m.slip_bias + m.slip_sigma * self.rng.standard_normal()
        v = 0.5 * (vl * sl + vr * sr)
        w = (vr * sr - vl * sl) / m.track_width_m
        mid = t.yaw + 0.5 * w * dt
        nx, ny = t.x + v * dt * math.cos(mid), t.y + v * dt * math.sin(mid)
        free = 1.0 if contact is None else contact.free_fraction(t.x, t.y, nx, ny)
        if free < 1.0:
            # Pushing into something: the robot goes as far as contact and the forward drive stalls there (its
            # encoders stop counting it); the turning part goes on, the tracks skidding on the spot.
            self.blocked = True
            forward, turning = 0.5 * (vl + vr), 0.5 * (vr - vl)
            t.x += free * (nx - t.x)
            t.y += free * (ny - t.y)
            t.yaw = (t.yaw + w * dt + math.pi) % (2 * math.pi) - math.pi
            t.left_m += (free * forward - turning) * dt
            t.right_m += (free * forward + turning) * dt
            t.left_mps, t.right_mps = -turning, turning
            t.v_mps, t.w_rps = 0.0, w
            self.path_length_m += free * abs(v) * dt
            t.t_s += dt
            contact.observe(t.x, t.y)  # type: ignore[union-attr]  # free < 1 only with contact
            return
        self.blocked = False
        t.x, t.y = nx, ny
        t.yaw = (t.yaw + w * dt + math.pi) % (2 * math.pi) - math.pi
        t.left_m += vl * dt
        t.right_m += vr * dt
        t.left_mps, t.right_mps = vl, vr
        t.v_mps, t.w_rps = v, w
        self.path_length_m += abs(v) * dt
        self.max_speed_mps = max(self.max_speed_mps, abs(v))
        t.t_s += dt
        if contact is not None:
            contact.observe(t.x, t.y)
