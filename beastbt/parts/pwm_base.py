"""A PWM base (``base: {type: pwm}``): motor drivers on a PCA9685, open loop, on the robot or emulated.

On the robot :class:`~beastbt.actuation.pwm_base.PwmBase` drives the motor
driver's inputs through the PCA9685 on ``/dev/i2c-N``; on the simulator the
same adapter writes the registers of an emulated chip, read back as wheel
speed targets by :class:`~beastbt.sim.pwm_motor_emulator.SimPwmMotors`. There
is no odometry, as on the real base.
"""

from __future__ import annotations

from beastbt.actuation.pwm_base import PwmBase
from beastbt.core.clock import Clock
from beastbt.core.events import EventLog
from beastbt.parts.pca9685_chip import open_pca9685, real_sleep, sim_chip
from beastbt.robot.actuator_profile import pwm_config
from beastbt.robot.part import BasePart, Build
from beastbt.robot.profile import RobotProfile
from beastbt.robot.robot_io import RobotIO
from beastbt.sim.pwm_motor_emulator import SimPwmMotors
from beastbt.sim.robot import Simulator


def open_pwm_base(profile: RobotProfile, clock: Clock, events: EventLog) -> RobotIO:
    """The PWM base of ``profile`` on its PCA9685, or :class:`DeviceUnavailable`."""
    config = pwm_config(profile)
    pca = open_pca9685(profile, events, "base")
    base = PwmBase(pca, config, events.sink("base"), wait=real_sleep)
    io = RobotIO(base=base)
    io.pca9685 = pca
    return io


def sim_pwm_base(sim: Simulator, profile: RobotProfile, events: EventLog) -> RobotIO:
    """The PWM base of ``profile`` on an emulated PCA9685 whose outputs drive the simulated wheels."""
    config = pwm_config(profile)
    io = RobotIO(base=None, sim=sim)  # type: ignore[arg-type]  # the base is set just below
    pca = sim_chip(profile, io, events)
    io.base = PwmBase(pca, config, events.sink("base"))
    motors = SimPwmMotors(io.sim_pca9685, config)
    io.pwm_motors = motors

    def update(t_s: float, dt_s: float) -> None:
        sim.drive.set_wheel_targets(*motors.wheel_targets_mps())

    sim.emulators.append(update)
    return io


class PwmBasePart(BasePart):
    """``base: {type: pwm}``: two motor channels on a PCA9685."""

    name = "pwm_base"
    section = "base"
    schema = "parts/pwm_base.schema.json"
    opens = "I2C bus (PCA9685)"
    base_types = ("pwm",)

    def open_real(self, build: Build) -> RobotIO:
        """Open the PCA9685; DeviceUnavailable when it does not answer."""
        return open_pwm_base(build.profile, build.clock, build.events)

    def open_sim(self, build: Build) -> RobotIO:
        """The emulated chip whose outputs drive the simulated wheels."""
        assert build.sim is not None
        return sim_pwm_base(build.sim, build.profile, build.events)


__all__ = ["PwmBasePart", "open_pwm_base", "sim_pwm_base"]
