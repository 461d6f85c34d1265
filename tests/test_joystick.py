"""Linux joystick driver against hand-made and scripted event bytes."""

from __future__ import annotations

import json
import os
import struct
from pathlib import Path

import jsonschema
import numpy as np
import pytest

from beastbt.devices.joystick import (
    JS_EVENT_AXIS,
    JS_EVENT_BUTTON,
    JS_EVENT_INIT,
    JoystickDevice,
    JoystickMapping,
    open_linux_joystick,
)
from beastbt.core.clock import SimClock
from beastbt.sim.joystick_script import ScriptedJoystick, parse_time_s

SCHEMAS = Path(__file__).resolve().parents[1] / "schemas" / "parts"


def ev(value: int, kind: int, number: int, t_ms: int = 0) -> bytes:
    return struct.pack("<IhBB", t_ms, value, kind, number)


class Source:
    """A hand-fed byte source with an unplug switch."""

    def __init__(self) -> None:
        self.pending = bytearray()
        self.present = True
        self.opens = 0

    def open(self):
        if not self.present:
            raise FileNotFoundError(2, "No such file or directory: '/dev/input/js0'")
        self.opens += 1

        def read() -> bytes:
            if not self.present:
                raise OSError(19, "No such device")
            out = bytes(self.pending)
            self.pending.clear()
            return out

        return read


class Events:
    def __init__(self) -> None:
        self.items: list[tuple[str, str]] = []

    def __call__(self, kind: str, text: str) -> None:
        self.items.append((kind, text))

    def kinds(self) -> list[str]:
        return [k for k, _ in self.items]


def device(src_open, clock=None, mapping=None):
    e = Events()
    return JoystickDevice(src_open, clock or SimClock(), e, mapping or JoystickMapping()), e


# --- the driver on hand-made bytes -------------------------------------------------------


def test_initial_burst_sets_state_and_axes_are_scaled():
    src = Source()
    js, _ = device(src.open)
    src.pending += ev(1, JS_EVENT_BUTTON | JS_EVENT_INIT, 4) + ev(0, JS_EVENT_BUTTON | JS_EVENT_INIT, 5)
    src.pending += ev(-32767, JS_EVENT_AXIS | JS_EVENT_INIT, 1) + ev(16384, JS_EVENT_AXIS | JS_EVENT_INIT, 0)
    s = js.poll()
    assert s.connected
    assert s.buttons == {"enable": True, "turbo": False, "estop": False, "estop_reset": False}
    assert s.axes["linear"] == pytest.approx(1.0)  # stick pushed up (negative raw) = full forward
    # right half-deflection: 0.5 raw, dead zone 0.05 rescaled -> (0.5 - 0.05) / 0.95, inverted -> turn right
    assert s.axes["angular"] == pytest.approx(-(16384 / 32767 - 0.05) / 0.95, abs=1e-6)
    assert js.events_read == 4 and js.garbage_bytes == 0


def test_dead_zone_reads_zero():
    src = Source()
    js, _ = device(src.open)
    src.pending += ev(int(0.049 * 32767), JS_EVENT_AXIS, 1) + ev(-1000, JS_EVENT_AXIS, 0)
    s = js.poll()
    assert s.axes == {"linear": 0.0, "angular": 0.0}


def test_partial_events_are_buffered_across_polls():
    src = Source()
    js, _ = device(src.open)
    data = ev(1, JS_EVENT_BUTTON, 4, 10) + ev(-32767, JS_EVENT_AXIS, 1, 11)
    src.pending += data[:5]
    assert js.poll().buttons["enable"] is False
    src.pending += data[5:12]
    assert js.poll().buttons["enable"] is True
    assert js.poll().axes["linear"] == 0.0  # second event still incomplete
    src.pending += data[12:]
    assert js.poll().axes["linear"] == pytest.approx(1.0)
    assert js.garbage_bytes == 0


