"""A scripted joystick for the simulator and tests: YAML events in, real joystick bytes out.

A script is a YAML list of timed events::

    - {at: 2 s, press: enable}          # buttons by role: enable, turbo, estop, estop_reset
    - {at: 2.5 s, linear: 0.8, angular: -0.3}   # stick positions -1..1 (either or both)
    - {at: 6 s, release: enable}
    - {at: 9 s, press: estop}
    - {at: 10 s, unplug: true}
    - {at: 12 s, replug: true}

:class:`ScriptedJoystick` turns them, through the same
:class:`~beastbt.devices.joystick.JoystickMapping` the driver uses (numbers,
inversion, dead zone), into the 8-byte Linux joystick events the kernel
would deliver, including the initial-state burst on every open, and hands
them to :class:`~beastbt.devices.joystick.JoystickDevice` through
:meth:`ScriptedJoystick.opener`. So the simulator exercises the real driver.
"""

from __future__ import annotations

import errno
import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Optional, Union

import numpy as np

from beastbt.devices.joystick import (
    AXIS_ANGULAR,
    AXIS_LINEAR,
    JS_EVENT,
    JS_EVENT_AXIS,
    JS_EVENT_BUTTON,
    JS_EVENT_INIT,
    ByteSource,
    JoystickMapping,
)

if TYPE_CHECKING:
    from beastbt.core.errors import Position
    from beastbt.core.yaml_source import SourceDoc

_DURATION = re.compile(r"^\s*([+-]?(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][+-]?\d+)?)\s*(ms|s|sec|min|h)?\s*$")
_DURATION_UNITS = {None: 1.0, "s": 1.0, "sec": 1.0, "ms": 1e-3, "min": 60.0, "h": 3600.0}


def _parse_duration_text(text: Union[str, int, float]) -> float:
    """Seconds from ``"2 s"``, ``"500 ms"``, ``"1 min"``; the shared unit parser when present."""
    try:
        from beastbt.core.units import parse_duration  # type: ignore[attr-defined]
    except ImportError:
        parse_duration = None
    if parse_duration is not None:
        try:
            return float(parse_duration(text))
        except Exception as exc:  # noqa: BLE001 - any failure of the shared parser is a bad value here
            raise ValueError(str(exc)) from None
    m = _DURATION.match(str(text))
    if not m:
        raise ValueError(f"'{text}' is not a duration (write e.g. '2 s' or '500 ms')")
    return float(m.group(1)) * _DURATION_UNITS[m.group(2)]


def parse_time_s(value: Any) -> float:
    """Seconds from a YAML value: a bare number (seconds) or a duration string."""
    if isinstance(value, bool):
        raise ValueError(f"expected a duration, got {value!r}")
    if isinstance(value, (int, float)):
        # Through the shared parser too: a bare number is seconds, and it bounds it (finite, at most a week).
        seconds = _parse_duration_text(value)  # type: ignore[arg-type]
    elif isinstance(value, str):
        seconds = _parse_duration_text(value)
    else:
        raise ValueError(f"expected a duration, got {value!r}")
    if not math.isfinite(seconds) or seconds < 0:
        raise ValueError(f"time must be zero or later, got {value!r}")
    return seconds


@dataclass(frozen=True)
class ScriptEvent:
    """One parsed script event: at ``at_s`` seconds, do ``action`` (press/release/sticks/unplug/replug)."""

    at_s: float
    action: str
    button: Optional[str] = None
    linear: Optional[float] = None
    angular: Optional[float] = None


_ACTION_KEYS = ("press", "release", "unplug", "replug")
_STICK_KEYS = (AXIS_LINEAR, AXIS_ANGULAR)


