"""``route: {places: [...], at_each: [...], stop_on_failure: false}`` on the simulator (worlds/campus.yaml, GPS)."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import py_trees

from beastbt.testing import MissionHarness

ROOT = Path(__file__).resolve().parents[1]
PLACES = """places:
  a: {lat: 40.41690, lon: -3.70380}
  b: {lat: 40.41700, lon: -3.70350, tolerance: 3 m}
  c: {lat: 40.41680, lon: -3.70330}
"""


def campus(steps: str, seed: int = 1) -> MissionHarness:
    text = "mission: t\nworld: ../worlds/campus.yaml\n" + PLACES + "steps:\n" + steps
    return MissionHarness.from_yaml(text, seed=seed, base_dir=ROOT / "missions")


def test_a_photo_and_a_look_at_each_place():
    h = campus("  - route: {places: [a, b, c], at_each: [photo, {look: {pan: -45 deg}}, {wait: 2 s}, "
               "{look: {pan: 0 deg}}]}\n")
    taken: dict[str, str] = {}
    where: dict[str, tuple[float, ...]] = {}  # the camera's true pose when each place's photo was taken
    least_pan = 0.0
    while not h.done and h.now_s < 600:
        h.tick()
        least_pan = min(least_pan, h.truth.pan_rad)
        for e in h.events:
            if e.kind == "photo" and e.text.split(":")[0] not in taken:
                place = e.text.split(":")[0]
                t = h.truth
                where[place] = (t.x, t.y, t.yaw, t.pan_rad, t.tilt_rad)
                # taken where it is named: that place's go_to has just succeeded, the next has not started
                legs = {n.name.split()[1]: n.status for n in h.root.iterate() if n.name.startswith("go_to ")}
                taken[place] = str(legs)
                assert legs[place] == py_trees.common.Status.SUCCESS, legs
                later = [q for q in "abc" if q > place]
                assert all(legs[q] == py_trees.common.Status.INVALID for q in later), legs
    assert h.result == "success"
    photos = h.summary()["vision"]["photos"]
    assert [p["name"] for p in photos] == ["a", "b", "c"]
    for p in photos:
        assert Path(p["file"]).name == f"{p['name']}.jpg" and cv2.imread(p["file"]) is not None
    assert least_pan < -0.6  # the gimbal looked right (-45 deg) at the places
    # each photo shows its place: it matches what the simulated camera sees from that place better than what it
    # sees from the others (not a frame from the way there, nor another place's)
    camera = h.run.io.sim_camera
    for p in photos:
        photo = grey_small(cv2.imread(p["file"]))
        scores = {q: likeness(photo, grey_small(camera.render(x, y, yaw, pan_rad=pan, tilt_rad=tilt)))
                  for q, (x, y, yaw, pan, tilt) in where.items()}
        assert max(scores, key=scores.get) == p["name"] and scores[p["name"]] > 0.8, (p["name"], scores)


def grey_small(image: np.ndarray) -> np.ndarray:
    """A picture as an 80x60 grey float array (the rendering's noise and texture averaged out)."""
    return cv2.resize(cv2.cvtColor(image, cv2.COLOR_BGR2GRAY), (80, 60), interpolation=cv2.INTER_AREA).astype(float)


def likeness(a: np.ndarray, b: np.ndarray) -> float:
    """Normalised cross-correlation of two pictures of one size (1: the same up to brightness and contrast)."""
    a, b = a - a.mean(), b - b.mean()
    return float((a * b).sum() / np.sqrt((a * a).sum() * (b * b).sum() + 1e-12))


def test_stop_on_failure_false_goes_on_after_a_place_it_cannot_reach():
    steps = ("  - route: {places: [a, b, c], gps_timeout: 5 s, stop_on_failure: false, "
             "at_each: [{wait: 1 s}]}\n")
    h = campus(steps)
    # b is made unreachable: its go_to fails at once (as a substituted failure would)
    node = next(n for n in h.root.iterate() if n.name.startswith("go_to b"))
    node.update = lambda: node.fail("no way through")  # type: ignore[method-assign]
    assert h.run_to_end(600) == "success"
    missed = [e.text for e in h.events if e.kind == "place_missed"]
    assert len(missed) == 1 and missed[0].startswith("b: go_to b") and "no way through" in missed[0]
    reached = {w["name"]: w["reached"] for w in h.summary()["waypoints"]}
    assert reached["a"] and reached["c"] and not reached.get("b", False), reached


def test_stop_on_failure_true_is_the_default():
    h = campus("  - route: {places: [a, b, c], at_each: [{wait: 1 s}]}\n")
    node = next(n for n in h.root.iterate() if n.name.startswith("go_to b"))
    node.update = lambda: node.fail("no way through")  # type: ignore[method-assign]
    assert h.run_to_end(600) == "failure"
    assert not any(e.kind == "place_missed" for e in h.events)
