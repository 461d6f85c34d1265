"""One ``beastbt run``: the options, the assembled run, and the loop that paces it.

:func:`beastbt.assembly.prepare` does all the checking (mission, profile,
world) and assembles the run before anything moves; :func:`execute` runs the
loop at the requested speed, handles Ctrl-C and SIGTERM, always ends with a
stop command, and writes the summary and run folder.
"""

from __future__ import annotations

import gc
import json
import signal
import sys
import threading
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Mapping, Optional, TextIO, Union

from beastbt.mission.model import Mission
from beastbt.core.clock import Clock, SimClock, WallClock
from beastbt.core.events import EventLog
from beastbt.robot.profile import RobotProfile
from beastbt.run.run_folder import RunFolder, save_text
from beastbt.run.operator_inputs import TERMINAL
from beastbt.run.sd_notify import process_notifier
from beastbt.run.summary import build_summary

if TYPE_CHECKING:  # annotations only: the parts import Prepared, and `beastbt tree` needs no tick loop nor world
    from beastbt.run.runner import MissionRun
    from beastbt.sim.world import World

DEFAULT_SIM_MAX_TIME_S = 3600.0
"""A simulated run with no --max-time ends after this much simulated time (s)."""


@dataclass
class RunOptions:
    """How to run a mission (the options of ``beastbt run``); times in seconds.

    ``speed`` is ``max``, ``realtime`` or a factor of real time. ``simulate``
    runs a real robot profile on the simulator (``--sim``).
    """

    robot: str = "sim"
    world: Optional[str] = None
    seed: int = 0
    speed: Union[str, float] = "max"
    max_time_s: Optional[float] = None
    summary_path: Optional[str] = None
    record_path: Optional[str] = None
    runs_dir: str = "runs"
    record: bool = True
    status_line: bool = False
    simulate: bool = False
    """Run a real robot profile on the simulator, with its geometry and limits (``--sim``)."""
    joystick_script: Optional[Union[str, Path, list]] = None
    """A scripted joystick played on the simulator (``--joystick FILE``): a file, or the list of events itself."""
    stream: Optional[Union[str, tuple[str, int]]] = None
    """Serve the camera live as MJPEG on ``[HOST:]PORT`` (``--stream``)."""
    console: Optional[Union[str, tuple[str, int]]] = None
    """Serve the operator console on ``[HOST:]PORT`` (``--console``): live state, map, tree, video and controls."""
    console_token: str = "auto"
    """``auto``: the console needs its token off loopback only; ``always``: on loopback too (``--console-token``)."""
    answers: Optional[Mapping[str, str]] = None
    """Answers to the mission's questions given before the run (``--answer ID=yes``): question id -> yes/no."""
    foxglove: Optional[Union[str, tuple[str, int]]] = None
    """Serve the recording's channels live to Foxglove (WebSocket) on ``[HOST:]PORT`` (``--foxglove``)."""
    stream_size: Optional[Union[str, tuple[int, int]]] = None
    """Streamed frame size, ``WxH`` or (width, height) pixels (``--stream-size``)."""
    stream_quality: Optional[int] = None
    """Streamed JPEG quality, 1-100 (``--stream-quality``)."""
    stream_fps: Optional[float] = None
    """Most frames streamed per second, Hz (``--stream-fps``)."""
    stream_overlay: bool = True
    """Draw the detected line and the step on the streamed frames (``--stream-no-overlay`` clears it)."""
    record_images_hz: Optional[float] = None
    """Camera images recorded per second as JPEG (``--record-images``); None: the recording's default."""
    keep_runs: Optional[int] = None
    """Keep the newest N finished runs in ``runs_dir``, pruning older ones when this run starts
    (``--keep-runs``; over the profile's ``runs: keep``)."""
    record_sensors: bool = False
    """Record every sensor, keeping awake those the run does not read (``--record-sensors``); by default a
    recording holds what the run used, and the parts nothing reads stay asleep."""
    fleet: Optional[Any] = None
    """Report to a fleet's station on Zenoh (``--fleet``): a :class:`beastbt.fleet.config.FleetOptions`."""
    recording: Optional[Mapping[str, Any]] = None
    """Recording settings (the fields of ``recording.config.RecordingConfig``), for tests and benchmarks."""
    build_map: Optional[str] = None
    """Build a map with the LiDAR while the run goes on and write it here (map_server YAML) at its end
    (``--build-map``)."""
    map_resolution_m: Optional[float] = None
    """The built map's cell size, metres (``--map-resolution``; default 5 cm)."""
    files_inside: Optional[str] = None
    """Read the files the mission names (``world:``, ``map:``, route files) only inside this folder, or shipped ones
    by name (``--files-inside``; :mod:`beastbt.core.file_refs`); None: anywhere, as written."""
    ros2: Optional[Mapping[str, Any]] = None
    """Show the run to ROS 2 over Zenoh (``--ros2``): ``{listen, config, on_goal}`` (docs/ros2.md); None: off."""

    @property
    def simulated(self) -> bool:
        """True when the run is on the simulator (``robot: sim`` or ``--sim``)."""
        return self.robot == "sim" or self.simulate


