"""``track: {colour: red, for: 30 s}``: keep the largest blob of a colour in the middle of the picture.

Each tick it asks the vision service (``ctx.services.vision``) for the colour's largest blob and its bearing
off the camera's axis. On a robot with a ``pan`` servo the pan follows the blob first (its angle moves at a
rate proportional to the bearing, within :data:`PAN_LIMIT_RAD`), and the base turns in place only while the
pan is beyond :data:`PAN_FREE_RAD`, toward the side the pan points, so the pan comes back within it; the pan
turns back by what the base turns, so the blob stays centred meanwhile. A robot without a pan servo turns
in place toward the blob. Either way it stands still (and the pan holds) while the colour is out of sight.
A robot with a tilt servo first levels its camera, as ``dock`` does.
"""

from __future__ import annotations

import math
from typing import Any, Optional

from beastbt.behaviours.base import BeastBehaviour, Status
from beastbt.behaviours.context import MissionContext
from beastbt.blackboard.types import ServoCommand

TRACK_GAIN = 1.5
"""Base turn rate per radian of bearing to the blob (1/s), or per radian of pan beyond PAN_FREE_RAD."""
CENTRED_RAD = math.radians(2.0)
"""Within this of the middle the robot and the pan hold still (rad): no hunting about a centred blob."""
GIMBAL_SETTLE_S = 0.6
"""Time for the gimbal to level the camera before tracking (s)."""
PAN_GAIN = 3.0
"""Pan rate per radian of bearing off the camera's axis (1/s): a blob 10 degrees off is centred in about a
third of a second, slow enough that a frame taken while the pan moves does not make it overshoot."""
PAN_MAX_RATE_RPS = math.radians(120.0)
"""Fastest the tracking turns the pan (rad/s), within what the Beast's gimbal servos do (about 200 deg/s)."""
PAN_LIMIT_RAD = math.radians(90.0)
"""Farthest the tracking turns the pan either way (rad): a hobby servo's range, and where the Beast's camera
would start to look over its own back."""
PAN_FREE_RAD = math.radians(60.0)
"""The pan alone keeps the blob centred within this (rad); beyond it the base turns too, before the pan
reaches PAN_LIMIT_RAD."""
PAN_RESEND_RAD = math.radians(0.25)
"""A pan change smaller than this is not sent (rad): no servo command every tick for nothing."""


class TrackColour(BeastBehaviour):
    """Keep the largest blob of ``colour`` centred with the pan servo and by turning, for ``duration_s``.

    Succeeds once the time has passed, if the colour was seen at some point; fails then when it never was, and at
    once on a robot without a camera. ``colour`` is a :class:`~beastbt.vision.colour.ColourRange`.
    """

    WRITES = ("cmd_mission", "servo_requests")

    def __init__(self, name: str, ctx: MissionContext, colour: Any, duration_s: float) -> None:
        super().__init__(name, ctx)
        self.colour = colour
        self.duration_s = duration_s
        self.start_s = 0.0
        self.seen = 0
        self.bearing_rad: Optional[float] = None
        """The blob's bearing from the robot's heading (rad, left positive): off the camera's axis plus the pan."""
        self.pan_rad = 0.0
        self.sent_pan_rad = 0.0
        self.last_s: Optional[float] = None

    @property
    def has_pan(self) -> bool:
        """Whether this robot points its camera with a ``pan`` servo."""
        return "pan" in self.ctx.servo_names

    def initialise(self) -> None:
        self.start_s = self.now()
        self.seen = 0
        self.bearing_rad = None
        self.last_s = None
        watch = self.ctx.services.vision
        self.pan_rad = self.sent_pan_rad = watch.gimbal()[0] if watch is not None else 0.0
        if watch is not None and "tilt" in self.ctx.servo_names:
            requests = dict(self.read("servo_requests") or {})
            requests["tilt"] = ServoCommand("tilt", math.radians(watch.geometry.pitch_deg), None, None, self.now())
            self.bb.servo_requests = requests
        else:
            self.start_s -= GIMBAL_SETTLE_S  # nothing to level: track at once

    def update(self) -> Status:
        watch = self.ctx.services.vision
        if watch is None:
            return self.fail("this robot has no camera")
        now = self.now()
        dt = 0.0 if self.last_s is None else max(0.0, now - self.last_s)
        self.last_s = now
        if now - self.start_s < GIMBAL_SETTLE_S:
            self.command(0.0, 0.0)
            self.feedback_message = "levelling the camera"
            return Status.RUNNING
        if now - self.start_s >= self.duration_s + GIMBAL_SETTLE_S:
            self.command(0.0, 0.0)
            if not self.seen:
                return self.fail(f"never saw {self.colour.name}")
            return Status.SUCCESS
        got = watch.colour(now, self.colour)
        blob, cam = got if got is not None else (None, None)
        if blob is None or cam is None:
            self.command(0.0, 0.0)
            self.feedback_message = f"no {self.colour.name} in sight"
            return Status.RUNNING
        self.seen += 1
        off_axis = blob.bearing_rad(cam.camera_matrix)
        if self.has_pan:
            turn = self._follow_with_pan(off_axis, dt)
            self.bearing_rad = self.pan_rad + off_axis
        else:
            self.bearing_rad = off_axis + watch.gimbal()[0]
            turn = self._turn_rate(self.bearing_rad)
        self.command(0.0, turn)
        where = f", pan {math.degrees(self.pan_rad):+.0f} deg" if self.has_pan else ""
        self.feedback_message = f"{self.colour.name} at {math.degrees(self.bearing_rad):+.0f} deg{where}"
        return Status.RUNNING

    def _turn_rate(self, error_rad: float) -> float:
        """The base's turn rate (rad/s, left positive) that closes ``error_rad``; 0 within CENTRED_RAD."""
        if abs(error_rad) <= CENTRED_RAD:
            return 0.0
        p = self.ctx.params
        rate = max(p.min_turn_rate_rps, min(self.ctx.turn_rate_limit_rps, TRACK_GAIN * abs(error_rad)))
        return math.copysign(rate, error_rad)

    def _follow_with_pan(self, off_axis_rad: float, dt: float) -> float:
        """Move the pan toward the blob (``off_axis_rad`` off the camera's axis, left positive) for ``dt`` s; the
        base's turn rate (rad/s) that brings a pan beyond PAN_FREE_RAD back within it."""
        beyond = abs(self.pan_rad) - PAN_FREE_RAD
        turn = self._turn_rate(math.copysign(beyond, self.pan_rad)) if beyond > 0.0 else 0.0
        rate = 0.0 if abs(off_axis_rad) <= CENTRED_RAD else \
            max(-PAN_MAX_RATE_RPS, min(PAN_MAX_RATE_RPS, PAN_GAIN * off_axis_rad))
        # The base turning left moves the blob right in the picture by as much: the pan turns back by it.
        self.pan_rad = max(-PAN_LIMIT_RAD, min(PAN_LIMIT_RAD, self.pan_rad + (rate - turn) * dt))
        if abs(self.pan_rad - self.sent_pan_rad) >= PAN_RESEND_RAD:
            requests = dict(self.read("servo_requests") or {})
            requests["pan"] = ServoCommand("pan", self.pan_rad, None, None, self.now())
            self.bb.servo_requests = requests
            self.sent_pan_rad = self.pan_rad
        return turn


__all__ = ["TrackColour"]