def script_doc(text: str, source: str) -> "SourceDoc":
    """A joystick script's YAML read with positions (an empty text is an empty script); raise
    :class:`~beastbt.core.errors.InvalidInput` for what the YAML loader refuses (syntax, alias bombs, numbers) and
    for a script beyond :mod:`beastbt.sim.joystick_limits`' bounds on events and values."""
    from beastbt.core.errors import InvalidInput
    from beastbt.core.yaml_source import SourceDoc, load_yaml
    from beastbt.sim.joystick_limits import text_size_problem
    too_big = text_size_problem(text, source)  # counted before the events are built: they cost 60x the bytes
    if too_big is not None:
        raise InvalidInput([too_big])
    try:
        return load_yaml(source, text=text, display_name=source, require_mapping=False)
    except InvalidInput as exc:
        if [p.message for p in exc.problems] == ["the file is empty"]:
            return SourceDoc(file=source, data=[])
        raise


EVENT_HINT = ("an event is {at: TIME, press: BUTTON}, {at: TIME, release: BUTTON}, {at: TIME, linear: -1..1, "
              "angular: -1..1}, {at: TIME, unplug: true} or {at: TIME, replug: true}")
"""The hint of every joystick script error: what an event looks like."""


class ScriptProblems(ValueError):
    """A joystick script's problems, each positioned (``problems``: :class:`~beastbt.core.errors.Problem`)."""

    def __init__(self, problems: list) -> None:
        super().__init__("\n".join(p.format() for p in problems))
        self.problems = problems


class _Handle:
    """One open file of the scripted device: its own byte stream, dead once unplugged."""

    def __init__(self, rng: Optional[np.random.Generator]) -> None:
        self.buffer = bytearray()
        self.dead = False
        self.rng = rng

    def read(self) -> bytes:
        if self.dead:
            raise OSError(errno.ENODEV, "No such device (scripted joystick unplugged)")
        if not self.buffer:
            return b""
        n = len(self.buffer)
        if self.rng is not None:
            # Arbitrary read boundaries exercise the driver's partial-event buffering.
            n = int(self.rng.integers(0, n + 1))
        out = bytes(self.buffer[:n])
        del self.buffer[:n]
        return out


