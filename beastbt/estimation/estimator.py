"""The estimator interface and the simplest estimator: wheel odometry dead reckoning.

The runner hands each tick's new readings to an :class:`Estimator` and writes
the returned :class:`FusedPose` to the blackboard. The EKF that fuses GPS and
IMU implements the same interface.
"""

from __future__ import annotations

import math
from typing import Optional, Protocol, Sequence

from beastbt.blackboard.types import FusedPose, GpsFix, ImuSample, WheelOdometry
from beastbt.estimation.geodesy import LocalFrame


def wrap_angle(a: float) -> float:
    """Wrap an angle in radians to [-pi, pi)."""
    return (a + math.pi) % (2.0 * math.pi) - math.pi


class Estimator(Protocol):
    """Turns sensor readings into a pose in the local ENU frame."""

    def update(
        self,
        now_s: float,
        odometry: Sequence[WheelOdometry],
        imu: Sequence[ImuSample],
        gps: Sequence[GpsFix],
    ) -> FusedPose:
        """Predict to ``now_s``, fuse the new readings (oldest first) and return the pose."""
        ...

    @property
    def frame(self) -> Optional[LocalFrame]:
        """The georeferenced local frame, once known (None before a datum or first fix)."""
        ...


class OdometryEstimator:
    """Dead reckoning from wheel odometry (differential drive, midpoint integration).

    ``track_width_m`` is the effective distance between the wheels/tracks.
    The pose starts at (``x0``, ``y0``, ``yaw0``). It never knows where it is
    in the world (``position_valid`` stays False unless a frame is given).
    """

    def __init__(self, track_width_m: float, x0: float = 0.0, y0: float = 0.0, yaw0: float = 0.0,
                 frame: Optional[LocalFrame] = None) -> None:
        self.track_width_m = track_width_m
        self.x, self.y, self.yaw = x0, y0, yaw0
        self.distance_m = 0.0
        self.speed_mps = 0.0
        self.yaw_rate_rps = 0.0
        self._last: Optional[WheelOdometry] = None
        self._frame = frame

    @property
    def frame(self) -> Optional[LocalFrame]:
        """The local frame given at construction, if any."""
        return self._frame

    def update(self, now_s: float, odometry: Sequence[WheelOdometry], imu: Sequence[ImuSample] = (),
               gps: Sequence[GpsFix] = ()) -> FusedPose:
        """Integrate the wheel travel since the previous reading; IMU and GPS are ignored."""
        for odo in odometry:
            if self._last is not None:
                dl = odo.left_m - self._last.left_m
                dr = odo.right_m - self._last.right_m
                ds = 0.5 * (dl + dr)
                dth = (dr - dl) / self.track_width_m
                mid = self.yaw + 0.5 * dth
                self.x += ds * math.cos(mid)
                self.y += ds * math.sin(mid)
                self.yaw = wrap_angle(self.yaw + dth)
                self.distance_m += abs(ds)
            self.speed_mps = 0.5 * (odo.left_mps + odo.right_mps)
            self.yaw_rate_rps = (odo.right_mps - odo.left_mps) / self.track_width_m
            self._last = odo
        lat = lon = None
        if self._frame is not None:
            lat, lon, _ = self._frame.to_geodetic(self.x, self.y)
        return FusedPose(
            stamp_s=now_s, x=self.x, y=self.y, yaw=self.yaw, speed_mps=self.speed_mps,
            yaw_rate_rps=self.yaw_rate_rps, distance_m=self.distance_m,
            position_valid=self._frame is not None, lat=lat, lon=lon,
        )
