"""Teleop, the emergency stop and the adapter watchdog in every run.

What this module adds to a run (it registers itself through the runner's,
the session's, the compiler's and the CLI's hooks):

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

* **The emergency stop**: the joystick's e-stop button, :func:`request_estop`
  (the API, callable from any thread) and, on the command line, Ctrl-C (or
  SIGTERM on the robot), which the session turns into a zero command and
  status ``stopped``. :func:`request_estop` latches the mux and the
  watchdog's adapter-side latch; the runner then ends the mission with
  status ``stopped`` and sends the base's own stop once. Only
  :func:`reset_estop` (API) or the joystick's reset button (while the
  e-stop button is not held) clears it. Each is an ``estop`` event.

* **The watchdog** (:class:`~beastbt.actuation.watchdog.AdapterWatchdog`)
  wraps every run's base adapter: on the robot a thread sends zero when the
  tick loop has not handed over a fresh command for ``watchdog.timeout_s``;
  in the simulator the simulator checks it at each physics step.

* ``beastbt run ... --joystick FILE`` plays a joystick script on the simulator.

What the mux passes and why is on the blackboard (``mux_source``,
``teleop_active``, ``estop``) and, whenever teleop, a failsafe or the e-stop
is involved, in the run's ``mux`` events.
"""

from __future__ import annotations

import atexit
import signal
import threading
from typing import Any, Optional

import py_trees

from beastbt.actuation.teleop import TeleopConfig, TeleopTwistJoy
from beastbt.actuation.watchdog import AdapterWatchdog, LockedServos
from beastbt.behaviours.teleop import JOYSTICK_MAX_AGE_S, TeleopStep
from beastbt.blackboard.types import JoystickState
from beastbt.cli import RUN_OPTIONS
from beastbt.devices.joystick import BUTTON_ENABLE
from beastbt.mission.compile import Compiler, register_step
from beastbt.core.errors import InvalidInput, Position, Problem
from beastbt.mission.model import Step
from beastbt.core.units import format_quantity, parse_quantity
from beastbt.robot.actuator_profile import joystick_mapping, teleop_config, watchdog_config
from beastbt.run.runner import PRE_TICK_HOOKS, MissionRun
from beastbt.run.session import PREPARE_HOOKS, Prepared
from beastbt.run.summary import SUMMARY_CONTRIBUTORS

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
        self.run = run
        self.teleop = TeleopTwistJoy(config)
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

    # -- what the teleop step and the runner's handlers use --------------------------
    @property
    def has_joystick(self) -> bool:
        """True when the robot has a joystick device (it may be unplugged right now)."""
        return self.run.io.extras.get("joystick") is not None

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
            run.events.add("teleop", f"{why}, but there is no joystick to hand over to: stopping")
            run.finish("failure", f"{why}; teleop: no joystick")
            return
        self.operator_control = pause
        self.took_over = False
        self.saved_pause = None
        run.paused_by = pause
        run.events.add("teleop", f"{why}: the operator has the robot (hold enable to drive) until the run is ended")

    # -- the tick ---------------------------------------------------------------------
    def joystick(self, now_s: float) -> Optional[JoystickState]:
        """This tick's joystick state, or None when there is none, it is unplugged or stale."""
        js = self.run.latest.get(JoystickState)
        if js is None or not js.connected or now_s - js.stamp_s > JOYSTICK_MAX_AGE_S:
            return None
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
        run.bb.teleop_active = self.teleop.active or (js is not None and bool(js.buttons.get(BUTTON_ENABLE, False)))

    def _report_mux(self, run: MissionRun) -> None:
        source = run.mux.source
        if source != self.last_source:
            if not {source, self.last_source} <= QUIET_SOURCES:
                run.events.add("mux", f"{self.last_source} -> {source}: {run.mux.reason}")
            self.last_source = source

    def _estop_buttons(self, run: MissionRun, js: Optional[JoystickState]) -> None:
        pressed = TeleopTwistJoy.estop_pressed(js)
        if pressed and not run.mux.estop_latched:
            request_estop(run, "joystick e-stop button")
        reset = TeleopTwistJoy.estop_reset_pressed(js)
        if reset and not self.reset_was_pressed and not pressed and run.mux.estop_latched:
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


# -- the emergency stop API ---------------------------------------------------------------

def _watchdog(run: MissionRun) -> Optional[AdapterWatchdog]:
    base = run.io.base
    return base if isinstance(base, AdapterWatchdog) else None


def request_estop(run: MissionRun, reason: str = "API request") -> bool:
    """Latch the emergency stop of ``run`` (any thread); False when it was already latched.

    The mux outputs zero from now on; the runner ends the mission with status
    ``stopped`` on its next tick and sends the base's own stop once; the
    watchdog refuses motion below the mux and sends that stop itself if the
    loop does not within ``watchdog.estop_grace_s``.
    """
    first = not run.mux.estop_latched
    run.mux.latch_estop(reason)
    dog = _watchdog(run)
    if dog is not None:
        dog.latch_estop(reason)
    if first:
        run.events.add("estop", f"emergency stop latched: {reason}")
    return first


