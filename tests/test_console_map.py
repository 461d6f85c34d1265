"""The console draws the mission's saved map under the robot, with the path planned on it, in a real browser
(Chromium via Playwright) on the office mission; the state's layers put the map, the places and the path where the
simulator's world has them. Screenshots go to ``$BEASTBT_SCREENSHOTS`` when set."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from console_support import CHROMIUM, CHROMIUM_ARGS, ConsoleRun, wait_for_page
from conftest import REPO

DATASET = "Object.assign({}, document.getElementById('map').dataset)"


def test_the_layers_put_the_saved_map_and_its_places_on_the_worlds_plan():
    from beastbt.live.console_state import MapFrame, map_layers, obstacle_layers
    from beastbt.testing import MissionHarness
    h = MissionHarness.from_file(REPO / "missions" / "office_rooms.yaml")
    h.tick(40)
    run = h.prepared.run
    frame = MapFrame(run, h.prepared.world)
    layers = map_layers(run, h.prepared.world, frame)
    saved = layers["saved_map"]
    assert saved["png"].startswith("data:image/png;base64,")
    # the map's origin is the robot's start in the world (2.5, 2.0), facing east: its lower-left corner at -3, -2.5
    assert saved["corner"] == [-0.5, -0.5] and saved["yaw_rad"] == 0.0
    places = {p["name"]: p["xy"] for p in layers["places"]}
    assert places == {"kitchen": [5.5, 7.5], "lab": [8.5, 2.5]}
    assert [w["name"] for w in layers["waypoints"]] == ["kitchen", "lab", "home"]
    pose = frame.pose()
    truth = run.io.sim.truth
    assert abs(pose[0] - truth.x) < 0.1 and abs(pose[1] - truth.y) < 0.1  # the map pose, on the plan
    from beastbt.recording.obstacle_views import board_reader
    path = obstacle_layers(run, frame, board_reader(), run.clock.now(), None)["path"]
    assert path[-1] == [5.5, 7.5] and abs(path[0][0] - 2.5) < 0.1


@pytest.mark.skipif(CHROMIUM is None, reason="Chromium is not installed (.ci/run installs Debian's)")
def test_the_page_draws_the_saved_map_and_the_planned_path(tmp_path: Path):
    playwright_api = pytest.importorskip("playwright.sync_api")
    folder = Path(os.environ.get("BEASTBT_SCREENSHOTS") or tmp_path)
    folder.mkdir(parents=True, exist_ok=True)
    run = ConsoleRun(REPO / "missions" / "office_rooms.yaml", "--speed", "4", "--runs-dir", str(tmp_path / "runs"),
                     cwd=tmp_path)
    try:
        with playwright_api.sync_playwright() as pw:
            browser = pw.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS, headless=True)
            page = browser.new_page(viewport={"width": 1400, "height": 1000})
            page.goto(run.url)
            page.get_by_test_id("status").wait_for()
            drawn = wait_for_page(page, f"(d => d.savedMap && +d.pathPoints > 1 && d)({DATASET})", timeout_s=30)
            assert drawn["savedMap"] == "300x200"  # the office map's cells, one pixel each
            page.screenshot(path=str(folder / "console_map.png"), full_page=True)
            browser.close()
    finally:
        run.kill()
