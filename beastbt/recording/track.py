"""The recording's position track: every recorded run on a robot with a GPS keeps where the robot was.

A mission that never reads the position lets the GPS, the IMU and the EKF
sleep (:func:`beastbt.robot.part.asleep`). A recording reads the GPS fix
(:class:`beastbt.parts.recording.RecordingPart`), so the GPS stays awake and
its fixes are recorded at the receiver's own rate (``/sensors/gps``). When the
navigation part's EKF sleeps all the same (nothing in the run reads the fused
pose), :class:`PositionTrack` stands in as the run's estimator, cheaply:

* the EKF steps only when a GPS epoch arrives and at least every
  ``1 / track_rate_hz`` seconds (the recording's ``track_rate_hz``, 1 Hz by
  default), fed the wheels' mean speed and turn rate over the interval, then
  predicted across it and given the fixes (about 0.1 ms per step here);
* between steps the wheels carry the pose on from the EKF's last one (a few
  float operations per tick), so the fused pose (``/estimate/fused``,
  ``/pose/fused``, ``/gps/fused``) is recorded at ``pose_rate_hz`` like any
  other;
* the IMU stays asleep: the wheels give the turn rate;
* the EKF's libraries (filterpy, SciPy) are imported when the run is
  prepared, once (about 0.7 s of CPU here), not in the loop.

What the track gives is written on the blackboard's ``pose`` like any
estimator's, but nothing in the run reads it (else the EKF would be awake and
stepping every tick): the mission runs exactly as it would without it.
``beastbt route from-run`` and ``beastbt report`` read it from the recording.
"""

from __future__ import annotations

import math
from typing import Any, Callable, Optional, Sequence

from beastbt.blackboard.types import FusedPose, GpsFix, ImuSample, WheelOdometry

EARTH_RADIUS_M = 6_378_137.0
"""WGS84 equatorial radius (m): the latitude and longitude between EKF steps are carried on in a flat patch around
the step's (metres of wheel travel, far below the GPS's own error)."""