def reset_estop(run: MissionRun, reason: str = "API request") -> bool:
    """Clear a latched emergency stop (an explicit operator action); False when none was latched.

    The safety gate forgets its last output, so motion starts again from rest.
    """
    dog = _watchdog(run)
    latched = run.mux.estop_latched or (dog is not None and dog.estop_latched)
    if not latched:
        return False
    run.mux.reset_estop()
    if dog is not None:
        dog.reset_estop()
    run.gate.reset()
    run.events.add("estop", f"emergency stop reset: {reason}")
    return True


# -- registration -------------------------------------------------------------------------

def _override_for(run: MissionRun) -> TeleopOverride:
    override = TeleopOverride(run, teleop_config(run.profile))
    run.ctx.services["teleop"] = override
    run.ctx.services["on_failure_teleop"] = override.on_failure
    run.ctx.services["failsafe_teleop"] = override.on_failsafe
    return override


PRE_TICK_HOOKS.append(_override_for)


@register_step("teleop")
def _teleop_step(c: Compiler, s: Step) -> py_trees.behaviour.Behaviour:
    v = s.value
    if "for" in v:
        duration = parse_quantity(v["for"], "duration")
        return TeleopStep(f"teleop for {format_quantity(duration, 'duration')}", c.ctx, duration_s=duration)
    return TeleopStep("teleop until released", c.ctx, until_released=True)


def _add_joystick_option(p: Any) -> None:
    p.add_argument("--joystick", metavar="FILE",
                   help="simulator only: play a joystick script (YAML list such as [{at: 2 s, press: enable}, "
                        "{at: 2.5 s, linear: 0.8}, {at: 6 s, release: enable}]) through the real joystick driver")


RUN_OPTIONS.append(_add_joystick_option)


def install_watchdog(prepared: Prepared) -> AdapterWatchdog:
    """Wrap the run's base in the watchdog: a thread on the robot, checked by the simulator in the sim."""
    io = prepared.run.io
    if isinstance(io.base, AdapterWatchdog):
        return io.base
    dog = AdapterWatchdog(io.base, prepared.clock, watchdog_config(prepared.profile), prepared.events.sink("watchdog"))
    # A base that also drives servos (the Waveshare gimbal) must share the watchdog's lock.
    io.servos = [LockedServos(s, dog.lock) if s is dog.inner else s for s in io.servos]
    io.base = dog
    io.extras["watchdog"] = dog
    if io.sim is not None:
        io.sim.emulators.append(lambda t_s, dt_s: dog.check(t_s))
        return dog
    dog.start_thread()
    # Whatever ends the process, the last bytes on the wire are a stop (close is idempotent).
    atexit.register(dog.close)
    if threading.current_thread() is threading.main_thread():
        previous = signal.getsignal(signal.SIGTERM)

        def on_sigterm(signum: int, frame: Any) -> None:
            raise KeyboardInterrupt("SIGTERM")

        signal.signal(signal.SIGTERM, on_sigterm)
        prepared.closers.append(lambda: signal.signal(signal.SIGTERM, previous))
    return dog


def _prepare(prepared: Prepared) -> None:
    """Attach a scripted joystick (``--joystick``, simulator only) and install the watchdog."""
    run, io = prepared.run, prepared.run.io
    spec = prepared.options.extras.get("joystick")
    if spec is not None:
        if io.sim is None:
            raise InvalidInput([Problem(str(spec), Position(), "--joystick plays a scripted joystick on the simulator only",
                                        "add --sim to run this robot profile on the simulator, or drop --joystick "
                                        "to drive with the real gamepad")])
        from beastbt.parts.sim_joystick import attach_scripted_joystick, load_joystick_script
        mapping = joystick_mapping(prepared.profile)
        script = load_joystick_script(spec, mapping)
        attach_scripted_joystick(io.sim, io, prepared.clock, prepared.events, script, mapping)
        run.ctx.capabilities = frozenset(run.ctx.capabilities | {"joystick"})
    install_watchdog(prepared)


PREPARE_HOOKS.append(_prepare)


def _summary(run: Any, summary: dict) -> None:
    override = run.ctx.services.get("teleop")
    dog = run.io.extras.get("watchdog")
    if not isinstance(override, TeleopOverride):
        return
    summary["teleop"] = {
        "joystick": override.has_joystick,
        "takeovers": override.takeovers,
        "teleop_time_s": round(override.teleop_time_s, 3),
        "estop_latched": bool(run.mux.estop_latched),
        "watchdog_trips": dog.trips if dog is not None else 0,
    }


SUMMARY_CONTRIBUTORS.append(_summary)


__all__ = ["TeleopOverride", "request_estop", "reset_estop", "install_watchdog", "restart_running_leaves",
           "PAUSE_TELEOP", "PAUSE_ON_FAILURE"]
