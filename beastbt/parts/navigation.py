"""Wiring GPS navigation into a run: the EKF as the estimator, the navigation tuning, going home.

- :func:`ekf_estimator`: a robot with a GPS
  or an IMU gets the :class:`~beastbt.estimation.ekf.EkfEstimator`, tuned by
  the profile's ``estimator:`` section, fed one GPS fix per epoch
  (:class:`~beastbt.estimation.gps_epochs.EpochFilter`). Its local frame is
  anchored at the first good fix, on the robot and in the simulator alike:
  the simulator's world datum is never told to the filter.
- :func:`install_navigation`: the profile's
  ``navigation:`` section for go_to; on a robot with a LiDAR the local
  costmap and planner that go_to steers around obstacles with
  (:func:`local_navigator`, the profile's ``local_costmap:`` and
  ``local_planner:``); and, on a robot with a GPS, the
  ``return_home`` handlers of failsafes (``then: return_home``) and of
  ``on_failure: return_home``. Both replace the mission's tree by a single
  return_home; once home (or when going home fails) the run ends as a
  failure, since the mission itself did not complete.
"""

from __future__ import annotations

import math

from dataclasses import replace
from typing import TYPE_CHECKING, Any, Callable, Mapping, Optional, Sequence

import py_trees

from beastbt.behaviours.navigation import GoTo, NavConfig, RetracePath, home_target
from beastbt.blackboard.types import FusedPose, GpsFix, ImuSample, WheelOdometry
from beastbt.estimation.geodesy import LocalFrame
from beastbt.estimation.gps_epochs import EpochFilter
from beastbt.estimation.imu_tap import ImuTap
from beastbt.mission.compile import StepBuilder
from beastbt.mission.model import HOME
from beastbt.core.events import EventLog
from beastbt.core.schema_defaults import schema_default
from beastbt.robot.profile import RobotProfile, section_config
from beastbt.parts.nav_summary import contribute, install_truth
from beastbt.parts.navigation_steps import NAVIGATION_STEPS
from beastbt.robot.part import Build, Part
from beastbt.run.session import Prepared

if TYPE_CHECKING:  # the EKF (filterpy, scipy) is imported only for a robot that fuses GPS or IMU
    from beastbt.robot.robot_io import RobotIO
    from beastbt.run.runner import MissionRun  # annotations only: `beastbt tree` loads this part without a run
    from beastbt.estimation.ekf import EkfEstimator
    from beastbt.navigation.local_navigator import LocalNavigator

Status = py_trees.common.Status


class NavEstimator:
    """The EKF behind the :class:`~beastbt.estimation.estimator.Estimator` protocol.

    It gets one GPS fix per epoch (:class:`EpochFilter`). With an ``imu_tap``
    (the robot has an ``imu:`` device) it fuses that IMU's samples only, and
    only once the driver's gyro bias, estimated while the robot stands still
    at start, is final: the EKF's own bias state would otherwise learn the
    raw bias of the first samples and keep it after the driver starts
    removing it (a heading drift of about 1 deg every 10 s); until then the
    EKF turns with the wheels' yaw rate. Without a tap it fuses whatever IMU
    samples the tick brings (the base's own IMU).
    """

    def __init__(self, make_ekf: "Callable[[], EkfEstimator]", imu_tap: Optional[ImuTap] = None) -> None:
        # Built on first use: a run whose EKF sleeps (nothing reads the fused pose) never imports filterpy.
        self._make_ekf = make_ekf
        self._ekf: "Optional[EkfEstimator]" = None
        self.epochs = EpochFilter()
        self.imu_tap = imu_tap

    @property
    def ekf(self) -> "EkfEstimator":
        """The EKF (built, with filterpy imported, the first time it is asked for)."""
        if self._ekf is None:
            self._ekf = self._make_ekf()
        return self._ekf

    @property
    def frame(self) -> Optional[LocalFrame]:
        """The EKF's local frame (anchored at the first good fix), or None before it."""
        return self.ekf.frame

    def update(self, now_s: float, odometry: Sequence[WheelOdometry], imu: Sequence[ImuSample],
               gps: Sequence[GpsFix]) -> FusedPose:
        """Predict to ``now_s`` (s) and fuse this tick's readings; the fused pose."""
        if self.imu_tap is not None:
            imu = self.imu_tap.take()
        return self.ekf.update(now_s, odometry, imu, self.epochs(gps) if gps else ())


