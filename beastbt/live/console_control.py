"""The operator console's controls: pause, resume, abort, answer and the remote stick, applied on the tick thread.

The web server runs in a thread of its own; the run's state belongs to the
tick thread. So a control is a :class:`Command` put on a queue
(:meth:`ConsoleControls.submit`, any thread) and carried out by
:meth:`ConsoleControls.apply_pending`, which the run calls first thing in
every tick (a tick hook) and, on the robot, as soon as the loop is woken
between ticks (a reactor). Its result goes back through a
:class:`concurrent.futures.Future`.

The e-stop does not wait for a tick: :func:`~beastbt.run.safety.request_estop`
is safe from any thread and latches the mux and the watchdog at once.

Every control carried out (and a silent stick's release) is noted in
``run.inputs`` (:mod:`beastbt.run.operator_inputs`) with its tick: the
recording keeps it and ``beastbt replay`` carries it out again, here, at the
same tick.

The remote stick (the page's touch joystick or the browser's gamepad) is a
joystick to teleop (:class:`~beastbt.parts.teleop.TeleopOverride`): the same
deadman, scales, mux, gate and watchdog. Its axes are stick deflections in
[-1, 1] (forward, left turn). The page sends it several times a second while
the deadman is held; when nothing new has come for ``stick_timeout_s`` of wall
time (a lost link, a closed tab), the stick is released, and teleop sends one
zero and hands the robot back. A silent stick is a lost link, not an
operator's choice: that stop is not ramped down by the safety gate's
acceleration limit (the base brakes as hard as it may), so that the command
is zero within ``stick_timeout_s`` plus a tick, well within 0.5 s.
"""

from __future__ import annotations

import json
import math
import queue
from concurrent.futures import Future
from dataclasses import dataclass, field
from typing import Any, Callable, Optional

from beastbt.blackboard.types import JoystickState, VelocityCommand
from beastbt.devices.joystick import AXIS_ANGULAR, AXIS_LINEAR, BUTTON_ENABLE
from beastbt.run.operator_inputs import CONSOLE, STICK_SILENT, TUNE
from beastbt.live.refusal import Refused  # noqa: F401 - the controls' refusal, imported from here by the console

TUNING_CONTROLS = ("tuning", TUNE, "tune_reset", "tune_changes", "tune_saved")
"""Live tuning's controls (:mod:`beastbt.live.tuning`): the listing, a change, a reset, the changes to save and
that they were saved."""
READ_ONLY = ("tuning", "tune_changes")
"""Controls that only ask: carried out on the tick thread like the others, but not operator inputs (nothing to
replay)."""
STICK_TIMEOUT_S = 0.2
"""The remote stick is released when no message came for this long (wall s); the page sends every 0.1 s."""


@dataclass
class Command:
    """One control from the console: ``name`` (pause, resume, abort, answer, teleop, live tuning's), its body, its
    result."""

    name: str
    body: dict = field(default_factory=dict)
    result: Future = field(default_factory=Future)


