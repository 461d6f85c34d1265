"""A CAN motor controller base (``base: {type: can}``): python-can on the robot, a virtual bus in the simulator.

On the robot the :class:`~beastbt.actuation.can_base.CanBase` adapter opens
the profile's interface (SocketCAN ``can0`` by default); a bus that cannot be
opened stops the run before anything moves with a
:class:`~beastbt.robot.hardware.DeviceUnavailable` saying what to check. On
the simulator the same adapter talks over a python-can ``virtual`` bus to
:class:`~beastbt.sim.can_motor_emulator.SimCanMotorController`, which drives
the simulated wheels and sends feedback frames.
"""

from __future__ import annotations

import dataclasses
import itertools
import os

import can

from beastbt.actuation.can_base import CanBase, bring_up_hint, open_can_bus, socketcan_link
from beastbt.core.clock import Clock
from beastbt.core.errors import plain_reason
from beastbt.core.events import EventLog
from beastbt.robot.actuator_profile import can_config
from beastbt.robot.hardware import DeviceUnavailable
from beastbt.robot.part import BasePart, Build
from beastbt.robot.profile import RobotProfile
from beastbt.robot.robot_io import RobotIO
from beastbt.sim.can_motor_emulator import SimCanMotorController
from beastbt.sim.robot import Simulator


CAN_FEEDBACK_INTERVAL_S = 0.02
"""How often the emulated CAN motor controller sends a feedback frame (s): 50 Hz, as typical controllers do."""


_channels = itertools.count()


def _virtual_channel() -> str:
    # python-can joins every virtual bus of one name in the process: one name per simulated robot.
    return f"beastbt-sim-can-{os.getpid()}-{next(_channels)}"


def open_can_base(profile: RobotProfile, clock: Clock, events: EventLog) -> RobotIO:
    """The CAN base of ``profile`` on its SocketCAN interface, or :class:`DeviceUnavailable`."""
    config = can_config(profile)
    try:
        bus = open_can_bus(config)
    except Exception as exc:  # python-can raises CanInitializationError, OSError or ValueError by backend
        raise DeviceUnavailable(
            f"base (CAN motor controller): cannot open {config.interface} channel '{config.channel}' at "
            f"{config.bitrate} bit/s ({plain_reason(exc)}); check that the CAN HAT is enabled (dtoverlay=mcp2515-can0 in "
            f"/boot/firmware/config.txt), that the interface is up (sudo ip link set {config.channel} up type can "
            f"bitrate {config.bitrate}; ip -details link show {config.channel}), and the wiring and 120 ohm termination"
        ) from exc
    if config.interface == "socketcan":
        link = socketcan_link(config.channel)
        if link is not None and link["bitrate"] is not None and link["bitrate"] != config.bitrate:
            bus.shutdown()
            raise DeviceUnavailable(
                f"base (CAN motor controller): {config.channel} runs at {link['bitrate']} bit/s but the profile says "
                f"{config.bitrate} bit/s (python-can does not set a SocketCAN bitrate, the kernel does): "
                f"{bring_up_hint(config)}, or set can_base.bitrate to {link['bitrate']}")
    base = CanBase(bus, config, events.sink("base"))
    return RobotIO(base=base)


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
    io.can_controller, io.can_channel = controller, config.channel
    io.closers.append(controller.close)
    return io


class CanBasePart(BasePart):
    """``base: {type: can}``: wheel speed frames out, encoder feedback in."""

    name = "can_base"
    section = "base"
    schema = "parts/can_base.schema.json"
    opens = "CAN bus (python-can; SocketCAN can0 by default)"
    fills = ("odometry",)
    base_types = ("can",)

    def open_real(self, build: Build) -> RobotIO:
        """Open the profile's CAN interface; DeviceUnavailable when it cannot be opened."""
        return open_can_base(build.profile, build.clock, build.events)

    def open_sim(self, build: Build) -> RobotIO:
        """The emulated motor controller on a virtual bus."""
        assert build.sim is not None
        return sim_can_base(build.sim, build.profile, build.events)


__all__ = ["CanBasePart", "open_can_base", "sim_can_base", "CAN_FEEDBACK_INTERVAL_S"]
