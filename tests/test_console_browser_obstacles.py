"""The console's map draws what the robot sees, in a real browser (Chromium via Playwright) on a simulator run.

``beastbt run ... --console`` in the corridor with the pacing person, at real
time: the page must draw the LiDAR's returns, the collision monitor's zones
and the person where it walks now (the canvas's ``data-*`` counts say what was
drawn). The local plan comes from go_to, route and return_home, which this
GPS-less corridor has none of: once the run has ended (no more states), the
page is handed its last state with a plan, the global costmap's marks and a
way round added, as the console's socket would hand them, and must draw those
too (the marks only while their box is ticked). Screenshots go to ``$BEASTBT_SCREENSHOTS``
when set.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from console_support import CHROMIUM, CHROMIUM_ARGS, ConsoleRun, wait_for_page
from conftest import REPO

if os.environ.get("BEASTBT_REQUIRE_BROWSER"):
    import playwright.sync_api as playwright_api
    assert CHROMIUM is not None, "Chromium is not installed (.ci/run installs Debian's package)"
else:
    playwright_api = pytest.importorskip("playwright.sync_api")
pytestmark = pytest.mark.skipif(CHROMIUM is None, reason="Chromium is not installed (.ci/run installs Debian's)")

MISSION = f"""mission: console_obstacles
world: {REPO / "worlds" / "corridor_person.yaml"}
steps:
  - drive: {{distance: 0.5 m, speed: 0.15 m/s}}
  - wait: 6 s
"""
"""About 9.5 s at real time; the person sets off at 5 s from the east end, toward the robot."""

DATASET = "Object.assign({}, document.getElementById('map').dataset)"


def test_the_map_draws_the_scan_the_zones_the_walking_person_and_a_local_plan_and_costmap(tmp_path: Path):
    folder = Path(os.environ.get("BEASTBT_SCREENSHOTS") or tmp_path)
    folder.mkdir(parents=True, exist_ok=True)
    mission = tmp_path / "mission.yaml"
    mission.write_text(MISSION, encoding="utf-8")
    run = ConsoleRun(mission, "--speed", "realtime", "--runs-dir", str(tmp_path / "runs"), cwd=tmp_path)
    try:
        with playwright_api.sync_playwright() as pw:
            browser = pw.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS, headless=True)
            page = browser.new_page(viewport={"width": 1400, "height": 1000})
            page.goto(run.url)
            page.get_by_test_id("status").wait_for()
            drawn = wait_for_page(page, f"(d => +d.scanPoints > 100 && d.persons === '1' && d)({DATASET})")
            assert drawn["zones"] == "slow,stop" and drawn["planPoints"] == "0" and drawn["costmapCells"] == "0"
            assert drawn["globalCostmap"] == "" and drawn["pathPoints"] == "0"  # no go_to: no global costmap, no way
            start = float(drawn["personsXy"].split()[0])
            walked = wait_for_page(page, f"(d => parseFloat(d.personsXy) < {start - 1.0} && d)({DATASET})",
                                   timeout_s=15)
            page.screenshot(path=str(folder / "console_obstacles.png"), full_page=True)
            assert int(walked["scanPoints"]) <= 240  # decimated: the state stays small
            wait_for_page(page, "state && ['succeeded', 'failed', 'aborted'].includes(state.status)", timeout_s=30)
            page.wait_for_timeout(300)  # the socket has closed: no state will replace the one handed below
            page.evaluate("""() => { const s = JSON.parse(JSON.stringify(state));
                const p = s.pose; const yaw = p.yaw_deg * Math.PI / 180;
                s.obstacles.plan = [0, 1, 2, 3].map((k) => [p.x + 0.3 * k * Math.cos(yaw),
                                                            p.y + 0.3 * k * Math.sin(yaw) + 0.05 * k * k]);
                s.obstacles.costmap = {resolution_m: 0.05, cells: [[p.x + 1.2, p.y - 0.3], [p.x + 1.25, p.y - 0.3]]};
                s.obstacles.zones.action = "stop";
                const marks = document.createElement("canvas"); marks.width = 3; marks.height = 20;
                const m = marks.getContext("2d"); m.fillStyle = "#ffaa3c6e"; m.fillRect(0, 0, 3, 20);
                s.obstacles.global_costmap = {png: marks.toDataURL(), corner: [p.x + 2.0, p.y - 1.0], yaw_rad: 0,
                                              width_m: 0.3, height_m: 2.0};
                s.obstacles.path = [[p.x, p.y], [p.x + 1.0, p.y + 1.5], [p.x + 3.0, p.y]];
                render(s); }""")
            planned = wait_for_page(page, f"(d => d.planPoints === '4' && d.globalCostmap && d)({DATASET})")
            assert planned["zoneActive"] == "stop" and planned["costmapCells"] == "2"
            assert planned["globalCostmap"] == "3x20" and planned["pathPoints"] == "3"  # the marks and the way round
            page.get_by_test_id("show-global").uncheck()  # the faint layer can be switched off
            assert wait_for_page(page, f"(d => d.globalCostmap === '' && d)({DATASET})")["pathPoints"] == "3"
            page.get_by_test_id("show-global").check()
            page.screenshot(path=str(folder / "console_obstacles_plan.png"), full_page=True)
            browser.close()
    finally:
        run.kill()