def test_unplug_releases_deadman_and_replug_restores():
    src = Source()
    clock = SimClock()
    js, e = device(src.open, clock)
    src.pending += ev(1, JS_EVENT_BUTTON | JS_EVENT_INIT, 4) + ev(-20000, JS_EVENT_AXIS | JS_EVENT_INIT, 1)
    assert js.poll().buttons["enable"]
    clock.advance(0.05)
    src.present = False
    s = js.poll()
    assert not s.connected and not s.buttons["enable"] and s.axes["linear"] == 0.0
    assert s.stamp_s == pytest.approx(0.05)  # stale: stamped when lost
    assert e.kinds() == ["joystick_lost"]
    clock.advance(1.0)
    assert js.poll().stamp_s == pytest.approx(0.05)
    src.present = True
    clock.advance(0.6)
    src.pending += ev(0, JS_EVENT_BUTTON | JS_EVENT_INIT, 4)
    s = js.poll()
    assert s.connected and not s.buttons["enable"] and s.stamp_s == pytest.approx(1.65)
    assert e.kinds() == ["joystick_lost", "joystick_reopened"]
    assert js.disconnects == 1


def test_reopen_is_rate_limited():
    src = Source()
    src.present = False
    clock = SimClock()
    js, e = device(src.open, clock, JoystickMapping(reopen_interval_s=0.5))
    for t in (0.0, 0.25, 0.5, 0.75):  # attempts at 0 and 0.5 only
        clock.set(t)
        js.poll()
    src.present = True
    clock.set(0.875)
    assert not js.poll().connected  # not due yet
    clock.set(1.0)
    assert js.poll().connected
    assert src.opens == 1
    assert e.kinds() == ["joystick_unavailable"]  # reported once, not every tick


def test_garbage_is_counted_and_dropped_whole():
    src = Source()
    js, e = device(src.open)
    src.pending += b"\xff" * 8  # an impossible event (type 0xff), then good events
    src.pending += ev(1, JS_EVENT_BUTTON, 4) + ev(1, JS_EVENT_BUTTON, 1)
    s = js.poll()
    assert js.garbage_bytes == 8
    assert s.buttons["enable"] and s.buttons["estop"]
    assert "joystick_garbage" in e.kinds()


def test_bad_button_values_are_not_presses():
    src = Source()
    js, _ = device(src.open)
    src.pending += ev(7, JS_EVENT_BUTTON, 4) + ev(0, 0x04, 4)  # impossible value, unknown type
    assert js.poll().buttons["enable"] is False
    assert js.garbage_bytes > 0


def test_fuzz_random_bytes_never_crash():
    rng = np.random.default_rng(7)
    src = Source()
    clock = SimClock()
    js, _ = device(src.open, clock)
    total = 0
    for _ in range(300):
        n = int(rng.integers(0, 40))
        src.pending += rng.integers(0, 256, n, dtype=np.uint8).tobytes()
        total += n
        if rng.random() < 0.03:
            src.present = not src.present
        s = js.poll()
        clock.advance(0.05)
        assert all(-1.0 <= v <= 1.0 for v in s.axes.values())
        assert set(s.buttons) == {"enable", "turbo", "estop", "estop_reset"}
    assert js.garbage_bytes > 0
    # Every byte read is either part of an event, garbage, buffered or dropped with a lost device.
    assert js.garbage_bytes + 8 * js.events_read <= total


# --- the scripted joystick through the real driver ------------------------------------


SCRIPT = """\
- {at: 1 s, linear: 0.5}
- {at: 2 s, press: enable}
- {at: 2.5 s, linear: 0.8, angular: -0.3}
- {at: 3 s, press: turbo}
- {at: 4 s, release: enable}
- {at: 5, press: estop}
- {at: 6 s, unplug: true}
- {at: 7000 ms, replug: true}
"""


def run(script: ScriptedJoystick, times, mapping=None):
    clock = SimClock()
    js, e = device(script.opener(), clock, mapping or script.mapping)
    out = {}
    for t in times:
        clock.set(t)
        script.update(t)
        out[t] = js.poll()
    return out, js, e


