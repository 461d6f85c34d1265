"""What the tick loop drives: the robot's base, servos and sensors, real or simulated.

A :class:`RobotIO` is assembled from a robot profile: on the robot from real
ports (``beastbt.robot.hardware``), in the simulator from emulators
(``beastbt.sim.robot``). The tick loop cannot tell them apart, except that a
simulated one has a world to step and a ground truth to compare against.
"""

from __future__ import annotations

import threading

from dataclasses import dataclass, field, fields
from typing import TYPE_CHECKING, Any, Callable, Optional

from beastbt.actuation.adapter import BaseAdapter, ServoAdapter

if TYPE_CHECKING:  # the device types, for annotations only: a robot imports only the drivers it has
    from beastbt.actuation.servo_board import PcaServoBoard
    from beastbt.actuation.watchdog import AdapterWatchdog
    from beastbt.devices.mpu9250 import Mpu9250
    from beastbt.devices.nmea_gps import NmeaGps
    from beastbt.devices.pca9685 import Pca9685
    from beastbt.estimation.imu_tap import ImuTap
    from beastbt.sim.camera_emulator import SimCamera
    from beastbt.sim.can_motor_emulator import SimCanMotorController
    from beastbt.sim.floor import FloorMap
    from beastbt.sim.gps_emulator import SimGps
    from beastbt.sim.i2c_bus import SimI2CBus
    from beastbt.sim.imu_emulator import SimImu
    from beastbt.sim.joystick_script import ScriptedJoystick
    from beastbt.sim.pca9685_emulator import SimPca9685
    from beastbt.sim.pwm_motor_emulator import SimPwmMotors
    from beastbt.sim.waveshare_emulator import SimWaveshareBase
    from beastbt.vision.camera_pipeline import CameraPipeline

SensorPoll = Callable[[float], list]
"""A device's poll: given the time (s), the readings that arrived since the last call."""


@dataclass
class RobotIO:
    """The devices of one robot.

    ``sensors``: name -> poll function; ``capabilities``: words such as ``gps``,
    ``imu``, ``camera``, ``joystick``, ``pwm_servos``; ``sim``: the simulator
    (None on the robot), which the loop advances before polling.
    """

    base: BaseAdapter
    servos: list[ServoAdapter] = field(default_factory=list)
    sensors: dict[str, SensorPoll] = field(default_factory=dict)
    capabilities: set[str] = field(default_factory=set)
    sim: Optional[Any] = None
    closers: list[Callable[[], None]] = field(default_factory=list)
    wakeup: threading.Event = field(default_factory=threading.Event)
    """Set by a device's thread when input wants an answer before the next tick (the joystick): the real
    loop then runs :meth:`~beastbt.run.runner.MissionRun.react` at once."""
    joystick_watcher: Optional[Any] = None
    """The :class:`~beastbt.devices.joystick.JoystickWatcher` that sets :attr:`wakeup`, on the robot."""

    # -- the devices the parts opened (None: this robot has none), by what they are --------------------
    watchdog: Optional["AdapterWatchdog"] = None
    """The command watchdog around ``base`` (the run wires it)."""
    gps_driver: Optional["NmeaGps"] = None
    imu_driver: Optional["Mpu9250"] = None
    imu_tap: Optional["ImuTap"] = None
    """The IMU device's samples, as the EKF takes them (only once the gyro bias is final)."""
    camera: Optional["CameraPipeline"] = None
    """The camera and the line detector on its frames."""
    joystick: Optional[Any] = None
    """The gamepad (``JoystickDevice``; in a replay, a stand-in that only says there was one)."""
    pca9685: Optional["Pca9685"] = None
    """The PCA9685 driver a PWM base and a servo board share."""
    servo_board: Optional["PcaServoBoard"] = None
    magnetic_declination_deg: Optional[float] = None
    """The declination the EKF uses when the profile sets none (the simulated world's); recorded for replay."""
    plugins: dict[str, Any] = field(default_factory=dict)
    """Devices of parts from other packages, by the part's name."""

    # -- the simulator's side of those devices (None on the robot) -----------------------------------
    esp32: Optional["SimWaveshareBase"] = None
    can_controller: Optional["SimCanMotorController"] = None
    can_channel: Optional[str] = None
    pwm_motors: Optional["SimPwmMotors"] = None
    sim_pca9685: Optional["SimPca9685"] = None
    i2c_bus: Optional["SimI2CBus"] = None
    sim_gps: Optional["SimGps"] = None
    sim_imu: Optional["SimImu"] = None
    imu_bus: Optional["SimI2CBus"] = None
    sim_camera: Optional["SimCamera"] = None
    floor_map: Optional[Callable[[], "FloorMap"]] = None
    """Builds (once) and returns the simulated floor the camera sees."""
    joystick_script: Optional["ScriptedJoystick"] = None
    viewer_camera: Optional[dict] = None
    """How a live viewer's process builds a simulated camera of its own (floor, seed, geometry, effects)."""

    def devices(self) -> dict[str, Any]:
        """Every device this robot has, by field name (what a recording lists, and replay stands in for)."""
        skip = {"base", "servos", "sensors", "capabilities", "sim", "closers", "plugins", "wakeup", "joystick_watcher",
                "viewer_camera"}
        return {f.name: getattr(self, f.name) for f in fields(self)
                if f.name not in skip and getattr(self, f.name) is not None}

    def servo_names(self) -> frozenset[str]:
        """Every servo name any adapter drives."""
        names: set[str] = set()
        for s in self.servos:
            names.update(s.servo_names())
        return frozenset(names)

    def close(self) -> None:
        """Stop and release everything (the base last sends a stop)."""
        for close in self.closers:
            try:
                close()
            except Exception:
                pass
        try:
            self.base.close()
        except Exception:
            pass
