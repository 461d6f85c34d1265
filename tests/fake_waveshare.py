"""A fake Waveshare base on a pseudo-terminal: the firmware emulator, in real time, behind a real serial device.

The driver under test opens ``FakeWaveshare.port`` (the pty's slave) like the
real ``/dev/serial0``. A thread steps the emulated motors at 100 Hz of wall
time, feeds what the driver wrote to
:class:`~beastbt.sim.waveshare_emulator.SimWaveshareBase` (either firmware)
and writes its feedback back. It records when each command arrived and when
the emulated firmware's wheel targets changed, so a test can measure how
long the robot kept moving after beastbt died. (Test support: it runs on the
wall clock on purpose.)
"""

from __future__ import annotations

import os
import select
import time
from typing import Optional

import numpy as np

from beastbt.sim.dynamics import DiffDriveSim, DriveModel
from beastbt.sim.truth import RobotTruth
from beastbt.sim.waveshare_emulator import SimWaveshareBase
from pty_device import PtyDevice

PHYSICS_DT_S = 0.01


class FakeWaveshare(PtyDevice):
    """The emulated sub-controller of ``firmware`` (``ros`` or ``general``) on a pty; use as a context manager."""

    thread_name = "fake-waveshare"

    def __init__(self, firmware: str = "ros", gimbal_present: bool = True) -> None:
        super().__init__()
        model = DriveModel(track_width_m=0.17, max_wheel_speed_mps=0.5, max_wheel_accel_mps2=1.5,
                           motor_time_constant_s=0.08, slip_sigma=0.0, slip_bias=0.0, footprint_radius_m=0.15)
        self.drive = DiffDriveSim(model, RobotTruth(), np.random.default_rng(0))
        self.esp32 = SimWaveshareBase(self.drive, np.random.default_rng(1), firmware=firmware,
                                      gimbal_present=gimbal_present)
        self.received: list[tuple[float, dict]] = []
        """(monotonic s, command) for every command the firmware parsed."""
        self.targets: list[tuple[float, float, float]] = []
        """(monotonic s, left, right) whenever the firmware's wheel targets changed."""

    def _run(self) -> None:
        start = time.monotonic()
        sim_s = 0.0
        arrived: list[dict] = []  # every command the firmware took, through its listener (its own log is bounded)
        self.esp32.command_listeners.append(arrived.append)
        last_targets = (0.0, 0.0)
        while not self._stop.is_set():
            ready, _, _ = select.select([self.master], [], [], PHYSICS_DT_S / 2)
            now = time.monotonic()
            with self._lock:
                self.esp32.now_s = sim_s
                if ready:
                    try:
                        data = os.read(self.master, 4096)
                    except OSError:
                        data = b""
                    self.esp32.port.write(data)
                    self.received.extend((now, command) for command in arrived)
                    arrived.clear()
                while sim_s + PHYSICS_DT_S <= now - start:
                    sim_s += PHYSICS_DT_S
                    self.drive.step(PHYSICS_DT_S)
                    self.esp32.update(sim_s, PHYSICS_DT_S)
                targets = (self.drive.target_left_mps, self.drive.target_right_mps)
                if targets != last_targets:
                    self.targets.append((now, *targets))
                    last_targets = targets
                waiting = self.esp32.port.in_waiting
                out = self.esp32.port.read(waiting) if waiting else b""
            if out:
                try:
                    os.write(self.master, out)
                except OSError:
                    pass

    def odometry_m(self) -> tuple[float, float]:
        """Left and right distance as the emulated firmware computes it (m)."""
        with self._lock:
            return self.esp32.odometry_m()

    def moving_since(self) -> Optional[float]:
        """When the wheel targets last became non-zero (monotonic s), or None."""
        for t, left, right in reversed(self.targets):
            if left != 0.0 or right != 0.0:
                return t
        return None

    def stopped_at(self, after: float) -> Optional[float]:
        """When the wheel targets were last set to zero after ``after`` (monotonic s), or None."""
        for t, left, right in self.targets:
            if t >= after and left == 0.0 and right == 0.0:
                return t
        return None
