"""CAN and PWM bases and PCA9685 servos on the simulator, through the same adapters the robot uses.

A profile whose base is ``can`` gets :class:`~beastbt.actuation.can_base.CanBase`
on a python-can ``virtual`` bus, with
:class:`~beastbt.sim.can_motor_emulator.SimCanMotorController` at the other end
driving the simulated wheels and sending feedback frames. A ``pwm`` base gets
:class:`~beastbt.actuation.pwm_base.PwmBase` writing the registers of a
:class:`~beastbt.sim.pca9685_emulator.SimPca9685` on a
:class:`~beastbt.sim.i2c_bus.SimI2CBus`, read back as wheel speed targets by
:class:`~beastbt.sim.pwm_motor_emulator.SimPwmMotors` (open loop: no
odometry, as on the real base). A ``servos:`` section puts
:class:`~beastbt.actuation.servo_board.PcaServoBoard` on the same emulated
chip (or a chip of its own); servos called ``pan``/``tilt`` turn the
simulated camera when the base has no gimbal. Protocols, ids, scaling and
wiring all come from the profile, as on the robot.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import os

import can

from beastbt.actuation.can_base import CanBase
from beastbt.actuation.pwm_base import PwmBase
from beastbt.actuation.servo_board import PcaServoBoard
from beastbt.devices.pca9685 import Pca9685
from beastbt.robot.actuator_profile import can_config, pca_config, pwm_config, servo_calibrations
from beastbt.core.events import EventLog
from beastbt.robot.profile import RobotProfile
from beastbt.robot.robot_io import RobotIO
from beastbt.sim.can_motor_emulator import SimCanMotorController
from beastbt.sim.i2c_bus import SimI2CBus
from beastbt.sim.pca9685_emulator import SimPca9685
from beastbt.sim.pwm_motor_emulator import SimPwmMotors
from beastbt.sim.robot import SIM_BASES, Simulator, register_sim_device

CAN_FEEDBACK_INTERVAL_S = 0.02
"""How often the emulated CAN motor controller sends a feedback frame (s): 50 Hz, as typical controllers do."""

_channels = itertools.count()


def _virtual_channel() -> str:
    # python-can joins every virtual bus of one name in the process: one name per simulated robot.
    return f"beastbt-sim-can-{os.getpid()}-{next(_channels)}"


def sim_can_base(sim: Simulator, profile: RobotProfile, events: EventLog) -> RobotIO:
    """The CAN base of ``profile`` on a virtual bus, with the emulated motor controller driving the wheels."""
    config = dataclasses.replace(can_config(profile), interface="virtual", channel=_virtual_channel())
    controller = SimCanMotorController(config.channel, config, events=events.sink("sim can controller"))
    bus = can.Bus(interface="virtual", channel=config.channel, receive_own_messages=False)
    base = CanBase(bus, config, events.sink("base"))
    state = {"next_feedback_s": 0.0}

    def update(t_s: float, dt_s: float) -> None:
        sim.drive.set_wheel_targets(*controller.wheel_targets_mps(t_s))
        if t_s + 1e-9 >= state["next_feedback_s"]:
            state["next_feedback_s"] = max(state["next_feedback_s"] + CAN_FEEDBACK_INTERVAL_S, t_s)
            controller.update(sim.truth)

    sim.emulators.append(update)
    io = RobotIO(base=base, sim=sim)
    io.extras.update(can_controller=controller, can_channel=config.channel)
    io.closers.append(controller.close)
    return io


def _sim_chip(profile: RobotProfile, io: RobotIO, events: EventLog) -> Pca9685:
    """The emulated PCA9685 of this robot (made on first use), as the driver sees it."""
    pca = io.extras.get("pca9685")
    if pca is None:
        cfg = pca_config(profile)
        bus = SimI2CBus()
        chip = SimPca9685(oscillator_hz=cfg.oscillator_hz)
        bus.attach(cfg.address, chip)
        # The profile's oscillator_hz is the chip's calibrated true clock: emulate exactly that chip.
        pca = Pca9685(bus, cfg.address, cfg.oscillator_hz, events.sink("pca9685"))
        io.extras.update(pca9685=pca, sim_pca9685=chip, i2c_bus=bus)
    return pca


def sim_pwm_base(sim: Simulator, profile: RobotProfile, events: EventLog) -> RobotIO:
    """The PWM base of ``profile`` on an emulated PCA9685 whose outputs drive the simulated wheels."""
    config = pwm_config(profile)
    io = RobotIO(base=None, sim=sim)  # type: ignore[arg-type]  # the base is set just below
    pca = _sim_chip(profile, io, events)
    io.base = PwmBase(pca, config, events.sink("base"))
    motors = SimPwmMotors(io.extras["sim_pca9685"], config)
    io.extras["pwm_motors"] = motors

    def update(t_s: float, dt_s: float) -> None:
        sim.drive.set_wheel_targets(*motors.wheel_targets_mps())

    sim.emulators.append(update)
    return io


SIM_BASES["can"] = sim_can_base
SIM_BASES["pwm"] = sim_pwm_base


@register_sim_device
def sim_pca_servos(sim: Simulator, profile: RobotProfile, io: RobotIO, events: EventLog) -> None:
    """The profile's ``servos:`` on an emulated PCA9685 (shared with a PWM base when there is one)."""
    cals = servo_calibrations(profile)
    if not cals:
        return
    pca = _sim_chip(profile, io, events)
    board = PcaServoBoard(pca, cals, pca_config(profile).frequency_hz, events.sink("servos"))
    io.servos.append(board)
    io.capabilities.add("pwm_servos")
    io.extras["servo_board"] = board
    chip: SimPca9685 = io.extras["sim_pca9685"]
    if "esp32" in io.extras:
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


__all__ = ["sim_can_base", "sim_pwm_base", "sim_pca_servos", "CAN_FEEDBACK_INTERVAL_S"]