@dataclass
class Prepared:
    """A run assembled and checked, not yet started."""

    mission: Mission
    profile: RobotProfile
    world: Optional[World]
    run: MissionRun
    options: RunOptions
    events: EventLog
    clock: Clock
    folder: Optional[RunFolder] = None
    closers: list[Callable[[], None]] = field(default_factory=list)
    after_summary: list[Callable[[Optional[dict]], None]] = field(default_factory=list)
    """Called with the run's summary once it is written (after the closers), or with None when the run is
    abandoned: what tells others the run has ended (the fleet's station) must not tell them before its summary
    can be read."""
    warnings: list = field(default_factory=list)
    """Problems (severity ``warning``) of the mission on this robot: printed before the run; ``--strict`` refuses."""
    reads: Optional[frozenset] = None
    """What the run and its awake parts read (blackboard keys and readings): the recording keeps those
    readings only, unless ``--record-sensors``. None: not known (everything is kept)."""

    def abandon(self) -> None:
        """Release what was opened without running (the base sends its stop) and remove the unused run folder."""
        for close in self.closers:
            try:
                close()
            except Exception:  # noqa: BLE001 - closing must not hide why the run was abandoned
                pass
        self.run.io.close()
        _tell_ended(self, None)
        if self.folder is not None:
            import shutil
            shutil.rmtree(self.folder.path, ignore_errors=True)  # made for this run, which never started


def parse_speed(text: str) -> Union[str, float]:
    """``max``, ``realtime`` or a positive factor (``10``, ``0.5``)."""
    if text in ("max", "realtime"):
        return text
    try:
        factor = float(text)
    except ValueError:
        raise ValueError(f"--speed takes max, realtime or a factor such as 10, not '{text}'")
    if factor <= 0:
        raise ValueError("--speed factor must be greater than zero")
    return factor


REACT_MIN_INTERVAL_S = 0.005
"""Between ticks, input is answered at most this often (s): a stick sweep sends hundreds of events a second,
and each answer writes to the base (a T:1 line is about 30 bytes at 115200 baud)."""


def wait_for_tick(run: Any, clock: Any, deadline_s: float) -> None:
    """Sleep until the next tick at ``deadline_s`` (clock s), answering device input meanwhile (:meth:`MissionRun.react`)."""
    wakeup = run.io.wakeup
    if not run.reactors:
        clock.sleep_until(deadline_s)
        return
    last = -1.0
    while True:
        remaining = deadline_s - clock.now()
        if remaining <= 0 or not wakeup.wait(remaining):
            return
        wakeup.clear()
        now = clock.now()
        if now - last < REACT_MIN_INTERVAL_S:
            clock.sleep_until(min(deadline_s, last + REACT_MIN_INTERVAL_S))
            now = clock.now()
        last = now
        run.react(now)