class ScriptedJoystick:
    """Plays a joystick script as Linux joystick events.

    ``n_axes``/``n_buttons``: how many the emulated pad has (the initial
    burst reports them all; mapped numbers beyond them are added). ``rng``,
    when given, splits reads at random byte boundaries. ``plugged``: whether
    the pad is present at the start.
    """

    def __init__(
        self,
        events: Sequence[Any],
        mapping: Optional[JoystickMapping] = None,
        *,
        source: str = "<joystick script>",
        positions: Optional[Sequence[Optional[tuple[int, int]]]] = None,
        doc: Optional["SourceDoc"] = None,
        rng: Optional[np.random.Generator] = None,
        n_axes: int = 8,
        n_buttons: int = 11,
        plugged: bool = True,
    ) -> None:
        self.mapping = mapping if mapping is not None else JoystickMapping()
        self.source = source
        self.doc = doc
        self.rng = rng
        self.events: list[ScriptEvent] = self._validate(events, positions)
        self.plugged = plugged
        self._next = 0
        self._handles: list[_Handle] = []
        self._time_ms = 0
        n_axes = max([n_axes] + [num + 1 for num, _ in self.mapping.axes().values()])
        n_buttons = max([n_buttons] + [num + 1 for nums in self.mapping.roles().values() for num in nums])
        self.raw_axes = [0] * n_axes
        self.raw_buttons = [0] * n_buttons

    # --- loading and validation ---------------------------------------------------------
    def _where(self, i: int, positions: Optional[Sequence[Optional[tuple[int, int]]]], key: Optional[str],
               value: bool) -> "Position":
        """Where event ``i`` (or its ``key``, or that key's value) is written: the document's position when the
        script was read with one, else the event's line and column, else the file's start."""
        from beastbt.core.errors import Position
        if self.doc is not None:
            return self.doc.position((i,) if key is None else (i, key), key=key is not None and not value)
        pos = positions[i] if positions is not None and i < len(positions) else None
        return Position(pos[0], pos[1]) if pos else Position()

    @classmethod
    def from_yaml(cls, text: str, mapping: Optional[JoystickMapping] = None, *, source: str = "<joystick script>", **kwargs: Any) -> "ScriptedJoystick":
        """Build from YAML text; errors name ``source:line:column`` and the event index.

        The text is read by the project's YAML loader (:func:`script_doc`), with its bounds on aliases and numbers.
        """
        from beastbt.core.errors import InvalidInput
        try:
            doc = script_doc(text, source)
        except InvalidInput as exc:
            raise ValueError("\n".join(f"{p.file}:{p.position.line}:{p.position.column}: error: {p.message}"
                                       for p in exc.problems)) from None
        return cls.from_doc(doc, mapping, **kwargs)

    @classmethod
    def from_doc(cls, doc: "SourceDoc", mapping: Optional[JoystickMapping] = None, **kwargs: Any) -> "ScriptedJoystick":
        """Build from a script read by :func:`script_doc` (its events positioned at their lines)."""
        data = doc.data if doc.data is not None else []
        if not isinstance(data, list):
            at = doc.position(())
            raise ValueError(f"{doc.file}:{at.line}:{at.column}: error: a joystick script is a list of events")
        positions: list[Optional[tuple[int, int]]] = []
        for i in range(len(data)):
            at = doc.position((i,))
            positions.append((at.line, at.column))
        return cls(data, mapping, source=doc.file, positions=positions, doc=doc, **kwargs)

    @classmethod
    def from_file(cls, path: Union[str, Path], mapping: Optional[JoystickMapping] = None, **kwargs: Any) -> "ScriptedJoystick":
        """Build from a YAML file (see :meth:`from_yaml`): a regular file within the joystick script's byte cap
        (:func:`beastbt.core.file_refs.read_capped`; RefusedFile otherwise)."""
        from beastbt.core.file_refs import JOYSTICK, read_capped
        p = Path(path)
        return cls.from_yaml(read_capped(p, JOYSTICK).decode("utf-8"), mapping, source=str(p), **kwargs)

    def _validate(self, events: Any, positions: Optional[Sequence[Optional[tuple[int, int]]]]) -> list[ScriptEvent]:
        from beastbt.core.errors import Position, Problem, did_you_mean
        if not isinstance(events, Sequence) or isinstance(events, (str, bytes)):
            raise ScriptProblems([Problem(self.source, Position(), "a joystick script is a list of events, got "
                                          + ("a mapping" if isinstance(events, Mapping) else repr(events)),
                                          EVENT_HINT)])
        problems: list[Problem] = []
        out: list[ScriptEvent] = []
        buttons = self.mapping.roles()
        keys = ("at",) + _ACTION_KEYS + _STICK_KEYS
        for i, ev in enumerate(events):
            def bad(text: str, hint: str = EVENT_HINT, key: Optional[str] = None, value: bool = False) -> None:
                problems.append(Problem(self.source, self._where(i, positions, key, value),
                                        f"joystick script event {i + 1}: {text}", hint))

            if not isinstance(ev, Mapping):
                bad(f"expected a mapping like {{at: 2 s, press: enable}}, got {ev!r}")
                continue
            unknown = [k for k in ev if k not in keys]
            for k in unknown:
                swapped = [known for known in keys if sorted(known) == sorted(str(k))]  # 'ta' for 'at'
                bad(f"unknown key '{k}'" + (f"; did you mean '{swapped[0]}'?" if swapped else
                                            did_you_mean(str(k), keys)), key=str(k))
            if unknown:
                continue
            if "at" not in ev:
                bad("missing 'at' (when the event happens, e.g. at: 2 s)")
                continue
            try:
                at_s = parse_time_s(ev["at"])
            except ValueError as exc:
                bad(f"at: {exc}", "a time since the run started: 'at: 2 s', 'at: 500 ms'", "at", True)
                continue
            actions = [k for k in _ACTION_KEYS if k in ev]
            sticks = [k for k in _STICK_KEYS if k in ev]
            if len(actions) + (1 if sticks else 0) != 1:
                bad("needs exactly one of press, release, unplug, replug, or stick positions (linear/angular)")
                continue
            if sticks:
                values: dict[str, float] = {}
                for k in sticks:
                    v = ev[k]
                    # Compared before float(): a huge int would overflow it, and NaN fails every comparison.
                    if isinstance(v, bool) or not isinstance(v, (int, float)) or not -1 <= v <= 1:
                        bad(f"{k} must be a number from -1 to 1 (the stick's position), got {v!r}",
                            f"1 is the stick pushed all the way ({'forward' if k == AXIS_LINEAR else 'left'}), "
                            f"-1 the other way, 0 centred: e.g. {k}: 0.8", k, True)
                        break
                    values[k] = float(v)
                else:
                    out.append(ScriptEvent(at_s, "sticks", linear=values.get(AXIS_LINEAR), angular=values.get(AXIS_ANGULAR)))
                continue
            action = actions[0]
            if action in ("press", "release"):
                name = ev[action]
                if name not in buttons:
                    bad(f"{action}: no button '{name}' in the mapping{did_you_mean(str(name), list(buttons))}",
                        f"the buttons, by role: {', '.join(buttons)}", action, True)
                    continue
                out.append(ScriptEvent(at_s, action, button=name))
            else:
                if ev[action] is not True:
                    bad(f"write '{action}: true', got {ev[action]!r}", f"e.g. {{at: 10 s, {action}: true}}", action, True)
                    continue
                out.append(ScriptEvent(at_s, action))
        if problems:
            raise ScriptProblems(problems)
        # Stable sort: events at the same time keep their written order.
        return sorted(out, key=lambda e: e.at_s)

    # --- the device side ----------------------------------------------------------------------
    def _emit(self, kind: int, number: int, value: int) -> None:
        data = JS_EVENT.pack(self._time_ms, value, kind, number)
        for h in self._handles:
            h.buffer += data

    def _open(self) -> ByteSource:
        if not self.plugged:
            raise OSError(errno.ENOENT, "No such file or directory (scripted joystick unplugged)")
        handle = _Handle(self.rng)
        # The kernel's initial-state burst: every button, then every axis, flagged INIT.
        for number, value in enumerate(self.raw_buttons):
            handle.buffer += JS_EVENT.pack(self._time_ms, value, JS_EVENT_BUTTON | JS_EVENT_INIT, number)
        for number, value in enumerate(self.raw_axes):
            handle.buffer += JS_EVENT.pack(self._time_ms, value, JS_EVENT_AXIS | JS_EVENT_INIT, number)
        self._handles.append(handle)
        return handle.read

    def opener(self) -> Callable[[], ByteSource]:
        """The ``open_device`` callable for :class:`~beastbt.devices.joystick.JoystickDevice`."""
        return self._open

    def _apply(self, ev: ScriptEvent) -> None:
        m = self.mapping
        if ev.action in ("press", "release"):
            value = 1 if ev.action == "press" else 0
            for number in m.roles()[ev.button]:  # type: ignore[index]  # a chord: every button of it
                self.raw_buttons[number] = value
                if self.plugged:
                    self._emit(JS_EVENT_BUTTON, number, value)
        elif ev.action == "sticks":
            for name, value in ((AXIS_LINEAR, ev.linear), (AXIS_ANGULAR, ev.angular)):
                if value is None:
                    continue
                number, inverted = m.axes()[name]
                raw = m.raw_for(value, inverted)
                self.raw_axes[number] = raw
                if self.plugged:
                    self._emit(JS_EVENT_AXIS, number, raw)
        elif ev.action == "unplug":
            self.plugged = False
            for h in self._handles:
                h.dead = True
                h.buffer.clear()
            self._handles.clear()
        elif ev.action == "replug":
            self.plugged = True

    def update(self, now_s: float) -> None:
        """Deliver every event due at or before ``now_s`` (seconds) to the open device."""
        while self._next < len(self.events) and self.events[self._next].at_s <= now_s:
            ev = self.events[self._next]
            self._time_ms = int(round(ev.at_s * 1000.0)) & 0xFFFFFFFF
            self._apply(ev)
            self._next += 1
        self._time_ms = int(round(now_s * 1000.0)) & 0xFFFFFFFF

    @property
    def finished(self) -> bool:
        """True once every event has been delivered."""
        return self._next >= len(self.events)