class ConsoleControls:
    """The queue of controls and the remote stick of one run (see the module docstring).

    ``wall`` is a monotonic wall clock (s), for the stick's timeout.
    """

    def __init__(self, run: Any, wall: Callable[[], float], stick_timeout_s: float = STICK_TIMEOUT_S) -> None:
        self.run = run
        self.wall = wall
        self.stick_timeout_s = stick_timeout_s
        self.pending: "queue.SimpleQueue[Command]" = queue.SimpleQueue()
        self.closed = False
        self.stick_wall_s = -math.inf
        self.stick_held = False
        self.applied = 0
        override = run.ctx.services.teleop
        if override is not None and hasattr(override, "remote_attached"):
            override.remote_attached = True
        run.inputs.sources.add(CONSOLE)

    # -- any thread ------------------------------------------------------------------
    def submit(self, name: str, body: Optional[dict] = None) -> Future:
        """Queue a control for the tick thread; its Future gets a result dict or raises :class:`Refused`."""
        cmd = Command(name, body or {})
        if self.closed or self.run.status is not None:
            cmd.result.set_exception(Refused(409, "the run has ended"))
            return cmd.result
        self.pending.put(cmd)
        self.run.io.wakeup.set()  # on the robot the loop answers between ticks
        return cmd.result

    def close(self) -> None:
        """The run has ended: refuse what is still queued, and everything from now on."""
        self.closed = True
        while True:
            try:
                cmd = self.pending.get_nowait()
            except queue.Empty:
                return
            if not cmd.result.done():
                cmd.result.set_exception(Refused(409, "the run has ended"))

    # -- the tick thread ---------------------------------------------------------------
    def __call__(self, run: Any, now_s: float) -> None:
        """A tick hook (and a reactor): carry out the queued controls, then release a silent stick."""
        self.apply_pending(now_s)

    def apply_pending(self, now_s: float) -> None:
        """Carry out every queued control (the tick thread)."""
        if not self.stick_held and self.pending.empty():
            return  # the usual tick: nothing to do, and no exception raised to find that out
        while True:
            try:
                cmd = self.pending.get_nowait()
            except queue.Empty:
                break
            try:
                outcome = self.apply(cmd, now_s)
            except Refused as exc:
                cmd.result.set_exception(exc)
            except Exception as exc:  # noqa: BLE001 - a bad control must never end the run
                cmd.result.set_exception(Refused(400, f"could not {cmd.name}: {exc}"))
            else:
                # Carried out: recorded with its tick, so that a replay does it again at the same tick (a question
                # that changes nothing, such as the tuning's listing, is not an input).
                if cmd.name not in READ_ONLY:
                    self.run.inputs.note(self.run, CONSOLE, cmd.name, cmd.body, now_s)
                cmd.result.set_result(outcome)
            self.applied += 1
        if self.stick_held and self.wall() - self.stick_wall_s > self.stick_timeout_s:
            self.release_silent_stick(now_s)

    def release_silent_stick(self, now_s: float) -> None:
        """The stick's messages stopped (wall time): stop at once and hand the robot back (recorded for replay)."""
        self._set_stick(0.0, 0.0, False, now_s)
        self.run.mux.submit("teleop", VelocityCommand(0.0, 0.0, now_s, "teleop"), now_s)
        self.run.gate.reset()
        self.run.events.add("teleop", f"console stick silent for {self.stick_timeout_s:g} s (lost link or closed "
                                      f"page): stopped at once, the robot is handed back")
        self.run.inputs.note(self.run, CONSOLE, STICK_SILENT, {}, now_s)

    def apply(self, cmd: Command, now_s: float) -> dict:
        """Carry out one control; raise :class:`Refused` when it cannot be done now."""
        run = self.run
        if run.status is not None:
            raise Refused(409, "the run has ended")
        name = cmd.name
        if name == "pause":
            return {"paused": run.pause("the operator console") or run.operator_paused}
        if name == "resume":
            if not run.operator_paused:
                raise Refused(409, "the mission is not paused")
            run.resume("the operator console")
            return {"paused": False}
        if name == "abort":
            run.abort("the operator console")
            return {"status": "aborted"}
        if name == "answer":
            return self._answer(cmd.body)
        if name == "teleop":
            return self._teleop(cmd.body, now_s)
        if name in TUNING_CONTROLS:
            return self._tuning(name, cmd.body, now_s)
        raise Refused(400, f"unknown control '{name}'")

    def _answer(self, body: dict) -> dict:
        questions = self.run.ctx.services.questions
        question = questions.current() if questions is not None else None
        if question is None:
            raise Refused(409, "no question is open")
        if str(body.get("id")) != question.id:
            raise Refused(409, f"question '{body.get('id')}' is not open; the open one is '{question.id}'")
        if not questions.answer(question.id, body.get("choice"), "console"):
            raise Refused(400, f"choice must be one of {', '.join(question.choices)}, not {body.get('choice')!r}")
        return {"answered": question.id, "choice": questions.answer_of(question.id)}

    def _tuning(self, name: str, body: dict, now_s: float) -> dict:
        """Live tuning (:mod:`beastbt.live.tuning`): list the knobs, set one, reset them, take or mark the changes to
        save."""
        from beastbt.live.tuning import check_tune_body, tuning_of
        registry = tuning_of(self.run)
        if name == "tuning":
            return registry.listing()
        if name == TUNE:
            body = check_tune_body(body)
            return registry.set(body["name"], body["value"], now_s)
        if name == "tune_reset":
            return registry.reset(now_s)
        if name == "tune_changes":
            return {"changes": registry.changes(), "profile_file": getattr(self.run.profile, "file", None),
                    "integers": sorted(n for n, k in registry.knobs.items() if k.integer)}
        values = body.get("values")  # tune_saved
        if not isinstance(values, dict):
            raise Refused(400, "expected {\"values\": {KNOB: NUMBER}}")
        return registry.saved(values)

    def _teleop(self, body: dict, now_s: float) -> dict:
        override = self.run.ctx.services.teleop
        if override is None or not hasattr(override, "remote"):
            raise Refused(409, "this run has no teleop")
        deadman = bool(body["deadman"])
        self._set_stick(float(body["linear"]), float(body["angular"]), deadman, now_s)
        self.stick_wall_s = self.wall()
        allowed = override.allowed() and not self.run.mux.estop_latched
        return {"driving": deadman and allowed,
                "why_not": None if allowed or not deadman else (
                    "the e-stop is latched" if self.run.mux.estop_latched else "this mission does not allow teleop")}

    def _set_stick(self, linear: float, angular: float, deadman: bool, now_s: float) -> None:
        override = self.run.ctx.services.teleop
        if override is None:
            return
        self.stick_held = deadman
        self.run.operator_driving = deadman
        override.remote = JoystickState(now_s, axes={AXIS_LINEAR: max(-1.0, min(1.0, linear)),
                                                     AXIS_ANGULAR: max(-1.0, min(1.0, angular))},
                                        buttons={BUTTON_ENABLE: deadman})


