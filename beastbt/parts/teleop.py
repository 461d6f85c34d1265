"""Teleop in a run: the joystick's say over the robot, its e-stop buttons, the teleop step.

What this part adds to a run:

* **The joystick's say over the robot** (:class:`TeleopOverride`, a
  pre-tick hook, after sensing and before the tree). Teleop follows ROS
  ``teleop_twist_joy`` (:class:`~beastbt.actuation.teleop.TeleopTwistJoy`):
  nothing moves unless the enable (deadman) button is held; while it is, a
  command from the sticks goes to the mux's ``teleop`` source every tick
  (teleop outranks failsafes and the mission); on release exactly one zero
  follows and the source is withdrawn on the next tick.

  - Mission ``teleop: true`` (the default): holding enable pauses the
    mission at once (``run.paused_by == "teleop"``, blackboard
    ``teleop_active`` True). On release the mission carries on at the step it
    was on; that step starts afresh from where the robot now is (a
    ``drive: 3 m`` drives 3 m from there, a ``turn`` to a heading still ends
    at that heading, a ``go_to`` still goes to its place), because its
    progress and stuck timers were measured before the operator moved the
    robot. A ``hold`` failsafe that was holding before is restored.
  - ``teleop: {on_release: abort}``: releasing enable after a take-over ends
    the mission with status ``stopped`` (exit 1) and a ``teleop`` event.
  - ``teleop: false``: holding enable does nothing, except inside a
    ``teleop`` step or after a hand-over below.
  - The ``teleop`` step (:class:`~beastbt.behaviours.teleop.TeleopStep`)
    hands the robot over without pausing the mission (it *is* the mission).
  - ``on_failure: teleop`` and a failsafe's ``then: teleop`` pause the
    mission for the rest of the run; the operator drives whenever enable is
    held. With no joystick they end the mission as ``failure`` instead.

* **The joystick's e-stop buttons**: the e-stop button calls
  :func:`~beastbt.run.safety.request_estop`; the reset button (while the
  e-stop button is not held) calls :func:`~beastbt.run.safety.reset_estop`.
  The latch itself, the mux, the gate and the command watchdog are not part
  of teleop: every run wires them (:mod:`beastbt.run.safety`).

* ``beastbt run ... --joystick FILE`` plays a joystick script on the simulator.

What the mux passes and why is on the blackboard (``mux_source``,
``teleop_active``, ``estop``) and, whenever teleop, a failsafe or the e-stop
is involved, in the run's ``mux`` events.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Mapping, Optional

import py_trees

from beastbt.behaviours.teleop import JOYSTICK_MAX_AGE_S, TeleopStep
from beastbt.blackboard.types import JoystickState
from beastbt.mission.compile import Compiler, StepBuilder
from beastbt.core.errors import InvalidInput, Position, Problem
from beastbt.mission import steps as st
from beastbt.core.units import format_quantity
from beastbt.robot.part import Part
from beastbt.run.session import Prepared

if TYPE_CHECKING:  # annotations only: `beastbt tree` loads this part (for its steps) without a run
    from beastbt.actuation.teleop import TeleopConfig
    from beastbt.run.runner import MissionRun
# The teleop mapping, the gamepad presets and the e-stop wiring are imported by the run's own code below (the
# override, the scripted joystick, the summary), not here: `beastbt tree` loads this part for its step only.

Status = py_trees.common.Status

PAUSE_TELEOP = "teleop"
"""``run.paused_by`` while the operator has taken over a mission with ``teleop: true``."""
PAUSE_ON_FAILURE = "on_failure teleop"
"""``run.paused_by`` after the steps failed and the robot was handed to the operator."""
QUIET_SOURCES = frozenset({"none", "mission"})
"""Mux changes between these alone are routine (start, end) and make no event."""


class TeleopOverride:
    """The joystick's say over one run: teleop, take-over and resume, the joystick e-stop.

    Called by the runner every tick as ``override(run, now_s)``; also the
    ``teleop`` service the teleop step talks to. Counters: ``takeovers``,
    ``teleop_time_s`` (seconds with enable held).
    """

    def __init__(self, run: MissionRun, config: Optional[TeleopConfig] = None) -> None:
        from beastbt.actuation.teleop import TeleopTwistJoy
        from beastbt.devices.joystick import BUTTON_ENABLE

        self.run = run
        self.teleop = TeleopTwistJoy(config)
        self._button_enable = BUTTON_ENABLE
        """The ``JoystickState.buttons`` key of the enable (dead-man) button (``devices.joystick.BUTTON_ENABLE``)."""
        self.handovers: set[int] = set()
        """Teleop steps running now (the operator drives without pausing the mission)."""
        self.operator_control: Optional[str] = None
        """Why the robot belongs to the operator for the rest of the run (on_failure / failsafe teleop)."""
        self.took_over = False
        """True while a ``teleop: true`` take-over has the mission paused."""
        self.saved_pause: Optional[str] = None
        self.withdraw_next = False
        self.reset_was_pressed = False
        self.last_source = "none"
        self.takeovers = 0
        self.teleop_time_s = 0.0
        self._active_since_s: Optional[float] = None
        self.remote: Optional[JoystickState] = None
        """The operator console's on-page stick or browser gamepad (set by the console on the tick thread), or None."""
        self.remote_attached = False
        """True when an operator console can drive this run (it counts as a joystick for hand-overs)."""

    # -- what the teleop step and the runner's handlers use --------------------------
    @property
    def has_joystick(self) -> bool:
        """True when the robot has a joystick device (it may be unplugged right now)."""
        return self.run.io.joystick is not None or self.remote_attached

    def no_joystick_hint(self) -> str:
        """How to give this run a joystick: a script on the simulator, the gamepad on a robot, or the console."""
        if self.run.io.sim is not None:
            return ("on the simulator, play a joystick script with --joystick FILE (e.g. "
                    "missions/joystick/teleop_demo.yaml), or drive from the operator console: --console 8080")
        return "plug in the gamepad (beastbt doctor checks it), or drive from the operator console: --console 8080"

    def request_handover(self, step: Any) -> None:
        """A teleop step starts: the operator may drive while it runs, without pausing the mission."""
        self.handovers.add(id(step))

    def release_handover(self, step: Any) -> None:
        """A teleop step ended."""
        self.handovers.discard(id(step))

    def on_failure(self, run: MissionRun) -> None:
        """``on_failure: teleop``: the operator has the robot until the run is ended (no joystick: failure)."""
        self._hand_to_operator(run, PAUSE_ON_FAILURE, "the steps failed")

    def on_failsafe(self, run: MissionRun, spec: Any) -> None:
        """A failsafe's ``then: teleop``: the operator has the robot until the run is ended (no joystick: failure)."""
        self._hand_to_operator(run, f"failsafe teleop ({spec.kind})", f"failsafe {spec.kind}")

    def _hand_to_operator(self, run: MissionRun, pause: str, why: str) -> None:
        if not self.has_joystick:
            run.events.add("teleop", f"{why}, but there is no joystick to hand over to: stopping; "
                                     f"{self.no_joystick_hint()}")
            run.finish("failure", f"{why}; teleop: no joystick")
            return
        self.operator_control = pause
        self.took_over = False
        self.saved_pause = None
        run.paused_by = pause
        run.events.add("teleop", f"{why}: the operator has the robot (hold enable to drive) until the run is ended")

    # -- the tick ---------------------------------------------------------------------
    def joystick(self, now_s: float) -> Optional[JoystickState]:
        """This tick's joystick state, or None when there is none, it is unplugged or stale.

        The console's remote stick, when there is one, counts while its deadman
        is held, or when there is no usable joystick (so that its release is seen).
        """
        js = self.run.latest.get(JoystickState)
        if js is None or not js.connected or now_s - js.stamp_s > JOYSTICK_MAX_AGE_S:
            js = None
        remote = self.remote
        if remote is not None and (js is None or remote.buttons.get(self._button_enable, False)):
            return remote
        return js

    def allowed(self) -> bool:
        """May the operator drive now? (teleop: true, a teleop step running, or a hand-over.)"""
        return self.run.mission.teleop_override or bool(self.handovers) or self.operator_control is not None

    def __call__(self, run: MissionRun, now_s: float) -> None:
        """One tick (after sensing, before the tree): e-stop buttons, teleop to the mux, pause and resume."""
        self._report_mux(run)
        if self.withdraw_next:
            run.mux.withdraw("teleop")
            self.withdraw_next = False
        js = self.joystick(now_s)
        self._estop_buttons(run, js)
        usable = js if self.allowed() and not run.mux.estop_latched else None
        was_active = self.teleop.active
        cmd = self.teleop.update(usable, now_s)
        if cmd is not None:
            run.mux.submit("teleop", cmd, now_s)
        if self.teleop.active:
            if not was_active:
                self._on_press(run, now_s)
            self._keep_paused(run)
        elif was_active:
            # The one zero was submitted above; the source goes on the next tick so that the mission,
            # not a stale teleop zero, drives from then on.
            self.withdraw_next = True
            self._on_release(run, now_s)
        # As the catalogue says: the operator holds enable (even where teleop may not drive, so that a
        # teleop: false mission can wait for it).
        held = js is not None and bool(js.buttons.get(self._button_enable, False))
        run.bb.teleop_active = self.teleop.active or held

    def _report_mux(self, run: MissionRun) -> None:
        source = run.mux.source
        if source != self.last_source:
            if not {source, self.last_source} <= QUIET_SOURCES:
                run.events.add("mux", f"{self.last_source} -> {source}: {run.mux.reason}")
            self.last_source = source

    def _estop_buttons(self, run: MissionRun, js: Optional[JoystickState]) -> None:
        pressed = self.teleop.estop_pressed(js)
        if pressed and not run.mux.estop_latched:
            from beastbt.run.safety import request_estop
            request_estop(run, "joystick e-stop button")
        reset = self.teleop.estop_reset_pressed(js)
        if reset and not self.reset_was_pressed and not pressed and run.mux.estop_latched:
            from beastbt.run.safety import reset_estop
            reset_estop(run, "joystick reset button")
        self.reset_was_pressed = reset

    def _on_press(self, run: MissionRun, now_s: float) -> None:
        self.takeovers += 1
        self._active_since_s = now_s
        if self.handovers:
            run.events.add("teleop", "enable held: the operator drives (teleop step)")
        elif self.operator_control is not None:
            run.events.add("teleop", "enable held: the operator drives")
        else:
            self.took_over = True
            self.saved_pause = run.paused_by
            where = run.current_step() if run.paused_by is None else f"({run.paused_by})"
            run.events.add("teleop", f"enable held: the operator takes over; mission paused at {where}")

    def _keep_paused(self, run: MissionRun) -> None:
        if not self.took_over or self.operator_control is not None:
            return
        if run.paused_by != PAUSE_TELEOP:
            # A failsafe may have asked to hold meanwhile: remember it for the release.
            if run.paused_by is not None:
                self.saved_pause = run.paused_by
            run.paused_by = PAUSE_TELEOP

    def _on_release(self, run: MissionRun, now_s: float) -> None:
        if self._active_since_s is not None:
            self.teleop_time_s += now_s - self._active_since_s
            self._active_since_s = None
        if not self.took_over:
            run.events.add("teleop", "enable released: one zero command sent")
            return
        self.took_over = False
        if run.status is not None:
            return
        if run.mission.teleop_on_release == "abort":
            run.events.add("teleop", "enable released: one zero command sent; the mission ends (on_release: abort)")
            run.finish("stopped", "the operator released the deadman (teleop on_release: abort)")
            return
        saved, self.saved_pause = self.saved_pause, None
        if saved is not None and saved.startswith("hold") and not run.failsafes.holding():
            saved = None
        run.paused_by = saved
        if saved is not None:
            run.events.add("teleop", f"enable released: one zero command sent; the mission stays paused ({saved})")
            return
        restarted = restart_running_leaves(run.root)
        at = ", ".join(restarted) if restarted else run.current_step()
        run.events.add("teleop", f"enable released: one zero command sent; the mission resumes at {at}")


