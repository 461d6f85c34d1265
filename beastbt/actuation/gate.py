"""The safety gate: the last check before the actuators, independent of the tree being right.

It clamps every command to the speed and turn-rate limits (the mission's and
the robot's), limits acceleration, and zeroes the output when the command it
is given is older than the watchdog timeout (default 0.5 s).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional

from beastbt.blackboard.types import VelocityCommand


@dataclass
class GateLimits:
    """Limits the gate enforces: m/s, rad/s, m/s^2, rad/s^2, s."""

    max_speed_mps: float
    max_turn_rate_rps: float
    max_accel_mps2: float
    max_angular_accel_rps2: float
    command_timeout_s: float = 0.5


class SafetyGate:
    """Clamps, rate-limits and times out velocity commands.

    ``filter(cmd, now_s)`` returns what may be sent now. A ``cmd`` whose stamp is
    older than ``command_timeout_s`` is replaced by zero (the watchdog), and
    ``watchdog_tripped`` says so. Deceleration to zero is never rate-limited
    beyond the acceleration limit: stopping always proceeds.
    """

    def __init__(self, limits: GateLimits) -> None:
        self.limits = limits
        self.out = VelocityCommand(0.0, 0.0, 0.0, "gate")
        self.last_s: Optional[float] = None
        self.watchdog_tripped = False
        self.clamped = False

    def filter(self, cmd: Optional[VelocityCommand], now_s: float) -> VelocityCommand:
        """The command to send at ``now_s``."""
        lim = self.limits
        dt = 0.0 if self.last_s is None else max(0.0, now_s - self.last_s)
        self.last_s = now_s
        if cmd is None or now_s - cmd.stamp_s > lim.command_timeout_s:
            self.watchdog_tripped = True
            v_goal, w_goal = 0.0, 0.0
        else:
            self.watchdog_tripped = False
            v_goal = max(-lim.max_speed_mps, min(lim.max_speed_mps, cmd.linear_mps))
            w_goal = max(-lim.max_turn_rate_rps, min(lim.max_turn_rate_rps, cmd.angular_rps))
            self.clamped = v_goal != cmd.linear_mps or w_goal != cmd.angular_rps
        if dt == 0.0:
            dv_max, dw_max = lim.max_accel_mps2 * 0.05, lim.max_angular_accel_rps2 * 0.05
        else:
            dv_max, dw_max = lim.max_accel_mps2 * dt, lim.max_angular_accel_rps2 * dt
        v = self.out.linear_mps + max(-dv_max, min(dv_max, v_goal - self.out.linear_mps))
        w = self.out.angular_rps + max(-dw_max, min(dw_max, w_goal - self.out.angular_rps))
        # Snap tiny residues to exact zero so a stop is a stop on the wire.
        if v_goal == 0.0 and abs(v) < 1e-6:
            v = 0.0
        if w_goal == 0.0 and abs(w) < 1e-6:
            w = 0.0
        self.out = VelocityCommand(v, w, now_s, cmd.source if cmd is not None else "watchdog")
        return self.out

    def reset(self) -> None:
        """Forget the previous output (after an e-stop the robot starts from rest)."""
        self.out = VelocityCommand(0.0, 0.0, 0.0, "gate")
        self.last_s = None


def tightest(*limits: Optional[float]) -> float:
    """The smallest of the given limits that are set (``inf`` when none is)."""
    values = [x for x in limits if x is not None]
    return min(values) if values else math.inf