def execute(p: Prepared, out: TextIO = sys.stdout, wall: Optional[WallClock] = None) -> dict:
    """Run the loop until the mission ends (or max time, or Ctrl-C); return the summary.

    ``wall`` is the wall clock (s) that paces a simulation at ``--speed realtime``
    or a factor, throttles the status line and times the run (``wall_time_s``);
    a new :class:`WallClock` when not given.
    """
    wall = wall if wall is not None else WallClock()
    run, clock, opts = p.run, p.clock, p.options
    dt = 1.0 / p.mission.rate_hz
    simulated = isinstance(clock, SimClock)
    max_time = opts.max_time_s if opts.max_time_s is not None else (DEFAULT_SIM_MAX_TIME_S if simulated else None)
    factor = None if opts.speed == "max" else (1.0 if opts.speed == "realtime" else float(opts.speed))
    say_listener = _console_listener(out, opts.status_line)
    p.events.listeners.append(say_listener)
    wall0 = wall.now()
    last_status_wall = 0.0
    tty = opts.status_line
    restore_sigterm = _sigterm_as_interrupt()
    terminal = TerminalAnswers(run.ctx.services.questions, out, run) if tty and sys.stdin.isatty() else None
    unanswerable = (UnanswerableQuestions(run.ctx.services.questions, p.events)
                    if terminal is None and opts.console is None and opts.fleet is None else None)
    # Everything built so far (modules, the tree, drivers, the simulator) lives for the whole run: move it
    # out of the garbage collector's sight, so that a full collection during the run walks only what the run
    # made since, instead of pausing a tick for tens of milliseconds. Given back when the loop ends.
    gc.freeze()
    pacing: Optional[float] = factor
    anchor = wall0
    notifier = process_notifier()
    notifier.ready(f"running mission {p.mission.name}")
    try:
        while run.status is None:
            run.tick()
            notifier.watchdog()  # under systemd: a tick that never returns stops this, and the unit is restarted
            if run.status is not None:
                break
            if max_time is not None and run.elapsed_s + dt > max_time + 1e-9:
                run.finish("stopped", f"max time {max_time:g} s reached")
                break
            if simulated:
                clock.advance(dt)
                # While the operator holds the mission or drives, a fast simulation runs in real time:
                # the robot waits for a person, not the other way round (and max time is not raced to).
                pace = 1.0 if factor is None and (run.operator_paused or run.operator_driving) else factor
                if pace != pacing:
                    pacing, anchor = pace, wall.now() - clock.now() / pace if pace else 0.0
                if pace is not None:
                    wall.sleep_until(anchor + clock.now() / pace)
            else:
                wait_for_tick(run, clock, run.start_s + run.ticks * dt)
            if tty and terminal is not None:
                terminal.poll()
            if unanswerable is not None:
                unanswerable.poll()
            if tty:
                now_wall = wall.now()
                if now_wall - last_status_wall > 0.1:
                    last_status_wall = now_wall
                    out.write(status_line(run))
                    out.flush()
    except KeyboardInterrupt as exc:
        run.stop_robot(clock.now())
        run.finish("stopped", f"interrupted ({'SIGTERM' if str(exc) == 'SIGTERM' else 'Ctrl-C'})")
    except Exception as exc:
        # Whatever broke, the robot must not keep moving: stop first, then report.
        run.stop_robot(clock.now())
        run.finish("failure", f"internal error: {exc!r}")
        raise
    finally:
        gc.unfreeze()
        restore_sigterm()
        notifier.status(f"mission {p.mission.name} ended: {run.status}")
        run.stop_robot(clock.now())
        run.events.drain()  # what other threads said last goes to the recording before it closes
        for close in p.closers:
            try:
                close()
            except Exception:
                pass
        run.io.close()
        if tty:
            out.write(CLEAR_LINE)
    wall_time_s = wall.now() - wall0
    world_name = p.world.name if p.world is not None else None
    summary = build_summary(run, opts.seed, wall_time_s, world_name, p.profile.name)
    keep_summary(p, summary, out)
    _tell_ended(p, summary)
    return summary


def _tell_ended(p: Prepared, summary: Optional[dict]) -> None:
    """Call ``p.after_summary`` with the summary (None: abandoned); one failing does not stop the others."""
    for ended in p.after_summary:
        try:
            ended(summary)
        except Exception as exc:  # noqa: BLE001 - the run is over and recorded: say it, go on
            print(f"beastbt: after the run: {exc!r}", file=sys.stderr, flush=True)


def keep_summary(p: Prepared, summary: dict, out: TextIO) -> None:
    """Write the summary to ``--summary`` and the run folder; what cannot be written (a full disk) is said on
    standard error, and a summary written nowhere is printed on ``out`` as JSON, so that it is never lost."""
    opts = p.options
    wanted = saved = 0
    problems = []
    if opts.summary_path:
        wanted += 1
        problem = save_text(Path(opts.summary_path), json.dumps(summary, indent=2) + "\n")
        saved += problem is None
        problems += [problem] if problem else []
    if p.folder is not None:
        wanted += 1
        problems += p.folder.finish(summary)
        saved += p.folder.summary_written
    for problem in problems:
        print(f"beastbt: {problem}", file=sys.stderr, flush=True)
    if p.folder is not None:
        out.write(f"run recorded in {p.folder.path}\n")
    if wanted and not saved:
        out.write("the run summary (written nowhere else):\n" + json.dumps(summary, indent=2) + "\n")


