"""``dock`` and ``undock``: drive up to a fiducial tag and stop square to it at a set distance, and back off again.

:class:`Dock` works as Nav2's docking server does, with odometry (``pose_odom``) between sightings:

1. **find**: level the camera (a tilt servo is turned so the optical axis is horizontal), then look for the
   tag; it turns in place to look around when it is not in view.
2. **stage**: drive to the staging pose :data:`STAGING_M` in front of the tag (where its estimate puts it),
   and turn to face it.
3. **approach**: follow the tag's axis to ``distance_m`` (robot centre to the tag's face), steering by
   where the tag is seen; once the tag is too near to be seen whole, the last estimate and odometry finish it.
4. **square**: turn in place to face the tag square.

The tag's pose is kept in the odometry frame, averaged over the recent sightings (nearer sightings count
more). If the tag is not seen for :data:`LOST_AFTER_S` while it should be, the robot backs off
:data:`BACK_OFF_M` and starts again from staging, at most :data:`RETRIES` times; then the step fails.
When it ends, the estimated pose error (position and heading against the goal) goes to the vision
service's ``docks`` (the summary's ``vision.docks``), where the simulator adds the true error.
"""

from __future__ import annotations

import math
from typing import Any, Optional

from beastbt.behaviours.base import BeastBehaviour, Status
from beastbt.behaviours.context import MissionContext
from beastbt.blackboard.types import ServoCommand
from beastbt.estimation.estimator import wrap_angle

STAGING_M = 1.0
"""The staging pose is this far in front of the tag's face (m)."""
LOST_AFTER_S = 1.0
"""A tag not seen for this long (s), while it should be, is lost: back off and retry."""
BACK_OFF_M = 0.4
"""How far a retry backs off (m)."""
RETRIES = 2
"""Retries after losing the tag before the step fails."""
SEARCH_RATE_RPS = 0.35
"""Turn rate while looking around for the tag (rad/s)."""
POSITION_TOLERANCE_M = 0.004
"""The approach stops when the robot is this close to the goal along the tag's axis (m)."""
HEADING_TOLERANCE_RAD = math.radians(0.4)
"""Squaring stops within this of the goal heading (rad)."""
STAGE_TOLERANCE_M = 0.03
"""The staging pose is reached within this (m)."""
SIGHTINGS_KEPT = 12
"""Sightings averaged into the tag's pose."""
GIMBAL_SETTLE_S = 0.6
"""Time for the gimbal to level the camera before looking (s)."""


