"""The command watchdog below everything: zero on the wire when fresh commands stop, a stop as the last word.

:class:`AdapterWatchdog` wraps a :class:`~beastbt.actuation.adapter.BaseAdapter`
and is itself one, so the tick loop cannot tell it is there. It remembers when
the loop last handed it a fresh velocity command; :meth:`AdapterWatchdog.check`
sends zero through the wrapped adapter once no fresh command has come for
``timeout_s``, whatever the loop above is doing (frozen in a driver call,
crashed, stuck in a behaviour). On the robot a daemon thread calls ``check``
every ``check_period_s``; in the simulator the simulator calls it at every
physics step, so the same code runs deterministically under test.

It also holds the adapter side of the emergency stop: once the base's own
stop has been sent (:meth:`emergency_stop`) or :meth:`latch_estop` was called,
every velocity command is replaced by zero until :meth:`reset_estop` — a latch
that does not depend on the mux above being right. :meth:`close` stops the
thread first and then closes the wrapped adapter, so the last bytes on the wire
are the adapter's own stop.

Time comes only from the injected clock; the thread sleeps only through the
injected ``sleeper`` (by default a wait on the thread's stop event).
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass, fields
from typing import Any, Callable, Optional

from beastbt.core.schema_defaults import schema_defaults
from beastbt.actuation.adapter import BaseAdapter, ServoAdapter
from beastbt.blackboard.types import ServoCommand, VelocityCommand
from beastbt.devices.interfaces import EventSink, ignore_events
from beastbt.core.clock import Clock

Sleeper = Callable[[float], Any]
"""Blocks the calling thread for about the given number of seconds (returns early on shutdown)."""


@dataclass
@schema_defaults("parts/watchdog.schema.json")
class WatchdogConfig:
    """Settings of the adapter-side watchdog (robot profile ``watchdog:``).

    The zero reaches the wire at most ``timeout_s + check_period_s`` (0.47 s by
    default) after the last fresh command: inside the field's 0.5 s.
    """

    # Seconds without a fresh velocity command before the watchdog sends zero itself.
    # Keep timeout_s + check_period_s below the 0.5 s the field asks for.
    timeout_s: float
    # Seconds between two checks of the watchdog thread on the robot (the simulator
    # checks at every physics step instead). Smaller reacts sooner, costs a wake-up each time.
    check_period_s: float
    # Seconds the watchdog gives the tick loop to send the base's own stop after an
    # e-stop was latched through the API; past that it sends it itself (a frozen loop).
    estop_grace_s: float
    # False turns the watchdog off (commands pass straight through). Only for bench tests.
    enabled: bool

    def __post_init__(self) -> None:
        for key in ("timeout_s", "check_period_s", "estop_grace_s"):
            value = getattr(self, key)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value <= 0:
                raise ValueError(f"watchdog.{key} must be a positive number of seconds, got {value!r}")
        if not isinstance(self.enabled, bool):
            raise ValueError(f"watchdog.enabled must be true or false, got {self.enabled!r}")

    @classmethod
    def from_dict(cls, d: Optional[dict]) -> "WatchdogConfig":
        """Build from a profile's ``watchdog:`` mapping; unknown keys are a ValueError."""
        d = dict(d or {})
        names = {f.name for f in fields(cls)}
        unknown = sorted(set(d) - names)
        if unknown:
            raise ValueError(f"unknown watchdog setting(s): {', '.join(unknown)} (known: {', '.join(sorted(names))})")
        return cls(**d)


