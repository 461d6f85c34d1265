"""route: {resume: nearest}: after a hold or a take-over the route goes on from the closest remaining place."""

from __future__ import annotations

from beastbt.estimation.geodesy import LocalFrame
from beastbt.testing import MissionHarness
from conftest import REPO

DATUM = LocalFrame(40.41680, -3.70380)  # worlds/campus.yaml; the robot starts at its origin


def place(east: float, north: float) -> str:
    lat, lon, _ = DATUM.to_geodetic(east, north, 0.0)
    return f"{{lat: {lat:.8f}, lon: {lon:.8f}}}"


def run(resume: str) -> MissionHarness:
    text = (f"mission: resume\nworld: campus.yaml\nplaces:\n  far: {place(0, 30)}\n  near: {place(4, 2)}\n"
            f"steps:\n  - route: {{places: [far, near], resume: {resume}}}\n")
    h = MissionHarness.from_yaml(text, base_dir=REPO / "worlds", seed=1)
    h.tick_until(lambda h: h.now_s >= 12.0)  # on the way to 'far', still close to 'near'
    h.run.paused_by = "hold (test)"  # a hold: the tree is not ticked for 3 s
    h.tick_until(lambda h: h.now_s >= 15.0)
    h.run.paused_by = None
    assert h.run_to_end(300) == "success"
    return h


def test_nearest_goes_on_from_the_closest_remaining_place():
    h = run("nearest")
    visits = [(w["name"], w["reached"]) for w in h.summary()["waypoints"]]
    assert visits == [("far", False), ("near", True)]
    assert any(e.kind == "route" and "resuming at the nearest place, near" in e.text for e in h.events)


def test_current_carries_on_to_the_place_it_was_going_to():
    h = run("current")
    assert [(w["name"], w["reached"]) for w in h.summary()["waypoints"]] == [("far", True), ("near", True)]
