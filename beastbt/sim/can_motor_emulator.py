"""An emulated CAN motor controller on python-can's ``virtual`` bus.

:class:`SimCanMotorController` is the node at the other end of
:class:`beastbt.actuation.can_base.CanBase` in the simulator. It decodes
command frames into wheel speed targets (m/s) for the robot dynamics and,
on every :meth:`update`, sends a feedback frame with the true wheel speeds
or the encoder ticks the true wheel travel would count. Like real
controllers it stops the wheels when commands stop arriving. The protocol
is the same :class:`CanBaseConfig` the robot profile gives the adapter; an
``invert_*`` flag means that motor really is mounted mirrored.

python-can's virtual buses talk to every bus opened on the same channel
name in the process, so give each simulated robot (and each test) its own
channel name.
"""

from __future__ import annotations

import math
from typing import Optional

import can

from beastbt.actuation.can_base import CanBaseConfig
from beastbt.devices.interfaces import EventSink, ignore_events
from beastbt.sim.truth import RobotTruth


class SimCanMotorController:
    """Motor controller node: commands in, wheel speed targets out, feedback frames back.

    ``command_timeout_s``: with no valid command for this long the targets
    drop to zero (a controller's own watchdog). ``silent`` stops feedback
    (to emulate a controller that hangs); :meth:`send_error_frame` injects
    bus trouble.
    """

    def __init__(
        self,
        channel: str,
        config: CanBaseConfig,
        command_timeout_s: float = 0.5,
        events: EventSink = ignore_events,
    ) -> None:
        self.channel = channel
        self.config = config
        self.command_timeout_s = command_timeout_s
        self.events = events
        # preserve_timestamps: our frames carry simulated time, not the wall clock.
        self.bus = can.Bus(interface="virtual", channel=channel, receive_own_messages=False, preserve_timestamps=True)
        self.commands_received = 0
        self.unknown_frames = 0
        self.feedback_sent = 0
        self.silent = False
        self._targets = (0.0, 0.0)
        self._last_command_s: Optional[float] = None
        self._now_s = 0.0

    def _decode(self, msg: can.Message) -> Optional[tuple[float, float]]:
        c = self.config
        if msg.is_error_frame or msg.is_remote_frame or msg.arbitration_id != c.command_id:
            return None
        if bool(msg.is_extended_id) != c.extended_id:
            return None
        pair = c.unpack_pair(bytes(msg.data), c.value_bytes)
        if pair is None:
            return None
        k = 1.0 / (c.scale * c.unit_per_mps())
        left, right = pair[0] * k, pair[1] * k
        # A mirrored motor turns the other way for the same number.
        return (-left if c.invert_left else left), (-right if c.invert_right else right)

    def process_commands(self, now_s: float) -> int:
        """Read every waiting frame; returns how many were valid commands."""
        self._now_s = now_s
        n = 0
        while True:
            msg = self.bus.recv(timeout=0)
            if msg is None:
                return n
            targets = self._decode(msg)
            if targets is None:
                self.unknown_frames += 1
                continue
            self._targets = targets
            self._last_command_s = now_s
            self.commands_received += 1
            n += 1

    def wheel_targets_mps(self, now_s: float) -> tuple[float, float]:
        """(left, right) wheel speed targets in m/s after reading new commands; zero when stale."""
        self.process_commands(now_s)
        if self._last_command_s is None or now_s - self._last_command_s > self.command_timeout_s:
            return 0.0, 0.0
        return self._targets

    def feedback_frame(self, truth: RobotTruth) -> Optional[can.Message]:
        """The feedback frame the controller would send for ``truth`` (None when it sends none)."""
        c = self.config
        if c.feedback_kind == "none":
            return None
        sign_l = -1.0 if c.invert_left else 1.0
        sign_r = -1.0 if c.invert_right else 1.0
        nbytes = c.feedback_value_bytes
        if c.feedback_kind == "wheel_speeds":
            k = c.scale * c.unit_per_mps()
            lo, hi = c.value_limits(nbytes)
            left = max(lo, min(hi, int(round(truth.left_mps * sign_l * k))))
            right = max(lo, min(hi, int(round(truth.right_mps * sign_r * k))))
        else:
            per_m = c.ticks_per_rev / (2.0 * math.pi * c.wheel_radius_m)
            modulus = 1 << (8 * nbytes)
            left_t = int(math.floor(truth.left_m * sign_l * per_m)) % modulus
            right_t = int(math.floor(truth.right_m * sign_r * per_m)) % modulus
            if c.signed:
                # Back into two's complement range so int.to_bytes(signed=True) accepts it.
                left_t = left_t - modulus if left_t >= modulus // 2 else left_t
                right_t = right_t - modulus if right_t >= modulus // 2 else right_t
            left, right = left_t, right_t
        return can.Message(
            timestamp=truth.t_s,
            arbitration_id=c.feedback_id,
            is_extended_id=c.extended_id,
            data=c.pack_pair(left, right, nbytes),
        )

    def update(self, truth: RobotTruth) -> None:
        """Read new commands, then send one feedback frame describing ``truth``."""
        self.process_commands(truth.t_s)
        if self.silent:
            return
        msg = self.feedback_frame(truth)
        if msg is None:
            return
        try:
            self.bus.send(msg, timeout=0)
            self.feedback_sent += 1
        except can.CanError as exc:
            self.events("sim_can_send_failed", f"simulated motor controller could not send: {exc}")

    def send_error_frame(self, t_s: float = 0.0) -> None:
        """Put one CAN error frame on the bus (bus trouble, as a transceiver reports it)."""
        self.bus.send(can.Message(timestamp=t_s, is_error_frame=True, arbitration_id=0, data=b""), timeout=0)

    def close(self) -> None:
        """Leave the virtual bus."""
        self.bus.shutdown()
