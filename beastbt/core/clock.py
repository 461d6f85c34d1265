"""Clocks: where every piece of beastbt gets the time from.

Behaviours, drivers, the estimator and the safety gate never call
``time.time()``; they are handed a :class:`Clock`. On the robot that is a
:class:`WallClock`; in the simulator a :class:`SimClock` that the runner
advances in lockstep, so runs are deterministic and faster than real time.
"""

from __future__ import annotations

import datetime as _dt
import time
from typing import Protocol


class Clock(Protocol):
    """Anything that tells the current time in seconds (monotonic, arbitrary epoch)."""

    def now(self) -> float:
        """Return the current time in seconds."""
        ...


class SimClock:
    """A clock that only moves when told to: the simulator's time, in seconds."""

    def __init__(self, start_s: float = 0.0) -> None:
        self._now = float(start_s)

    def now(self) -> float:
        """Return the simulated time in seconds."""
        return self._now

    def advance(self, dt_s: float) -> float:
        """Move time forward by ``dt_s`` seconds (never backwards) and return the new time."""
        if dt_s < 0:
            raise ValueError(f"a clock cannot go backwards (dt_s={dt_s})")
        self._now += dt_s
        return self._now

    def set(self, t_s: float) -> None:
        """Jump to ``t_s`` seconds; used by replay, which follows a recorded clock."""
        if t_s < self._now:
            raise ValueError(f"a clock cannot go backwards ({t_s} < {self._now})")
        self._now = float(t_s)


class WallClock:
    """The robot's clock: monotonic wall time in seconds since this clock was made."""

    def __init__(self) -> None:
        self._t0 = time.monotonic()

    def now(self) -> float:
        """Return seconds elapsed since construction (monotonic)."""
        return time.monotonic() - self._t0

    def sleep_until(self, t_s: float) -> None:
        """Block until :meth:`now` reaches ``t_s`` (only the tick loop may call this)."""
        delay = t_s - self.now()
        if delay > 0:
            time.sleep(delay)


def utc_now() -> _dt.datetime:
    """The calendar date and time now, UTC: for names people read (run folders), never for timing."""
    return _dt.datetime.now(_dt.timezone.utc)
