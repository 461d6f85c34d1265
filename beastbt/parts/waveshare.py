"""The Waveshare UGV base (ESP32 sub-controller, serial JSON): the default base, on the robot and in the simulator.

On the robot the :class:`~beastbt.devices.waveshare_base.WaveshareBase`
driver opens the profile's ``base.port``; in the simulator the same driver
talks to :class:`~beastbt.sim.waveshare_emulator.SimWaveshareBase` on an
emulated serial port. A profile whose base type has no emulator of its own
is driven on the simulator through this one, with the same geometry.
"""

from __future__ import annotations

from beastbt.devices.waveshare_base import WaveshareBase, WaveshareConfig
from beastbt.robot.hardware import open_serial
from beastbt.robot.part import BasePart, Build
from beastbt.robot.profile import section_config
from beastbt.robot.serial_hint import serial_port_hint
from beastbt.robot.robot_io import RobotIO
from beastbt.sim.waveshare_emulator import SimWaveshareBase




class WaveshareBasePart(BasePart):
    """``base: {type: waveshare_serial}``: wheels, battery, IMU and gimbal of the ESP32 over serial JSON."""

    name = "waveshare_base"
    section = "base"
    schema = "parts/waveshare_base.schema.json"
    opens = "serial port (Waveshare JSON, 115200 baud)"
    fills = ("odometry", "battery", "imu")
    takes = ("velocity", "servo (gimbal pan/tilt)")
    base_types = ("waveshare_serial",)

    def open_real(self, build: Build) -> RobotIO:
        """Open ``base.port``; DeviceUnavailable when it cannot be opened."""
        config = section_config(build.profile, "base", WaveshareConfig)
        port = open_serial("base (Waveshare ESP32)", config.port, config.baud,
                           f"check the cable to the sub-controller; {serial_port_hint(config.port)}")
        base = WaveshareBase(port, config, build.events.sink("base"), track_width_m=build.profile.track_width_m)
        return RobotIO(base=base, servos=[base] if config.gimbal else [])

    def open_sim(self, build: Build) -> RobotIO:
        """The emulated ESP32 driving the simulator's wheels, behind the real driver."""
        sim = build.sim
        assert sim is not None
        base_cfg = build.profile.section("base") or {}
        if base_cfg.get("type") not in self.base_types:
            base_cfg = {"type": "waveshare_serial"}  # another base type without an emulator: same geometry
        config = WaveshareConfig.from_dict({k: v for k, v in base_cfg.items() if k != "port"})
        world = sim.world
        esp32 = SimWaveshareBase(sim.drive, sim.child_rng(), battery_v=world.battery_start_v,
                                 battery_drain_v_per_s=world.battery_drain_v_per_s,
                                 firmware="general" if config.firmware == "general" else "ros")
        sim.emulators.append(esp32.update)
        base = WaveshareBase(esp32.port, config, build.events.sink("base"), track_width_m=build.profile.track_width_m)
        io = RobotIO(base=base, servos=[base] if config.gimbal else [], sim=sim)
        io.esp32 = esp32
        return io


__all__ = ["WaveshareBasePart"]