def restart_running_leaves(root: py_trees.behaviour.Behaviour) -> list[str]:
    """Make every running leaf start afresh on its next tick (its parents keep their place); return their names."""
    names = []
    for node in root.iterate():
        if not node.children and node.status == Status.RUNNING:
            node.stop(Status.INVALID)
            names.append(node.name)
    return names


# -- the part -------------------------------------------------------------------------------

def _teleop_step(c: Compiler, s: st.Teleop) -> py_trees.behaviour.Behaviour:
    if s.duration_s is not None:
        return TeleopStep(f"teleop for {format_quantity(s.duration_s, 'duration')}", c.ctx, duration_s=s.duration_s)
    return TeleopStep("teleop until released", c.ctx, until_released=True)


def attach_joystick_script(prepared: Prepared) -> None:
    """``--joystick FILE``: play a scripted joystick through the real driver (simulator only)."""
    run, io = prepared.run, prepared.run.io
    spec = prepared.options.joystick_script
    if spec is None:
        return
    if io.sim is None:
        raise InvalidInput([Problem(str(spec), Position(), "--joystick plays a scripted joystick on the simulator only",
                                    "add --sim to run this robot profile on the simulator, or drop --joystick "
                                    "to drive with the real gamepad")])
    from beastbt.devices.gamepad_presets import SIMULATED_PAD_NAME
    from beastbt.parts.sim_joystick import attach_scripted_joystick, load_joystick_script
    from beastbt.robot.actuator_profile import joystick_mapping
    mapping = joystick_mapping(prepared.profile).for_device(SIMULATED_PAD_NAME)[0]  # the sim's pad: an Xbox layout
    script = load_joystick_script(spec, mapping)
    attach_scripted_joystick(io.sim, io, prepared.clock, prepared.events, script, mapping)
    run.ctx.capabilities = frozenset(run.ctx.capabilities | {"joystick"})


