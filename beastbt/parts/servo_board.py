"""Hobby servos on a PCA9685 (the profile's ``servos:``), on the robot or emulated.

A :class:`~beastbt.actuation.servo_board.PcaServoBoard` on the PCA9685 (the
PWM base's chip when there is one). On the simulator, servos called ``pan``
and ``tilt`` turn the simulated camera when the base has no gimbal.
"""

from __future__ import annotations

import math

from beastbt.actuation.servo_board import PcaServoBoard
from beastbt.core.clock import Clock
from beastbt.core.events import EventLog
from beastbt.parts.pca9685_chip import open_pca9685, real_sleep, sim_chip
from beastbt.robot.actuator_profile import pca_config, servo_calibrations
from beastbt.robot.part import REAL, SIM, Build, Part
from beastbt.robot.profile import RobotProfile
from beastbt.robot.robot_io import RobotIO
from beastbt.sim.pca9685_emulator import SimPca9685
from beastbt.sim.robot import Simulator


def attach_servos(profile: RobotProfile, io: RobotIO, clock: Clock, events: EventLog) -> None:
    """The profile's ``servos:`` on the PCA9685 (the PWM base's chip when there is one)."""
    cals = servo_calibrations(profile)
    if not cals:
        return
    pca = io.pca9685
    if pca is None:
        pca = open_pca9685(profile, events, "servos")
        io.pca9685 = pca
    board = PcaServoBoard(pca, cals, pca_config(profile).frequency_hz, events.sink("servos"), wait=real_sleep)
    io.servos.append(board)
    io.capabilities.add("pwm_servos")
    io.servo_board = board


def sim_pca_servos(sim: Simulator, profile: RobotProfile, io: RobotIO, events: EventLog) -> None:
    """The profile's ``servos:`` on an emulated PCA9685 (shared with a PWM base when there is one)."""
    cals = servo_calibrations(profile)
    if not cals:
        return
    pca = sim_chip(profile, io, events)
    board = PcaServoBoard(pca, cals, pca_config(profile).frequency_hz, events.sink("servos"))
    io.servos.append(board)
    io.capabilities.add("pwm_servos")
    io.servo_board = board
    chip: SimPca9685 = io.sim_pca9685
    if io.esp32 is not None:
        return  # the base's gimbal points the camera
    aimed = {name: cal for name, cal in cals.items() if name in ("pan", "tilt")}
    if not aimed:
        return

    def update(t_s: float, dt_s: float) -> None:
        # Hobby servos follow their pulse within a few tens of ms: take them as instant at physics rate.
        for name, cal in aimed.items():
            pulse = chip.pulse_s(cal.channel)
            if pulse is None:
                continue
            angle = math.radians(cal.angle_deg_for(pulse * 1000.0))
            if name == "pan":
                sim.truth.pan_rad = angle
            else:
                sim.truth.tilt_rad = angle

    sim.emulators.append(update)


class ServoBoardPart(Part):
    """``servos:``: named servos on PCA9685 channels, driven by ``look`` and ``servo`` steps."""

    name = "servos"
    section = "servos"
    schema = "parts/servos.schema.json"
    opens = "I2C bus (PCA9685)"
    takes = ("servo",)

    def attach(self, build: Build) -> None:
        """Open the board (robot) or its emulated chip (simulator) when the profile has ``servos:``."""
        assert build.io is not None
        if build.mode == REAL:
            attach_servos(build.profile, build.io, build.clock, build.events)
        elif build.mode == SIM:
            assert build.sim is not None
            sim_pca_servos(build.sim, build.profile, build.io, build.events)


__all__ = ["ServoBoardPart", "attach_servos", "sim_pca_servos"]
