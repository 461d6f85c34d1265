"""What every behaviour is handed: the clock, the control parameters, what the robot has, the event log.

Behaviours never reach for globals: the compiler builds one
:class:`MissionContext` per run and passes it to each leaf.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Optional, Protocol

from beastbt.core.config import dataclass_from_dict
from beastbt.core.schema_defaults import schema_defaults
from beastbt.core.clock import Clock
from beastbt.core.events import EventLog


@dataclass
@schema_defaults("robot.schema.json#/properties/control")
class ControlParams:
    """Tuning of the motion behaviours, as in a Nav2 parameter file (SI units).

    Set in a robot profile under ``control:``; every field has a default that
    suits a small tracked robot at walking pace.
    """

    default_speed_mps: float
    """Speed of drive/go_to when the step gives none (m/s)."""
    default_turn_rate_rps: float
    """Top turn rate of turn steps when none is given (rad/s)."""
    decel_mps2: float
    """Deceleration planned at the end of a drive, so it stops on the mark (m/s^2)."""
    min_drive_speed_mps: float
    """Slowest creeping speed at the end of a drive, so it never stalls short (m/s)."""
    heading_gain: float
    """Heading hold while driving straight: turn rate per radian of heading error (1/s)."""
    turn_gain: float
    """Turning in place: turn rate per radian of remaining angle (1/s)."""
    min_turn_rate_rps: float
    """Slowest turn rate commanded while turning in place; tracks stall below it (rad/s)."""
    turn_tolerance_rad: float
    """A turn is done within this angle of its target (rad). The language says 3 deg."""
    drive_tolerance_m: float
    """A drive is done this close to its distance (m)."""
    still_speed_mps: float
    """Below this forward speed the robot counts as still (m/s)."""
    still_turn_rps: float
    """Below this turn rate the robot counts as still (rad/s)."""
    stuck_progress_m: float
    """Progress smaller than this within stuck_after counts as no progress (m)."""
    stuck_progress_rad: float
    """Turning progress smaller than this within stuck_after counts as none (rad)."""
    default_stuck_after_s: float
    """How long without progress before a motion step fails (s). The language says 5 s."""
    default_settle_s: float
    """How long a servo is given to reach its angle (s). The language says 0.5 s."""
    sensor_max_age_s: float
    """Data older than this is stale and not trusted by behaviours (s)."""

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "ControlParams":
        """Build from a profile's ``control:`` mapping (keys are field names, SI values)."""
        return dataclass_from_dict(cls, d, "control")


FailureHandler = Callable[[Any], None]
"""What ``on_failure: ACTION`` does: ``fn(run)`` (the run is a ``beastbt.run.runner.MissionRun``)."""
FailsafeHandler = Callable[[Any, Any], None]
"""What a failsafe's ``then: ACTION`` does: ``fn(run, failsafe)``."""


class TeleopService(Protocol):
    """What the teleop step asks of the run's teleop part."""

    @property
    def has_joystick(self) -> bool:
        """True when the robot has a joystick device (it may be unplugged right now)."""

    def request_handover(self, step: Any) -> None:
        """A teleop step starts: the operator may drive while it runs."""

    def release_handover(self, step: Any) -> None:
        """A teleop step ended."""


