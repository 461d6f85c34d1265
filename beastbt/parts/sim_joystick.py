"""A scripted joystick on the simulated robot: the script's bytes read by the real joystick driver.

``beastbt run ... --joystick FILE`` (see :mod:`beastbt.parts.teleop`)
loads FILE as a :class:`~beastbt.sim.joystick_script.ScriptedJoystick`, using
the profile's ``joystick:`` mapping to turn ``press: enable`` and stick
positions into the 8-byte Linux joystick events the kernel would deliver.
The simulator plays the script in step with its clock and
:class:`~beastbt.devices.joystick.JoystickDevice` reads the bytes, exactly
as it reads ``/dev/input/js0`` on the robot; its state goes on the
blackboard as ``joystick`` through the run's sensor polls.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any, Union

from beastbt.core.errors import plain_reason
from beastbt.devices.joystick import JoystickDevice, JoystickMapping
from beastbt.core.errors import InvalidInput, Position, Problem
from beastbt.core.clock import Clock
from beastbt.core.events import EventLog
from beastbt.robot.robot_io import RobotIO
from beastbt.sim.joystick_script import ScriptedJoystick, ScriptProblems, script_doc
from beastbt.sim.robot import Simulator

DUE_TOLERANCE_S = 1e-6
"""A script event due within this much of the physics time is played now (s): sums of steps are not exact."""

_WHERE = re.compile(r"^(?P<file>.*?):(?P<line>\d+):(?P<col>\d+): error: (?P<msg>.*)$")


def load_joystick_script(spec: Union[str, Path, list], mapping: JoystickMapping) -> ScriptedJoystick:
    """A script from a YAML file path or a list of event mappings; raise InvalidInput naming file:line:column."""
    from beastbt.sim.joystick_limits import file_size_problem
    too_big = None if isinstance(spec, (list, tuple)) else file_size_problem(spec, str(spec))  # from stat
    if too_big is not None:
        raise InvalidInput([too_big])
    try:
        if isinstance(spec, (list, tuple)):
            return ScriptedJoystick(list(spec), mapping, source="<joystick events>")
        path = Path(spec)
        from beastbt.core.file_refs import JOYSTICK, RefusedFile, read_capped
        try:
            # a regular file within the joystick script's byte cap: a device or a pipe is not read
            text = read_capped(path, JOYSTICK, str(spec)).decode("utf-8")
        except (RefusedFile, UnicodeDecodeError) as exc:
            why = exc.message if isinstance(exc, RefusedFile) else "it is not UTF-8 text"
            raise InvalidInput([Problem(str(path), Position(), f"cannot read the joystick script: {why}",
                                        "--joystick takes a YAML file: a list like [{at: 2 s, press: enable}]")]
                               ) from None
        # Read here, not in from_yaml, so that the loader's problems keep their hints.
        return ScriptedJoystick.from_doc(script_doc(text, str(spec)), mapping)
    except ScriptProblems as exc:
        raise InvalidInput(exc.problems) from None
    except ValueError as exc:
        problems = []
        for line in str(exc).splitlines():
            m = _WHERE.match(line)
            if m:
                problems.append(Problem(m["file"], Position(int(m["line"]), int(m["col"])), m["msg"]))
            else:
                problems.append(Problem(str(spec) if not isinstance(spec, (list, tuple)) else "<joystick events>",
                                        Position(), line.split(": error: ", 1)[-1]))
        raise InvalidInput(problems) from None


def attach_scripted_joystick(sim: Simulator, io: RobotIO, clock: Clock, events: EventLog, script: ScriptedJoystick,
                             mapping: JoystickMapping) -> JoystickDevice:
    """Plug ``script`` into the simulated robot: the simulator plays it, the real driver reads it."""
    device = JoystickDevice(script.opener(), clock, events.sink("joystick"), mapping)

    def play(t_s: float, dt_s: float) -> None:
        script.update(t_s + DUE_TOLERANCE_S)

    sim.emulators.append(play)
    io.sensors["joystick"] = joystick_poll(device)
    io.joystick, io.joystick_script = device, script
    io.capabilities.add("joystick")
    return device


def joystick_poll(device: JoystickDevice) -> Any:
    """The run's sensor poll for a joystick: ``poll(now_s) -> [JoystickState]``."""
    def poll(now_s: float) -> list:
        return [device.poll()]
    return poll


__all__ = ["load_joystick_script", "attach_scripted_joystick", "joystick_poll", "DUE_TOLERANCE_S"]
