"""A differential base whose motor controller listens on a CAN bus (python-can).

:class:`CanBase` turns body velocity commands into left/right wheel speeds and
sends them as one frame per command; it reads the controller's feedback
frames (wheel speeds or encoder ticks) back into
:class:`~beastbt.blackboard.types.WheelOdometry`. Ids, scaling, field size,
byte order and feedback layout come from :class:`CanBaseConfig` (robot
profile ``can_base:``); the defaults are the example protocol of HARDWARE.md:
id 0x100, 4 bytes, int16 little-endian left then right wheel speed in
hundredths of rad/s. On the robot the bus is SocketCAN (``can0``); in the
simulator it is python-can's ``virtual`` interface with
:class:`beastbt.sim.can_motor_emulator.SimCanMotorController` on the other end.

Bus trouble never raises out of this adapter: error frames, failed sends
(bus-off, full transmit queue), receive errors, frames with unknown ids and
malformed feedback are counted and reported through the ``EventSink``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Literal, Optional

import can

from beastbt.core.schema_defaults import schema_defaults
from beastbt.blackboard.types import VelocityCommand, WheelOdometry
from beastbt.core.config import dataclass_from_dict
from beastbt.devices.interfaces import EventSink, ignore_events

SpeedUnit = Literal["rad/s", "rpm", "m/s"]
FeedbackKind = Literal["wheel_speeds", "encoder_ticks", "none"]
ByteOrder = Literal["little", "big"]

MAX_FRAMES_PER_POLL = 1000  # bounds one poll even when a babbling node floods the bus


@dataclass
@schema_defaults("parts/can_base.schema.json")
class CanBaseConfig:
    """How the motor controller on the CAN bus is spoken to (robot profile ``can_base:``)."""

    # SocketCAN interface name (bring it up with `ip link set can0 up type can bitrate 500000`).
    channel: str
    # python-can interface: "socketcan" on the Pi with the Waveshare CAN HAT, "virtual" in tests.
    interface: str
    # Bus bitrate in bit/s; must match every node on the bus.
    bitrate: int
    # Arbitration id of the wheel speed command frame.
    command_id: int
    # True when the controller uses 29-bit (extended) ids for commands and feedback.
    extended_id: bool
    # Unit of the wheel speeds in command (and wheel-speed feedback) frames.
    speed_unit: SpeedUnit
    # Integer counts per speed_unit on the wire: 100 means hundredths of rad/s.
    scale: float
    # Byte order of each value in command and feedback frames.
    byte_order: ByteOrder
    # True when values are two's complement (negative = backwards).
    signed: bool
    # Bytes per value in the command frame (left then right): 1, 2 or 4.
    value_bytes: int
    # Wheel (or drive sprocket) radius in metres: converts rad/s to m/s.
    wheel_radius_m: float
    # Distance between the left and right wheel contact lines, metres.
    track_width_m: float
    # Wheel surface speed limit in m/s: faster requests are scaled down keeping the turn radius.
    max_wheel_speed_mps: float
    # True when the left motor turns backwards for a positive value (mounted mirrored).
    invert_left: bool
    # True when the right motor turns backwards for a positive value.
    invert_right: bool
    # What the controller reports: "wheel_speeds" (same unit and scale as commands),
    # "encoder_ticks" (cumulative counts) or "none".
    feedback_kind: FeedbackKind
    # Arbitration id of the feedback frame (ignored when feedback_kind is "none").
    feedback_id: int
    # Bytes per value in the feedback frame (left then right): 2 for speeds, often 4 for ticks.
    feedback_value_bytes: int
    # encoder_ticks only: counts per wheel revolution (after any gearbox).
    ticks_per_rev: float
    # Feedback older than this (s) is reported lost; wheel speeds are not integrated across a gap longer than this.
    feedback_timeout_s: float

    def __post_init__(self) -> None:
        if not self.channel:
            raise ValueError("channel must not be empty")
        if not self.bitrate > 0:
            raise ValueError(f"bitrate must be positive, got {self.bitrate}")
        id_max = 0x1FFFFFFF if self.extended_id else 0x7FF
        for key in ("command_id", "feedback_id"):
            value = getattr(self, key)
            if not 0 <= value <= id_max:
                raise ValueError(f"{key} 0x{value:x} does not fit a {'29' if self.extended_id else '11'}-bit id")
        if self.feedback_kind != "none" and self.feedback_id == self.command_id:
            raise ValueError("feedback_id must differ from command_id")
        if self.speed_unit not in ("rad/s", "rpm", "m/s"):
            raise ValueError(f"speed_unit must be 'rad/s', 'rpm' or 'm/s', got {self.speed_unit!r}")
        if self.byte_order not in ("little", "big"):
            raise ValueError(f"byte_order must be 'little' or 'big', got {self.byte_order!r}")
        if self.feedback_kind not in ("wheel_speeds", "encoder_ticks", "none"):
            raise ValueError(f"feedback_kind must be 'wheel_speeds', 'encoder_ticks' or 'none', got {self.feedback_kind!r}")
        for key in ("value_bytes", "feedback_value_bytes"):
            if getattr(self, key) not in (1, 2, 4):
                raise ValueError(f"{key} must be 1, 2 or 4, got {getattr(self, key)}")
        for key in ("scale", "wheel_radius_m", "track_width_m", "max_wheel_speed_mps", "ticks_per_rev", "feedback_timeout_s"):
            value = getattr(self, key)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{key} must be positive, got {value}")

    @classmethod
    def from_dict(cls, d: Any) -> "CanBaseConfig":
        """Build from a profile dict; unknown keys or bad values raise ``ValueError``."""
        return dataclass_from_dict(cls, d, "can_base")

    # --- wire arithmetic, shared by the adapter and the emulator ------------------------------
    def unit_per_mps(self) -> float:
        """How many ``speed_unit`` one m/s of wheel surface speed is."""
        if self.speed_unit == "m/s":
            return 1.0
        rad_per_s = 1.0 / self.wheel_radius_m
        return rad_per_s * 60.0 / (2.0 * math.pi) if self.speed_unit == "rpm" else rad_per_s

    def value_limits(self, nbytes: int) -> tuple[int, int]:
        """Smallest and largest integer a field of ``nbytes`` holds."""
        bits = 8 * nbytes
        return (-(1 << (bits - 1)), (1 << (bits - 1)) - 1) if self.signed else (0, (1 << bits) - 1)

    def pack_pair(self, left: int, right: int, nbytes: int) -> bytes:
        """Two integers (already within limits) as the frame's payload."""
        return left.to_bytes(nbytes, self.byte_order, signed=self.signed) + right.to_bytes(
            nbytes, self.byte_order, signed=self.signed
        )

    def unpack_pair(self, data: bytes, nbytes: int) -> Optional[tuple[int, int]]:
        """Left/right integers from a payload, or None when it is too short."""
        if len(data) < 2 * nbytes:
            return None
        left = int.from_bytes(data[:nbytes], self.byte_order, signed=self.signed)
        right = int.from_bytes(data[nbytes : 2 * nbytes], self.byte_order, signed=self.signed)
        return left, right

    def wheel_speeds_mps(self, linear_mps: float, angular_rps: float) -> tuple[float, float]:
        """Left/right wheel speeds (m/s) for a body velocity, scaled together to the limit."""
        half = 0.5 * self.track_width_m
        left, right = linear_mps - angular_rps * half, linear_mps + angular_rps * half
        biggest = max(abs(left), abs(right))
        if biggest > self.max_wheel_speed_mps:
            k = self.max_wheel_speed_mps / biggest
            left, right = left * k, right * k
        return left, right


