"""What the operator did to a run from outside its tree: the console's controls and stick, a terminal's answers.

The tree, the devices and the clock are recorded as they are; what a person
does through the operator console (pause, resume, abort, answer, the on-page
stick, a knob tuned live: :mod:`beastbt.live.tuning`) or a terminal (an answer typed at the prompt) happens between their
readings, in wall time. Each such input, once carried out, is noted here
with the tick it counted in (:class:`OperatorInput`); the recorder keeps the
notes (channel ``/operator/input``) and ``beastbt replay`` carries them out
again at the same ticks through the same code (the console's
:class:`~beastbt.live.console_control.ConsoleControls`, the question board),
so that a run someone answered, paused or drove replays identically.

A joystick (a real one or ``--joystick FILE``) is not an input here: its
states are readings (``/sensors/joystick``), replayed as the other sensors are.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable

CONSOLE = "console"
"""The source of the operator console's controls (:mod:`beastbt.live.console_control`)."""
TERMINAL = "terminal"
"""The source of answers typed at the run's terminal (:class:`~beastbt.run.session.TerminalAnswers`)."""
STICK_SILENT = "stick_silent"
"""The console's control that releases a stick whose messages stopped (its timeout is wall time)."""
TUNE = "tune"
"""The console's (or the station's) control that sets one knob live, ``{name, value}`` (:mod:`beastbt.live.tuning`);
``tune_reset`` throws the changes away and ``tune_saved`` says they were written to the profile (a reset comes back
to them). Replayed at their tick, so a tuned run replays identically."""


@dataclass(frozen=True)
class OperatorInput:
    """One input carried out: the tick it counted in, the clock time (s) it was carried out at, where it came
    from (``console``, ``terminal``), the control (``pause``, ``resume``, ``abort``, ``answer``, ``teleop``,
    ``stick_silent``, ``tune``, ``tune_reset``, ``tune_saved``) and its body (the console's JSON body; ``{id, choice}`` for an answer)."""

    tick: int
    now_s: float
    source: str
    control: str
    body: dict = field(default_factory=dict)


class OperatorInputs:
    """The run's log of operator inputs: ``sources`` attached (console, terminal), ``listeners`` told of each."""

    def __init__(self) -> None:
        self.sources: set[str] = set()
        """The input channels this run has (the console makes the robot drivable by hand even before use)."""
        self.listeners: list[Callable[[OperatorInput], None]] = []
        """Called with each input as it is carried out (the recorder)."""
        self.count = 0
        """Inputs carried out so far."""

    def note(self, run: Any, source: str, control: str, body: dict, now_s: float) -> None:
        """An input from ``source`` was carried out at clock time ``now_s`` (s): it counts in tick ``run.ticks``
        (the tick under way, or the next one when it came between ticks)."""
        self.count += 1
        if not self.listeners:
            return
        item = OperatorInput(int(run.ticks), float(now_s), source, control, dict(body))
        for listener in self.listeners:
            listener(item)


__all__ = ["OperatorInput", "OperatorInputs", "CONSOLE", "TERMINAL", "STICK_SILENT", "TUNE"]
