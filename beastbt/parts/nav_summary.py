"""What a navigation run adds to the summary: the places visited and, in the simulator, how good the pose was.

- ``waypoints``: one entry per place visit of go_to, route and return_home
  (on a long run the first and the last 500, with ``waypoints_dropped``):
  ``{name, lat, lon, reached, arrival_error_m, time_s, tolerance_m}``. The
  arrival error is the true distance (m) from the simulated robot to the
  place when the step succeeded (the truth converted to WGS84 through the
  world's datum); on a robot, the estimated one. It is null for a place not
  reached. The tolerance (m) is the one the step used (the step's, else the
  place's, else the profile's navigation default): the true error can exceed
  it, since arrival is judged on the estimate. Places on a saved map (a
  mission with ``map:``) get the same rows after them, with ``lat`` and
  ``lon`` null and ``x``, ``y`` the place in the map frame (m).
- ``truth.position_error_rms_m``: RMS horizontal distance (m) between the
  fused pose and the truth over every tick with a valid position;
  ``truth.gps_error_rms_m``: the same for the raw GPS fixes (one per epoch),
  the baseline the fusion should beat. Also the largest fused error and the
  RMS heading error (deg) while the heading is valid.

The fused pose lives in the EKF's own frame (anchored at its first fix); its
latitude and longitude are compared with the truth's, so nothing of the
simulated world leaks into the filter.
"""

from __future__ import annotations

import math
from collections import deque
from typing import TYPE_CHECKING, Any, Deque, Optional

from beastbt.behaviours.navigation import Visit, visit_log
from beastbt.blackboard.types import GpsFix
from beastbt.estimation.estimator import wrap_angle
from beastbt.estimation.geodesy import distance_m
from beastbt.run.session import Prepared

if TYPE_CHECKING:  # annotations only: `beastbt tree` loads the navigation part without a run
    from beastbt.run.runner import TickRecord


ERRORS_KEPT = 12000
"""Per-tick fused errors :attr:`NavTruth.errors` keeps: the latest 10 minutes at 20 Hz (the metrics themselves
are running sums over the whole run)."""


class NavTruth:
    """Accumulates fused and raw GPS errors against the simulator's truth, tick by tick (a run recorder)."""

    def __init__(self, frame: Any, sim_gps: Any = None) -> None:
        self.frame = frame
        """The world's datum frame (LocalFrame): where the simulated truth is on Earth."""
        self.sim_gps = sim_gps
        """The emulated GPS (its ``last_true_enu``), or None."""
        self.fused_sq_m2 = 0.0
        self.fused_n = 0
        self.fused_max_m = 0.0
        self.heading_sq_rad2 = 0.0
        self.heading_n = 0
        self.gps_sq_m2 = 0.0
        self.gps_n = 0
        self._last_gps_time: Optional[str] = None
        self.errors: Deque[tuple[float, float]] = deque(maxlen=ERRORS_KEPT)
        """(clock s, fused error m) per tick with a valid position, the latest :data:`ERRORS_KEPT`, for benchmarks
        and tests."""

    def __call__(self, rec: TickRecord) -> None:
        truth = rec.truth
        if truth is None:
            return
        pose = rec.pose
        if pose is not None and pose.position_valid and pose.lat is not None:
            e, n, _ = self.frame.to_enu(pose.lat, pose.lon, None)
            err = math.hypot(e - truth.x, n - truth.y)
            self.fused_sq_m2 += err * err
            self.fused_n += 1
            self.fused_max_m = max(self.fused_max_m, err)
            self.errors.append((rec.now_s, err))
            if pose.heading_valid:
                d = wrap_angle(pose.yaw - truth.yaw)
                self.heading_sq_rad2 += d * d
                self.heading_n += 1
        gps = self.sim_gps_truth()
        for r in rec.readings:
            if type(r) is GpsFix and (r.time_utc is None or r.time_utc != self._last_gps_time):
                self._last_gps_time = r.time_utc
                e, n, _ = self.frame.to_enu(r.lat, r.lon, None)
                tx, ty = gps if gps is not None else (truth.x, truth.y)
                err = math.hypot(e - tx, n - ty)
                self.gps_sq_m2 += err * err
                self.gps_n += 1

    def sim_gps_truth(self) -> Optional[tuple[float, float]]:
        """Where the robot truly was when the emulated GPS sent its last epoch (m, world ENU)."""
        true = getattr(self.sim_gps, "last_true_enu", None)
        return (true[0], true[1]) if true is not None else None

    def metrics(self) -> dict:
        """The ``truth`` fields: RMS errors in m and deg, rounded for the summary (None when nothing was seen)."""
        def rms(sq: float, n: int) -> Optional[float]:
            return round(math.sqrt(sq / n), 4) if n else None
        heading = rms(self.heading_sq_rad2, self.heading_n)
        return {
            "position_error_rms_m": rms(self.fused_sq_m2, self.fused_n),
            "position_error_max_m": round(self.fused_max_m, 4) if self.fused_n else None,
            "gps_error_rms_m": rms(self.gps_sq_m2, self.gps_n),
            "gps_fixes": self.gps_n,
            "heading_error_rms_deg": round(math.degrees(heading), 3) if heading is not None else None,
        }