class AdapterWatchdog:
    """A :class:`BaseAdapter` that guards another one (see the module docstring).

    Counters: ``trips`` (zeros sent because commands stopped), ``stale_commands``
    (commands whose stamp was already older than ``timeout_s`` and went out as
    zero), ``blocked_by_estop`` (non-zero commands refused while latched),
    ``estops_sent`` (the base's own stop, by the loop or by the watchdog).
    Every call to the wrapped adapter holds one lock, so the thread and the
    loop never write to the port at the same moment.
    """

    def __init__(self, inner: BaseAdapter, clock: Clock, config: Optional[WatchdogConfig] = None,
                 events: EventSink = ignore_events) -> None:
        self.inner = inner
        self.clock = clock
        self.config = config or WatchdogConfig()
        self.events = events
        self.name = getattr(inner, "name", "base")
        self.lock = threading.RLock()
        self.trips = 0
        self.stale_commands = 0
        self.blocked_by_estop = 0
        self.estops_sent = 0
        self.last_fresh_s: Optional[float] = None
        """Clock time of the last fresh command the loop handed over (None before the first)."""
        self.zeroed = False
        """True after the watchdog sent zero itself, until the next fresh command."""
        self.estop_latched = False
        self.estop_reason = ""
        self._estop_at_s = 0.0
        self._estop_sent = False
        self._closed = False
        self._stop = threading.Event()
        self._thread: Optional[threading.Thread] = None

    # -- the BaseAdapter interface (what the tick loop calls) -------------------------
    def start(self, now_s: float) -> None:
        """Pass the base's start-up sequence through."""
        with self.lock:
            if not self._closed:
                self.inner.start(now_s)

    def send_velocity(self, cmd: VelocityCommand, now_s: float) -> None:
        """Forward ``cmd`` (m/s, rad/s) and note it as fresh; zero instead while latched or when stale."""
        timeout = self.config.timeout_s
        with self.lock:
            if self._closed:
                return
            if not self.config.enabled:
                self.inner.send_velocity(cmd, now_s)
                return
            now = self.clock.now()
            out = cmd
            if now - cmd.stamp_s > timeout:
                # A command already older than the timeout is not fresh, whoever hands it over.
                self.stale_commands += 1
                out = VelocityCommand(0.0, 0.0, now_s, "watchdog")
            elif self.estop_latched and not cmd.is_zero():
                self.blocked_by_estop += 1
                out = VelocityCommand(0.0, 0.0, now_s, "estop")
            else:
                if self.zeroed:
                    self.events("watchdog", f"fresh commands again after {now - (self.last_fresh_s or now):.2f} s")
                self.zeroed = False
                self.last_fresh_s = now
            self.inner.send_velocity(out, now_s)

    def emergency_stop(self, now_s: float) -> None:
        """Send the base's own stop and latch: velocities stay zero until :meth:`reset_estop`."""
        with self.lock:
            if self._closed:
                return
            if not self.estop_latched:
                self.estop_latched = True
                self.estop_reason = self.estop_reason or "emergency stop"
                self._estop_at_s = self.clock.now()
            self.inner.emergency_stop(now_s)
            self._estop_sent = True
            self.estops_sent += 1

    def poll(self, now_s: float) -> list:
        """The wrapped adapter's feedback."""
        with self.lock:
            if self._closed:
                return []
            return self.inner.poll(now_s)

    def close(self) -> None:
        """Stop the thread, then close the wrapped adapter: its final stop is the last thing sent."""
        self.stop_thread()
        with self.lock:
            if self._closed:
                return
            self._closed = True
            self.inner.close()

    # -- e-stop latch -----------------------------------------------------------------
    def latch_estop(self, reason: str) -> None:
        """Latch the e-stop from outside the loop (API, CLI); the stop goes out now or within ``estop_grace_s``."""
        with self.lock:
            if self.estop_latched:
                return
            self.estop_latched = True
            self.estop_reason = reason
            self._estop_at_s = self.clock.now()
            self._estop_sent = False

    def reset_estop(self) -> None:
        """Clear the adapter-side latch (an explicit operator action)."""
        with self.lock:
            self.estop_latched = False
            self.estop_reason = ""
            self._estop_sent = False

    # -- the watchdog proper ----------------------------------------------------------
    def check(self, now_s: float) -> Optional[str]:
        """Act on the time ``now_s`` (clock seconds): ``"zero"`` or ``"estop"`` when it sent something, else None.

        Sends zero once when the last fresh command is ``timeout_s`` old (again
        after each new fresh command), and the base's own stop when an e-stop
        latched from outside has not been sent by the loop within ``estop_grace_s``.
        """
        if not self.config.enabled:
            return None
        with self.lock:
            if self._closed:
                return None
            if self.estop_latched and not self._estop_sent and now_s - self._estop_at_s >= self.config.estop_grace_s:
                self.inner.emergency_stop(now_s)
                self._estop_sent = True
                self.estops_sent += 1
                self.events("watchdog", f"the loop did not send the e-stop ({self.estop_reason}): sent it from below")
                return "estop"
            if self.last_fresh_s is None or self.zeroed:
                return None
            age = now_s - self.last_fresh_s
            if age < self.config.timeout_s:
                return None
            self.inner.send_velocity(VelocityCommand(0.0, 0.0, now_s, "watchdog"), now_s)
            self.zeroed = True
            self.trips += 1
        self.events("watchdog", f"no fresh command for {age:.2f} s: sent zero")
        return "zero"

    # -- the thread (robot, real time) ------------------------------------------------
    def start_thread(self, sleeper: Optional[Sleeper] = None) -> None:
        """Check every ``check_period_s`` in a daemon thread; ``sleeper`` blocks between checks.

        The default sleeper waits on the thread's stop event, so :meth:`stop_thread` ends it at once.
        """
        if self._thread is not None or not self.config.enabled:
            return
        sleep = sleeper if sleeper is not None else self._stop.wait
        period = self.config.check_period_s

        def loop() -> None:
            while not self._stop.is_set():
                try:
                    self.check(self.clock.now())
                except Exception as exc:  # a broken port must not end the watchdog
                    self.events("watchdog", f"check failed: {exc!r}")
                sleep(period)

        self._thread = threading.Thread(target=loop, name="beastbt-watchdog", daemon=True)
        self._thread.start()

    def stop_thread(self, timeout_s: float = 1.0) -> None:
        """Ask the thread to end and wait for it (at most ``timeout_s`` seconds)."""
        self._stop.set()
        thread, self._thread = self._thread, None
        if thread is not None and thread is not threading.current_thread():
            thread.join(timeout_s)

    def on_physics_step(self, t_s: float, dt_s: float) -> None:
        """The simulator's emulator hook: check at every physics step (``t_s`` simulated seconds)."""
        self.check(t_s)

    @property
    def running(self) -> bool:
        """True while the watchdog thread is alive."""
        return self._thread is not None and self._thread.is_alive()

    # -- everything else the adapter offers (stats, lights, gimbal...) -----------------
    def __getattr__(self, name: str) -> Any:
        # Only reached for attributes this class does not define.
        if name == "inner":
            raise AttributeError(name)
        return getattr(self.inner, name)


class LockedServos:
    """A :class:`ServoAdapter` that takes the watchdog's lock (for a base that is also the servo driver)."""

    def __init__(self, inner: ServoAdapter, lock: Any) -> None:
        self.inner = inner
        self.lock = lock

    def servo_names(self) -> list[str]:
        """The wrapped adapter's servo names."""
        return self.inner.servo_names()

    def set_servo(self, cmd: ServoCommand, now_s: float) -> bool:
        """Command one servo while holding the lock."""
        with self.lock:
            return self.inner.set_servo(cmd, now_s)

    def __getattr__(self, name: str) -> Any:
        if name == "inner":
            raise AttributeError(name)
        return getattr(self.inner, name)


__all__ = ["AdapterWatchdog", "WatchdogConfig", "LockedServos", "Sleeper"]
