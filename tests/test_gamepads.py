"""Real gamepads: a layout by the device's name, a chord to clear the e-stop, teleop_twist_joy's names, joystick test."""

from __future__ import annotations

import os
import struct
import subprocess
import sys
import threading
import time

import pytest

from beastbt.actuation.teleop import TeleopTwistJoy
from beastbt.core.clock import SimClock
from beastbt.core.errors import InvalidInput
from beastbt.devices.gamepad_presets import PRESETS, preset_for_name
from beastbt.devices.joystick import JS_EVENT, JS_EVENT_BUTTON, JoystickDevice, JoystickMapping
from beastbt.robot.actuator_profile import joystick_mapping, teleop_config
from beastbt.robot.profile import load_profile
from conftest import REPO

DS4_USB = "Sony Interactive Entertainment Wireless Controller"


@pytest.mark.parametrize("name, preset", [
    ("Microsoft X-Box 360 pad", "xbox"),
    ("Microsoft X-Box One pad", "xbox"),
    ("Microsoft Xbox Series S|X Controller", "xbox"),
    ("Xbox Wireless Controller", "xbox"),  # Bluetooth, xpadneo
    ("Logitech Gamepad F310", "xbox"),
    (DS4_USB, "dualshock4"),
    ("Sony Computer Entertainment Wireless Controller", "dualshock4"),
    ("Wireless Controller", "dualshock4"),  # a DualShock 4 over Bluetooth
    ("Sony Interactive Entertainment DualSense Wireless Controller", "dualsense"),
    ("DualSense Wireless Controller", "dualsense"),
    ("SHANWAN Android Gamepad", "shanwan"),
    ("8BitDo Pro 2", "8bitdo"),
    ("8BitDo SN30 Pro+ Wireless Controller", "8bitdo"),
    ("Some Unknown Joystick", "generic"),
    (None, "generic"),
])
def test_a_preset_is_picked_by_the_kernels_name(name, preset):
    assert preset_for_name(name).name == preset


def test_every_named_preset_resets_with_a_chord_and_an_unknown_pad_not_at_all():
    for preset in PRESETS.values():
        mapping, used = JoystickMapping.from_dict({"preset": preset.name}).for_device("whatever")
        assert used is preset
        if preset.name == "generic":  # any two buttons of an unknown pad could be its triggers
            assert mapping.chord() == () and JoystickMapping().for_device("Unknown Pad")[0].chord() == ()
        else:
            assert len(mapping.chord()) == 2 and mapping.estop_button not in mapping.chord()


def test_numbers_the_profile_writes_win_over_the_preset():
    mapping, preset = JoystickMapping.from_dict({"enable_button": 10}).for_device(DS4_USB)
    assert preset.name == "dualshock4"
    assert (mapping.enable_button, mapping.estop_button, mapping.chord()) == (10, 1, (8, 9))
    forced, preset = JoystickMapping.from_dict({"preset": "shanwan"}).for_device("Microsoft X-Box 360 pad")
    assert preset.name == "shanwan" and forced.enable_button == 6


def press(device_bytes: bytearray, *buttons: int, value: int = 1) -> None:
    for b in buttons:
        device_bytes += JS_EVENT.pack(0, value, JS_EVENT_BUTTON, b)


def test_r2_on_a_dualshock_never_clears_the_estop_and_one_button_of_the_chord_neither():
    mapping, _ = JoystickMapping().for_device(DS4_USB)
    pending = bytearray()

    def read() -> bytes:
        data = bytes(pending)
        pending.clear()
        return data

    pad = JoystickDevice(lambda: read, SimClock(), mapping=mapping)
    pad.poll()
    press(pending, 7)  # R2: the old single reset button (7) of the Xbox numbering
    assert not TeleopTwistJoy.estop_reset_pressed(pad.poll())
    press(pending, 8)  # Share alone
    assert not TeleopTwistJoy.estop_reset_pressed(pad.poll())
    press(pending, 9)  # Share + Options
    assert TeleopTwistJoy.estop_reset_pressed(pad.poll())
    press(pending, 8, value=0)
    assert not TeleopTwistJoy.estop_reset_pressed(pad.poll())


def test_the_layout_follows_the_pad_plugged_in():
    plugged = {"name": "Microsoft X-Box 360 pad"}
    base = JoystickMapping()
    pad = JoystickDevice(lambda: (lambda: b""), SimClock(), mapping=base,
                         identify=lambda: base.for_device(plugged["name"])[0])
    pad.poll()
    assert pad.mapping.chord() == (6, 7)
    pad._lose(0.0, "unplugged")
    plugged["name"] = "DualSense Wireless Controller"
    pad.clock.advance(1.0)
    pad.poll()
    assert pad.mapping.chord() == (8, 9)