def test_scripted_bytes_through_driver():
    script = ScriptedJoystick.from_yaml(SCRIPT)
    st, js, e = run(script, [0.0, 1.0, 2.0, 2.5, 3.0, 4.0, 5.0, 6.0, 6.5, 7.0])
    assert st[0.0].connected and st[0.0].axes == {"linear": 0.0, "angular": 0.0}
    assert st[1.0].axes["linear"] == pytest.approx(0.5, abs=1e-4)
    assert not st[1.0].buttons["enable"]
    assert st[2.0].buttons["enable"]
    assert st[2.5].axes["linear"] == pytest.approx(0.8, abs=1e-4)
    assert st[2.5].axes["angular"] == pytest.approx(-0.3, abs=1e-4)
    assert st[3.0].buttons["turbo"] and st[3.0].buttons["enable"]
    assert not st[4.0].buttons["enable"]
    assert st[5.0].buttons["estop"]
    assert not st[6.0].connected and not st[6.0].buttons["estop"]
    # Replugged: the initial burst brings back the sticks and buttons still held.
    assert st[7.0].connected and st[7.0].buttons["estop"] and st[7.0].buttons["turbo"]
    assert st[7.0].axes["linear"] == pytest.approx(0.8, abs=1e-4)
    assert e.kinds() == ["joystick_lost", "joystick_reopened"]
    assert js.garbage_bytes == 0


def test_scripted_raw_values_follow_mapping_inversion():
    script = ScriptedJoystick.from_yaml("- {at: 0 s, linear: 1.0, angular: 1.0}\n- {at: 0 s, press: enable}")
    handle = script.opener()()
    script.update(0.0)
    data = b""
    while chunk := handle():
        data += chunk
    events = [struct.unpack_from("<IhBB", data, i) for i in range(0, len(data), 8)]
    init = [x for x in events if x[2] & JS_EVENT_INIT]
    live = [x for x in events if not x[2] & JS_EVENT_INIT]
    assert len(init) == 8 + 11  # a whole pad: 8 axes, 11 buttons
    assert (0, -32767, JS_EVENT_AXIS, 1) in live  # forward = stick up = negative raw on axis 1
    assert (0, -32767, JS_EVENT_AXIS, 0) in live  # left turn = stick left = negative raw on axis 0
    assert (0, 1, JS_EVENT_BUTTON, 4) in live


def test_scripted_random_read_boundaries():
    script = ScriptedJoystick.from_yaml(SCRIPT, rng=np.random.default_rng(3))
    times = [i * 0.05 for i in range(0, 115)]  # up to 5.7 s: after the estop press
    st, js, _ = run(script, times)
    # Split reads only delay events by a poll or two; they never corrupt them.
    assert js.garbage_bytes == 0
    assert any(s.buttons["enable"] for s in st.values())
    assert st[times[-1]].buttons["estop"]


def test_script_errors_name_line_column_and_event():
    bad = "- {at: 1 s, press: enable}\n- {at: 2 parsecs, press: enable}\n- {at: 3 s, press: jump}\n- {at: 4 s}\n- {at: 5 s, linear: 2}\n"
    with pytest.raises(ValueError) as exc:
        ScriptedJoystick.from_yaml(bad, source="demo.yaml")
    text = str(exc.value)
    # Each error points at the value at fault (events counted from 1, as people count them), with a hint.
    assert "demo.yaml:2:8: error: joystick script event 2: at:" in text
    assert "demo.yaml:3:20: error: joystick script event 3: press: no button 'jump'" in text
    assert "demo.yaml:4:3: error: joystick script event 4: needs exactly one" in text
    assert "demo.yaml:5:21: error: joystick script event 5: linear must be a number from -1 to 1" in text
    assert "hint: the buttons, by role: enable" in text and "hint: 1 is the stick pushed all the way" in text
    with pytest.raises(ValueError, match="unknown key"):
        ScriptedJoystick([{"at": 1, "presss": "enable"}])
    with pytest.raises(ValueError, match="no button 'turbo'"):
        ScriptedJoystick([{"at": 1, "press": "turbo"}], JoystickMapping(turbo_button=None))


