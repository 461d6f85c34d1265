"""Per-frame cost of the simulated camera and the line detector (a measurement, not a test).

Run from the repository root::

    python benchmarks/vision_bench.py

Renders the sample track (worlds/line_track.yaml) from poses along the loop
at 320x240 and 640x480, with and without camera effects, and times
``SimCamera.read`` and ``LineDetector.detect`` separately (median and 90th
percentile over the frames, milliseconds).
"""

from __future__ import annotations

import math
import pathlib
import statistics
import time

import numpy as np
import yaml

from beastbt.sim.camera_emulator import CameraEffects, SimCamera
from beastbt.sim.floor import FloorMap
from beastbt.sim.truth import RobotTruth
from beastbt.vision.camera_model import CameraGeometry
from beastbt.vision.line_detector import LineDetector, LineDetectorConfig

ROOT = pathlib.Path(__file__).resolve().parents[1]


def poses_along_track(floor: FloorMap, n: int) -> list[tuple[float, float, float]]:
    """``n`` poses on the loop's centreline, heading along it."""
    segs = floor.lines[0].segments()
    lengths = np.linalg.norm(segs[:, 1] - segs[:, 0], axis=1)
    cum = np.concatenate([[0.0], np.cumsum(lengths)])
    out = []
    for s in np.linspace(0.0, cum[-1], n, endpoint=False):
        i = int(np.searchsorted(cum, s, side="right")) - 1
        a, b = segs[i]
        t = (s - cum[i]) / lengths[i]
        p = a + t * (b - a)
        out.append((float(p[0]), float(p[1]), math.atan2(b[1] - a[1], b[0] - a[0])))
    return out


def main() -> None:
    """Print the timing table."""
    world = yaml.safe_load((ROOT / "worlds" / "line_track.yaml").read_text())
    floor = FloorMap.from_dict(world["floor"], np.random.default_rng(0))
    poses = poses_along_track(floor, 400)
    print(f"{'size':>9} {'effects':>8} {'render ms (median/p90)':>24} {'detect ms (median/p90)':>24}")
    for w, h in ((320, 240), (640, 480)):
        geom = CameraGeometry(width_px=w, height_px=h)
        for effects_name, effects in (("none", CameraEffects.none()), ("default", CameraEffects())):
            cam = SimCamera(floor, geom, np.random.default_rng(1), effects)
            det = LineDetector(LineDetectorConfig(), geom)
            render_ms, detect_ms = [], []
            for x, y, yaw in poses:
                cam.update(RobotTruth(x=x, y=y, yaw=yaw, v_mps=0.15))
                t0 = time.perf_counter()
                ok, img = cam.read()
                t1 = time.perf_counter()
                det.detect(img, 0.0)
                t2 = time.perf_counter()
                render_ms.append((t1 - t0) * 1e3)
                detect_ms.append((t2 - t1) * 1e3)

            def fmt(v: list[float]) -> str:
                return f"{statistics.median(v):.2f} / {np.percentile(v, 90):.2f}"

            print(f"{w}x{h:<5} {effects_name:>8} {fmt(render_ms):>24} {fmt(detect_ms):>24}")


if __name__ == "__main__":
    main()