def open_can_bus(config: CanBaseConfig) -> can.BusABC:
    """Open the bus the profile names (``can.Bus(interface, channel, bitrate)``).

    Raises ``can.CanInitializationError`` (or ``OSError``) when the interface
    is missing or down: check ``ip link show can0``.
    """
    return can.Bus(interface=config.interface, channel=config.channel, bitrate=config.bitrate)


def socketcan_link(channel: str) -> Optional[dict]:
    """What the kernel says of a SocketCAN interface: ``{"up": bool, "bitrate": int|None}``, or None if there is none.

    From ``ip -details -json link show CHANNEL`` (iproute2): python-can's
    socketcan backend does not set the bitrate, the kernel does, so a profile's
    ``bitrate`` is only true if the interface was brought up with it.
    """
    import json
    import subprocess
    try:
        out = subprocess.run(["ip", "-details", "-json", "link", "show", channel], capture_output=True, text=True,
                             timeout=5)
    except (OSError, subprocess.TimeoutExpired):
        return None
    if out.returncode != 0:
        return None
    try:
        link = (json.loads(out.stdout or "[]") or [{}])[0]
    except ValueError:
        return None
    timing = ((link.get("linkinfo") or {}).get("info_data") or {}).get("bittiming") or {}
    bitrate = timing.get("bitrate")
    return {"up": "UP" in (link.get("flags") or []), "bitrate": int(bitrate) if bitrate is not None else None}


def bring_up_hint(config: CanBaseConfig) -> str:
    """The commands that bring the profile's interface up at its bitrate."""
    return (f"sudo ip link set {config.channel} down; "
            f"sudo ip link set {config.channel} up type can bitrate {config.bitrate}")


