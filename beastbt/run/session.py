"""One ``beastbt run``: load everything, assemble the robot, loop, summarise, record.

:func:`prepare` does all the checking (mission, profile, world) before
anything moves; :func:`execute` runs the loop at the requested speed, handles
Ctrl-C, always ends with a stop command, and writes the summary and run folder.
"""

from __future__ import annotations

import gc
import json
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Optional, TextIO, Union

from beastbt.core.errors import InvalidInput
from beastbt.mission.model import Mission, load_mission
from beastbt.core.clock import SimClock, WallClock
from beastbt.core.events import EventLog
from beastbt.robot.profile import RobotProfile, load_profile
from beastbt.recording.run_folder import RunFolder
from beastbt.run.runner import MissionRun
from beastbt.run.summary import build_summary, human_summary
from beastbt.sim.robot import build_sim_robot
from beastbt.sim.world import World, empty_world, load_world

DEFAULT_SIM_MAX_TIME_S = 3600.0
"""A simulated run with no --max-time ends after this much simulated time (s)."""

RunHook = Callable[["Prepared"], None]
PREPARE_HOOKS: list[RunHook] = []
"""Called after a run is assembled and before it starts (recording, streaming, scripted joystick...)."""


@dataclass
class RunOptions:
    """How to run: ``speed`` is ``max``, ``realtime`` or a factor of real time; times in seconds."""

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
    extras: dict = field(default_factory=dict)
    """Options that parts of beastbt add (``joystick``, ``stream``...)."""


@dataclass
class Prepared:
    """A run assembled and checked, not yet started."""

    mission: Mission
    profile: RobotProfile
    world: Optional[World]
    run: MissionRun
    options: RunOptions
    events: EventLog
    clock: object
    folder: Optional[RunFolder] = None
    closers: list = field(default_factory=list)


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


def prepare(mission_path: str, options: RunOptions, mission_text: Optional[str] = None) -> Prepared:
    """Load and check the mission, profile and world and build the run; raise InvalidInput before anything moves."""
    mission = load_mission(mission_path, text=mission_text)
    profile = load_profile(options.robot)
    simulated = options.robot == "sim" or bool(options.extras.get("simulate"))
    world: Optional[World] = None
    if simulated:
        world_path = options.world or (str(mission.world) if mission.world is not None else None)
        world = load_world(world_path) if world_path else empty_world()
    clock = SimClock() if simulated else WallClock()
    events = EventLog(clock)
    if simulated:
        io = build_sim_robot(profile, world, options.seed, events)
    else:
        from beastbt.robot.hardware import build_real_robot
        io = build_real_robot(profile, clock, events)
    services: dict = {}
    run = MissionRun(mission, profile, io, clock, events, services)
    prepared = Prepared(mission, profile, world, run, options, events, clock)
    if options.record:
        prepared.folder = RunFolder.create(options.runs_dir, mission.name, clock)
        services["save_snapshot"] = prepared.folder.save_snapshot
        run.ctx.services["save_snapshot"] = prepared.folder.save_snapshot
    for hook in PREPARE_HOOKS:
        hook(prepared)
    return prepared


def execute(p: Prepared, out: TextIO = sys.stdout) -> dict:
    """Run the loop until the mission ends (or max time, or Ctrl-C); return the summary."""
    run, clock, opts = p.run, p.clock, p.options
    dt = 1.0 / p.mission.rate_hz
    simulated = isinstance(clock, SimClock)
    max_time = opts.max_time_s if opts.max_time_s is not None else (DEFAULT_SIM_MAX_TIME_S if simulated else None)
    factor = None if opts.speed == "max" else (1.0 if opts.speed == "realtime" else float(opts.speed))
    say_listener = _console_listener(out)
    p.events.listeners.append(say_listener)
    wall0 = time.perf_counter()
    last_status_wall = 0.0
    tty = opts.status_line
    # Everything built so far (modules, the tree, drivers, the simulator) lives for the whole run: move it
    # out of the garbage collector's sight, so that a full collection during the run walks only what the run
    # made since, instead of pausing a tick for tens of milliseconds. Given back when the loop ends.
    gc.freeze()
    try:
        while run.status is None:
            run.tick()
            if run.status is not None:
                break
            if max_time is not None and run.elapsed_s + dt > max_time + 1e-9:
                run.finish("stopped", f"max time {max_time:g} s reached")
                break
            if simulated:
                clock.advance(dt)
                if factor is not None:
                    target = wall0 + clock.now() / factor
                    delay = target - time.perf_counter()
                    if delay > 0:
                        time.sleep(delay)
            else:
                clock.sleep_until(run.start_s + run.ticks * dt)
            if tty:
                now_wall = time.perf_counter()
                if now_wall - last_status_wall > 0.1:
                    last_status_wall = now_wall
                    out.write(f"\r[{run.elapsed_s:7.1f} s] {run.current_step()[:40]:40s} {run.pose_text()}  ")
                    out.flush()
    except KeyboardInterrupt:
        run.stop_robot(clock.now())
        run.finish("stopped", "interrupted (Ctrl-C)")
    except Exception as exc:
        # Whatever broke, the robot must not keep moving: stop first, then report.
        run.stop_robot(clock.now())
        run.finish("failure", f"internal error: {exc!r}")
        raise
    finally:
        gc.unfreeze()
        run.stop_robot(clock.now())
        for close in p.closers:
            try:
                close()
            except Exception:
                pass
        run.io.close()
        if tty:
            out.write("\r" + " " * 110 + "\r")
    wall = time.perf_counter() - wall0
    world_name = p.world.name if p.world is not None else None
    summary = build_summary(run, opts.seed, wall, world_name, p.profile.name)
    if opts.summary_path:
        Path(opts.summary_path).write_text(json.dumps(summary, indent=2) + "\n", encoding="utf-8")
    if p.folder is not None:
        p.folder.finish(summary)
        summary_dir = str(p.folder.path)
        out.write(f"run recorded in {summary_dir}\n")
    return summary


def _console_listener(out: TextIO) -> Callable:
    def listener(ev) -> None:
        if ev.kind in ("say",):
            out.write(f"\r[{ev.time_s:7.1f} s] say: {ev.text}\n")
        elif ev.kind in ("mission_end", "failsafe", "estop", "step_failed", "device_error"):
            out.write(f"\r[{ev.time_s:7.1f} s] {ev.kind}: {ev.text}\n")
    return listener


def run_file(mission_path: str, options: RunOptions, out: TextIO = sys.stdout) -> dict:
    """Prepare and execute a run; print the human summary. Raises InvalidInput for bad input."""
    p = prepare(mission_path, options)
    summary = execute(p, out)
    out.write(human_summary(summary) + "\n")
    return summary


__all__ = ["RunOptions", "prepare", "execute", "run_file", "parse_speed", "InvalidInput", "PREPARE_HOOKS"]