def ekf_estimator(profile: RobotProfile, io: RobotIO, events: EventLog) -> Optional[NavEstimator]:
    """The EKF for a robot with a GPS or an IMU (None otherwise: odometry alone)."""
    if not ({"gps", "imu"} & set(io.capabilities)):
        return None
    from beastbt.estimation.ekf import EkfConfig, EkfEstimator
    config: EkfConfig = section_config(profile, "estimator", EkfConfig)
    raw = profile.section("estimator") or {}
    # The profile's geometry is the track width unless the estimator section tunes its own.
    track = None if "track_width_m" in raw else profile.track_width_m
    if "declination_deg" not in raw:
        # On the simulator the world is where the robot is: unless the profile says
        # otherwise, use the world's declination, as a user sets theirs for their place.
        # Kept on the robot's io so that a recording (and its replay) carries the same value.
        world = getattr(io.sim, "world", None)
        if io.magnetic_declination_deg is None and world is not None:
            declination = (world.section("imu") or {}).get(
                "mag_declination_deg", schema_default("parts/imu_sim.schema.json", "mag_declination_deg"))
            io.magnetic_declination_deg = float(declination)
        if io.magnetic_declination_deg is not None:
            config = replace(config, declination_deg=float(io.magnetic_declination_deg))
    sink = events.sink("ekf")
    return NavEstimator(lambda: EkfEstimator(config, frame=None, events=sink, track_width_m=track), io.imu_tap)


class ReturnHomeInstead(py_trees.decorators.Decorator):
    """The tree that replaces a mission going home after a failure or a failsafe.

    Runs its return_home leaf; when that ends (either way) it stands still,
    RUNNING, and records in ``outcome`` why the run should end.
    """

    def __init__(self, name: str, child: py_trees.behaviour.Behaviour) -> None:
        super().__init__(name=name, child=child)
        self.outcome: Optional[str] = None

    def update(self) -> Status:
        status = self.decorated.status
        if status == Status.SUCCESS and self.outcome is None:
            self.outcome = "returned home"
        elif status == Status.FAILURE and self.outcome is None:
            self.outcome = f"could not return home ({self.decorated.feedback_message})"
        self.feedback_message = self.outcome or "going home"
        return Status.RUNNING


def return_home_instead(run: MissionRun, why: str) -> None:
    """Replace the run's tree by a return_home; the run ends as a failure once that is over."""
    if isinstance(run.root, ReturnHomeInstead):
        return  # already on the way home
    if run.root.status == Status.RUNNING:
        run.root.stop(Status.INVALID)
    planner = run.ctx.services.plugins.get("map_planner")
    if planner is not None:  # a mission on a saved map goes home on the map, by a planned path
        from beastbt.behaviours.map_navigation import MapGoTo, map_home_target
        leaf: GoTo = MapGoTo("return_home (on the map)", run.ctx, HOME, map_home_target(planner), planner, None)
    else:
        leaf = GoTo("return_home (within 2 m)", run.ctx, HOME, home_target(run.ctx), None)
    root = ReturnHomeInstead(f"return home ({why})", leaf)
    run.root = root
    run.nodes = list(root.iterate())
    run.events.add("return_home", f"going home: {why}")

    def end_when_home(r: MissionRun, now_s: float) -> None:
        if root.outcome is not None and r.status is None:
            r.finish("failure", f"{why}; {root.outcome}")

    run.hooks.append(end_when_home)