class Dock(BeastBehaviour):
    """Dock at tag ``tag`` (see the module docstring).

    Succeeds square to the tag at ``distance_m`` from its face (robot centre); fails when the robot has no
    camera or odometry, when the tag is not found in a full turn, or after :data:`RETRIES` retries.
    """

    READS = ("pose_odom",)
    WRITES = ("cmd_mission", "servo_requests")

    def __init__(self, name: str, ctx: MissionContext, tag: int, family: str, size_m: float, distance_m: float,
                 speed_mps: Optional[float] = None) -> None:
        super().__init__(name, ctx)
        self.tag = tag
        self.family = family
        self.size_m = size_m
        self.distance_m = distance_m
        self.speed_mps = min(speed_mps or 0.12, ctx.speed_limit_mps)
        self.phase = "level"
        self.phase_s = 0.0
        self.sightings: list[tuple[float, float, float, float]] = []  # (x, y, facing, weight) in odom
        self.last_seen_s = -math.inf
        self.retries = 0
        self.searched_rad = 0.0
        self.last_yaw: Optional[float] = None
        self.back_from: Optional[tuple[float, float]] = None
        self.blind_m = 0.0

    # -- the tag's pose ---------------------------------------------------------------
    def initialise(self) -> None:
        watch = self.ctx.services.vision
        if watch is not None:
            watch.tag_sizes_m[self.tag] = self.size_m
            geom = watch.geometry
            # Nearer than this (robot centre to the face) the printed sheet no longer fits in the picture.
            vfov_half = math.atan((geom.height_px / 2.0) / geom.focal_px)
            self.blind_m = 0.65 * self.size_m / math.tan(vfov_half) + geom.x_offset_m + 0.05
        self.phase = "level"
        self.phase_s = self.now()
        self.sightings = []
        self.last_seen_s = -math.inf
        self.retries = 0
        self.searched_rad = 0.0
        self.last_yaw = None
        self.back_from = None

    def _look(self, pose: Any) -> bool:
        """Read the camera: add a sighting of the tag in the odometry frame; True when it was seen now."""
        watch = self.ctx.services.vision
        seen = watch.tag(self.now(), self.tag, self.family) if watch is not None else None
        if seen is None or seen.position_m is None or seen.facing_rad is None:
            return False
        bx, by, _ = seen.position_m
        c, s = math.cos(pose.yaw), math.sin(pose.yaw)
        x, y = pose.x + c * bx - s * by, pose.y + s * bx + c * by
        facing = wrap_angle(pose.yaw + seen.facing_rad)
        rng = math.hypot(bx, by)
        self.sightings.append((x, y, facing, 1.0 / max(0.2, rng) ** 2))
        del self.sightings[:-SIGHTINGS_KEPT]
        self.last_seen_s = self.now()
        return True

    def tag_pose(self) -> Optional[tuple[float, float, float]]:
        """The tag's (x, y, facing) in the odometry frame (m, rad), averaged over the kept sightings."""
        if not self.sightings:
            return None
        total = sum(w for *_, w in self.sightings)
        x = sum(p[0] * p[3] for p in self.sightings) / total
        y = sum(p[1] * p[3] for p in self.sightings) / total
        sx = sum(math.cos(p[2]) * p[3] for p in self.sightings)
        sy = sum(math.sin(p[2]) * p[3] for p in self.sightings)
        return x, y, math.atan2(sy, sx)

    def goal(self, stand_off_m: float) -> Optional[tuple[float, float, float]]:
        """The pose (x, y, yaw) ``stand_off_m`` in front of the tag's face, facing it, in the odometry frame."""
        tag = self.tag_pose()
        if tag is None:
            return None
        x, y, facing = tag
        return x + stand_off_m * math.cos(facing), y + stand_off_m * math.sin(facing), wrap_angle(facing + math.pi)

    # -- motion helpers ------------------------------------------------------------------
    def _set_phase(self, phase: str) -> None:
        self.phase = phase
        self.phase_s = self.now()

    def _turn_rate(self, err: float) -> float:
        p = self.ctx.params
        rate = max(p.min_turn_rate_rps, min(self.ctx.turn_rate_limit_rps, 1.0, p.turn_gain * abs(err)))
        return math.copysign(rate, err)

    def _drive_to(self, pose: Any, gx: float, gy: float, tolerance_m: float) -> bool:
        """Steer toward (gx, gy); True once within ``tolerance_m`` (stopped)."""
        dx, dy = gx - pose.x, gy - pose.y
        dist = math.hypot(dx, dy)
        if dist <= tolerance_m:
            self.command(0.0, 0.0)
            return True
        err = wrap_angle(math.atan2(dy, dx) - pose.yaw)
        if abs(err) > math.radians(25):
            self.command(0.0, self._turn_rate(err))
        else:
            v = max(0.04, min(self.speed_mps * 1.5, 0.8 * dist))
            self.command(v, 2.0 * err)
        return False

    # -- the step ------------------------------------------------------------------------
    def update(self) -> Status:
        if self.ctx.services.vision is None:
            return self.fail("this robot has no camera")
        pose = self.read("pose_odom")
        if pose is None:
            return self.fail("no odometry")
        seen = self._look(pose)
        now = self.now()
        if self.phase == "level":
            self.command(0.0, 0.0)
            if "tilt" in self.ctx.servo_names or "pan" in self.ctx.servo_names:
                self._level_camera()
                if now - self.phase_s < GIMBAL_SETTLE_S:
                    self.feedback_message = "levelling the camera"
                    return Status.RUNNING
                self.sightings = []  # sightings while the gimbal moved were placed with the wrong camera pose
            self._set_phase("find")
            self.last_yaw = pose.yaw
            self.searched_rad = 0.0
            return Status.RUNNING
        if self.phase == "find":
            if len(self.sightings) >= 3:
                self.command(0.0, 0.0)
                self._set_phase("stage")
                return Status.RUNNING
            if seen:  # hold still for a few sightings
                self.command(0.0, 0.0)
                return Status.RUNNING
            if now - self.phase_s < 0.5:  # a fresh frame may be on its way
                self.command(0.0, 0.0)
                return Status.RUNNING
            self.searched_rad += abs(wrap_angle(pose.yaw - (self.last_yaw if self.last_yaw is not None else pose.yaw)))
            self.last_yaw = pose.yaw
            if self.searched_rad > 2.0 * math.pi:
                self.command(0.0, 0.0)
                return self._finish(pose, f"tag {self.tag} not found in a full turn", Status.FAILURE)
            self.command(0.0, SEARCH_RATE_RPS)
            self.feedback_message = f"looking for tag {self.tag}"
            return Status.RUNNING
        goal = self.goal(STAGING_M)
        assert goal is not None
        if self.phase == "stage":
            if self._drive_to(pose, goal[0], goal[1], STAGE_TOLERANCE_M):
                self._set_phase("face")
            self.feedback_message = f"to the staging pose of tag {self.tag}"
            return Status.RUNNING
        if self.phase == "face":
            err = wrap_angle(goal[2] - pose.yaw)
            if abs(err) > math.radians(1.0):
                self.command(0.0, self._turn_rate(err))
                return Status.RUNNING
            self.command(0.0, 0.0)
            if now - self.phase_s < 0.5:  # a few sightings from the staging pose, the best ones so far
                return Status.RUNNING
            if now - self.last_seen_s > LOST_AFTER_S:
                return self._retry(pose, "tag not in view at the staging pose")
            self._set_phase("approach")
            return Status.RUNNING
        if self.phase == "approach":
            return self._approach(pose, now)
        if self.phase == "back_off":
            assert self.back_from is not None
            if math.hypot(pose.x - self.back_from[0], pose.y - self.back_from[1]) >= BACK_OFF_M:
                self.command(0.0, 0.0)
                self._set_phase("stage")
                return Status.RUNNING
            self.command(-0.08, 0.0)
            return Status.RUNNING
        # square
        final = self.goal(self.distance_m)
        assert final is not None
        err = wrap_angle(final[2] - pose.yaw)
        if abs(err) > HEADING_TOLERANCE_RAD:
            self.command(0.0, self._turn_rate(err))
            return Status.RUNNING
        self.command(0.0, 0.0)
        return self._finish(pose, "", Status.SUCCESS)

    def _approach(self, pose: Any, now: float) -> Status:
        tx, ty, facing = self.tag_pose()  # type: ignore[misc]
        nx, ny = math.cos(facing), math.sin(facing)
        along = (pose.x - tx) * nx + (pose.y - ty) * ny  # distance in front of the face
        lateral = -(pose.x - tx) * ny + (pose.y - ty) * nx
        if along > self.blind_m and now - self.last_seen_s > LOST_AFTER_S:
            return self._retry(pose, "tag lost on the approach")
        remaining = along - self.distance_m
        if remaining <= POSITION_TOLERANCE_M:
            self.command(0.0, 0.0)
            self._set_phase("square")
            return Status.RUNNING
        # Pure pursuit of a point on the tag's axis a little ahead (never past the goal).
        look = min(0.3, max(0.08, remaining))
        px, py = tx + nx * (along - look), ty + ny * (along - look)
        err = wrap_angle(math.atan2(py - pose.y, px - pose.x) - pose.yaw)
        v = max(0.03, min(self.speed_mps, 1.0 * remaining))
        self.command(v, max(-0.6, min(0.6, 2.5 * err)))
        self.feedback_message = f"{remaining:.2f} m to go, {lateral * 100:+.1f} cm off the axis"
        return Status.RUNNING

    def _retry(self, pose: Any, why: str) -> Status:
        self.command(0.0, 0.0)
        if self.retries >= RETRIES:
            return self._finish(pose, f"{why}, after {RETRIES} retries", Status.FAILURE)
        self.retries += 1
        self.ctx.events.add("dock_retry", f"{self.name}: {why}; backing off {BACK_OFF_M:g} m, retry {self.retries}")
        self.back_from = (pose.x, pose.y)
        self._set_phase("back_off")
        return Status.RUNNING

    def _level_camera(self) -> None:
        """Point the gimbal straight ahead with the optical axis level (tilt up by the mounting's pitch)."""
        watch = self.ctx.services.vision
        requests = dict(self.read("servo_requests") or {})
        if "pan" in self.ctx.servo_names:
            requests["pan"] = ServoCommand("pan", 0.0, None, None, self.now())
        if "tilt" in self.ctx.servo_names and watch is not None:
            requests["tilt"] = ServoCommand("tilt", math.radians(watch.geometry.pitch_deg), None, None, self.now())
        self.bb.servo_requests = requests

    def _finish(self, pose: Any, why: str, status: Status) -> Status:
        final = self.goal(self.distance_m)
        entry: dict[str, Any] = {"tag": self.tag, "time_s": round(self.now(), 3),
                                 "status": "docked" if status == Status.SUCCESS else "failed",
                                 "retries": self.retries, "distance_m": self.distance_m}
        if final is not None:
            entry["error_m"] = round(math.hypot(pose.x - final[0], pose.y - final[1]), 4)
            entry["error_deg"] = round(math.degrees(abs(wrap_angle(pose.yaw - final[2]))), 2)
        watch = self.ctx.services.vision
        if watch is not None:
            watch.docks.append(entry)
            if watch.on_dock is not None:
                watch.on_dock(entry)
        if status == Status.SUCCESS:
            self.ctx.events.add("docked", f"tag {self.tag}: {entry.get('error_m', 0) * 100:.1f} cm, "
                                          f"{entry.get('error_deg', 0):.1f} deg from the goal (estimated)")
            self.feedback_message = "docked"
            return status
        return self.fail(why)


