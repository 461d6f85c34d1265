"""``beastbt joystick test [DEVICE]``: the gamepad live: its name, the preset picked, and what each control does."""

from __future__ import annotations

import argparse
import sys
import time

EXIT_OK, EXIT_NO_DEVICE = 0, 2


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Options of ``beastbt joystick``."""
    sub = p.add_subparsers(dest="action", metavar="ACTION", required=True)
    test = sub.add_parser("test", help="show the gamepad's axes and buttons live, and what each one does")
    test.add_argument("device", nargs="?", help="joystick device (default: the profile's, /dev/input/js0)")
    test.add_argument("--robot", default="ugv_beast", metavar="PROFILE",
                      help="robot profile whose joystick: and teleop: sections apply (default: ugv_beast)")
    test.add_argument("--name", help="the device's name, when it cannot tell it (JSIOCGNAME), e.g. a FIFO in a test")
    test.add_argument("--events", type=int, help="stop after this many events (default: until Ctrl-C)")
    test.add_argument("--duration", type=float, help="stop after this many seconds (default: until Ctrl-C)")


def command(args: argparse.Namespace) -> int:
    """Open the pad, say which preset applies and what each control does, then print its input live."""
    import os
    import select
    from dataclasses import replace

    from beastbt.actuation.teleop import TeleopTwistJoy
    from beastbt.core.clock import WallClock
    from beastbt.core.errors import InvalidInput
    from beastbt.devices.gamepad_presets import describe_controls
    from beastbt.devices.joystick import (AXIS_FULL_SCALE, JS_EVENT, JS_EVENT_AXIS, JS_EVENT_INIT, JS_EVENT_SIZE,
                                          JoystickDevice, device_name, open_linux_joystick)
    from beastbt.robot.actuator_profile import joystick_mapping, teleop_config
    from beastbt.robot.profile import load_profile
    try:
        profile = load_profile(args.robot)
        mapping, teleop = joystick_mapping(profile), teleop_config(profile)
    except InvalidInput as exc:
        print(exc.format(), file=sys.stderr)
        return EXIT_NO_DEVICE
    path = args.device or mapping.device
    try:
        source = open_linux_joystick(path)
    except OSError as exc:
        print(f"beastbt joystick: error: cannot open {path} ({exc.strerror or exc}); plug in or pair the gamepad "
              f"(ls /dev/input/js*) and check that your user is in the 'input' group", file=sys.stderr)
        return EXIT_NO_DEVICE
    name = args.name or device_name(path)
    mapping, preset = replace(mapping, device=path).for_device(name)
    print(f"joystick {path}: '{name or 'unnamed device'}'")
    print(f"preset {preset.name} ({preset.description})" + ("" if mapping.preset == "auto" else " (set in the profile)"))
    print(f"controls: {describe_controls(mapping, preset)}")
    print("live input (Ctrl-C to stop):", flush=True)

    seen = bytearray()

    def tee() -> bytes:
        data = source()
        seen.extend(data)
        return data

    pad = JoystickDevice(lambda: tee, WallClock(), mapping=mapping)
    drive = TeleopTwistJoy(teleop)
    axes = {num: role for role, (num, _) in mapping.axes().items()}
    roles: dict[int, list[str]] = {}
    for role, numbers in mapping.roles().items():
        for number in numbers:
            roles.setdefault(number, []).append(role + (" (chord)" if len(numbers) > 1 else ""))
    fd = source.fileno()  # type: ignore[attr-defined]
    count = 0
    end = time.monotonic() + args.duration if args.duration is not None else None
    last_command = None
    try:
        while (args.events is None or count < args.events) and (end is None or time.monotonic() < end):
            timeout = 0.2 if end is None else max(0.0, min(0.2, end - time.monotonic()))
            ready, _, _ = select.select([fd], [], [], timeout)
            if not ready:
                continue
            state = pad.poll()
            while len(seen) >= JS_EVENT_SIZE:
                _, value, kind, number = JS_EVENT.unpack_from(seen, 0)
                del seen[:JS_EVENT_SIZE]
                if kind & JS_EVENT_INIT:
                    continue  # the kernel's initial state burst
                count += 1
                if kind & ~JS_EVENT_INIT == JS_EVENT_AXIS:
                    what = f"axis {number} {value / AXIS_FULL_SCALE:+.2f}"
                    role = {"linear": "forward", "angular": "turn"}.get(axes.get(number, ""), "")
                    print(f"{what}" + (f": {role} {state.axes[axes[number]]:+.2f}" if role else ": (not used)"))
                else:
                    what = f"button {number} {'down' if value else 'up'}"
                    print(f"{what}: {', '.join(roles[number]) if number in roles else '(not used)'}")
            cmd = drive.update(state, 0.0)
            text = (f"-> would drive {cmd.linear_mps:+.2f} m/s, {cmd.angular_rps:+.2f} rad/s" if cmd is not None
                    else "-> no motion (hold enable to drive)")
            if state.buttons.get("estop"):
                text = "-> E-STOP pressed: the robot would stop and stay stopped until the reset chord"
            elif state.buttons.get("estop_reset"):
                text = "-> reset chord held: a latched e-stop would clear"
            if text != last_command:
                print(f"   {text}", flush=True)
                last_command = text
    except KeyboardInterrupt:
        pass
    finally:
        os.close(fd)
    print(f"{count} events")
    return EXIT_OK
