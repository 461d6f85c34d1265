"""Button and axis layouts of common gamepads on Linux's joystick API, picked by the device's name.

The kernel's joydev numbers a pad's controls in the order its driver reports
them, so the same physical button has different numbers on different pads:
button 7 is Start on an Xbox pad (``xpad``) but R2 on a DualShock 4
(``hid-sony``/``hid-playstation``). A profile with ``joystick: {preset:
auto}`` (the default) gets the layout of the pad it finds, by the name the
kernel gives it (``JSIOCGNAME``, what ``jstest`` prints); numbers written in
the profile win over the preset's. ``beastbt joystick test`` shows which
preset was picked and what each control does.

Numbers are those of the drivers named with each preset; for the generic HID
layouts (SHANWAN and other Android pads, 8BitDo in D-input mode) they are the
usual ones and worth a check with ``beastbt joystick test``. Every preset
clears the e-stop with a chord of two buttons, never with one.
"""

from __future__ import annotations

from dataclasses import dataclass
from types import MappingProxyType
from typing import Any, Mapping, Optional


@dataclass(frozen=True)
class GamepadPreset:
    """One pad's layout: which names it answers to and the numbers of the controls beastbt uses.

    ``matches``: lower-case substrings of the kernel's device name, tried in
    the order of :data:`PRESETS` (the first preset with a match wins).
    Axes: ``linear_axis`` (left stick vertical), ``angular_axis`` (left stick
    horizontal); the kernel reports up and left as negative, hence the
    inverts. Buttons: ``enable_button`` (deadman), ``turbo_button``,
    ``estop_button``, ``estop_reset_buttons`` (a chord, all held together).
    ``labels``: what the pad prints on those buttons, for people.
    """

    name: str
    description: str
    matches: tuple[str, ...]
    linear_axis: int
    angular_axis: int
    enable_button: int
    turbo_button: int
    estop_button: int
    estop_reset_buttons: Optional[tuple[int, int]]
    labels: Mapping[str, str]
    invert_linear: bool = True
    invert_angular: bool = True


XBOX = GamepadPreset(
    "xbox", "Xbox 360 / One / Series pads (xpad; over Bluetooth with xpadneo), 8BitDo in X-input mode, "
    "Logitech F310/F710 in X mode",
    ("x-box", "xbox", "x-input", "xinput", "microsoft", "logitech gamepad f"),
    linear_axis=1, angular_axis=0, enable_button=4, turbo_button=5, estop_button=1, estop_reset_buttons=(6, 7),
    labels=MappingProxyType({"enable": "LB", "turbo": "RB", "estop": "B", "estop_reset": "Back + Start"}))
"""xpad: buttons 0 A, 1 B, 2 X, 3 Y, 4 LB, 5 RB, 6 Back/View, 7 Start/Menu, 8 Guide, 9/10 stick clicks;
axes 0/1 left stick, 2 LT, 3/4 right stick, 5 RT, 6/7 d-pad."""

DUALSENSE = GamepadPreset(
    "dualsense", "Sony DualSense (PS5), hid-playstation",
    ("dualsense",),
    linear_axis=1, angular_axis=0, enable_button=4, turbo_button=5, estop_button=1, estop_reset_buttons=(8, 9),
    labels=MappingProxyType({"enable": "L1", "turbo": "R1", "estop": "circle", "estop_reset": "Create + Options"}))
"""hid-playstation: buttons 0 cross, 1 circle, 2 triangle, 3 square, 4 L1, 5 R1, 6 L2, 7 R2, 8 Create,
9 Options, 10 PS, 11/12 stick clicks; axes 0/1 left stick, 2 L2, 3/4 right stick, 5 R2, 6/7 d-pad."""

DUALSHOCK4 = GamepadPreset(
    "dualshock4", "Sony DualShock 4 (PS4), hid-sony (its USB name, or 'Wireless Controller' over Bluetooth)",
    ("sony", "playstation", "wireless controller"),
    linear_axis=1, angular_axis=0, enable_button=4, turbo_button=5, estop_button=1, estop_reset_buttons=(8, 9),
    labels=MappingProxyType({"enable": "L1", "turbo": "R1", "estop": "circle", "estop_reset": "Share + Options"}))
"""hid-sony (kernel 4.10 and later): the same numbering as the DualSense's, Share at 8."""