class CanBase:
    """:class:`~beastbt.actuation.adapter.BaseAdapter` for a CAN motor controller.

    Counters (all since construction): ``frames_sent``, ``send_errors``,
    ``frames_received``, ``feedback_frames``, ``error_frames``,
    ``unknown_frames`` (ids we do not know, remote frames), ``bad_frames``
    (our feedback id with a short payload), ``recv_errors``,
    ``saturated_commands`` (speeds that did not fit the field).
    """

    name = "can_base"

    def __init__(self, bus: can.BusABC, config: CanBaseConfig, events: EventSink = ignore_events) -> None:
        self.bus = bus
        self.config = config
        self.events = events
        self.frames_sent = 0
        self.send_errors = 0
        self.frames_received = 0
        self.feedback_frames = 0
        self.error_frames = 0
        self.unknown_frames = 0
        self.bad_frames = 0
        self.recv_errors = 0
        self.saturated_commands = 0
        self._send_failing = False
        self._unknown_ids_seen: set[tuple[int, bool]] = set()
        # Odometry integration state.
        self._left_m = 0.0
        self._right_m = 0.0
        self._last_feedback_s: Optional[float] = None
        self._feedback_lost = False
        self._tick_prev: Optional[tuple[int, int]] = None
        self._tick_total = [0, 0]
        self._closed = False

    # --- sending ----------------------------------------------------------------------
    def _to_counts(self, speed_mps: float, invert: bool) -> tuple[int, bool]:
        c = self.config
        value = speed_mps * c.unit_per_mps() * c.scale * (-1.0 if invert else 1.0)
        lo, hi = c.value_limits(c.value_bytes)
        counts = int(round(value))
        clipped = max(lo, min(hi, counts))
        return clipped, clipped != counts

    def command_frame(self, left_mps: float, right_mps: float) -> can.Message:
        """The command frame for wheel speeds ``left_mps``/``right_mps`` (m/s)."""
        c = self.config
        left, sat_l = self._to_counts(left_mps, c.invert_left)
        right, sat_r = self._to_counts(right_mps, c.invert_right)
        if sat_l or sat_r:
            self.saturated_commands += 1
            self.events("can_command_saturated", f"wheel speeds ({left_mps:.3f}, {right_mps:.3f}) m/s exceed the frame's range; clipped")
        return can.Message(
            arbitration_id=c.command_id,
            is_extended_id=c.extended_id,
            data=c.pack_pair(left, right, c.value_bytes),
        )

    def _send(self, msg: can.Message) -> bool:
        if self._closed:
            return False
        try:
            # timeout=0: never block the tick loop on a full transmit queue.
            self.bus.send(msg, timeout=0)
        except can.CanError as exc:
            self.send_errors += 1
            if not self._send_failing:
                self.events(
                    "can_send_failed",
                    f"cannot send to the motor controller on {self.config.channel}: {exc} "
                    "(bus-off or queue full: check wiring, termination and bitrate)",
                )
            self._send_failing = True
            return False
        if self._send_failing:
            self.events("can_send_recovered", f"sending on {self.config.channel} works again after {self.send_errors} failures")
        self._send_failing = False
        self.frames_sent += 1
        return True

    def start(self, now_s: float) -> None:
        """Send a zero command, so the controller starts from a known stop."""
        self._send(self.command_frame(0.0, 0.0))

    def send_velocity(self, cmd: VelocityCommand, now_s: float) -> None:
        """Send one wheel speed frame for a body velocity (m/s, rad/s CCW)."""
        v, w = cmd.linear_mps, cmd.angular_rps
        if not (math.isfinite(v) and math.isfinite(w)):
            self.events("can_bad_command", f"non-finite velocity command ({v}, {w}): sending zero")
            v, w = 0.0, 0.0
        self._send(self.command_frame(*self.config.wheel_speeds_mps(v, w)))

    def emergency_stop(self, now_s: float) -> None:
        """Send zero wheel speeds (the example protocol has no dedicated stop frame)."""
        self._send(self.command_frame(0.0, 0.0))

    # --- receiving ------------------------------------------------------------------------
    def _speeds_from(self, pair: tuple[int, int]) -> tuple[float, float]:
        c = self.config
        k = 1.0 / (c.scale * c.unit_per_mps())
        left = pair[0] * k * (-1.0 if c.invert_left else 1.0)
        right = pair[1] * k * (-1.0 if c.invert_right else 1.0)
        return left, right

    def _tick_delta(self, new: int, old: int) -> int:
        # Counters wrap; the shortest modular difference is the real motion.
        modulus = 1 << (8 * self.config.feedback_value_bytes)
        d = (new - old) % modulus
        return d - modulus if d >= modulus // 2 else d

    def poll(self, now_s: float) -> list:
        """Read every frame waiting and return at most one WheelOdometry (stamped ``now_s``).

        Wheel speed feedback is integrated into distance over the time since
        the previous feedback poll, using the mean of the speeds received in
        between; encoder ticks are unwrapped and converted directly.
        """
        c = self.config
        speeds: list[tuple[float, float]] = []
        ticks: Optional[tuple[int, int]] = None
        error_frames = bad = 0
        for _ in range(MAX_FRAMES_PER_POLL):
            if self._closed:
                break
            try:
                msg = self.bus.recv(timeout=0)
            except can.CanError as exc:
                self.recv_errors += 1
                self.events("can_recv_failed", f"receiving on {c.channel} failed: {exc}")
                break
            if msg is None:
                break
            self.frames_received += 1
            if msg.is_error_frame:
                error_frames += 1
                continue
            if (
                c.feedback_kind == "none"
                or msg.is_remote_frame
                or msg.arbitration_id != c.feedback_id
                or bool(msg.is_extended_id) != c.extended_id
            ):
                self.unknown_frames += 1
                key = (msg.arbitration_id, bool(msg.is_extended_id))
                if key not in self._unknown_ids_seen and len(self._unknown_ids_seen) < 64:
                    self._unknown_ids_seen.add(key)
                    self.events("can_unknown_frame", f"ignoring frames with id 0x{msg.arbitration_id:x} on {c.channel}")
                continue
            pair = c.unpack_pair(bytes(msg.data), c.feedback_value_bytes)
            if pair is None:
                bad += 1
                continue
            self.feedback_frames += 1
            if c.feedback_kind == "wheel_speeds":
                speeds.append(self._speeds_from(pair))
            else:
                ticks = pair
        if error_frames:
            self.error_frames += error_frames
            self.events("can_error_frame", f"{error_frames} CAN error frame(s) on {c.channel}: check wiring, termination and bitrate")
        if bad:
            self.bad_frames += bad
            self.events("can_bad_feedback", f"{bad} feedback frame(s) with id 0x{c.feedback_id:x} too short to decode")
        if speeds:
            return [self._odometry_from_speeds(speeds, now_s)]
        if ticks is not None:
            return [self._odometry_from_ticks(ticks, now_s)]
        self._check_feedback_lost(now_s)
        return []

    def _check_feedback_lost(self, now_s: float) -> None:
        c = self.config
        if c.feedback_kind == "none" or self._last_feedback_s is None or self._feedback_lost:
            return
        if now_s - self._last_feedback_s > c.feedback_timeout_s:
            self._feedback_lost = True
            self.events("can_feedback_lost", f"no motor feedback on {c.channel} for {now_s - self._last_feedback_s:.2f} s")

    def _feedback_arrived(self, now_s: float) -> Optional[float]:
        """Note feedback at ``now_s``; return the time since the previous feedback (None at first)."""
        if self._feedback_lost:
            self._feedback_lost = False
            self.events("can_feedback_restored", f"motor feedback on {self.config.channel} is back")
        prev = self._last_feedback_s
        self._last_feedback_s = now_s
        return None if prev is None else max(0.0, now_s - prev)

    def _odometry_from_speeds(self, speeds: list[tuple[float, float]], now_s: float) -> WheelOdometry:
        left = sum(s[0] for s in speeds) / len(speeds)
        right = sum(s[1] for s in speeds) / len(speeds)
        dt = self._feedback_arrived(now_s)
        # Across a long gap we do not know what the wheels did: add nothing rather than guess.
        if dt is not None and dt <= self.config.feedback_timeout_s:
            self._left_m += left * dt
            self._right_m += right * dt
        return WheelOdometry(stamp_s=now_s, left_m=self._left_m, right_m=self._right_m, left_mps=left, right_mps=right)

    def _odometry_from_ticks(self, ticks: tuple[int, int], now_s: float) -> WheelOdometry:
        c = self.config
        if self._tick_prev is not None:
            self._tick_total[0] += self._tick_delta(ticks[0], self._tick_prev[0])
            self._tick_total[1] += self._tick_delta(ticks[1], self._tick_prev[1])
        self._tick_prev = ticks
        m_per_tick = 2.0 * math.pi * c.wheel_radius_m / c.ticks_per_rev
        left = self._tick_total[0] * m_per_tick * (-1.0 if c.invert_left else 1.0)
        right = self._tick_total[1] * m_per_tick * (-1.0 if c.invert_right else 1.0)
        dt = self._feedback_arrived(now_s)
        left_mps = right_mps = 0.0
        if dt:
            left_mps = (left - self._left_m) / dt
            right_mps = (right - self._right_m) / dt
        self._left_m, self._right_m = left, right
        return WheelOdometry(stamp_s=now_s, left_m=left, right_m=right, left_mps=left_mps, right_mps=right_mps)

    def close(self) -> None:
        """Send a final zero command and shut the bus down."""
        if self._closed:
            return
        self._send(self.command_frame(0.0, 0.0))
        self._closed = True
        try:
            self.bus.shutdown()
        except can.CanError as exc:
            self.events("can_close_failed", f"shutting down {self.config.channel} failed: {exc}")
