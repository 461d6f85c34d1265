"""Safety below the tree, wired around every run's actuators: the command watchdog and the e-stop API.

:func:`guard_actuators` wraps a robot's base adapter in the
:class:`~beastbt.actuation.watchdog.AdapterWatchdog` and is called by
:class:`~beastbt.run.runner.MissionRun` itself, so that no run, whatever
assembled it (the CLI, the testing harness, the Python API, a replay), ticks a
tree without it. With the run's :class:`~beastbt.actuation.mux.CommandMux`
(e-stop latch, sources by priority) and
:class:`~beastbt.actuation.gate.SafetyGate` (speed, turn rate, acceleration
limits) it is the safety layer.

How the watchdog is checked depends on what drives time:

* on the robot (wall clock, no simulator): a thread of its own, every
  ``watchdog.check_period_s``, whatever the tick loop is doing;
* on the simulator: at every physics step, so a frozen loop is seen in
  simulated time, deterministically;
* in a replay: at every tick (nothing moves, but the same code runs).

:func:`request_estop` and :func:`reset_estop` are the e-stop's API (any
thread); the joystick's buttons and the console call them too.

:func:`guard_collisions` builds the run's collision monitor
(:mod:`beastbt.actuation.collision_monitor`) when the profile has ``lidar:``
(and ``collision_monitor: {enabled: false}`` does not turn it off). The run
applies it to every command between the mux and the gate, whoever sent it; it
reads the newest ``LaserScan`` the run polled from ``io.sensors['lidar']``
through one callable, ``latest_scan()``.
"""

from __future__ import annotations

import atexit
from typing import TYPE_CHECKING, Any, Callable, Optional

from beastbt.actuation.watchdog import AdapterWatchdog, LockedServos
from beastbt.core.clock import Clock, WallClock
from beastbt.core.events import EventLog
from beastbt.robot.actuator_profile import watchdog_config
from beastbt.robot.profile import RobotProfile, section_config
from beastbt.robot.robot_io import RobotIO

if TYPE_CHECKING:
    from beastbt.actuation.collision_monitor import CollisionMonitor
    from beastbt.run.runner import MissionRun

THREAD = "thread"
"""The watchdog checks itself in a thread (on the robot)."""
PHYSICS = "physics"
"""The simulator checks the watchdog at every physics step."""
TICK = "tick"
"""The run checks the watchdog at every tick (replay)."""


def guard_actuators(io: RobotIO, clock: Clock, profile: RobotProfile, events: EventLog) -> tuple[AdapterWatchdog, str]:
    """Wrap ``io.base`` in the command watchdog (once); return it and who checks it (:data:`THREAD`...).

    A base that also drives servos (the Waveshare gimbal) shares the
    watchdog's lock, so a servo command never interleaves with its stop.
    """
    if isinstance(io.base, AdapterWatchdog):
        dog = io.base
    else:
        dog = AdapterWatchdog(io.base, clock, watchdog_config(profile), events.sink("watchdog"))
        io.servos = [LockedServos(s, dog.lock) if s is dog.inner else s for s in io.servos]
        io.base = dog
        io.watchdog = dog
    if io.sim is not None:
        if dog.on_physics_step not in io.sim.emulators:
            io.sim.emulators.append(dog.on_physics_step)
        return dog, PHYSICS
    if isinstance(clock, WallClock):
        if not dog.running:
            dog.start_thread()
            # Whatever ends the process, the last bytes on the wire are a stop (close is idempotent).
            atexit.register(dog.close)
        return dog, THREAD
    return dog, TICK


def watchdog_of(run: "MissionRun") -> Optional[AdapterWatchdog]:
    """The run's command watchdog (None only for a base that is not guarded, which a run never has)."""
    base = run.io.base
    return base if isinstance(base, AdapterWatchdog) else None


def request_estop(run: "MissionRun", reason: str = "API request") -> bool:
    """Latch the emergency stop of ``run`` (any thread); False when it was already latched.

    The mux outputs zero from now on; the runner ends the mission with status
    ``stopped`` on its next tick and sends the base's own stop once; the
    watchdog refuses motion below the mux and sends that stop itself if the
    loop does not within ``watchdog.estop_grace_s``.
    """
    first = not run.mux.estop_latched
    run.mux.latch_estop(reason)
    dog = watchdog_of(run)
    if dog is not None:
        dog.latch_estop(reason)
    if first:
        run.events.add("estop", f"emergency stop latched: {reason}")
    return first


def reset_estop(run: "MissionRun", reason: str = "API request") -> bool:
    """Clear a latched emergency stop (an explicit operator action); False when none was latched.

    The safety gate forgets its last output, so motion starts again from rest.
    """
    dog = watchdog_of(run)
    latched = run.mux.estop_latched or (dog is not None and dog.estop_latched)
    if not latched:
        return False
    run.mux.reset_estop()
    if dog is not None:
        dog.reset_estop()
    run.gate.reset()
    run.events.add("estop", f"emergency stop reset: {reason}")
    return True


def guard_collisions(profile: RobotProfile, events: EventLog,
                     latest_scan: Callable[[], Optional[Any]]) -> Optional["CollisionMonitor"]:
    """The collision monitor for ``profile`` reading ``latest_scan()``; None without ``lidar:`` or when disabled.

    Raises :class:`~beastbt.core.errors.InvalidInput` at the section's line
    for a bad ``collision_monitor:`` (before anything moves). Imported only
    for a robot with a LiDAR, so the others pay nothing.
    """
    if profile.section("lidar") is None:
        return None
    from beastbt.actuation.collision_monitor import CollisionMonitor, CollisionMonitorConfig, footprint_radius
    from beastbt.devices.lidar_scan import LidarConfig

    config: CollisionMonitorConfig = section_config(profile, "collision_monitor", CollisionMonitorConfig)
    if not config.enabled:
        events.add("collision_monitor", "collision monitor: off (collision_monitor: {enabled: false}): "
                                        "nothing limits commands near obstacles")
        return None
    lidar: LidarConfig = section_config(profile, "lidar", LidarConfig)
    return CollisionMonitor(config, latest_scan, footprint_radius(profile.data), profile.max_speed_mps,
                            lidar.mounting, events.add)


__all__ = ["guard_actuators", "guard_collisions", "watchdog_of", "request_estop", "reset_estop", "THREAD", "PHYSICS",
           "TICK"]
