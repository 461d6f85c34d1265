"""The run's event log: what happened, when, for the operator, the summary and the recording."""

from __future__ import annotations

import threading
from collections import deque
from dataclasses import dataclass, field
from typing import Callable, Optional

from beastbt.core.bounded import HeadTail
from beastbt.core.clock import Clock

EVENTS_KEPT = 10000
"""Events a run keeps in memory (and in its summary): the first half and the last half of this many; the
others are counted (``dropped``). The recording has every one."""


@dataclass
class Event:
    """One event: ``time_s`` since the run started (clock seconds), a ``kind`` word and a ``text``."""

    time_s: float
    kind: str
    text: str

    def as_dict(self) -> dict:
        """The event as the run summary stores it."""
        return {"time_s": round(self.time_s, 3), "kind": self.kind, "text": self.text}


@dataclass
class EventLog:
    """Collects events stamped with the run's clock and passes each to listeners (console, recorder).

    ``events`` keeps the first and the last ``max_events / 2`` events (how the
    run began, and how it is going or how it ended); those in between are
    counted in ``dropped``. Every listener sees every event.

    Listeners (the recorder, the console, the fleet link) are called on the
    thread that owns the log, the one that ticks the run, and never on two
    threads at once: an event added on another thread (the console's e-stop,
    the watchdog, the camera, a joystick watcher) is stamped at once and waits
    in an inbox until the owner calls :meth:`drain`, which the runner does at
    every tick and as the run ends.
    """

    clock: Clock
    t0_s: float = 0.0
    listeners: list[Callable[[Event], None]] = field(default_factory=list)
    max_events: int = EVENTS_KEPT
    events: HeadTail[Event] = field(init=False, repr=False)
    _owner: int = field(default_factory=threading.get_ident, init=False, repr=False)
    _inbox: deque = field(default_factory=deque, init=False, repr=False)

    def __post_init__(self) -> None:
        head = self.max_events // 2
        self.events = HeadTail(head, self.max_events - head)

    def own(self) -> None:
        """Make the calling thread the log's owner (the runner, at its first tick): listeners run on it."""
        self._owner = threading.get_ident()

    @property
    def dropped(self) -> int:
        """Events let go between the first and the last kept."""
        return self.events.dropped

    def add(self, kind: str, text: str) -> Event:
        """Record an event now; beyond ``max_events`` events the oldest of the latest half is counted and let go."""
        ev = Event(self.clock.now() - self.t0_s, kind, text)
        if threading.get_ident() != self._owner:
            self._inbox.append(ev)  # (deque.append is atomic: no lock, the adding thread never waits)
            return ev
        self.drain()
        self._deliver(ev)
        return ev

    def drain(self) -> None:
        """Deliver the events other threads added since the last call, in the order they came (owner only:
        on another thread this does nothing)."""
        if threading.get_ident() != self._owner:
            return
        inbox = self._inbox
        while inbox:
            self._deliver(inbox.popleft())

    def _deliver(self, ev: Event) -> None:
        self.events.append(ev)
        for listener in self.listeners:
            listener(ev)

    def sink(self, source: str) -> Callable[[str, str], None]:
        """An :data:`~beastbt.devices.interfaces.EventSink` for a device, prefixing its texts with ``source``."""
        def _sink(kind: str, text: str) -> None:
            self.add(kind, f"{source}: {text}")
        return _sink

    def last(self, kind: Optional[str] = None) -> Optional[Event]:
        """The most recent event (of ``kind``), or None."""
        for ev in reversed(self.events):
            if kind is None or ev.kind == kind:
                return ev
        return None
