"""CanBase over python-can's virtual bus, against the simulated motor controller."""

from __future__ import annotations

import itertools
import json
import math
import os
from pathlib import Path

import can
import jsonschema
import numpy as np
import pytest

from beastbt.actuation.can_base import CanBase, CanBaseConfig
from beastbt.blackboard.types import VelocityCommand, WheelOdometry
from beastbt.sim.can_motor_emulator import SimCanMotorController
from beastbt.sim.truth import RobotTruth

SCHEMAS = Path(__file__).resolve().parents[1] / "schemas" / "parts"
_counter = itertools.count()


def channel_name() -> str:
    """A virtual channel no other test (or parallel worker) shares."""
    return f"beastbt-test-can-{os.getpid()}-{next(_counter)}"


class Events:
    def __init__(self) -> None:
        self.items: list[tuple[str, str]] = []

    def __call__(self, kind: str, text: str) -> None:
        self.items.append((kind, text))

    def kinds(self) -> list[str]:
        return [k for k, _ in self.items]


@pytest.fixture
def rig():
    made: list = []

    def build(cfg: CanBaseConfig | None = None):
        cfg = cfg or CanBaseConfig(interface="virtual")
        ch = channel_name()
        sim = SimCanMotorController(ch, cfg)
        bus = can.Bus(interface="virtual", channel=ch, receive_own_messages=False)
        ev = Events()
        base = CanBase(bus, cfg, events=ev)
        made.append((base, sim))
        return base, sim, ev

    yield build
    for base, sim in made:
        base.close()
        sim.close()


def sniff(channel: str) -> can.BusABC:
    return can.Bus(interface="virtual", channel=channel, receive_own_messages=False)


def drain(bus: can.BusABC) -> list[can.Message]:
    out = []
    while (m := bus.recv(timeout=0)) is not None:
        out.append(m)
    return out


def test_command_bytes_for_a_known_sequence_are_pinned():
    ch = channel_name()
    cfg = CanBaseConfig(channel=ch, interface="virtual")
    listener = sniff(ch)
    base = CanBase(sniff(ch), cfg)
    base.start(0.0)
    base.send_velocity(VelocityCommand(0.2, 0.0), 0.05)  # 0.2 m/s / 0.04 m = 5 rad/s -> 500
    base.send_velocity(VelocityCommand(0.0, 1.0), 0.10)  # wheels -/+0.1 m/s -> -/+250
    base.send_velocity(VelocityCommand(-0.1, 0.5), 0.15)  # -0.15 / -0.05 m/s -> -375 / -125
    base.emergency_stop(0.2)
    frames = drain(listener)
    assert [(m.arbitration_id, m.is_extended_id) for m in frames] == [(0x100, False)] * 5
    assert [bytes(m.data).hex(" ") for m in frames] == [
        "00 00 00 00",
        "f4 01 f4 01",
        "06 ff fa 00",
        "89 fe 83 ff",
        "00 00 00 00",
    ]
    assert base.frames_sent == 5
    base.close()
    listener.shutdown()


def test_other_protocols_big_endian_rpm_extended_ids():
    ch = channel_name()
    cfg = CanBaseConfig(
        channel=ch, interface="virtual", command_id=0x18FF0010, extended_id=True, speed_unit="rpm",
        scale=1.0, byte_order="big", value_bytes=4, invert_right=True,
    )
    listener = sniff(ch)
    base = CanBase(sniff(ch), cfg)
    base.send_velocity(VelocityCommand(0.2, 0.0), 0.0)  # 5 rad/s = 47.75 rpm -> 48
    (m,) = drain(listener)
    assert m.arbitration_id == 0x18FF0010 and m.is_extended_id
    assert bytes(m.data).hex(" ") == "00 00 00 30 ff ff ff d0"
    base.close()
    listener.shutdown()


def test_saturation_clips_instead_of_wrapping():
    ch = channel_name()
    cfg = CanBaseConfig(channel=ch, interface="virtual", value_bytes=1, scale=10.0, max_wheel_speed_mps=2.0)
    listener = sniff(ch)
    ev = Events()
    base = CanBase(sniff(ch), cfg, events=ev)
    base.send_velocity(VelocityCommand(1.0, 0.0), 0.0)  # 25 rad/s * 10 = 250 > 127
    (m,) = drain(listener)
    assert bytes(m.data) == bytes([127, 127])
    assert base.saturated_commands == 1 and "can_command_saturated" in ev.kinds()
    base.close()
    listener.shutdown()


def test_emulator_decodes_commands_and_times_out(rig):
    base, sim, _ = rig()
    base.send_velocity(VelocityCommand(0.2, 0.4), 1.0)
    assert sim.wheel_targets_mps(1.0) == pytest.approx((0.16, 0.24), abs=1e-3)
    assert sim.wheel_targets_mps(1.4) == pytest.approx((0.16, 0.24), abs=1e-3)
    assert sim.wheel_targets_mps(1.6) == (0.0, 0.0)  # controller watchdog: no command for 0.6 s