def write_profile(tmp_path, joystick: str = "", teleop: str = "") -> object:
    text = (REPO / "robots" / "diy_can.yaml").read_text(encoding="utf-8")
    text = text.replace("joystick:\n  device: /dev/input/js0\n", "joystick:\n  device: /dev/input/js0\n" + joystick)
    text = text.replace("teleop:\n", "teleop:\n" + teleop, 1)
    path = tmp_path / "robot.yaml"
    path.write_text(text, encoding="utf-8")
    return path


def test_teleop_twist_joy_names_port_a_ros_config_over(tmp_path):
    ros = ("  axis_linear: {x: 4}\n  axis_angular: {yaw: 3}\n  scale_linear: {x: -0.4}\n"
           "  scale_angular: {yaw: 1.2}\n  scale_linear_turbo: {x: 0.8}\n  enable_button: 2\n"
           "  enable_turbo_button: 3\n  require_enable_button: true\n")
    text = (REPO / "robots" / "diy_can.yaml").read_text(encoding="utf-8")
    text = text.replace("teleop:\n  scale_linear_mps: 0.3\n  scale_angular_rps: 1.0\n  scale_linear_turbo_mps: 0.6\n",
                        "teleop:\n" + ros)
    path = tmp_path / "ros.yaml"
    path.write_text(text, encoding="utf-8")
    profile = load_profile(path)
    m, teleop = joystick_mapping(profile), teleop_config(profile)
    assert (m.linear_axis, m.angular_axis, m.enable_button, m.turbo_button) == (4, 3, 2, 3)
    assert m.invert_linear is False and m.invert_angular is True  # a negative ROS scale reverses the stick
    assert (teleop.scale_linear_mps, teleop.scale_angular_rps, teleop.scale_linear_turbo_mps) == (0.4, 1.2, 0.8)
    resolved, _ = m.for_device(DS4_USB)
    assert resolved.enable_button == 2 and resolved.chord() == (8, 9)  # the preset fills only the rest


@pytest.mark.parametrize("teleop, joystick, says", [
    ("  require_enable_button: false\n", "", "require_enable_button"),
    ("  enable_button: 2\n", "  enable_button: 3\n", "set twice"),
    ("", "  estop_reset_button: 7\n", "did you mean 'estop_reset_buttons'"),
    ("", "  estop_reset_buttons: [7]\n", "estop_reset_buttons"),
])
def test_unsafe_or_ambiguous_gamepad_settings_are_refused_with_their_position(tmp_path, teleop, joystick, says):
    path = write_profile(tmp_path, joystick, teleop)
    with pytest.raises(InvalidInput) as info:
        profile = load_profile(path)
        joystick_mapping(profile)
    text = info.value.format()
    assert "robot.yaml:" in text and says in text, text


def run_test_command(args: list[str], events: list[tuple[int, int, int]], tmp_path) -> subprocess.CompletedProcess:
    fifo = tmp_path / "js0"
    os.mkfifo(fifo)
    holder = os.open(fifo, os.O_RDWR | os.O_NONBLOCK)

    def feed() -> None:
        time.sleep(1.0)
        for value, kind, number in events:
            os.write(holder, struct.pack("<IhBB", 0, value, kind, number))
            time.sleep(0.05)

    threading.Thread(target=feed, daemon=True).start()
    try:
        return subprocess.run([sys.executable, "-m", "beastbt", "joystick", "test", str(fifo), *args],
                              capture_output=True, text=True, timeout=60, env=dict(os.environ, PYTHONPATH=str(REPO)))
    finally:
        os.close(holder)


def test_joystick_test_shows_the_preset_and_what_each_control_does(tmp_path):
    done = run_test_command(["--name", DS4_USB, "--events", "5", "--duration", "20"],
                            [(1, 1, 4), (-20000, 2, 1), (1, 1, 7), (1, 1, 8), (1, 1, 9)], tmp_path)
    out = done.stdout
    assert done.returncode == 0, done.stderr
    assert "preset dualshock4" in out and "reset: Share + Options (button 8 + 9)" in out
    assert "button 4 down: enable" in out and "axis 1 -0.61: forward +0.59" in out
    assert "button 7 down: (not used)" in out  # R2 does nothing on a DualShock
    assert "would drive +0.12 m/s" in out  # ugv_beast's teleop scale, 0.2 m/s, at 0.59 of the stick
    assert "reset chord held" in out and out.rstrip().endswith("5 events")


def test_joystick_test_without_a_device_says_what_to_do(tmp_path):
    done = subprocess.run([sys.executable, "-m", "beastbt", "joystick", "test", str(tmp_path / "js9")],
                          capture_output=True, text=True, timeout=60, env=dict(os.environ, PYTHONPATH=str(REPO)))
    assert done.returncode == 2 and "cannot open" in done.stderr and "input' group" in done.stderr
