"""Per-frame cost of the simulated camera with the world drawn around the floor (a measurement, not a test).

Run from the repository root::

    python benchmarks/sim_camera.py

Renders 640x480 (a larger camera) and 320x240 (robots/sim.yaml's) frames at poses around worlds/corridor.yaml (walls),
worlds/corridor_person.yaml (a person), worlds/campus_obstacles.yaml (boxes
and cylinders) and worlds/line_track.yaml (a painted floor, no scenery: the
control), the camera once at its mounting and once tilted 40 deg up (walls and
sky in view), with the default camera effects. The baseline, timed in the same
run on the same poses, is the camera as it was before the scenery: the plain
floor raster and a grey sky (``SimCamera`` without ``scenery``). Each pose is
rendered by both in turn and the best of REPEATS tries counts, so that a busy
machine slows both alike; OpenCV runs on one thread, so the figure is the work
per frame, not how a loaded machine schedules OpenCV's thread pool. Prints the
median over poses, milliseconds per frame, and the ratio to the baseline.
"""

from __future__ import annotations

import math
import pathlib
import statistics
import time

import cv2
import numpy as np

from beastbt.parts.camera import PLAIN_FLOOR, build_floor
from beastbt.sim.camera_emulator import CameraEffects, SimCamera
from beastbt.sim.scenery import Scenery
from beastbt.sim.world import load_world
from beastbt.vision.camera_model import CameraGeometry

ROOT = pathlib.Path(__file__).resolve().parents[1]
FRAMES = 100
"""Poses rendered per case."""

REPEATS = 3
"""Renders of each pose by each camera; the fastest counts."""


def drive(world: str, n: int) -> list[tuple[float, float, float]]:
    """``n`` poses (x, y m, yaw rad) wandering the world's area around its start, deterministic."""
    rng = np.random.default_rng(3)
    if "corridor" in world:
        return [(float(rng.uniform(0.5, 9.5)), float(rng.uniform(-0.6, 0.6)), float(rng.uniform(-math.pi, math.pi)))
                for _ in range(n)]
    if "line_track" in world:
        return [(float(rng.uniform(0, 3)), float(rng.uniform(0, 1)), float(rng.uniform(-math.pi, math.pi)))
                for _ in range(n)]
    return [(float(rng.uniform(-2, 40)), float(rng.uniform(-2, 20)), float(rng.uniform(-math.pi, math.pi)))
            for _ in range(n)]


def median_ms(old: SimCamera, new: SimCamera, poses: list[tuple[float, float, float]], tilt_rad: float,
              persons: object) -> tuple[float, float]:
    """Milliseconds of one ``render``, (old camera, new camera): the median over ``poses`` of the best of REPEATS.

    Each pose is rendered by both cameras in turn; the best of a few tries
    drops the frames that another process on the machine slowed down.
    """
    t_old, t_new = [], []
    for x, y, yaw in poses:
        best_old = best_new = math.inf
        for _ in range(REPEATS):
            t0 = time.perf_counter()
            old.render(x, y, yaw, 0.1, 0.0, 0.0, tilt_rad)
            t1 = time.perf_counter()
            new.render(x, y, yaw, 0.1, 0.0, 0.0, tilt_rad, persons)
            t2 = time.perf_counter()
            best_old, best_new = min(best_old, t1 - t0), min(best_new, t2 - t1)
        t_old.append(best_old * 1e3)
        t_new.append(best_new * 1e3)
    return statistics.median(t_old), statistics.median(t_new)


def main() -> None:
    """Print the table: size, world, tilt, baseline ms, with scenery ms, ratio."""
    cv2.setNumThreads(1)
    from figures import Figures  # benchmarks/figures.py: saved for benchmarks/check_docs.py, printed
    figures = Figures("sim_camera")
    print("default camera effects, OpenCV on one thread; ms per frame (median over poses of the best of 3)")
    print(f"{'size':>8} {'world':<18} {'tilt':>5} {'baseline ms':>12} {'scenery ms':>11} {'ratio':>6}")
    for w, h in ((640, 480), (320, 240)):
        geom = CameraGeometry(width_px=w, height_px=h, pitch_deg=40.0)
        for name in ("corridor", "corridor_person", "campus_obstacles", "line_track"):
            world = load_world(ROOT / "worlds" / f"{name}.yaml")
            raw = world.section("floor")
            floor = build_floor(raw if raw is not None else PLAIN_FLOOR, 11)
            scenery = Scenery.of_world(world.walls, world.obstacles, raw is not None, 11)
            persons = [p.path[0] for p in scenery.persons] or None
            old = SimCamera(floor, geom, np.random.default_rng(1), CameraEffects())
            new = SimCamera(floor, geom, np.random.default_rng(1), CameraEffects(), scenery)
            poses = drive(name, FRAMES)
            for tilt_deg in (0.0, 40.0):
                tilt = math.radians(tilt_deg)
                median_ms(old, new, poses[:10], tilt, persons)  # warm caches
                base, with_scenery = median_ms(old, new, poses, tilt, persons)
                print(f"{w}x{h:<4} {name:<18} {tilt_deg:>5.0f} {base:>12.2f} {with_scenery:>11.2f} "
                      f"{with_scenery / base:>6.2f}")
                key = f"size{w}x{h}.{name}.tilt{tilt_deg:.0f}"
                figures.put(f"{key}.baseline_ms", base)
                figures.put(f"{key}.scenery_ms", with_scenery)
                figures.put(f"{key}.ratio", with_scenery / base)
    figures.save()


if __name__ == "__main__":
    main()