def teleop_summary(run: Any, summary: dict) -> None:
    """``teleop: {joystick, takeovers, teleop_time_s, estop_latched, watchdog_trips}``."""
    from beastbt.run.safety import watchdog_of

    override = run.ctx.services.teleop
    dog = watchdog_of(run)
    if not isinstance(override, TeleopOverride):
        return
    summary["teleop"] = {
        "joystick": override.has_joystick,
        "takeovers": override.takeovers,
        "teleop_time_s": round(override.teleop_time_s, 3),
        "estop_latched": bool(run.mux.estop_latched),
        "watchdog_trips": dog.trips if dog is not None else 0,
    }


class TeleopPart(Part):
    """Teleop: the joystick's say over the run (take-over, hand-over, e-stop buttons) and the teleop step."""

    name = "teleop"
    section = "teleop"
    schema = "parts/teleop.schema.json"
    fills = ("teleop_active", "mux_source")
    reads = ("joystick",)
    takes = ("velocity (teleop source of the mux)",)

    def steps(self) -> Mapping[str, StepBuilder]:
        """teleop."""
        return {"teleop": _teleop_step}

    def __init__(self) -> None:
        self.override: Optional[TeleopOverride] = None

    def install(self, prepared: Prepared) -> None:
        """A scripted joystick if asked for; the override and its handlers as services; the summary."""
        from beastbt.robot.actuator_profile import teleop_config

        attach_joystick_script(prepared)
        run = prepared.run
        override = self.override = TeleopOverride(run, teleop_config(run.profile))
        run.ctx.services.teleop = override
        run.ctx.services.on_failure["teleop"] = override.on_failure
        run.ctx.services.failsafe["teleop"] = override.on_failsafe
        if run.io.joystick_watcher is not None:
            run.reactors.append(self.react)

    def react(self, run: MissionRun, now_s: float) -> None:
        """Joystick input between ticks: read it, and give it its say at once (e-stop, teleop to the mux)."""
        poll = run.io.sensors.get("joystick")
        watcher = run.io.joystick_watcher
        if poll is None or self.override is None:
            return
        try:
            states = poll(now_s)
        finally:
            if watcher is not None:
                watcher.drained()
        for state in states:
            run.latest[JoystickState] = state
            run.bb.joystick = state
        run.read_between_ticks.extend(states)  # recorded with the next tick: a replay sees them too
        self.override(run, now_s)

    def summarise(self, run: MissionRun, summary: dict) -> None:
        """``teleop``: joystick, take-overs, time driven by the operator, e-stop, watchdog trips."""
        teleop_summary(run, summary)

    def tick(self, run: MissionRun, now_s: float) -> None:
        """The joystick's say this tick: e-stop buttons, teleop to the mux, pause and resume."""
        if self.override is not None:
            self.override(run, now_s)


__all__ = ["TeleopPart", "TeleopOverride", "restart_running_leaves", "attach_joystick_script", "teleop_summary",
           "PAUSE_TELEOP", "PAUSE_ON_FAILURE"]
