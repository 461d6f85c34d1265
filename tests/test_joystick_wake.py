"""On the robot the joystick wakes the loop: a stick or e-stop reaches the base between ticks, not at the next one."""

from __future__ import annotations

import io
import os
import threading
import time

from beastbt.assembly import assemble
from beastbt.blackboard.types import JoystickState, VelocityCommand
from beastbt.core.clock import WallClock
from beastbt.devices.joystick import (BUTTON_ENABLE, JS_EVENT, JS_EVENT_AXIS, JS_EVENT_BUTTON, JoystickDevice,
                                      JoystickMapping, JoystickWatcher)
from beastbt.mission.model import load_mission
from beastbt.parts.teleop import TeleopPart
from beastbt.robot.part import REAL
from beastbt.robot.profile import load_profile
from beastbt.robot.robot_io import RobotIO
from beastbt.run.session import RunOptions, execute

PROFILE = """robot: bench
geometry: {track_width_m: 0.2}
limits: {max_speed_mps: 0.5, max_turn_rate_dps: 180, max_accel_mps2: 100.0}
base: {type: waveshare_serial}
"""
# One tick a second: anything the base gets between ticks came from the wake path.
MISSION = "mission: slow\nrate: 1 Hz\nteleop: true\nsteps:\n  - wait: 1 h\n"


class Base:
    """A base that keeps what it was sent, with the tick count at that moment."""

    def __init__(self) -> None:
        self.sent: list[tuple[int, str, float]] = []
        self.run = None

    def start(self, now_s: float) -> None:
        pass

    def send_velocity(self, cmd: VelocityCommand, now_s: float) -> None:
        self.sent.append((self.run.ticks if self.run else -1, "velocity", cmd.linear_mps))

    def emergency_stop(self, now_s: float) -> None:
        self.sent.append((self.run.ticks if self.run else -1, "estop", 0.0))

    def poll(self, now_s: float) -> list:
        return []

    def close(self) -> None:
        pass


def test_stick_and_estop_reach_the_base_between_ticks(tmp_path):
    (tmp_path / "robot.yaml").write_text(PROFILE)
    r, w = os.pipe()
    os.set_blocking(r, False)

    def open_pad():
        def read() -> bytes:
            try:
                return os.read(r, 4096)
            except BlockingIOError:
                return b""
        read.fileno = lambda: r  # type: ignore[attr-defined]
        return read

    clock = WallClock()
    mapping = JoystickMapping()
    device = JoystickDevice(open_pad, clock, mapping=mapping)
    base = Base()
    robot = RobotIO(base=base)  # type: ignore[arg-type]
    robot.sensors["joystick"] = lambda now: [device.poll()]
    robot.joystick = device
    robot.capabilities.add("joystick")
    robot.joystick_watcher = JoystickWatcher(device, robot.wakeup.set).start()
    robot.closers.append(robot.joystick_watcher.stop)
    prepared = assemble(load_mission(str(tmp_path / "m.yaml"), text=MISSION), load_profile(tmp_path / "robot.yaml"),
                        RunOptions(robot="bench", record=False, speed="realtime", max_time_s=30.0), REAL, io=robot,
                        clock=clock, parts=[TeleopPart()])
    run = prepared.run
    base.run = run
    marks: dict[str, int] = {}

    def operator() -> None:
        while run.ticks < 2:
            time.sleep(0.01)
        time.sleep(0.2)  # well inside the second between ticks 2 and 3
        marks["press"] = run.ticks
        number, inverted = mapping.axes()["linear"]
        os.write(w, JS_EVENT.pack(0, 1, JS_EVENT_BUTTON, mapping.buttons()["enable"]))
        os.write(w, JS_EVENT.pack(0, mapping.raw_for(0.8, inverted), JS_EVENT_AXIS, number))
        time.sleep(0.2)
        marks["estop"] = run.ticks
        os.write(w, JS_EVENT.pack(0, 1, JS_EVENT_BUTTON, mapping.buttons()["estop"]))
        time.sleep(0.2)
        marks["after"] = run.ticks

    threading.Thread(target=operator, daemon=True).start()
    seen: list = []
    run.recorders.append(seen.append)
    try:
        summary = execute(prepared, io.StringIO())
    finally:
        os.close(r)
        os.close(w)
    assert summary["status"] == "stopped"
    assert marks["press"] == marks["estop"] == marks["after"], "the test needs all of it between two ticks"
    between = [(kind, v) for tick, kind, v in base.sent if tick == marks["press"]]
    moving = [i for i, (kind, v) in enumerate(between) if kind == "velocity" and v > 0.0]
    stops = [i for i, (kind, _) in enumerate(between) if kind == "estop"]
    assert moving, f"the stick waited for the next tick: {between}"
    assert stops and stops[0] > moving[0], f"the e-stop waited for the next tick: {between}"
    assert all(v == 0.0 for kind, v in between[stops[0]:] if kind == "velocity")
    assert robot.joystick_watcher.wakes >= 2
    # What the loop read between the ticks is recorded with the next tick, before that tick's own reading.
    [after] = [rec for rec in seen if rec.tick == marks["press"]]
    states = [r for r in after.readings if isinstance(r, JoystickState)]
    assert len(states) >= 3 and states[0].buttons.get(BUTTON_ENABLE), states