@pytest.mark.parametrize("shared_parser", [True, False])
def test_parse_time(shared_parser, monkeypatch):
    if not shared_parser:
        # None in sys.modules makes the lazy import fail: the built-in fallback parses.
        monkeypatch.setitem(__import__("sys").modules, "beastbt.core.units", None)
        with pytest.raises(ValueError, match="not a duration"):
            parse_time_s("2 parsecs")
    assert parse_time_s(2) == 2.0
    assert parse_time_s("1.5 min") == 90.0
    assert parse_time_s("500 ms") == pytest.approx(0.5)
    assert parse_time_s("2 s") == 2.0
    with pytest.raises(ValueError):
        parse_time_s("-1 s")
    with pytest.raises(ValueError):
        parse_time_s(True)


# --- the real-device opener ---------------------------------------------------------


def test_open_linux_joystick_reads_nonblocking(tmp_path):
    fifo = tmp_path / "js0"
    os.mkfifo(fifo)
    read = open_linux_joystick(str(fifo))
    writer = os.open(fifo, os.O_WRONLY | os.O_NONBLOCK)
    try:
        assert read() == b""  # nothing ready: BlockingIOError becomes b""
        os.write(writer, ev(1, JS_EVENT_BUTTON, 4))
        assert read() == ev(1, JS_EVENT_BUTTON, 4)
    finally:
        os.close(writer)
    with pytest.raises(FileNotFoundError):
        open_linux_joystick(str(tmp_path / "missing"))


# --- config ------------------------------------------------------------------------------


def test_mapping_from_dict_and_schema_agree():
    schema = json.loads((SCHEMAS / "joystick.schema.json").read_text())
    m = JoystickMapping()
    knobs = {k: v for k, v in vars(m).items() if k != "explicit"}  # explicit: what a profile wrote, not a knob
    assert set(schema["properties"]) == set(knobs)
    for key, value in knobs.items():
        assert schema["properties"][key]["default"] == (list(value) if isinstance(value, tuple) else value)
    d = {"enable_button": 6, "turbo_button": None, "dead_zone": 0.1}
    jsonschema.validate(d, schema)
    m = JoystickMapping.from_dict(d)
    assert m.turbo_button is None and "turbo" not in m.buttons()
    with pytest.raises(ValueError, match="did you mean 'dead_zone'"):
        JoystickMapping.from_dict({"deadzone": 0.1})
    with pytest.raises(ValueError, match="own button"):
        JoystickMapping.from_dict({"enable_button": 1})


def test_validate_reads_any_top_level_list_as_a_joystick_script_with_positioned_errors(tmp_path):
    import subprocess
    import sys

    from conftest import REPO
    path = tmp_path / "js.yaml"
    path.write_text("- {at: 1 s, press: enabel}\n- {at: 2 s, linear: 1.5}\n- {ta: 3 s, release: enable}\n")
    done = subprocess.run([sys.executable, "-m", "beastbt", "validate", str(path)], capture_output=True, text=True,
                          timeout=60, env={**__import__("os").environ, "PYTHONPATH": str(REPO)})
    assert done.returncode == 2
    err = done.stderr
    assert "mission:" not in err and "top level must be a mapping" not in err  # not judged as a mission
    assert f"{path}:1:20: error: joystick script event 1: press: no button 'enabel' in the mapping; did you mean " \
           f"'enable'?" in err
    assert f"{path}:2:21: error: joystick script event 2: linear must be a number from -1 to 1" in err
    assert f"{path}:3:4: error: joystick script event 3: unknown key 'ta'; did you mean 'at'?" in err
