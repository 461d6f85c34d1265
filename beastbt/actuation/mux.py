"""The command mux, in the manner of twist_mux: sources with priorities and timeouts, and an e-stop lock.

Sources (highest first): ``estop`` (a latch, not a source of motion: while it
is latched the output is zero), ``teleop``, ``failsafe``, ``mission``. Each
source's command counts for ``timeout_s`` after it was submitted; the highest
priority source with a fresh command wins. What was chosen and why is kept in
:attr:`CommandMux.source` and :attr:`CommandMux.reason`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

from beastbt.blackboard.types import VelocityCommand


@dataclass
class MuxSource:
    """One input of the mux: its name, priority (higher wins) and timeout in seconds."""

    name: str
    priority: int
    timeout_s: float
    last: Optional[VelocityCommand] = None
    last_s: float = -1e9


DEFAULT_SOURCES = (("teleop", 100, 0.5), ("failsafe", 50, 0.5), ("mission", 10, 0.5))
"""(name, priority, timeout_s) of the standard sources."""

ZERO = VelocityCommand(0.0, 0.0, 0.0, "none")


class CommandMux:
    """Chooses, every tick, which source's velocity command goes on to the safety gate."""

    def __init__(self, sources: tuple[tuple[str, int, float], ...] = DEFAULT_SOURCES) -> None:
        self.sources = {name: MuxSource(name, prio, timeout) for name, prio, timeout in sources}
        self._order = sorted(self.sources.values(), key=lambda s: -s.priority)
        self.estop_latched = False
        self.estop_reason = ""
        self.source = "none"
        self.reason = "no command yet"

    def submit(self, source: str, cmd: VelocityCommand, now_s: float) -> None:
        """Offer ``cmd`` from ``source`` at ``now_s``."""
        s = self.sources[source]
        s.last = cmd
        s.last_s = now_s

    def withdraw(self, source: str) -> None:
        """Forget ``source``'s command at once (e.g. teleop released)."""
        s = self.sources[source]
        s.last = None
        s.last_s = -1e9

    def latch_estop(self, reason: str) -> None:
        """Latch the emergency stop; only :meth:`reset_estop` clears it."""
        if not self.estop_latched:
            self.estop_latched = True
            self.estop_reason = reason

    def reset_estop(self) -> None:
        """Clear the emergency stop (an explicit operator action)."""
        self.estop_latched = False
        self.estop_reason = ""

    def select(self, now_s: float) -> VelocityCommand:
        """The command that wins at ``now_s`` (zero when latched or when no source is fresh)."""
        if self.estop_latched:
            self.source, self.reason = "estop", f"emergency stop latched: {self.estop_reason}"
            return VelocityCommand(0.0, 0.0, now_s, "estop")
        for s in self._order:
            if s.last is not None and now_s - s.last_s <= s.timeout_s:
                self.source, self.reason = s.name, f"{s.name} is the highest fresh source"
                return s.last
        self.source, self.reason = "none", "no fresh command from any source"
        return VelocityCommand(0.0, 0.0, now_s, "none")