CONTROL_MAX_BYTES = 4096
"""The largest body a control may have (bytes): the biggest, an answer or a stick message, is under 200."""
INT_MAX_DIGITS = 18
"""A whole number in a control's body has at most this many digits (no control means a larger one)."""


def describe(value: Any, limit: int = 40) -> str:
    """``repr(value)`` cut to ``limit`` characters, for an error message (never fails, even on a 10,000-digit int)."""
    if isinstance(value, int) and not isinstance(value, bool) and abs(value) >= 10 ** limit:
        return f"a {len(str(abs(value))) if abs(value).bit_length() < 14000 else 'many'}-digit number"
    text = repr(value)
    return text if len(text) <= limit else text[:limit] + "..."


def _bounded_int(text: str) -> int:
    digits = len(text.lstrip("-"))
    if digits > INT_MAX_DIGITS:
        raise Refused(400, f"a whole number of {digits} digits: no control takes a number that large")
    return int(text)


def _finite_float(text: str) -> float:
    value = float(text)
    if not math.isfinite(value):
        raise Refused(400, f"the number {text[:40]}{'...' if len(text) > 40 else ''} is too large "
                           f"(it is not a finite number)")
    return value


def _no_constant(text: str) -> Any:
    raise Refused(400, f"{text} is not a number a control can take (JSON has no NaN or Infinity)")


def parse_control_body(raw: bytes) -> dict:
    """The JSON object a control sends (an empty body is ``{}``); :class:`Refused` (400) with the reason otherwise.

    Strict where Python's ``json`` is lenient: no ``NaN``/``Infinity``, no number beyond a float's range
    (``1e400``), no whole number of more than :data:`INT_MAX_DIGITS` digits, no nesting that would
    exhaust the interpreter's stack.
    """
    if len(raw) > CONTROL_MAX_BYTES:
        raise Refused(413, f"the body has {len(raw)} bytes: a control is a small JSON object "
                           f"(at most {CONTROL_MAX_BYTES} bytes)")
    if not raw.strip():
        return {}
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError:
        raise Refused(400, "the body is not UTF-8 text: a control is a JSON object") from None
    try:
        body = json.loads(text, parse_int=_bounded_int, parse_float=_finite_float, parse_constant=_no_constant)
    except (json.JSONDecodeError, ValueError) as exc:
        where = f" (line {exc.lineno}, column {exc.colno}: {exc.msg})" if isinstance(exc, json.JSONDecodeError) else ""
        raise Refused(400, f"the body is not JSON{where}") from None
    except RecursionError:
        raise Refused(400, "the body is nested too deeply: a control is a flat JSON object") from None
    if not isinstance(body, dict):
        raise Refused(400, f"expected a JSON object, not {type(body).__name__ if body is not None else 'null'}")
    return body


def check_teleop_body(body: Any) -> dict:
    """The body of ``POST /api/teleop``: ``{linear, angular}`` numbers in [-1, 1] and ``deadman`` true/false."""
    if not isinstance(body, dict):
        raise Refused(400, "expected a JSON object {linear, angular, deadman}")
    out = {}
    for key in ("linear", "angular"):
        value = body.get(key, 0.0)
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise Refused(400, f"'{key}' must be a number from -1 to 1 (stick deflection), not {describe(value)}")
        # compared before any conversion: a huge int must not overflow float() (no OverflowError, ever)
        if (isinstance(value, float) and not math.isfinite(value)) or not -1 <= value <= 1:
            raise Refused(400, f"'{key}' must be from -1 to 1 (stick deflection), not {describe(value)}")
        out[key] = float(value)
    deadman = body.get("deadman")
    if not isinstance(deadman, bool):
        raise Refused(400, f"'deadman' must be true (held) or false, not {describe(deadman)}")
    out["deadman"] = deadman
    return out


def check_answer_body(body: Any) -> dict:
    """The body of ``POST /api/answer``: ``{id, choice}``, two short strings (the question's id, yes or no)."""
    if not isinstance(body, dict) or not isinstance(body.get("id"), str) or not isinstance(body.get("choice"), str):
        raise Refused(400, "expected {\"id\": QUESTION_ID, \"choice\": \"yes\" or \"no\"}")
    if len(body["id"]) > 200 or len(body["choice"]) > 40:
        raise Refused(400, "the question's id or the choice is too long to be one")
    return {"id": body["id"], "choice": body["choice"]}


__all__ = ["ConsoleControls", "Command", "Refused", "TUNING_CONTROLS", "READ_ONLY", "check_teleop_body", "check_answer_body", "parse_control_body",
           "describe", "STICK_TIMEOUT_S", "CONTROL_MAX_BYTES"]
