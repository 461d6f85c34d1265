"""The PCA9685 PWM chip a PWM base and a servo board share: opened once per robot, on the robot or emulated.

On the robot :func:`open_pca9685` opens ``/dev/i2c-N`` through smbus2 and
checks the chip answers; on the simulator :func:`sim_chip` puts a
:class:`~beastbt.sim.pca9685_emulator.SimPca9685` on a
:class:`~beastbt.sim.i2c_bus.SimI2CBus` behind the same driver. Either way
the driver is kept in ``io.pca9685`` for the next part that needs it.
"""

from __future__ import annotations

import time

from beastbt.core.errors import plain_reason
from beastbt.core.events import EventLog
from beastbt.devices.pca9685 import MODE1, Pca9685
from beastbt.robot.actuator_profile import pca_config
from beastbt.robot.hardware import DeviceUnavailable
from beastbt.robot.profile import RobotProfile
from beastbt.robot.robot_io import RobotIO
from beastbt.sim.i2c_bus import SimI2CBus
from beastbt.sim.pca9685_emulator import SimPca9685


def real_sleep(duration_s: float) -> None:
    """The sleeper handed to drivers on the robot (the PCA9685's 500 us oscillator wait)."""
    time.sleep(duration_s)


def open_pca9685(profile: RobotProfile, events: EventLog, what: str) -> Pca9685:
    """Open the profile's PCA9685 and check it answers, or raise :class:`DeviceUnavailable` naming ``what`` needs it."""
    import smbus2

    cfg = pca_config(profile)
    path = f"/dev/i2c-{cfg.bus}"
    try:
        bus = smbus2.SMBus(cfg.bus)
    except (OSError, FileNotFoundError) as exc:
        raise DeviceUnavailable(
            f"{what} (PCA9685): cannot open {path} ({plain_reason(exc)}); check that I2C is enabled (raspi-config: Interface "
            f"Options > I2C), that the HAT is seated, and that your user is in the 'i2c' group") from exc
    try:
        bus.read_byte_data(cfg.address, MODE1)
    except OSError as exc:
        bus.close()
        raise DeviceUnavailable(
            f"{what} (PCA9685): nothing answers at address 0x{cfg.address:02x} on {path} ({plain_reason(exc)}); check "
            f"'i2cdetect -y {cfg.bus}' shows 0x{cfg.address:02x}, the HAT's power and its address jumpers") from exc
    return Pca9685(bus, cfg.address, cfg.oscillator_hz, events.sink("pca9685"))


def sim_chip(profile: RobotProfile, io: RobotIO, events: EventLog) -> Pca9685:
    """The emulated PCA9685 of this robot (made on first use), as the driver sees it."""
    pca = io.pca9685
    if pca is None:
        cfg = pca_config(profile)
        bus = SimI2CBus()
        chip = SimPca9685(oscillator_hz=cfg.oscillator_hz)
        bus.attach(cfg.address, chip)
        # The profile's oscillator_hz is the chip's calibrated true clock: emulate exactly that chip.
        pca = Pca9685(bus, cfg.address, cfg.oscillator_hz, events.sink("pca9685"))
        io.pca9685, io.sim_pca9685, io.i2c_bus = pca, chip, bus
    return pca


__all__ = ["open_pca9685", "sim_chip", "real_sleep"]
