"""Closed loop: the detector is good enough to follow the sample track with a simple controller.

A unicycle with true kinematics drives at 0.15 m/s; 15 times a second the
simulated camera renders a frame, the detector reads it and a pure-pursuit
law turns the robot towards the line point at the look-ahead:

    curvature = 2 y / (L^2 + y^2),  angular speed = speed * curvature

(``y`` = ``offset_m`` at ``L`` = ``lookahead_m``; the last command is held
while the line is not seen). One full lap passes two crossings, a T junction,
two sharp corners, the gentle arc with its gap, a shadow and a glare spot.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import yaml

from beastbt.blackboard.types import LineObservation
from beastbt.sim.camera_emulator import CameraEffects, SimCamera
from beastbt.sim.floor import FloorMap
from beastbt.sim.truth import RobotTruth
from beastbt.vision.camera_model import CameraGeometry
from beastbt.vision.line_detector import LineDetector, LineDetectorConfig

REPO = Path(__file__).resolve().parent.parent

SPEED_MPS = 0.15
FRAME_RATE_HZ = 15.0
MAX_TURN_RPS = 1.5
RUN_S = 90.0  # a full lap of the 13.1 m loop


def pure_pursuit(obs: LineObservation, lookahead_m: float, speed_mps: float) -> float:
    """Angular speed (rad/s, CCW) that steers the robot centre through the line point at the look-ahead."""
    y = obs.offset_m
    return max(-MAX_TURN_RPS, min(MAX_TURN_RPS, speed_mps * 2.0 * y / (lookahead_m**2 + y**2)))


def loop_arc_length(floor: FloorMap, x: float, y: float) -> float:
    """Arc length along the loop (path 0) of its point nearest to (x, y), metres."""
    segs = floor.lines[0].segments()
    a, ab = segs[:, 0], segs[:, 1] - segs[:, 0]
    lengths = np.linalg.norm(ab, axis=1)
    t = np.clip(((np.array([x, y]) - a) * ab).sum(1) / lengths**2, 0.0, 1.0)
    d = np.linalg.norm(a + t[:, None] * ab - np.array([x, y]), axis=1)
    i = int(np.argmin(d))
    return float(lengths[:i].sum() + t[i] * lengths[i])


def test_follows_the_sample_track_for_a_lap() -> None:
    world = yaml.safe_load((REPO / "worlds" / "line_track.yaml").read_text())
    floor = FloorMap.from_dict(world["floor"], np.random.default_rng(0))
    geom = CameraGeometry()
    camera = SimCamera(floor, geom, np.random.default_rng(42), CameraEffects())
    config = LineDetectorConfig()
    detector = LineDetector(config, geom)
    start = world["start"]
    x, y, yaw = start["x"], start["y"], math.radians(start["yaw_deg"])
    loop_length = float(np.linalg.norm(np.diff(floor.lines[0].segments(), axis=1), axis=2).sum())

    w_rps, t, dt = 0.0, 0.0, 1.0 / FRAME_RATE_HZ
    errors, seen, progress = [], 0, 0.0
    s_prev = loop_arc_length(floor, x, y)
    junction_frames = 0
    while t < RUN_S:
        camera.update(RobotTruth(t_s=t, x=x, y=y, yaw=yaw, v_mps=SPEED_MPS, w_rps=w_rps))
        ok, image = camera.read()
        assert ok
        obs = detector.detect(image, t)
        if obs.seen:
            seen += 1
            w_rps = pure_pursuit(obs, config.lookahead_m, SPEED_MPS)
        junction_frames += obs.intersection
        for _ in range(4):  # integrate the unicycle between frames
            h = dt / 4
            x += SPEED_MPS * math.cos(yaw) * h
            y += SPEED_MPS * math.sin(yaw) * h
            yaw += w_rps * h
            errors.append(floor.distance_to_line(x, y))
        s = loop_arc_length(floor, x, y)
        progress += (s - s_prev + loop_length / 2) % loop_length - loop_length / 2  # forward along the loop, across the seam
        s_prev = s
        t += dt

    errors_m = np.array(errors)
    frames = int(round(RUN_S * FRAME_RATE_HZ))
    assert (errors_m < 0.05).mean() >= 0.9
    assert np.percentile(errors_m, 95) < 0.04
    # it went round the loop (not off along a crossing line or the spur) ...
    assert progress >= 0.95 * SPEED_MPS * RUN_S
    # ... seeing the line nearly all the time, and the junctions on the way
    assert seen >= 0.97 * frames
    assert junction_frames >= 3 * 5
