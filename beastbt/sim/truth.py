"""Ground truth of the simulated robot, as the device emulators see it."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass
class RobotTruth:
    """The true state of the simulated robot at ``t_s`` seconds.

    Position in metres in the world's local east-north-up frame, ``yaw`` rad
    CCW from east, ``v_mps``/``w_rps`` the true body velocity, ``left_m``/
    ``right_m`` the cumulative distance each wheel/track has rolled (with
    slip, what an encoder would count), ``left_mps``/``right_mps`` their speeds,
    ``pan_rad``/``tilt_rad`` the camera servo angles (pan positive left, tilt
    positive up).
    """

    t_s: float = 0.0
    x: float = 0.0
    y: float = 0.0
    yaw: float = 0.0
    v_mps: float = 0.0
    w_rps: float = 0.0
    left_m: float = 0.0
    right_m: float = 0.0
    left_mps: float = 0.0
    right_mps: float = 0.0
    pan_rad: float = 0.0
    tilt_rad: float = 0.0
    battery_v: float = 12.3
