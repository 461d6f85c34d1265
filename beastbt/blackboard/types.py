"""The values that travel on the blackboard, each stamped with when it was measured.

Units are SI and frames follow ROS conventions: the local world frame is
east-north-up (x east, y north, yaw counter-clockwise from east, radians); the
body frame is x forward, y left. Every reading has ``stamp_s``: the clock time
at which it was measured (or received, when the device gives no better time).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Optional, Union

if TYPE_CHECKING:  # NumPy is imported by the methods that compute: 'beastbt tree' and 'validate' never need it
    import numpy as np


@dataclass(frozen=True)
class GpsFix:
    """One GPS position with a valid fix (no fix means no GpsFix at all).

    Latitude and longitude in decimal degrees (WGS84), altitude above mean sea
    level in metres, ``quality`` the NMEA GGA fix quality (1 GPS, 2 DGPS,
    4 RTK fixed, 5 RTK float...), ``hdop`` unitless, ``speed_mps`` and
    ``track_deg`` (true course over ground, clockwise from north) when the
    receiver gave them. ``covariance_enu`` is the 3x3 position covariance in
    m^2 (east, north, up), never zero.
    """

    stamp_s: float
    lat: float
    lon: float
    alt_msl: Optional[float] = None
    quality: int = 1
    sats: Optional[int] = None
    hdop: Optional[float] = None
    speed_mps: Optional[float] = None
    track_deg: Optional[float] = None
    time_utc: Optional[str] = None
    sentence: str = "GGA"
    covariance_enu: tuple[tuple[float, float, float], ...] = ((9.0, 0, 0), (0, 9.0, 0), (0, 0, 36.0))


@dataclass(frozen=True)
class ImuSample:
    """One IMU sample in the body frame (x forward, y left, z up).

    ``gyro_rps`` in rad/s (bias already removed when the driver estimated it),
    ``accel_mps2`` in m/s^2 (gravity included: +9.81 on z at rest),
    ``mag_t`` in tesla or None when there is no magnetometer reading,
    ``temperature_c`` in degrees Celsius.
    """

    stamp_s: float
    gyro_rps: tuple[float, float, float]
    accel_mps2: tuple[float, float, float]
    mag_t: Optional[tuple[float, float, float]] = None
    temperature_c: Optional[float] = None


@dataclass(frozen=True)
class WheelOdometry:
    """Cumulative wheel travel from the base controller.

    ``left_m``/``right_m``: distance each side has rolled since the base
    started, metres (forward positive). ``left_mps``/``right_mps``: the
    measured wheel speeds, m/s.
    """

    stamp_s: float
    left_m: float
    right_m: float
    left_mps: float = 0.0
    right_mps: float = 0.0


@dataclass(frozen=True)
class BatteryState:
    """Battery voltage in volts."""

    stamp_s: float
    voltage_v: float


@dataclass(frozen=True)
class Pose2D:
    """A planar pose in the local ENU frame: metres and radians (yaw CCW from east)."""

    x: float
    y: float
    yaw: float


@dataclass(frozen=True)
class FusedPose:
    """The estimator's output.

    ``x``, ``y`` metres east/north of the local origin; ``yaw`` rad CCW from
    east; ``speed_mps`` forward speed; ``yaw_rate_rps`` rad/s CCW;
    ``covariance`` 3x3 over (x, y, yaw) in m^2/rad^2; ``distance_m`` the
    odometric path length travelled (always increasing); ``heading_valid``
    false until the heading is known (e.g. before the first metres of motion
    without a magnetometer); ``position_valid`` false until there is a
    position in the world (GPS or datum). ``lat``/``lon`` the same position in
    WGS84 degrees when the local origin is georeferenced.
    """

    stamp_s: float
    x: float
    y: float
    yaw: float
    speed_mps: float = 0.0
    yaw_rate_rps: float = 0.0
    covariance: tuple[tuple[float, float, float], ...] = ((0.0, 0, 0), (0, 0.0, 0), (0, 0, 0.0))
    distance_m: float = 0.0
    heading_valid: bool = True
    position_valid: bool = True
    lat: Optional[float] = None
    lon: Optional[float] = None


@dataclass(frozen=True)
class MapPose:
    """The robot's pose on a saved map (``map`` frame: x forward, y left of where mapping began), as AMCL gives it.

    ``x``, ``y`` metres and ``yaw`` rad CCW from the map's x axis; ``covariance``
    3x3 over (x, y, yaw) in m^2/rad^2, honest (it grows while the scan matches
    poorly); ``match_quality`` in [0, 1], the share of the scan's points that
    agree with the map; ``localized`` false while the quality has stayed below
    the localiser's threshold; ``odom_x``, ``odom_y``, ``odom_yaw`` the
    transform from the localiser's odometry frame (the wheels' travel turned
    by the gyro, starting where ``pose_odom`` starts) to the map frame that
    this pose implies (ROS's ``map -> odom``).
    """

    stamp_s: float
    x: float
    y: float
    yaw: float
    covariance: tuple[tuple[float, float, float], ...]
    match_quality: float
    localized: bool
    odom_x: float = 0.0
    odom_y: float = 0.0
    odom_yaw: float = 0.0


@dataclass(frozen=True)
class VelocityCommand:
    """A body velocity command: ``linear_mps`` forward, ``angular_rps`` CCW (rad/s)."""

    linear_mps: float = 0.0
    angular_rps: float = 0.0
    stamp_s: float = 0.0
    source: str = "mission"

    def is_zero(self) -> bool:
        """True when the command asks for no motion at all."""
        return self.linear_mps == 0.0 and self.angular_rps == 0.0


@dataclass(frozen=True)
class ServoCommand:
    """Point a named servo (``pan``, ``tilt``, ``gripper``...) at ``angle_rad``.

    Alternatively ``channel`` and ``pulse_s`` address a PWM channel directly.
    """

    name: Optional[str] = None
    angle_rad: Optional[float] = None
    channel: Optional[int] = None
    pulse_s: Optional[float] = None
    stamp_s: float = 0.0


@dataclass(frozen=True)
class LineObservation:
    """What the line detector saw in one camera frame (body frame, metres/radians).

    ``offset_m``: lateral offset of the line from the robot's centreline at the
    look-ahead distance, positive to the left. ``angle_rad``: the line's
    direction relative to the robot's heading, positive CCW. ``width_m``: the
    apparent line width. ``confidence`` 0-1. ``intersection``: a crossing,
    T or Y is in view; ``intersection_distance_m``: how far ahead of the robot
    centre it is, when known. ``line_end``: the line ends in view.
    """

    stamp_s: float
    seen: bool
    offset_m: float = 0.0
    angle_rad: float = 0.0
    width_m: float = 0.0
    confidence: float = 0.0
    intersection: bool = False
    intersection_distance_m: Optional[float] = None
    line_end: bool = False


@dataclass(frozen=True)
class JoystickState:
    """The joystick as the teleop logic sees it: named axes (-1..1) and buttons."""

    stamp_s: float
    axes: dict = field(default_factory=dict)
    buttons: dict = field(default_factory=dict)
    connected: bool = True


@dataclass(frozen=True)
class CameraFrame:
    """One camera image (BGR uint8, shape (h, w, 3)) and when it was taken; ``jpeg``: the camera's own JPEG of
    it when the camera gave one (passed on untouched to the console), else None; ``h264``: likewise the camera's
    own H.264 access unit (Annex B)."""

    stamp_s: float
    image: np.ndarray
    seq: int = 0
    jpeg: Optional[bytes] = None
    h264: Optional[bytes] = None


Feedback = Union[WheelOdometry, ImuSample, BatteryState]
"""What a drive base reports on the wire it is commanded over (wheel odometry, its IMU, the battery)."""


@dataclass(frozen=True)
class LaserScan:
    """One revolution of a 2D LiDAR, in the LiDAR's own frame (``lidar``: the profile's ``lidar.mounting`` on
    base_link). Given by the drivers in :mod:`beastbt.devices.lidar_scan` (which re-exports it).

    ``angles_rad`` counterclockwise from the LiDAR's 0 degree mark, in
    [-pi, pi), in the order measured; ``ranges_m`` metres, NaN for no return
    (no echo, out of range or masked); ``intensities`` the model's raw
    reflectivity (LD19 0-255; RPLIDAR quality 0-63). ``stamp_s`` is the clock
    time at which the revolution's last bytes were read, ``scan_time_s`` the
    time the revolution took (1 / ``scan_rate_hz``).
    """

    stamp_s: float
    angles_rad: np.ndarray
    ranges_m: np.ndarray
    intensities: np.ndarray
    scan_rate_hz: float
    model: str

    @property
    def scan_time_s(self) -> float:
        """Duration of the revolution, seconds."""
        return 1.0 / self.scan_rate_hz if self.scan_rate_hz > 0 else math.nan

    @property
    def valid_count(self) -> int:
        """Number of points with a return (finite range)."""
        import numpy as np

        return int(np.count_nonzero(np.isfinite(self.ranges_m)))

    def __len__(self) -> int:
        return int(self.angles_rad.shape[0])

    def points_xy(self) -> np.ndarray:
        """The returns as (n, 2) x, y in metres in the LiDAR's frame (no-return points left out)."""
        import numpy as np

        ok = np.isfinite(self.ranges_m)
        r, a = self.ranges_m[ok], self.angles_rad[ok]
        return np.column_stack((r * np.cos(a), r * np.sin(a)))


