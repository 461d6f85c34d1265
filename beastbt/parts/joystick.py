"""The gamepad on the robot (the profile's ``joystick:``, ``/dev/input/jsN``).

A missing gamepad is not fatal: it is reported as a ``joystick_unavailable``
event, the driver keeps trying to open it, and a ``teleop`` step fails with
"no joystick" while it is absent. On the simulator a joystick is scripted
(``--joystick FILE``, :mod:`beastbt.parts.sim_joystick`).
"""

from __future__ import annotations

from beastbt.core.clock import Clock
from beastbt.core.events import EventLog
from beastbt.devices.gamepad_presets import describe_controls
from beastbt.devices.joystick import JoystickDevice, JoystickMapping, JoystickWatcher, device_name, linux_joystick_opener
from beastbt.robot.actuator_profile import joystick_mapping
from beastbt.robot.part import REAL, Build, Part
from beastbt.robot.profile import RobotProfile
from beastbt.robot.robot_io import RobotIO


JOYSTICK_HINT = ("check that the gamepad is plugged in or paired (ls /dev/input/js*; jstest {path}) and that your user "
                 "is in the 'input' group; teleop and the joystick e-stop work once it appears")


def attach_joystick(profile: RobotProfile, io: RobotIO, clock: Clock, events: EventLog) -> None:
    """The profile's gamepad on ``/dev/input/jsN``; a missing one is an event, not an error."""
    if profile.section("joystick") is None:
        return
    mapping = joystick_mapping(profile)
    sink = events.sink("joystick")
    hint = JOYSTICK_HINT.format(path=mapping.device)

    def with_hint(kind: str, text: str) -> None:
        sink(kind, f"{text}; {hint}" if kind == "joystick_unavailable" else text)

    def identify() -> JoystickMapping:
        # The layout of the pad plugged in now: a preset by its name, the profile's own numbers winning.
        name = device_name(mapping.device)
        resolved, preset = mapping.for_device(name)
        sink("joystick_preset", f"'{name or 'unnamed device'}' -> preset {preset.name}: "
                                f"{describe_controls(resolved, preset)}")
        return resolved

    device = JoystickDevice(linux_joystick_opener(mapping.device), clock, with_hint, mapping.for_device(None)[0],
                            identify=identify)
    device.poll()  # open it now, so that a missing gamepad is reported before the run starts

    def poll(now_s: float) -> list:
        return [device.poll()]

    io.sensors["joystick"] = poll
    io.joystick = device
    io.capabilities.add("joystick")
    # Input wakes the loop: a stick or e-stop reaches the base in milliseconds, not at the next tick.
    watcher = io.joystick_watcher = JoystickWatcher(device, io.wakeup.set).start()
    io.closers.append(watcher.stop)


class JoystickPart(Part):
    """``joystick:``: a Linux joystick device read into ``JoystickState`` readings."""

    name = "joystick"
    section = "joystick"
    schema = "parts/joystick.schema.json"
    opens = "Linux joystick device (/dev/input/jsN)"
    fills = ("joystick",)

    def attach(self, build: Build) -> None:
        """Open the gamepad on the robot (a missing one is an event, not an error)."""
        if build.mode == REAL:
            assert build.io is not None
            attach_joystick(build.profile, build.io, build.clock, build.events)


__all__ = ["JoystickPart", "attach_joystick", "JOYSTICK_HINT"]
