"""The station's page in Chromium: every robot listed, its controls, STOP ALL, and a mission dropped on a robot.

Robots are agents in this process (no run), so a mission dropped on the serving one waits in its
queue and is answered here: what the page sent is what the robot got.
"""

from __future__ import annotations

import os
import socket
import time

import pytest

pytest.importorskip("zenoh")
from console_support import CHROMIUM, CHROMIUM_ARGS  # noqa: E402

if os.environ.get("BEASTBT_REQUIRE_BROWSER"):  # CI installs both: there a missing one is a failure, not a skip
    import playwright.sync_api as playwright_api
    assert CHROMIUM is not None, "Chromium is not installed (.ci/run installs Debian's package)"
else:
    playwright_api = pytest.importorskip("playwright.sync_api")
from beastbt.fleet.agent import FleetAgent  # noqa: E402
from beastbt.fleet.config import FleetOptions  # noqa: E402
from beastbt.fleet.station import Station, StationServer  # noqa: E402

pytestmark = pytest.mark.skipif(CHROMIUM is None, reason="Chromium is not installed (.ci/run installs Debian's)")


def free_port() -> int:
    """A TCP port free on loopback now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def until(check, timeout_s: float = 5.0) -> None:
    """Poll ``check`` from here (the page's policy allows no script from a string, so no wait_for_function)."""
    end = time.monotonic() + timeout_s
    while not check():
        assert time.monotonic() < end, "not within the time"
        time.sleep(0.05)


def test_the_station_page_lists_the_robots_stops_them_all_and_sends_a_dropped_mission():
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    station = Station(endpoint).open()
    server = StationServer(station, "127.0.0.1", 0).start()
    agents = [FleetAgent(name, FleetOptions(endpoint), takes_missions=True).start() for name in ("p-1", "p-2")]
    for i, agent in enumerate(agents):  # where each was when its last run ended: both with a GPS fix
        agent.last_state = {"pose": {"x": float(i), "y": 0.0, "yaw_deg": 90.0, "heading_deg": 0.0},
                            "gps": {"lat": 40.4168 + i * 1e-5, "lon": -3.7038, "fix": 1}}
    try:
        with playwright_api.sync_playwright() as pw:
            browser = pw.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS, headless=True)
            page = browser.new_page()
            errors: list = []
            page.on("pageerror", lambda error: errors.append(str(error)))
            page.goto(f"http://127.0.0.1:{server.port}/")
            page.wait_for_selector("tr[data-robot='p-2']", timeout=10000)
            assert page.locator("tr[data-robot]").count() == 2
            until(lambda: "GPS" in (page.locator("#map-info").text_content() or ""))  # one map, on GPS
            page.click("[data-testid=estop-all]")
            deadline = time.monotonic() + 3
            while not all(a.estop_latched for a in agents) and time.monotonic() < deadline:
                time.sleep(0.05)
            assert all(a.estop_latched for a in agents)
            # the table puts the e-stopped robots first, and says so
            until(lambda: "E-STOPPED" in (page.locator("tr[data-robot] .status").first.text_content() or ""))
            for agent in agents:
                agent.estop_latched = False
            # a mission dropped on p-1's row goes to p-1's mission queryable, as YAML
            page.evaluate("""() => {
                const row = document.querySelector("tr[data-robot='p-1']");
                const data = new DataTransfer();
                data.items.add(new File(["mission: dropped\\nsteps: [stop]\\n"], "dropped.yaml"));
                row.dispatchEvent(new DragEvent("drop", {dataTransfer: data, bubbles: true, cancelable: true}));
            }""")
            request = agents[0].missions.get(timeout=5)
            assert request.payload == b"mission: dropped\nsteps: [stop]\n"
            request.answer(True, {"started": "dropped", "warnings": []})
            until(lambda: "'dropped' started" in (page.locator("#notice").text_content() or ""))
            assert agents[1].missions.empty()
            assert errors == []
            browser.close()
    finally:
        for agent in agents:
            agent.close()
        server.close()
        station.close()
