"""Measure the cost of one EkfEstimator.update() call in the simulator's common case.

Not a test: prints microseconds per call. The simulator must run >100x real
time at 20 Hz ticks, so one update has to stay well under ~150 us.
Run: python benchmarks/bench_ekf.py
"""

from __future__ import annotations

import math
import time

import numpy as np

from beastbt.blackboard.types import GpsFix, ImuSample, WheelOdometry
from beastbt.estimation.ekf import EkfConfig, EkfEstimator
from beastbt.estimation.geodesy import LocalFrame


def main(ticks: int = 20000, gps_hz: float = 1.0, imu_per_tick: int = 2) -> None:
    """Drive a circle at 20 Hz and time update() (inputs prepared beforehand)."""
    rng = np.random.default_rng(0)
    frame = LocalFrame(47.0, 8.0)
    dt = 0.05
    inputs = []
    x = y = yaw = left = right = 0.0
    v, w, track = 1.0, 0.1, 0.2
    every = max(1, int(round(1.0 / (gps_hz * dt))))
    for k in range(ticks):
        t = (k + 1) * dt
        x += v * math.cos(yaw) * dt
        y += v * math.sin(yaw) * dt
        yaw += w * dt
        left += (v - w * track / 2) * dt
        right += (v + w * track / 2) * dt
        odo = [WheelOdometry(t, left, right, v - w * track / 2, v + w * track / 2)]
        imu = [ImuSample(t - i * 0.01, (0.0, 0.0, w + rng.normal(0, 0.003)), (0.0, 0.0, 9.81))
               for i in range(imu_per_tick)]
        gps = []
        if k % every == 0:
            lat, lon, _ = frame.to_geodetic(x + rng.normal(0, 3), y + rng.normal(0, 3))
            track_deg = math.degrees(math.pi / 2 - yaw) % 360.0
            gps = [GpsFix(t, lat, lon, speed_mps=v, track_deg=track_deg)]
        inputs.append((t, odo, imu, gps))
    est = EkfEstimator(EkfConfig(track_width_m=track))
    start = time.perf_counter()
    for t, odo, imu, gps in inputs:
        est.update(t, odo, imu, gps)
    elapsed = time.perf_counter() - start
    print(f"EkfEstimator.update: {elapsed / ticks * 1e6:.1f} us per call "
          f"({ticks} calls, GPS {gps_hz:g} Hz, {imu_per_tick} IMU samples per call)")
    from figures import Figures  # benchmarks/figures.py: saved for benchmarks/check_docs.py, printed
    figures = Figures("bench_ekf")
    figures.put(f"gps_{gps_hz:g}hz".replace(".", "_") + ".update_us", elapsed / ticks * 1e6)
    figures.save()


if __name__ == "__main__":
    main(gps_hz=1.0)
    main(gps_hz=10.0)