CONSOLE_EVENTS = frozenset({"mission_end", "failsafe", "estop", "step_failed", "device_error", "on_failure", "ask",
                            "answer", "guard",
                            "snapshot", "bus_servo_error", "base_speed_clamped", "camera_backend", "joystick_preset",
                            "recording"})
"""Events printed on the terminal as they happen (all of them are in the summary and the recording)."""


CLEAR_LINE = "\r\x1b[K"
"""Back to the start of the terminal's line, and erase it."""


def status_line(run: Any) -> str:
    """The live status line: time, progress, step, pose, cut to the terminal's width (after :data:`CLEAR_LINE`).

    Most important first, so that a narrow terminal loses the pose, not the step.
    """
    import shutil
    from beastbt.run.progress import progress_of
    width = shutil.get_terminal_size((100, 24)).columns
    progress = progress_of(run.root, run.mission_time_s).text()
    text = f"[{run.elapsed_s:7.1f} s] {progress} | {run.current_step()} | {run.pose_text()}"
    if len(text) > width - 1:
        text = text[: max(0, width - 2)] + "…"
    return CLEAR_LINE + text


class TerminalAnswers:
    """Answer the mission's questions from an interactive terminal: the question is shown, y or n + Enter answers."""

    def __init__(self, questions: Any, out: TextIO, run: Any = None) -> None:
        self.questions = questions
        self.out = out
        self.run = run
        if run is not None:
            run.inputs.sources.add(TERMINAL)
        self.prompted: Optional[str] = None

    def poll(self) -> None:
        """Show the open question once; take a typed answer if a line is waiting (never blocks)."""
        import select
        question = self.questions.current() if self.questions is not None else None
        if question is None:
            self.prompted = None
            return
        if self.prompted != question.id:
            self.prompted = question.id
            self.out.write(f"{CLEAR_LINE}? {question.text} [y/n] (question '{question.id}')\n")
            self.out.flush()
        try:
            ready, _, _ = select.select([sys.stdin], [], [], 0)
        except (OSError, ValueError):
            return
        if ready:
            line = sys.stdin.readline()
            if not self.questions.answer(question.id, line, "terminal"):
                self.out.write(f"{CLEAR_LINE}? please type y or n, then Enter\n")
            elif self.run is not None:  # recorded, so that a replay answers at the same tick
                self.run.inputs.note(self.run, TERMINAL, "answer", {"id": question.id, "choice": line.strip()},
                                     self.run.clock.now())


class UnanswerableQuestions:
    """Say at once when a question is open that nobody can answer: no console, no terminal, no ``--answer``.

    Without this the run would stand silently until the question's timeout
    (an hour, say) with nothing on the screen telling why.
    """

    def __init__(self, questions: Any, events: Any) -> None:
        self.questions = questions
        self.events = events
        self.said: set[str] = set()

    def poll(self) -> None:
        """Add an ``ask`` event, once per question id, naming how to answer it."""
        question = self.questions.current() if self.questions is not None else None
        if question is None or question.id in self.said:
            return
        self.said.add(question.id)
        self.events.add("ask", f"nobody can answer '{question.id}' in this run (no --console, and the input is not "
                               f"a terminal): it waits for its timeout; answer in advance with "
                               f"--answer {question.id}=yes (or =no), or run with --console 8080")


def _console_listener(out: TextIO, tty: bool = False) -> Callable:
    """Print the events a person should see as they happen; on a terminal the status line is cleared first."""
    start = CLEAR_LINE if tty else ""

    def listener(ev) -> None:
        if ev.kind in ("say",) or ev.kind in CONSOLE_EVENTS:
            out.write(f"{start}[{ev.time_s:7.1f} s] {ev.kind}: {ev.text}\n")
    return listener


def _sigterm_as_interrupt() -> Callable[[], None]:
    """Make SIGTERM end the run as Ctrl-C does (stop, summary, recording); return what puts it back."""
    if threading.current_thread() is not threading.main_thread():
        return lambda: None
    previous = signal.getsignal(signal.SIGTERM)

    def on_sigterm(signum: int, frame: Any) -> None:
        raise KeyboardInterrupt("SIGTERM")

    signal.signal(signal.SIGTERM, on_sigterm)

    def restore() -> None:
        signal.signal(signal.SIGTERM, previous)
    return restore


__all__ = ["RunOptions", "Prepared", "execute", "parse_speed", "DEFAULT_SIM_MAX_TIME_S"]