COST_FREE = 0
"""A local costmap cell nothing is near (Nav2's FREE_SPACE)."""
COST_INSCRIBED = 253
"""A cell where the robot's footprint, centred there, would touch an obstacle (Nav2's INSCRIBED_INFLATED_OBSTACLE)."""
COST_LETHAL = 254
"""A cell with an obstacle in it (Nav2's LETHAL_OBSTACLE)."""
COST_UNKNOWN = 255
"""A cell nothing has been seen in or through (Nav2's NO_INFORMATION)."""


@dataclass(frozen=True)
class LocalCostmap:
    """The rolling local costmap around the robot, in the ``odom`` frame (Nav2's local costmap).

    ``cost`` is a (rows, cols) uint8 array, row 0 the southernmost: cell
    (row, col) covers x in [``origin_x_m`` + col * ``resolution_m``, + one
    cell) and likewise y with rows, metres in ``odom``. Costs follow Nav2:
    :data:`COST_FREE` 0, 1-252 inflated (the closer to an obstacle the
    higher), :data:`COST_INSCRIBED` 253, :data:`COST_LETHAL` 254,
    :data:`COST_UNKNOWN` 255. ``stamp_s`` is the stamp of the newest scan in it.
    """

    stamp_s: float
    origin_x_m: float
    origin_y_m: float
    resolution_m: float
    cost: np.ndarray

    @property
    def width_m(self) -> float:
        """Extent along x (m)."""
        return float(self.cost.shape[1] * self.resolution_m)

    @property
    def height_m(self) -> float:
        """Extent along y (m)."""
        return float(self.cost.shape[0] * self.resolution_m)


@dataclass(frozen=True)
class GlobalPlan:
    """The path go_to follows on the mission's map, in the ``map`` frame.

    ``points_xy`` is an (n, 2) array of metres from where the robot was when
    it was planned to the goal, ``goal`` the place's name, ``length_m`` the
    path's length (m); ``stamp_s`` when it was planned (a replan makes a new one).
    """

    stamp_s: float
    points_xy: np.ndarray
    goal: str = ""
    length_m: float = 0.0


@dataclass(frozen=True)
class LocalPlan:
    """What the local planner chose this tick, in the ``odom`` frame.

    ``points_xy`` is an (n, 2) array of metres: the path the chosen command
    would drive over the planner's horizon, starting at the robot.
    ``linear_mps`` and ``angular_rps`` are the command it chose; ``blocked``
    is true when no admissible command gets closer to the goal.
    """

    stamp_s: float
    points_xy: np.ndarray
    linear_mps: float = 0.0
    angular_rps: float = 0.0
    blocked: bool = False
