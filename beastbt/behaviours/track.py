"""``track: {colour: red, for: 30 s}``: turn the robot to keep the largest blob of a colour in the middle of the picture.

Each tick it asks the vision service (``ctx.services.vision``) for the colour's largest blob and turns in
place toward it (turn rate proportional to the blob's bearing, the gimbal's pan included), standing still
while the colour is out of sight. A robot with a tilt servo first levels its camera, as ``dock`` does.
"""

from __future__ import annotations

import math
from typing import Any, Optional

from beastbt.behaviours.base import BeastBehaviour, Status
from beastbt.behaviours.context import MissionContext
from beastbt.blackboard.types import ServoCommand

TRACK_GAIN = 1.5
"""Turn rate per radian of bearing to the blob (1/s)."""
CENTRED_RAD = math.radians(2.0)
"""Within this of the middle the robot holds still (rad): no hunting about a centred blob."""
GIMBAL_SETTLE_S = 0.6
"""Time for the gimbal to level the camera before tracking (s)."""


class TrackColour(BeastBehaviour):
    """Keep the largest blob of ``colour`` centred by turning, for ``duration_s``.

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

    def initialise(self) -> None:
        self.start_s = self.now()
        self.seen = 0
        self.bearing_rad = None
        watch = self.ctx.services.vision
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
        pan, _ = watch.gimbal()
        self.bearing_rad = blob.bearing_rad(cam.camera_matrix) + pan
        if abs(self.bearing_rad) <= CENTRED_RAD:
            self.command(0.0, 0.0)
        else:
            p = self.ctx.params
            rate = max(p.min_turn_rate_rps, min(self.ctx.turn_rate_limit_rps, TRACK_GAIN * abs(self.bearing_rad)))
            self.command(0.0, math.copysign(rate, self.bearing_rad))
        self.feedback_message = f"{self.colour.name} at {math.degrees(self.bearing_rad):+.0f} deg"
        return Status.RUNNING


__all__ = ["TrackColour"]