def test_wheel_speed_feedback_integrates_into_distance(rig):
    base, sim, ev = rig()
    t = 0.0
    odo: list[WheelOdometry] = []
    for i in range(41):  # 2 s at 20 Hz; the wheels run at 0.1 / 0.3 m/s
        t = i * 0.05
        sim.update(RobotTruth(t_s=t, left_mps=0.1, right_mps=0.3))
        odo += base.poll(t)
    assert len(odo) == 41
    assert odo[0].left_m == 0.0  # the first feedback only starts the integration
    assert odo[-1].left_mps == pytest.approx(0.1, abs=1e-3)
    assert odo[-1].right_mps == pytest.approx(0.3, abs=1e-3)
    assert odo[-1].left_m == pytest.approx(0.2, abs=2e-3)
    assert odo[-1].right_m == pytest.approx(0.6, abs=2e-3)
    assert odo[-1].stamp_s == pytest.approx(2.0)
    assert base.unknown_frames == 0 and base.bad_frames == 0


def test_feedback_gap_is_reported_and_not_integrated(rig):
    base, sim, ev = rig()
    sim.update(RobotTruth(t_s=0.0, left_mps=0.5, right_mps=0.5))
    base.poll(0.0)
    sim.update(RobotTruth(t_s=0.05, left_mps=0.5, right_mps=0.5))
    (o1,) = base.poll(0.05)
    assert o1.left_m == pytest.approx(0.025)
    assert base.poll(0.3) == [] and base.poll(1.0) == []
    assert ev.kinds().count("can_feedback_lost") == 1
    sim.update(RobotTruth(t_s=1.05, left_mps=0.5, right_mps=0.5))
    (o2,) = base.poll(1.05)
    assert o2.left_m == pytest.approx(0.025)  # nothing made up across the 1 s gap
    assert "can_feedback_restored" in ev.kinds()


def test_encoder_ticks_feedback_with_counter_wrap(rig):
    cfg = CanBaseConfig(interface="virtual", feedback_kind="encoder_ticks", feedback_value_bytes=2, ticks_per_rev=1000.0)
    base, sim, _ = rig(cfg)
    m_per_tick = 2 * math.pi * 0.04 / 1000
    # 16-bit counters wrap after 65536 ticks (about 16.5 m); drive through the wrap forwards on the left
    # and backwards on the right.
    start = 16.0
    odo = []
    for i in range(30):
        t = i * 0.1
        d = start + 0.05 * i
        sim.update(RobotTruth(t_s=t, left_m=d, right_m=-d, left_mps=0.5, right_mps=-0.5))
        odo += base.poll(t)
    travelled = 0.05 * 29
    assert odo[-1].left_m == pytest.approx(travelled, abs=2 * m_per_tick)
    assert odo[-1].right_m == pytest.approx(-travelled, abs=2 * m_per_tick)
    assert odo[-1].left_mps == pytest.approx(0.5, abs=0.02)
    assert odo[-1].right_mps == pytest.approx(-0.5, abs=0.02)


def test_error_frames_and_unknown_ids_are_counted(rig):
    base, sim, ev = rig()
    intruder = sniff(sim.channel)
    sim.send_error_frame()
    sim.send_error_frame()
    intruder.send(can.Message(arbitration_id=0x321, is_extended_id=False, data=b"\x01\x02"))
    intruder.send(can.Message(arbitration_id=0x101, is_extended_id=False, data=b"\x01"))  # our id, too short
    intruder.send(can.Message(arbitration_id=0x101, is_extended_id=False, is_remote_frame=True, dlc=4))
    intruder.send(can.Message(arbitration_id=0x101, is_extended_id=True, data=b"\x00" * 4))  # 29-bit: not ours
    sim.update(RobotTruth(t_s=0.0, left_mps=0.2, right_mps=0.2))
    odo = base.poll(0.0)
    assert len(odo) == 1 and odo[0].left_mps == pytest.approx(0.2, abs=1e-3)
    assert base.error_frames == 2 and base.unknown_frames == 3 and base.bad_frames == 1
    assert {"can_error_frame", "can_unknown_frame", "can_bad_feedback"} <= set(ev.kinds())
    intruder.shutdown()


class FlakyBus(can.BusABC):
    """A virtual bus whose sends fail while ``failing`` (bus-off / full transmit queue)."""

    def __init__(self, channel: str) -> None:
        self.inner = can.Bus(interface="virtual", channel=channel, receive_own_messages=False)
        self.failing = False
        super().__init__(channel=channel)

    def send(self, msg, timeout=None):
        if self.failing:
            raise can.CanOperationError("Failed to transmit: No buffer space available (bus-off)", 105)
        self.inner.send(msg, timeout)

    def _recv_internal(self, timeout):
        if self.failing:
            raise can.CanOperationError("Network is down")
        return self.inner.recv(timeout), False

    def shutdown(self):
        self.inner.shutdown()
        super().shutdown()