def install_truth(p: Prepared) -> None:
    """In the simulator: measure the pose against the truth and each arrival's true error."""
    run = p.run
    sim = run.io.sim
    log = visit_log(run.ctx)
    if sim is None or p.world is None:
        return
    frame = p.world.frame
    tracker = NavTruth(frame, run.io.sim_gps)
    run.ctx.services.nav_truth = tracker
    if run.estimator is not None:
        run.recorders.append(tracker)

    def arrival(visit: Visit) -> None:
        if visit.reached and visit.lat is not None and visit.lon is not None:
            lat, lon, _ = frame.to_geodetic(sim.truth.x, sim.truth.y, 0.0)
            visit.true_error_m = distance_m(visit.lat, visit.lon, lat, lon)

    log.listeners.append(arrival)


def contribute(run: Any, summary: dict) -> None:
    """Add ``waypoints`` and the truth metrics of navigation to a run summary."""
    log = run.ctx.services.nav_visits
    if log is not None:
        out = []
        for v in log.visits:
            if v.lat is None or v.lon is None:
                continue  # home was never known: there was no place to aim for
            err = v.true_error_m if v.true_error_m is not None else v.estimated_error_m
            out.append({
                "name": v.name, "lat": round(v.lat, 8), "lon": round(v.lon, 8), "reached": v.reached,
                "arrival_error_m": round(err, 3) if v.reached and err is not None else None,
                "time_s": round(v.time_s, 3) if v.time_s is not None else None,
                "tolerance_m": round(v.tolerance_m, 3) if v.tolerance_m is not None else None,
                "estimated_error_m": (round(v.estimated_error_m, 3)
                                      if v.reached and v.estimated_error_m is not None else None),
            })
        summary["waypoints"] = out
        if log.visits.dropped:  # a long route keeps its first and its last visits
            summary["waypoints_dropped"] = log.visits.dropped
    planner = (getattr(run.ctx.services, "plugins", None) or {}).get("map_planner")
    if planner is not None and planner.visits:  # places on a saved map: the same table, x and y for lat and lon
        from beastbt.behaviours.map_navigation import map_waypoint_rows
        summary["waypoints"] = list(summary.get("waypoints") or []) + map_waypoint_rows(planner)
    tracker = run.ctx.services.nav_truth
    if tracker is not None and run.estimator is not None and "truth" in summary:
        truth = summary["truth"]
        # An error the GPS fusion never measured (None: indoors, no fix) leaves the map localiser's in place.
        truth.update({k: v for k, v in tracker.metrics().items() if v is not None or k not in truth})
