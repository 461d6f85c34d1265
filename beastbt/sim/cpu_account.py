"""The simulator's own CPU time, kept apart from the robot's: what a run on the robot would not spend.

On the robot the Pi runs the drivers, the estimator, the tree, safety, the
recording and the console. The physics, the device emulators (the ESP32
base, the GPS, the IMU, the LiDAR's ray-casting) and the camera's rendering
and JPEG encoding (a camera's hardware does that) are the simulator's. Each
place where the simulator works is bracketed here (:meth:`SimCpu.enter` and
:meth:`SimCpu.leave`), reading the calling thread's CPU clock
(``time.thread_time``, about 0.4 µs a read) and charging the time between
to a kind of work (:data:`KINDS`); a physics step's emulators are told apart
by a wall clock (:meth:`SimCpu.leave_split`), ten times cheaper to read.
Brackets nest, and each kind gets its exclusive time: the robot's own work
called from inside the simulator (the command watchdog checked at every
physics step, which then writes a stop through the base's driver) is
charged to :data:`ROBOT`, which is not the simulator's, and the emulator
answering that write to its own kind again. Work on threads the brackets do
not run on (a library's worker pool) is not seen.

Nothing here decides anything, and nothing of the simulation depends on it:
the figures are read by benchmarks (``benchmarks/realtime_cpu.py``) and
tests. It is off unless turned on (:meth:`SimCpu.enable`, or the variable
below, read when a process builds the simulator or its viewer camera), and
then costs about 10-15 µs a tick of the patrol (3-5 % of its tick at
``--speed max``, about 0.03 % of a core at real time). In this process:
:meth:`SimCpu.seconds`. Across processes (the run and the console's
process, which renders the simulated viewer camera): when the environment
variable ``BEASTBT_SIM_CPU_DIR`` names a folder, each process keeps its
totals in the file ``DIR/PID`` as one float64 (native order) per kind in
:data:`KINDS` order (seconds), written in place at each charge, so that a
benchmark can read them while the run goes on, at the same moments it reads
the processes' CPU from ``/proc``.
"""

from __future__ import annotations

import mmap
import os
import threading
import time
from pathlib import Path
from typing import Any, Callable, Optional

ENV_DIR = "BEASTBT_SIM_CPU_DIR"
"""The environment variable naming the folder where each process keeps its totals (benchmarks set it)."""

KINDS: tuple[str, ...] = ("physics", "base", "gps", "imu", "lidar", "camera", "joystick", "servo", "other", "robot")
"""The kinds of work charged, in the order of a totals file; all but ``robot`` are the simulator's."""

PHYSICS, BASE, GPS, IMU, LIDAR, CAMERA, JOYSTICK, SERVO, OTHER, ROBOT = range(len(KINDS))
"""Indexes into :data:`KINDS`. ``ROBOT``: the robot's own work called from inside the simulator."""

SIMULATOR_KINDS: tuple[str, ...] = KINDS[:ROBOT]
"""The kinds that are the simulator's (all but ``robot``)."""

NONE = -1
"""The kind of a thread outside every bracket: nothing is charged."""

_KIND_OF_MODULE = {
    "waveshare_emulator": BASE, "waveshare": BASE, "can_motor_emulator": BASE, "can_base": BASE,
    "pwm_motor_emulator": BASE, "pwm_base": BASE, "gps_emulator": GPS, "gps": GPS, "imu_emulator": IMU, "imu": IMU,
    "lidar_emulator": LIDAR, "lidar": LIDAR, "camera_emulator": CAMERA, "scenery": CAMERA, "camera": CAMERA,
    "joystick_script": JOYSTICK, "sim_joystick": JOYSTICK, "pca9685_emulator": SERVO, "servo_board": SERVO,
    "pca9685_chip": SERVO, "dynamics": PHYSICS, "contact": PHYSICS, "obstacles": PHYSICS,
}
"""The kind of an emulator's update by the last part of its module's name (beastbt.sim.* and the parts that wrap
an emulator in a closure)."""

_ROBOT_PACKAGES = ("beastbt.actuation", "beastbt.run", "beastbt.devices", "beastbt.estimation", "beastbt.navigation")
"""Code of these packages called from the simulator (the watchdog at each physics step) is the robot's own."""


def kind_of(fn: Any) -> int:
    """The kind an emulator's update (or a port's callback) is charged to: its ``sim_cpu_kind`` attribute or its
    object's, else by its module (:data:`ROBOT` for the robot's own packages, :data:`OTHER` when unknown)."""
    for holder in (fn, getattr(fn, "__self__", None)):
        kind = getattr(holder, "sim_cpu_kind", None)
        if isinstance(kind, int):
            return kind
    func = getattr(fn, "__func__", fn)
    module = getattr(func, "__module__", None) or getattr(type(fn), "__module__", "") or ""
    if module.startswith(_ROBOT_PACKAGES):
        return ROBOT
    return _KIND_OF_MODULE.get(module.rsplit(".", 1)[-1], OTHER)


_KIND, _SINCE, _PENDING = 0, 1, 2
"""A thread's state, a plain list (a ``threading.local``'s attributes are slow to set): the kind charged now
(:data:`NONE` outside every bracket, :data:`SPLIT` in a split one), since when (thread CPU s), and a split
bracket's CPU time not yet shared out."""


SPLIT = -2
"""The kind of a bracket whose time is shared out among kinds when it ends (:meth:`SimCpu.leave_split`)."""