@dataclass
class RunServices:
    """What the parts of a run offer its behaviours and its runner; None where this robot has no such part.

    Filled by the assembly and the parts' ``install`` before the run starts.
    """

    home: Callable[[], Optional[tuple[float, float]]] = lambda: None
    """Where the mission started, (lat, lon) degrees, once the first good fix came (None before)."""
    save_snapshot: Optional[Callable[[str, Any], str]] = None
    """Save a camera frame under a name; returns where it went (None: the run is not recorded)."""
    teleop: Optional[TeleopService] = None
    """The teleop part (the teleop step's hand-over); None without it."""
    camera: Optional[Any] = None
    """The camera pipeline (``beastbt.vision.camera_pipeline.CameraPipeline``); None without a camera."""
    line_follower: Optional[Any] = None
    """The profile's line follower tuning (``beastbt.behaviours.follow_line.FollowLineConfig``)."""
    line_metrics: Optional[Any] = None
    """Truth scores of line following (``beastbt.run.line_metrics.LineTruthMetrics``), in the simulator."""
    navigation: Optional[Any] = None
    """The profile's navigation tuning (``beastbt.behaviours.navigation.NavConfig``)."""
    local_navigator: Optional[Any] = None
    """On a robot with a LiDAR: the local costmap and planner that go_to steers around obstacles with
    (``beastbt.navigation.local_navigator.LocalNavigator``); None without a LiDAR."""
    nav_visits: Optional[Any] = None
    """The log of place visits (``beastbt.behaviours.navigation.VisitLog``), made on first use."""
    nav_truth: Optional[Any] = None
    """Pose and arrival errors against the simulator's truth (``beastbt.parts.nav_summary.NavTruth``)."""
    video_stream: Optional[Any] = None
    """The live video server (``beastbt.live.video_stream.VideoStreamServer``) with ``--stream``."""
    vision: Optional[Any] = None
    """On a robot with a camera, for a mission that looks: the detectors (:class:`~beastbt.vision.watch.VisionWatch`)
    behind ``sees``, ``photo``, ``alert`` and ``dock``; set by the vision part."""
    on_failure: dict[str, FailureHandler] = field(default_factory=dict)
    """``on_failure`` actions beyond stop and hold that parts provide: action -> handler (teleop, return_home)."""
    failsafe: dict[str, FailsafeHandler] = field(default_factory=dict)
    """Failsafe ``then:`` actions beyond stop and hold that parts provide: action -> handler."""
    driven_path: Optional[Any] = None
    """The fused path driven so far (:class:`~beastbt.behaviours.navigation.DrivenPath`), kept only when a
    ``return_home: {along: path}`` needs it."""
    questions: Optional[Any] = None
    """The run's questions to the operator (:class:`~beastbt.behaviours.ask.OperatorQuestions`)."""
    substitute: Optional[Callable[[Any], Any]] = None
    """A mission test's forced step results: given the compiled tree's root, it puts a stand-in named as such in
    place of each substituted step and returns the root (:mod:`beastbt.testing.faults`); None in any other run."""
    obstacle_sensing: Optional[Any] = None
    """Where the LiDAR sits, the footprint and the scan rules for ``obstacle_within``
    (:class:`~beastbt.behaviours.obstacle_within.ObstacleSensing`); set by the LiDAR part."""
    collision_hold: Callable[[], Optional[str]] = lambda: None
    """Why the collision monitor holds the robot back now, naming the nearest obstacle's distance and bearing
    (:meth:`~beastbt.actuation.collision_monitor.CollisionMonitor.holding`); None when it does not, or without one."""
    plugins: dict[str, Any] = field(default_factory=dict)
    """What parts from other packages offer their steps, by the part's name (see docs/extending.md)."""


@dataclass
class MissionContext:
    """Everything a behaviour may use besides the blackboard.

    ``servo_names``: the servos this robot has (``pan``, ``tilt``...);
    ``capabilities``: which sensors exist (``gps``, ``camera``, ``joystick``, ``imu``);
    ``speed_limit_mps``/``turn_rate_limit_rps``: the tightest of mission and robot limits;
    ``run_dir``: where snapshots go (None: not recorded).
    """

    clock: Clock
    events: EventLog
    params: ControlParams = field(default_factory=ControlParams)
    servo_names: frozenset[str] = frozenset()
    capabilities: frozenset[str] = frozenset()
    speed_limit_mps: float = 1.0
    turn_rate_limit_rps: float = math.pi
    run_dir: Optional[Path] = None
    services: RunServices = field(default_factory=RunServices)
    """What the run's parts offer (home, snapshots, teleop, camera, navigation tuning...)."""
    condition_reads: set[str] = field(default_factory=set)
    """Blackboard keys the mission's compiled conditions read (leaves declare theirs on their own clients)."""

    def now(self) -> float:
        """The current time in seconds."""
        return self.clock.now()
