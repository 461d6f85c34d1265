"""Per-frame cost of the camera's mission detectors against OpenCV's own calls on the same frames (a measurement).

Run from the repository root::

    python benchmarks/vision_detectors.py [--frames 60] [--reps 5]

The frames are photo-like 320x240 pictures (tests/photo_like.py: perspective, blur, noise, uneven light,
JPEG 60) of a wall with a tag at a different pose in each, and a person-sized figure walking across
the motion frames. Timed per frame and interleaved frame by frame, so both sides of a ratio see the
same machine load:

* fiducials: ``FiducialDetector.detect`` (AprilTag 36h11, subpixel corners, solvePnP to the base frame)
  against ``cv2.aruco.ArucoDetector.detectMarkers`` with OpenCV's default parameters (no refinement,
  no pose); goal at most 5 ms a frame;
* motion: ``MotionDetector.process`` (shrink to 160 wide, grey, MOG2, opening) against
  ``BackgroundSubtractorMOG2.apply`` on the full colour frame; goal at most 2 ms a frame;
* for reference: ``QrReader.read`` against ``QRCodeDetector.detectAndDecode``, and ``ColourFinder.find``
  against ``cv2.inRange`` on the full HSV frame.

Each figure is the median over ``--reps`` passes of the median per-frame time of a pass (ms), with the
passes' spread; the ratio is subject over anchor, per pass.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path
from typing import Callable

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
sys.path.insert(0, str(ROOT / "benchmarks"))
from figures import Figures  # noqa: E402
from photo_like import CAMERA, degrade, scene, tag_at  # noqa: E402

from beastbt.vision.colour import ColourFinder, ColourRange  # noqa: E402
from beastbt.vision.fiducials import FiducialDetector  # noqa: E402
from beastbt.vision.motion import MotionDetector  # noqa: E402
from beastbt.vision.qr_codes import QrReader  # noqa: E402


def tag_frames(n: int) -> list[np.ndarray]:
    """``n`` photo-like frames, each with one tag at its own pose (0.5-2 m ahead, turned up to 40 deg)."""
    rng = np.random.default_rng(1)
    out = []
    for i in range(n):
        ahead = 0.5 + 1.5 * (i % 7) / 6
        tag = tag_at(i % 30, ahead, 0.3 * np.sin(i), 40.0 * np.cos(0.7 * i))
        out.append(degrade(scene(rng, tags=[tag], patches=[((40, 40, 200), (20 + 3 * i % 200, 150, 30, 40))]), rng))
    return out


def motion_frames(n: int) -> list[np.ndarray]:
    """``n`` photo-like frames of a still wall, a figure walking across from the tenth on."""
    rng = np.random.default_rng(2)
    base = scene(rng)
    out = []
    for i in range(n):
        img = base.copy()
        if i >= 10:
            x = (20 + 8 * (i - 10)) % 300
            cv2.rectangle(img, (x, 70), (x + 22, 170), (60, 60, 150), -1)
        out.append(degrade(img, rng))
    return out


def qr_frames(n: int) -> list[np.ndarray]:
    """``n`` photo-like frames of a QR board 0.5 m ahead, turned up to 30 deg."""
    rng = np.random.default_rng(3)
    return [degrade(scene(rng, qr_boards=[{"text": "door-3", "size_m": 0.2, "x": 0.5, "y": 0.0, "z_m": 0.2,
                                          "facing_deg": 180 + 30 * np.sin(i)}]), rng) for i in range(n)]


def passes(frames: list[np.ndarray], subject: Callable[[np.ndarray], object], anchor: Callable[[np.ndarray], object],
           reps: int) -> tuple[list[float], list[float]]:
    """Median per-frame ms of ``subject`` and ``anchor`` in each of ``reps`` passes, interleaved frame by frame."""
    subj, anch = [], []
    for _ in range(reps):
        ts, ta = [], []
        for img in frames:
            t0 = time.perf_counter()
            anchor(img)
            t1 = time.perf_counter()
            subject(img)
            t2 = time.perf_counter()
            ta.append((t1 - t0) * 1000.0)
            ts.append((t2 - t1) * 1000.0)
        subj.append(statistics.median(ts))
        anch.append(statistics.median(ta))
    return subj, anch


def report(figures: Figures, name: str, subj: list[float], anch: list[float], goal_ms: float = 0.0) -> None:
    """Print and keep one detector's figures: subject and anchor ms (median, spread) and their ratio."""
    ratios = [s / a for s, a in zip(subj, anch)]
    figures.put(f"{name}.ms", statistics.median(subj), 3)
    figures.spread(f"{name}.ms", subj)
    figures.put(f"{name}.opencv_ms", statistics.median(anch), 3)
    figures.put(f"{name}.ratio", statistics.median(ratios), 2)
    goal = f"  (goal <= {goal_ms:g} ms: {'met' if statistics.median(subj) <= goal_ms else 'MISSED'})" if goal_ms else ""
    print(f"{name:10s} {statistics.median(subj):7.3f} ms [{min(subj):.3f}-{max(subj):.3f}]  OpenCV's own call "
          f"{statistics.median(anch):7.3f} ms  ratio {statistics.median(ratios):.2f}{goal}")


def main() -> None:
    """Time the four detectors against OpenCV's calls and save the figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=60)
    parser.add_argument("--reps", type=int, default=5)
    args = parser.parse_args()
    cv2.setNumThreads(1)  # as a run with a camera does (beastbt.parts.camera.OPENCV_THREADS)
    figures = Figures("vision_detectors")

    frames = tag_frames(args.frames)
    fid = FiducialDetector()
    k, cam = CAMERA.camera_matrix, CAMERA.camera_from_body
    plain = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_APRILTAG_36h11))
    found = sum(1 for img in frames if fid.detect(img))
    print(f"fiducials: a tag found in {found} of {len(frames)} frames")
    report(figures, "fiducials", *passes(frames, lambda img: fid.detect(img, k, None, cam),
                                         lambda img: plain.detectMarkers(cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)),
                                         args.reps), goal_ms=5.0)

    moving = motion_frames(args.frames)
    ours, theirs = MotionDetector(), cv2.createBackgroundSubtractorMOG2(100, 25.0, False)
    report(figures, "motion", *passes(moving, lambda img: ours.process(img), lambda img: theirs.apply(img),
                                      args.reps), goal_ms=2.0)

    codes = qr_frames(max(10, args.frames // 4))
    reader, qr = QrReader(), cv2.QRCodeDetector()
    report(figures, "qr", *passes(codes, reader.read,
                                  lambda img: qr.detectAndDecode(cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)), args.reps))

    finder, red = ColourFinder(), ColourRange.parse("red")
    lo, hi = np.array(red.boxes[0][0], np.uint8), np.array(red.boxes[0][1], np.uint8)
    report(figures, "colour", *passes(frames, lambda img: finder.find(img, red),
                                      lambda img: cv2.inRange(cv2.cvtColor(img, cv2.COLOR_BGR2HSV), lo, hi), args.reps))
    figures.save()


if __name__ == "__main__":
    main()