class SimCpu:
    """Thread CPU seconds charged per kind of simulator work in this process (see the module's docstring).

    Off until :meth:`enable` (or a ``folder``): then a bracket costs one attribute test, and
    :meth:`Simulator.advance <beastbt.sim.robot.Simulator.advance>` runs as if this did not exist.
    """

    def __init__(self, folder: Optional[str] = None) -> None:
        self._local = threading.local()
        self._file: Optional[mmap.mmap] = None
        self.enabled = False
        """Whether brackets read the clock and charge (benchmarks and tests turn it on)."""
        self.totals: Any = [0.0] * len(KINDS)
        """Seconds per kind, :data:`KINDS` order: a list, or a float64 view of the totals file."""
        self._pid: Optional[int] = None
        """The process that opened the totals file (None: none opened)."""
        if folder:
            self.open_file(folder)

    def enable(self) -> None:
        """Charge from now on (a bracket already open in some thread charges from when it ends or nests)."""
        self.enabled = True

    def open_file(self, folder: str) -> None:
        """Keep the totals in ``folder/PID`` from now on (what was charged before is carried over), and charge."""
        path = Path(folder) / str(os.getpid())
        size = 8 * len(KINDS)
        with open(path, "w+b") as f:
            f.write(b"\0" * size)
            f.flush()
            self._file = mmap.mmap(f.fileno(), size)
        view = memoryview(self._file).cast("d")
        for i, value in enumerate(self.totals):
            view[i] = value
        self.totals = view
        self._pid = os.getpid()
        self.enabled = True

    def open_from_environment(self) -> None:
        """Keep this process's totals in ``BEASTBT_SIM_CPU_DIR/PID`` when the variable names a folder (a benchmark
        set it), else stay as it is. Called where a process builds simulator work (the simulator, the console's
        viewer camera); a second call in the same process keeps the file it opened, and one in a process forked
        after it opens a file of its own, from nothing."""
        folder = os.environ.get(ENV_DIR)
        if not folder or self._pid == os.getpid():
            return
        if self._pid is not None:  # forked from a process that had opened its own: its totals are not ours
            self.__init__()  # type: ignore[misc]
        self.open_file(folder)

    def _state(self) -> list:
        try:
            return self._local.s
        except AttributeError:
            st = self._local.s = [NONE, 0.0, 0.0]
            return st

    def _charge(self, st: list, now: float) -> None:
        kind = st[_KIND]
        if kind >= 0:
            self.totals[kind] += now - st[_SINCE]
        elif kind == SPLIT:
            st[_PENDING] += now - st[_SINCE]

    def enter(self, kind: int) -> int:
        """Charge this thread's time from now on to ``kind`` (or :data:`SPLIT`); returns what :meth:`leave` puts
        back."""
        if not self.enabled:
            return NONE
        now = time.thread_time()
        st = self._state()
        outer = st[_KIND]
        if outer != NONE:
            self._charge(st, now)
        st[_KIND] = kind
        st[_SINCE] = now
        if kind == SPLIT:
            st[_PENDING] = 0.0
        return outer

    def leave(self, outer: int) -> None:
        """End the bracket :meth:`enter` opened: charge its time, and go back to ``outer`` (its return value)."""
        if not self.enabled:
            return
        now = time.thread_time()
        st = self._state()
        self._charge(st, now)
        st[_KIND] = outer
        st[_SINCE] = now

    def leave_split(self, outer: int, weights: list[float]) -> None:
        """End a :data:`SPLIT` bracket: share its CPU time (less any bracket nested in it) among the kinds in
        proportion to ``weights`` (one per kind, :data:`KINDS` order: the wall time each took inside it), and go
        back to ``outer``.

        Reading a wall clock between pieces of work costs a tenth of reading the thread's CPU clock; the CPU
        clock, read at both ends, gives the total, and a preemption in between only blurs one split.
        """
        if not self.enabled:
            return
        now = time.thread_time()
        st = self._state()
        if st[_KIND] == SPLIT:
            own = st[_PENDING] + now - st[_SINCE]
            total = sum(weights)
            if total > 0:
                scale = own / total
                totals = self.totals
                for kind, weight in enumerate(weights):
                    if weight:
                        totals[kind] += weight * scale
            st[_PENDING] = 0.0
        else:  # the bracket was entered while the accounting was off
            self._charge(st, now)
        st[_KIND] = outer
        st[_SINCE] = now

    def call(self, kind: int, fn: Callable[..., Any], *args: Any) -> Any:
        """``fn(*args)``, its time charged to ``kind``."""
        if not self.enabled:
            return fn(*args)
        outer = self.enter(kind)
        try:
            return fn(*args)
        finally:
            self.leave(outer)

    def seconds(self) -> dict[str, float]:
        """Seconds charged so far in this process, per kind (``robot`` included: it is not the simulator's)."""
        return {name: float(self.totals[i]) for i, name in enumerate(KINDS)}

    def simulator_s(self) -> float:
        """Seconds of the simulator's work so far in this process (every kind but ``robot``)."""
        return float(sum(self.totals[i] for i in range(ROBOT)))


SIM_CPU = SimCpu()
"""This process's accounting: off until the simulator is built (:meth:`SimCpu.open_from_environment`)."""


def read_totals(path: Path) -> Optional[list[float]]:
    """The totals a process keeps in ``path`` (seconds per kind, :data:`KINDS` order), or None if unreadable."""
    import struct
    try:
        data = path.read_bytes()
    except OSError:
        return None
    if len(data) != 8 * len(KINDS):
        return None
    return list(struct.unpack(f"={len(KINDS)}d", data))


__all__ = ["SimCpu", "SIM_CPU", "KINDS", "SIMULATOR_KINDS", "ENV_DIR", "kind_of", "read_totals",
           "PHYSICS", "BASE", "GPS", "IMU", "LIDAR", "CAMERA", "JOYSTICK", "SERVO", "OTHER", "ROBOT", "NONE", "SPLIT"]