def test_bus_off_is_reported_and_survived():
    ch = channel_name()
    cfg = CanBaseConfig(channel=ch, interface="virtual")
    sim = SimCanMotorController(ch, cfg)
    bus = FlakyBus(ch)
    ev = Events()
    base = CanBase(bus, cfg, events=ev)
    base.send_velocity(VelocityCommand(0.2, 0.0), 0.0)
    bus.failing = True
    for i in range(5):
        base.send_velocity(VelocityCommand(0.2, 0.0), 0.05 * (i + 1))
        assert base.poll(0.05 * (i + 1)) == []
    base.emergency_stop(0.3)
    assert base.send_errors == 6 and base.recv_errors == 5
    assert ev.kinds().count("can_send_failed") == 1  # reported once, not once per tick
    bus.failing = False
    base.send_velocity(VelocityCommand(0.1, 0.0), 0.4)
    assert "can_send_recovered" in ev.kinds()
    assert sim.wheel_targets_mps(0.4) == pytest.approx((0.1, 0.1), abs=1e-3)
    base.close()
    sim.close()


def test_fuzz_random_frames_never_crash(rig):
    base, sim, ev = rig()
    rng = np.random.default_rng(1234)
    intruder = sniff(sim.channel)
    sent = 0
    for step in range(40):
        for _ in range(int(rng.integers(0, 12))):
            kind = rng.integers(0, 4)
            if kind == 0:
                msg = can.Message(is_error_frame=True, arbitration_id=0, data=b"")
            else:
                ext = bool(rng.integers(0, 2))
                arb = int(rng.integers(0, 0x1FFFFFFF if ext else 0x800))
                if kind == 1:
                    arb = 0x101  # our feedback id with random payloads
                    ext = False
                n = int(rng.integers(0, 9))
                msg = can.Message(arbitration_id=arb, is_extended_id=ext, data=rng.integers(0, 256, n, dtype=np.uint8).tobytes())
            intruder.send(msg)
            sent += 1
        out = base.poll(step * 0.05)
        for o in out:
            assert math.isfinite(o.left_m) and math.isfinite(o.right_m)
    assert base.frames_received == sent
    assert base.error_frames + base.unknown_frames + base.bad_frames + base.feedback_frames == sent
    assert base.unknown_frames > 0 and base.bad_frames > 0 and base.feedback_frames > 0
    intruder.shutdown()


def test_closed_adapter_stops_and_ignores_further_calls(rig):
    base, sim, _ = rig()
    base.send_velocity(VelocityCommand(0.3, 0.0), 0.0)
    base.close()
    assert sim.wheel_targets_mps(0.01) == (0.0, 0.0)  # the final frame was a stop
    base.send_velocity(VelocityCommand(0.3, 0.0), 0.02)  # must not raise on a shut bus
    assert base.poll(0.03) == []


def test_config_from_dict_and_schema_agree():
    schema = json.loads((SCHEMAS / "can_base.schema.json").read_text())
    cfg = CanBaseConfig()
    assert set(schema["properties"]) == set(vars(cfg))
    for key, value in vars(cfg).items():
        assert schema["properties"][key]["default"] == value
    d = {"channel": "can1", "feedback_kind": "encoder_ticks", "feedback_value_bytes": 4, "ticks_per_rev": 2048, "byte_order": "big"}
    jsonschema.validate(d, schema)
    c = CanBaseConfig.from_dict(d)
    assert c.ticks_per_rev == 2048.0 and c.byte_order == "big"
    with pytest.raises(ValueError, match="did you mean 'bitrate'"):
        CanBaseConfig.from_dict({"bitrat": 250000})
    with pytest.raises(ValueError, match="byte_order"):
        CanBaseConfig.from_dict({"byte_order": "middle"})
    with pytest.raises(ValueError, match="11-bit"):
        CanBaseConfig.from_dict({"command_id": 0x800})


def test_mirrored_motor_round_trip(rig):
    cfg = CanBaseConfig(interface="virtual", invert_left=True)
    base, sim, _ = rig(cfg)
    listener = sniff(sim.channel)
    base.send_velocity(VelocityCommand(0.2, 0.0), 0.0)
    (m,) = drain(listener)
    assert bytes(m.data).hex(" ") == "0c fe f4 01"  # left sent as -500: the motor is mounted mirrored
    assert sim.wheel_targets_mps(0.0) == pytest.approx((0.2, 0.2), abs=1e-3)
    sim.update(RobotTruth(t_s=0.0, left_mps=0.2, right_mps=0.2))
    (o,) = base.poll(0.0)
    assert (o.left_mps, o.right_mps) == pytest.approx((0.2, 0.2), abs=1e-3)
    listener.shutdown()