EIGHTBITDO = GamepadPreset(
    "8bitdo", "8BitDo pads in D-input / Switch mode (generic HID)",
    ("8bitdo",),
    linear_axis=1, angular_axis=0, enable_button=6, turbo_button=7, estop_button=0, estop_reset_buttons=(10, 11),
    labels=MappingProxyType({"enable": "L1", "turbo": "R1", "estop": "B", "estop_reset": "Select + Start"}))
"""Generic HID gamepad order: 0 B, 1 A, 3 X/Y ... 6 L1, 7 R1, 8 L2, 9 R2, 10 Select, 11 Start, 12 Home."""

SHANWAN = GamepadPreset(
    "shanwan", "SHANWAN and other Android / generic Bluetooth pads (generic HID)",
    ("shanwan", "android", "pc/ps3", "twin usb"),
    linear_axis=1, angular_axis=0, enable_button=6, turbo_button=7, estop_button=1, estop_reset_buttons=(10, 11),
    labels=MappingProxyType({"enable": "L1", "turbo": "R1", "estop": "B", "estop_reset": "Select + Start"}))
"""Android gamepad HID order: 0 A, 1 B, 3 X, 4 Y, 6 L1, 7 R1, 8 L2, 9 R2, 10 Select, 11 Start, 12 Home."""

GENERIC = GamepadPreset(
    "generic", "any other pad: the Xbox-style numbering most drivers follow, and no reset chord",
    (),
    linear_axis=1, angular_axis=0, enable_button=4, turbo_button=5, estop_button=1, estop_reset_buttons=None,
    labels=MappingProxyType({"enable": "button 4", "turbo": "button 5", "estop": "button 1"}))
"""The fallback when no name matches; the same numbers as the schema's defaults. No reset chord: on a pad
whose layout is unknown, any two buttons could be its triggers (the e-stop ends the mission anyway; set
``estop_reset_buttons`` or ``preset`` to clear it from the pad)."""

SIMULATED_PAD_NAME = "Microsoft X-Box 360 pad"
"""The name a scripted joystick on the simulator gives: it gets the xbox layout, with its reset chord."""

PRESETS: Mapping[str, GamepadPreset] = MappingProxyType(
    {p.name: p for p in (XBOX, DUALSENSE, EIGHTBITDO, DUALSHOCK4, SHANWAN, GENERIC)})
"""Every preset by name, in the order names are matched (the DualSense before the other Sony pads, 8BitDo
before the DualShock 4, whose Bluetooth name "Wireless Controller" other pads share)."""


def preset_for_name(device_name: Optional[str]) -> GamepadPreset:
    """The preset whose ``matches`` the kernel's device name contains (case-insensitive), else :data:`GENERIC`."""
    if device_name:
        lowered = device_name.lower()
        for preset in PRESETS.values():
            if any(m in lowered for m in preset.matches):
                return preset
    return GENERIC


def describe_controls(mapping: Any, preset: GamepadPreset) -> str:
    """What each control does, in words: ``enable L1 (button 4), turbo R1 (5), e-stop circle (1), reset ...``.

    ``mapping`` is a :class:`~beastbt.devices.joystick.JoystickMapping`; a
    label is shown only where the number is the preset's own.
    """
    def named(role: str, numbers: tuple[int, ...], presets: tuple[int, ...]) -> str:
        nums = " + ".join(str(n) for n in numbers)
        label = preset.labels.get(role) if numbers == presets else None
        return f"{label} (button {nums})" if label else f"button {nums}"

    parts = [f"drive: axes {mapping.linear_axis} (forward) and {mapping.angular_axis} (turn)"]
    for role, word, preset_numbers in (("enable", "enable", (preset.enable_button,)),
                                       ("turbo", "turbo", (preset.turbo_button,)),
                                       ("estop", "e-stop", (preset.estop_button,)),
                                       ("estop_reset", "reset", tuple(preset.estop_reset_buttons or ()))):
        numbers = mapping.roles().get(role)
        parts.append(f"{word}: {named(role, numbers, preset_numbers)}" if numbers else f"{word}: none")
    return ", ".join(parts)


__all__ = ["GamepadPreset", "PRESETS", "preset_for_name", "describe_controls", "GENERIC", "XBOX", "DUALSHOCK4", "DUALSENSE", "SHANWAN",
           "EIGHTBITDO", "SIMULATED_PAD_NAME"]
