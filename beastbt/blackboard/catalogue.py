"""The catalogue of blackboard keys: every key declared once with its type, unit and frame.

Behaviours register the keys they read and write (py_trees' declared access);
registering a key that is not in this catalogue is an error, so who reads and
writes what can always be listed. Values that come from sensors are stamped
(their ``stamp_s`` field); use :func:`is_fresh` instead of trusting old data.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Optional

import py_trees

from beastbt.blackboard.types import (BatteryState, CameraFrame, FusedPose, GpsFix, ImuSample, JoystickState,
                                      GlobalPlan, LaserScan, LineObservation, LocalCostmap, LocalPlan,
                                      MapPose, VelocityCommand,
                                      WheelOdometry)


@dataclass(frozen=True)
class KeySpec:
    """One blackboard key: its name, Python type, unit, frame and meaning."""

    name: str
    type: type
    unit: str
    frame: str
    description: str


KEYS: dict[str, KeySpec] = {k.name: k for k in (
    KeySpec("now_s", float, "s", "-", "The clock's time at the start of this tick."),
    KeySpec("mission_start_s", float, "s", "-", "When the mission started (for the 'elapsed' condition)."),
    KeySpec("odometry", WheelOdometry, "m, m/s", "wheels", "Latest cumulative wheel travel and wheel speeds."),
    KeySpec("pose_odom", FusedPose, "m, rad", "odom (ENU, starts at 0,0)", "Continuous dead-reckoned pose: never jumps; used by drive and turn."),
    KeySpec("pose", FusedPose, "m, rad", "local ENU (world datum or first fix)", "Best estimate of the pose (EKF when GPS/IMU exist); may jump."),
    KeySpec("map_pose", MapPose, "m, rad", "map (x forward, y left of where mapping began)",
            "The pose on the mission's map, from the localiser (absent without a map)."),
    KeySpec("gps_fix", GpsFix, "deg, m", "WGS84", "Latest GPS fix with a valid position (absent without a fix)."),
    KeySpec("imu", ImuSample, "rad/s, m/s^2, T", "body (x fwd, y left, z up)", "Latest IMU sample."),
    KeySpec("battery", BatteryState, "V", "-", "Latest battery voltage."),
    KeySpec("line", LineObservation, "m, rad", "body", "Latest line detection from the camera."),
    KeySpec("camera_frame", CameraFrame, "px", "camera", "Latest camera frame."),
    KeySpec("scan", LaserScan, "m, rad", "lidar (profile lidar.mounting on base_link)",
            "Latest LiDAR revolution: angles CCW, ranges (NaN = no return), stamp_s when read."),
    KeySpec("costmap", LocalCostmap, "m, Nav2 cost 0-255", "odom",
            "Rolling local costmap around the robot: scan points inflated by the footprint, decaying."),
    KeySpec("local_plan", LocalPlan, "m, m/s, rad/s", "odom",
            "The local planner's chosen command and the path it would drive (go_to, route, return_home)."),
    KeySpec("global_plan", GlobalPlan, "m", "map",
            "The path planned on the mission's map that go_to, route and return_home follow (absent without a map)."),
    KeySpec("joystick", JoystickState, "-", "-", "Latest joystick state (named axes -1..1 and buttons)."),
    KeySpec("home", tuple, "deg", "WGS84", "(lat, lon) where the mission started: the fused start position once the "
                                          "estimate settled (beastbt/run/home.py)."),
    KeySpec("cmd_mission", VelocityCommand, "m/s, rad/s", "body", "What the mission asks the base to do this tick."),
    KeySpec("servo_requests", dict, "rad", "servo", "name -> ServoCommand the mission asks for (latest per servo)."),
    KeySpec("servo_angles", dict, "rad", "servo", "name -> last angle sent to each servo."),
    KeySpec("teleop_active", bool, "-", "-", "True while the operator holds the joystick's enable button."),
    KeySpec("estop", bool, "-", "-", "True while the emergency stop is latched."),
    KeySpec("mux_source", str, "-", "-", "Which source the command mux passed through last tick (estop, teleop, failsafe, mission)."),
)}

NAMESPACE = "/beastbt/"


def reset_blackboard() -> None:
    """Clear the (process-global) py_trees blackboard so a new run starts from nothing."""
    py_trees.blackboard.Blackboard.clear()


def register(client: py_trees.blackboard.Client, name: str, write: bool = False) -> None:
    """Declare that ``client`` reads (or writes) catalogue key ``name``; unknown keys raise KeyError."""
    if name not in KEYS:
        raise KeyError(f"blackboard key '{name}' is not in the catalogue (beastbt/blackboard/catalogue.py)")
    access = py_trees.common.Access.WRITE if write else py_trees.common.Access.READ
    client.register_key(key=name, access=access)


def writer(name: str, keys: tuple[str, ...]) -> py_trees.blackboard.Client:
    """A blackboard client that may write ``keys`` (the runtime uses one to publish sensor data)."""
    client = py_trees.blackboard.Client(name=name)
    for key in keys:
        register(client, key, write=True)
    return client


def get(client: py_trees.blackboard.Client, name: str, default: Any = None) -> Any:
    """Read ``name`` through ``client``; ``default`` when it was never written."""
    try:
        return client.get(name)
    except KeyError:
        return default


def is_fresh(value: Any, now_s: float, max_age_s: float) -> bool:
    """True when a stamped value exists and was measured at most ``max_age_s`` ago."""
    stamp: Optional[float] = getattr(value, "stamp_s", None)
    return stamp is not None and now_s - stamp <= max_age_s
