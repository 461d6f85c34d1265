"""The run's event log: what happened, when, for the operator, the summary and the recording."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Optional

from beastbt.core.clock import Clock


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
    """Collects events stamped with the run's clock and passes each to listeners (console, recorder)."""

    clock: Clock
    t0_s: float = 0.0
    events: list[Event] = field(default_factory=list)
    listeners: list[Callable[[Event], None]] = field(default_factory=list)
    max_events: int = 10000
    dropped: int = 0

    def add(self, kind: str, text: str) -> Event:
        """Record an event now; beyond ``max_events`` events are counted, not kept."""
        ev = Event(self.clock.now() - self.t0_s, kind, text)
        if len(self.events) < self.max_events:
            self.events.append(ev)
        else:
            self.dropped += 1
        for listener in self.listeners:
            listener(ev)
        return ev

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
