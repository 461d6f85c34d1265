"""Which IMU the estimator fuses when a robot has two.

The Waveshare base reports an IMU of its own in its feedback, and the
runner hands every :class:`ImuSample` of a tick to the estimator. A robot
whose profile has an ``imu:`` device (the MPU9250) fuses that one only: the
EKF has a single gyro bias state, and two gyros with different biases
averaged into it would make neither right. The device's poll records what it
produced in an :class:`ImuTap`; the estimator takes its samples from there.
"""

from __future__ import annotations

from typing import Callable, Optional

from beastbt.blackboard.types import ImuSample


MAX_PENDING = 256
"""Samples kept for the estimator at most (2.5 s at the MPU9250's 100 Hz): while the EKF sleeps and another part
reads the IMU (the map localiser's gyro), nobody takes them, and a backlog older than that is nothing to fuse."""


class ImuTap:
    """The samples one IMU driver produced since the estimator last took them.

    ``ready()`` (default: always) says whether they may be fused yet, e.g.
    once the driver's standstill gyro bias is final; until then they are
    dropped. ``count`` is every sample seen, ``last`` the newest.
    """

    def __init__(self, ready: Optional[Callable[[], bool]] = None) -> None:
        self.ready = ready
        self.pending: list[ImuSample] = []
        self.count = 0
        self.last: Optional[ImuSample] = None

    def record(self, sample: Optional[ImuSample]) -> list[ImuSample]:
        """Keep ``sample`` (None: the driver had nothing) and return it as a poll's list of readings."""
        if sample is None:
            return []
        self.pending.append(sample)
        if len(self.pending) > MAX_PENDING:
            del self.pending[:len(self.pending) - MAX_PENDING]
        self.count += 1
        self.last = sample
        return [sample]

    def take(self) -> list[ImuSample]:
        """The samples to fuse now, oldest first (empty until ``ready()``); the tap is emptied."""
        out, self.pending = self.pending, []
        if self.ready is not None and not self.ready():
            return []
        return out
