"""Fuzz the Waveshare feedback parser: random bytes, broken and interleaved lines never crash it, garbage is counted."""

from __future__ import annotations

import json

import numpy as np
import pytest

from beastbt.blackboard.types import BatteryState, ImuSample, VelocityCommand, WheelOdometry
from beastbt.devices.waveshare_base import MAX_LINE_BYTES, WaveshareBase
from beastbt.sim.serial_port import SimSerialPort

GOOD = {"T": 1001, "L": 0.1, "R": 0.12, "ax": 10, "ay": -3, "az": 8192, "gx": 1, "gy": -2, "gz": 164,
        "mx": 100, "my": -50, "mz": 300, "odl": 12.5, "odr": 13.0, "v": 1180}


def line(obj: dict) -> bytes:
    return json.dumps(obj, separators=(",", ":")).encode() + b"\n"


def rig():
    port = SimSerialPort()
    events: list = []
    return port, WaveshareBase(port, events=lambda k, t: events.append((k, t))), events


def test_random_bytes_never_crash_and_are_counted():
    rng = np.random.default_rng(7)
    port, base, _ = rig()
    for i in range(300):
        n = int(rng.integers(0, 400))
        port.feed(rng.integers(0, 256, n, dtype=np.uint8).tobytes())
        out = base.poll(0.05 * i)
        assert all(isinstance(r, (WheelOdometry, ImuSample, BatteryState)) for r in out)
    s = base.stats
    assert s.garbage > 50 and s.feedback == 0
    assert len(base._buf) <= MAX_LINE_BYTES + 400


def test_good_lines_survive_among_broken_and_interleaved_ones():
    rng = np.random.default_rng(11)
    port, base, _ = rig()
    stream = bytearray()
    good = 0
    for i in range(400):
        kind = rng.integers(0, 6)
        if kind == 0:
            stream += line(dict(GOOD, odl=float(i)))
            good += 1
        elif kind == 1:  # a line cut in the middle, then the next line starts
            text = line(GOOD)
            stream += text[: int(rng.integers(1, len(text) - 1))] + b"\n"
        elif kind == 2:  # other JSON the base sends (echoes, answers)
            stream += line({"T": 131, "cmd": 1})
        elif kind == 3:  # junk glued to the front of a good object: resynchronise on '{"T"'
            stream += b"\x00\xff#garbage" + line(dict(GOOD, odl=float(i)))
            good += 1
        elif kind == 4:  # wrong types and non-finite numbers
            stream += line(dict(GOOD, odl="x", gx=None)) + b'{"T":1001,"v":NaN}\n'
        else:  # random bytes without a newline
            stream += rng.integers(32, 127, int(rng.integers(1, 60)), dtype=np.uint8).tobytes()
    readings: list = []
    # Arbitrary read boundaries: lines arrive in pieces.
    pos = 0
    t = 0.0
    while pos < len(stream):
        n = int(rng.integers(1, 200))
        port.feed(bytes(stream[pos:pos + n]))
        pos += n
        t += 0.01
        readings.extend(base.poll(t))
    port.feed(b"\n")
    readings.extend(base.poll(t + 0.01))
    odo = [r for r in readings if isinstance(r, WheelOdometry)]
    # Every intact feedback line whose start was not swallowed by preceding junk is read; junk is counted.
    assert len(odo) >= good * 0.8
    assert base.stats.garbage > 0 and base.stats.other_json > 0
    assert all(np.isfinite([r.left_m, r.right_m]).all() for r in odo)


def test_one_good_line_is_decoded_exactly():
    port, base, _ = rig()
    port.feed(b'xx{"T":1001,"L"' + b"\n" + line(GOOD))
    out = base.poll(1.0)
    odo = next(r for r in out if isinstance(r, WheelOdometry))
    imu = next(r for r in out if isinstance(r, ImuSample))
    bat = next(r for r in out if isinstance(r, BatteryState))
    assert (odo.left_m, odo.right_m) == (0.125, 0.13)
    assert imu.accel_mps2[2] == pytest.approx(9.80665)
    assert imu.gyro_rps[2] == pytest.approx(np.radians(10.0))
    assert bat.voltage_v == pytest.approx(11.8)
    assert base.stats.garbage == 1 and base.stats.feedback == 1


def test_an_endless_line_is_dropped_not_hoarded():
    port, base, _ = rig()
    for _ in range(50):
        port.feed(b"A" * 100)
        base.poll(0.0)
    assert len(base._buf) <= MAX_LINE_BYTES + 100
    assert base.stats.garbage >= 4
    port.feed(b"\n" + line(GOOD))
    assert any(isinstance(r, WheelOdometry) for r in base.poll(0.1))


def test_an_unplugged_port_is_reported_and_survived():
    port, base, events = rig()
    port.unplug()
    assert base.poll(0.0) == []
    base.send_velocity(VelocityCommand(0.1, 0.0, 0.0), 0.0)  # a write to a dead port is reported, not raised
    port.replug()
    port.feed(line(GOOD))
    assert any(isinstance(r, WheelOdometry) for r in base.poll(0.1))
    assert any(k == "base_port_error" for k, _ in events)