class PositionTrack:
    """The :class:`~beastbt.estimation.estimator.Estimator` of a recorded run whose EKF would sleep.

    ``nav``: the navigation part's estimator (a
    :class:`~beastbt.parts.navigation.NavEstimator`: its ``ekf`` and its
    ``epochs`` filter, one fix per GPS epoch). ``period_s``: the longest time
    between two EKF steps (s); a GPS epoch also makes one. ``steps`` counts
    them (for tests and benchmarks).
    """

    def __init__(self, nav: Any, period_s: float) -> None:
        self.nav = nav
        self.period_s = float(period_s)
        self.steps = 0
        self._odometry: list[WheelOdometry] = []
        self._fixes: list[GpsFix] = []
        self._step_s: Optional[float] = None
        """Clock time (s) of the last EKF step."""
        self._anchor: Optional[FusedPose] = None
        """The EKF's pose at its last step; the wheels carry it on."""
        self._cos = 1.0
        self._sin = 0.0
        self._dx = self._dy = self._dyaw = self._travel = 0.0
        """Wheel travel since the last step, in the anchor's body frame (m, rad) and its length (m)."""
        self._last: Optional[WheelOdometry] = None
        self._track_width_m = 0.0
        self._max_step_m = math.inf
        self._pose: Optional[FusedPose] = None

    def update(self, now_s: float, odometry: Sequence[WheelOdometry], imu: Sequence[ImuSample],
               gps: Sequence[GpsFix]) -> FusedPose:
        """Keep this tick's wheel readings and fixes; step the EKF when a fix came or ``period_s`` has passed;
        the pose now (the IMU's samples are not used: it sleeps)."""
        if odometry:
            self._odometry.extend(odometry)
        if gps:
            self._fixes.extend(gps)
        if gps or self._step_s is None or now_s - self._step_s >= self.period_s - 1e-9:
            return self._step(now_s)
        if odometry:
            self._carry(odometry)
            self._pose = self._carried(now_s)
        return self._pose if self._pose is not None else self._step(now_s)

    def _step(self, now_s: float) -> FusedPose:
        """One EKF step: the interval's mean speed and turn rate fused at its start (no prediction yet), then a
        prediction across it with them, and the fixes."""
        ekf = self.nav.ekf
        odometry, self._odometry = self._odometry, []
        fixes = self.nav.epochs(self._fixes) if self._fixes else ()
        self._fixes = []
        if self._step_s is not None and odometry:
            ekf.update(self._step_s, odometry)  # dt 0: fuses the wheels' mean rates over the interval
            pose = ekf.update(now_s, (), (), fixes)
        else:
            pose = ekf.update(now_s, odometry, (), fixes)
        if odometry:
            self._last = odometry[-1]
        self.steps += 1
        self._step_s = now_s
        self._anchor = self._pose = pose
        self._cos, self._sin = math.cos(pose.yaw), math.sin(pose.yaw)
        self._dx = self._dy = self._dyaw = self._travel = 0.0
        self._track_width_m = ekf.track_width_m
        self._max_step_m = ekf.config.odom_max_step_m
        return pose

    def _carry(self, odometry: Sequence[WheelOdometry]) -> None:
        """Dead-reckon the wheel travel of ``odometry`` onto the offsets since the last step (midpoint heading)."""
        last = self._last
        for odo in odometry:
            if last is not None:
                dl = odo.left_m - last.left_m
                dr = odo.right_m - last.right_m
                if abs(dl) <= self._max_step_m and abs(dr) <= self._max_step_m:  # a base restart: the EKF says so
                    ds = 0.5 * (dl + dr)
                    turn = (dr - dl) / self._track_width_m
                    mid = self._dyaw + 0.5 * turn
                    self._dx += ds * math.cos(mid)
                    self._dy += ds * math.sin(mid)
                    self._dyaw += turn
                    self._travel += abs(ds)
            last = odo
        self._last = last

    def _carried(self, now_s: float) -> FusedPose:
        """The last step's pose moved by the wheel travel since, with the wheels' current speed and turn rate."""
        a = self._anchor
        assert a is not None and self._last is not None
        # As the EKF does: a position known in the world with no heading yet stays put (which way it moved is unknown).
        moves = a.heading_valid or not a.position_valid
        de = self._cos * self._dx - self._sin * self._dy if moves else 0.0
        dn = self._sin * self._dx + self._cos * self._dy if moves else 0.0
        yaw = math.remainder(a.yaw + self._dyaw, math.tau)
        lat = lon = None
        if a.lat is not None and a.lon is not None:
            lat = a.lat + math.degrees(dn / EARTH_RADIUS_M)
            lon = a.lon + math.degrees(de / (EARTH_RADIUS_M * math.cos(math.radians(a.lat))))
        o = self._last
        return FusedPose(now_s, a.x + de, a.y + dn, yaw, 0.5 * (o.left_mps + o.right_mps),
                         (o.right_mps - o.left_mps) / self._track_width_m, a.covariance, a.distance_m + self._travel,
                         a.heading_valid, a.position_valid, lat, lon)


def install_track(prepared: Any, rate_hz: float, make_estimator: Callable[[], Any]) -> Optional[PositionTrack]:
    """Give a recorded run whose EKF sleeps, on a robot whose GPS is awake, a :class:`PositionTrack` as its
    estimator (``make_estimator()``: the navigation part's, or None without one); None when it needs none
    (the EKF is awake, there is no GPS, or ``rate_hz`` is 0)."""
    run = prepared.run
    if run.estimator is not None or "gps" not in run.io.sensors or rate_hz <= 0:
        return None
    nav = make_estimator()
    if nav is None:
        return None
    track = PositionTrack(nav, 1.0 / rate_hz)
    # The EKF (filterpy, which imports SciPy: about 0.7 s of CPU here, once) is built now, before the first tick,
    # so that the loop never waits for the import (a real robot's watchdog would see a stalled first tick).
    nav.ekf
    run.estimator = track
    truth = getattr(run.ctx.services, "nav_truth", None)
    if truth is not None and truth not in run.recorders:
        run.recorders.append(truth)  # the summary's fused position error: the track's, in the simulator
    run.events.add("asleep", f"navigation: its EKF steps at each GPS fix and at least every {1.0 / rate_hz:g} s "
                             f"for the recording's position track")
    return track


__all__ = ["PositionTrack", "install_track"]
