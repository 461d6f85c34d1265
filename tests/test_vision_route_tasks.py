"""``route: {places: [...], at_each: [...], stop_on_failure: false}`` on the simulator (worlds/campus.yaml, GPS)."""

from __future__ import annotations

from pathlib import Path

import cv2
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
    least_pan = 0.0
    while not h.done and h.now_s < 600:
        h.tick()
        least_pan = min(least_pan, h.truth.pan_rad)
        for e in h.events:
            if e.kind == "photo" and e.text.split(":")[0] not in taken:
                place = e.text.split(":")[0]
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
