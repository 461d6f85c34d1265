"""Per-frame cost of the simulated camera and the line detector (a measurement, not a test).

Run from the repository root::

    python benchmarks/vision_bench.py

Renders the sample track (worlds/line_track.yaml) from poses along the loop
at 320x240 and 640x480, with and without camera effects, and times, on the
same frames and interleaved frame by frame:

* the anchor: the naive tutorial pipeline of :mod:`naive_line` (grey, blur,
  Otsu, largest contour, centroid);
* the subject: ``LineDetector.detect`` (bird's-eye view, bands, fit,
  junctions);
* for reference, ``SimCamera.read`` (rendering the frame; not a baseline).

Each figure is the median over ``--reps`` passes (default 5) of the median
per-frame time of a pass, with the spread of the passes (min-max); the ratio
is the detector's over the naive pipeline's, per pass.
"""

from __future__ import annotations

import argparse
import math
import pathlib
import statistics
import sys
import time

import numpy as np
import yaml

from beastbt.sim.camera_emulator import CameraEffects, SimCamera
from beastbt.sim.floor import FloorMap
from beastbt.sim.truth import RobotTruth
from beastbt.vision.camera_model import CameraGeometry
from beastbt.vision.line_detector import LineDetector, LineDetectorConfig

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
from naive_line import interleaved_passes, spread  # noqa: E402


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
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--reps", type=int, default=5, help="passes over the frames (default 5)")
    parser.add_argument("--frames", type=int, default=200, help="frames along the loop per pass (default 200)")
    args = parser.parse_args()
    world = yaml.safe_load((ROOT / "worlds" / "line_track.yaml").read_text())
    floor = FloorMap.from_dict(world["floor"], np.random.default_rng(0))
    poses = poses_along_track(floor, args.frames)
    from figures import Figures  # benchmarks/figures.py: saved for benchmarks/check_docs.py, printed
    figures = Figures("vision_bench")
    print(f"per-frame ms, median of {args.reps} passes (min-max) of each pass's median over {args.frames} frames")
    print(f"{'size':>9} {'effects':>8} {'naive (anchor)':>20} {'LineDetector':>20} {'ratio':>18} {'render (ref.)':>20}")
    for w, h in ((320, 240), (640, 480)):
        geom = CameraGeometry(width_px=w, height_px=h)
        for effects_name, effects in (("none", CameraEffects.none()), ("default", CameraEffects())):
            cam = SimCamera(floor, geom, np.random.default_rng(1), effects)
            det = LineDetector(LineDetectorConfig(), geom)
            frames = []
            render_ms = []
            for x, y, yaw in poses:
                cam.update(RobotTruth(x=x, y=y, yaw=yaw, v_mps=0.15))
                t0 = time.perf_counter()
                ok, img = cam.read()
                render_ms.append((time.perf_counter() - t0) * 1e3)
                frames.append(img)
            naive_passes, detect_passes, ratios = interleaved_passes(frames, det, args.reps)
            print(f"{w}x{h:<5} {effects_name:>8} {spread(naive_passes):>20} {spread(detect_passes):>20} "
                  f"{spread(ratios):>17}x {statistics.median(render_ms):>20.2f}")
            key = f"size{w}x{h}.{effects_name}"
            figures.put(f"{key}.naive_ms", statistics.median(naive_passes))
            figures.put(f"{key}.detector_ms", statistics.median(detect_passes))
            figures.put(f"{key}.ratio", statistics.median(ratios))
            figures.put(f"{key}.render_ms", statistics.median(render_ms))
    figures.save()


if __name__ == "__main__":
    main()