class Undock(BeastBehaviour):
    """Back straight off a dock by ``distance_m`` (odometry). Succeeds once there; fails without odometry or when
    no progress is made for the robot's stuck time."""

    READS = ("pose_odom",)
    WRITES = ("cmd_mission",)

    def __init__(self, name: str, ctx: MissionContext, distance_m: float) -> None:
        super().__init__(name, ctx)
        self.distance_m = distance_m
        self.start: Optional[tuple[float, float]] = None
        self.best = 0.0
        self.progress_s = 0.0

    def initialise(self) -> None:
        self.start = None
        self.best = 0.0
        self.progress_s = self.now()

    def update(self) -> Status:
        pose = self.read("pose_odom")
        if pose is None:
            return self.fail("no odometry")
        if self.start is None:
            self.start = (pose.x, pose.y)
        done = math.hypot(pose.x - self.start[0], pose.y - self.start[1])
        if done >= self.distance_m - 0.005:
            self.command(0.0, 0.0)
            return Status.SUCCESS
        if done > self.best + 0.01:
            self.best = done
            self.progress_s = self.now()
        elif self.now() - self.progress_s > self.ctx.params.default_stuck_after_s:
            self.command(0.0, 0.0)
            return self.fail(f"no progress backing off, {self.distance_m - done:.2f} m to go")
        self.command(-min(0.1, max(0.03, 0.8 * (self.distance_m - done))), 0.0)
        self.feedback_message = f"{self.distance_m - done:.2f} m to go"
        return Status.RUNNING


__all__ = ["Dock", "Undock", "STAGING_M", "LOST_AFTER_S", "RETRIES"]