def local_navigator(profile: RobotProfile) -> Optional["LocalNavigator"]:
    """The local costmap and planner for a profile with ``lidar:`` (None without), from its ``local_costmap:``,
    ``local_planner:``, footprint, LiDAR mounting and limits; a bad section raises a positioned InvalidInput."""
    if profile.section("lidar") is None:
        return None
    from beastbt.actuation.collision_monitor import footprint_radius
    from beastbt.devices.lidar_scan import LidarConfig
    from beastbt.navigation.local_costmap import LocalCostmapConfig
    from beastbt.navigation.local_navigator import LocalNavigator
    from beastbt.navigation.local_planner import Limits, LocalPlannerConfig

    lidar: LidarConfig = section_config(profile, "lidar", LidarConfig)
    limits = Limits(profile.max_speed_mps, profile.max_turn_rate_rps, profile.max_accel_mps2,
                    profile.max_angular_accel_rps2)
    local = LocalNavigator(section_config(profile, "local_costmap", LocalCostmapConfig),
                           section_config(profile, "local_planner", LocalPlannerConfig),
                           footprint_radius(profile.data), lidar.mounting, limits)
    # GPS go_to plans on a rolling global costmap with memory (beastbt/navigation/global_navigator.py).
    from beastbt.navigation.global_navigator import GlobalNavigator
    from beastbt.navigation.global_planner import GlobalPlannerConfig
    from beastbt.navigation.obstacle_layer import GlobalCostmapConfig
    layer = section_config(profile, "global_costmap", GlobalCostmapConfig)
    if layer.enabled:
        local.global_nav = GlobalNavigator(layer, section_config(profile, "global_planner", GlobalPlannerConfig),
                                           footprint_radius(profile.data), lidar.mounting)
    return local


def install_map_truth(p: Prepared, planner: Any) -> None:
    """The summary's ``map_waypoints`` and, in the simulator, each arrival's true distance to its place (the true
    pose moved into the map frame by the world's start and the mission's start on the map)."""
    from beastbt.behaviours.map_navigation import map_waypoints
    run, world = p.run, p.world

    def contribute_map(r: MissionRun, summary: dict) -> None:
        summary["map_waypoints"] = map_waypoints(planner)
    run.summary_contributors.append(contribute_map)
    if run.io.sim is None or world is None:
        return
    from beastbt.estimation.map_localiser import compose, invert
    map_from_world = compose(planner.start, invert((world.start_x, world.start_y, world.start_yaw)))

    def true_error(visit: Any) -> None:
        if visit.reached and visit.x is not None:
            truth = run.io.sim.truth
            x, y, _ = compose(map_from_world, (truth.x, truth.y, truth.yaw))
            visit.true_error_m = math.hypot(x - visit.x, y - visit.y)
    planner.listeners.append(true_error)


def install_recoveries(p: Prepared) -> None:
    """The profile's ``recovery:`` section for go_to's recoveries, and the summary's ``recoveries`` (how many of
    each kind ran; beastbt/behaviours/recovery.py)."""
    from beastbt.behaviours.recovery import RECOVERY_CONFIG, RECOVERY_LOG, RecoveryConfig, RecoveryLog
    run = p.run
    run.ctx.services.plugins[RECOVERY_CONFIG] = section_config(p.profile, "recovery", RecoveryConfig)
    log = run.ctx.services.plugins.setdefault(RECOVERY_LOG, RecoveryLog())

    def contribute_recoveries(r: MissionRun, summary: dict) -> None:
        if any(isinstance(n, (GoTo, RetracePath)) for n in r.nodes) or log.kinds:
            summary["recoveries"] = log.summary()
    run.summary_contributors.append(contribute_recoveries)


