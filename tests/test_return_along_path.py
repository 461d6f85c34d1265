"""return_home: {along: path} retraces the path driven (like ArduPilot's SmartRTL); the default drives straight home."""

from __future__ import annotations

import math

from beastbt.testing import MissionHarness
from conftest import REPO

OUT = ("mission: out_and_back\nworld: campus.yaml\nsteps:\n  - wait: 3 s\n  - drive: {distance: 8 m, speed: 0.3 m/s}\n"
       "  - turn: {angle: 90 deg}\n  - drive: {distance: 6 m, speed: 0.3 m/s}\n  - return_home%s\n")


def closest_to_the_corner_on_the_way_back(along: str) -> tuple[str, float, float]:
    h = MissionHarness.from_yaml(OUT % along, base_dir=REPO / "worlds", seed=3)
    corner = None
    leaving = None
    best = math.inf
    while h.tick() is None and h.now_s < 400:
        name = h.run.root.tip().name if h.run.root.tip() else ""
        if corner is None and "turn" in name:
            corner = (h.truth.x, h.truth.y)
        if "return_home" in name or "back along the path" in name:
            leaving = leaving or h.now_s
            best = min(best, math.hypot(h.truth.x - corner[0], h.truth.y - corner[1]))
    return h.result, best, math.hypot(h.truth.x, h.truth.y)


def test_along_the_path_goes_back_by_the_corner_and_straight_does_not():
    result, by_corner, home_error = closest_to_the_corner_on_the_way_back(": {along: path}")
    assert result == "success" and by_corner < 2.5 and home_error < 4.0
    result, straight_by_corner, _ = closest_to_the_corner_on_the_way_back("")
    assert result == "success" and straight_by_corner > 3.5  # the straight way home cuts the corner


def test_the_retraced_points_are_named_in_order_and_the_last_is_home():
    h = MissionHarness.from_yaml(OUT % ": {along: path}", base_dir=REPO / "worlds", seed=3)
    assert h.run_to_end(400) == "success"
    names = [wp["name"] for wp in h.summary()["waypoints"]]
    along = [n for n in names if n != "home"]
    assert names[-1] == "home" and along and len(set(along)) == len(along)  # not twenty points all called "path"
    assert along == [f"path point {k} of {len(along)}" for k in range(1, len(along) + 1)]