def install_navigation(p: Prepared) -> None:
    """Give go_to the profile's navigation tuning and, with a LiDAR, the local costmap and planner; on a robot
    with a GPS, offer going home."""
    run = p.run
    run.ctx.services.navigation = section_config(p.profile, "navigation", NavConfig)
    if "lidar" in run.ctx.capabilities:
        run.ctx.services.local_navigator = local_navigator(p.profile)
        install_recoveries(p)
        if run.ctx.services.local_navigator is not None:  # stepping aside for people is told as events
            run.ctx.services.local_navigator.planner.events = run.events.add
        if run.ctx.services.local_navigator is not None and any(isinstance(n, (GoTo, RetracePath))
                                                                for n in run.nodes):
            # The planner's graph search (SciPy) now, before the first tick, rather than at go_to's first plan.
            from beastbt.navigation.local_planner import graph_search
            graph_search()
    planner = run.ctx.services.plugins.get("map_planner")
    if planner is None and getattr(p.mission, "map_grid", None) is not None:
        # no go_to on the map, but a failsafe or on_failure may go home on it
        from beastbt.behaviours.map_navigation import map_planner, mission_map_start
        planner = map_planner(run.ctx, p.mission.map_grid, mission_map_start(p.mission))
    if planner is not None:  # go_to on the mission's map: the profile's global planner and the robot's size
        from beastbt.actuation.collision_monitor import footprint_radius
        from beastbt.navigation.global_planner import GlobalPlannerConfig
        from beastbt.navigation.obstacle_layer import GlobalCostmapConfig
        planner.configure(section_config(p.profile, "global_planner", GlobalPlannerConfig),
                          footprint_radius(p.profile.data),
                          section_config(p.profile, "global_costmap", GlobalCostmapConfig))
        from beastbt.estimation.map_localiser import LocaliserConfig
        planner.mark_min_quality = section_config(p.profile, "localisation", LocaliserConfig).lost_quality
        install_map_truth(p, planner)
    path = run.ctx.services.driven_path
    if path is not None:  # a return_home: {along: path} will need the way back

        def keep_the_path(r: MissionRun, now_s: float) -> None:
            pose = r.bb.pose
            if pose is not None and pose.position_valid and pose.lat is not None:
                path.add(pose.lat, pose.lon)
        run.hooks.append(keep_the_path)
    if "gps" not in run.ctx.capabilities and planner is None:
        return

    def failsafe_return_home(r: MissionRun, spec: Any) -> None:
        return_home_instead(r, f"failsafe {spec.kind}")

    def on_failure_return_home(r: MissionRun) -> None:
        tip = r.root.tip()
        return_home_instead(r, f"steps failed at {tip.name}" if tip is not None else "steps failed")

    run.ctx.services.failsafe["return_home"] = failsafe_return_home
    run.ctx.services.on_failure["return_home"] = on_failure_return_home



class NavigationPart(Part):
    """GPS navigation: the EKF, the go_to, route and return_home steps, going home, waypoints in the summary."""

    name = "navigation"
    section = "navigation"
    schema = "parts/navigation.schema.json"
    fills = ("pose", "home")
    reads = ("odometry", "imu", "gps_fix")

    def steps(self) -> Mapping[str, StepBuilder]:
        """go_to, route and return_home."""
        return NAVIGATION_STEPS

    def estimator(self, build: Build) -> Optional[NavEstimator]:
        """The EKF on a robot with a GPS or an IMU."""
        assert build.io is not None
        return ekf_estimator(build.profile, build.io, build.events)

    def sleep(self, prepared: Prepared) -> None:
        """Nothing reads the fused pose: no EKF this run (the pose is the wheels' alone, marked not valid)."""
        prepared.run.estimator = None

    def install(self, prepared: Prepared) -> None:
        """Navigation tuning and going home; in the simulator, the truth of every arrival."""
        install_navigation(prepared)
        install_truth(prepared)

    def summarise(self, run: MissionRun, summary: dict) -> None:
        """``waypoints`` and, in the simulator, the truth metrics of the pose."""
        contribute(run, summary)


__all__ = ["NavigationPart", "NavEstimator", "ekf_estimator", "install_navigation", "local_navigator",
           "return_home_instead",
           "ReturnHomeInstead"]
