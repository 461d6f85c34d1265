"""The station's page as an operator sees it, in Chromium at 1280 px: an e-stop that looks like an alarm, controls
that fit and are off for a lost robot, a file picker for a tablet, success told apart from failure, a map with a
scale that never mixes GPS and map frames, and a robot's console linked only when it is an http(s) address.

Robots are agents in this process (no run), as in test_fleet_station_page.py.
"""

from __future__ import annotations

import time
from pathlib import Path

import pytest

pytest.importorskip("zenoh")
from test_fleet_station_page import CHROMIUM, CHROMIUM_ARGS, free_port, playwright_api, until  # noqa: E402
from beastbt.fleet.agent import FleetAgent  # noqa: E402
from beastbt.fleet.config import FleetOptions  # noqa: E402
from beastbt.fleet.station import Station, StationServer  # noqa: E402

pytestmark = pytest.mark.skipif(CHROMIUM is None, reason="Chromium is not installed (.ci/run installs Debian's)")


class ConsoleAgent(FleetAgent):
    """An agent that says its console is at ``console_url`` (what a robot running with ``--console`` says)."""

    console_url: object = None

    def current_state(self) -> dict:
        state = super().current_state()
        state["console_url"] = self.console_url
        return state


@pytest.fixture
def fleet():
    """A station on loopback and its page's address; ``add(name, ...)`` puts an agent on its fleet."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    station = Station(endpoint).open()
    server = StationServer(station, "127.0.0.1", 0).start()
    agents: list[FleetAgent] = []

    def add(name: str, console_url: object = None, **state) -> FleetAgent:
        agent = ConsoleAgent(name, FleetOptions(endpoint), takes_missions=True)
        agent.console_url = console_url
        agent.last_state = state
        agents.append(agent.start())
        return agent
    try:
        yield f"http://127.0.0.1:{server.port}/", add
    finally:
        for agent in agents:
            agent.close()
        server.close()
        station.close()


@pytest.fixture(scope="module")
def browser():
    with playwright_api.sync_playwright() as pw:
        b = pw.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS, headless=True)
        yield b
        b.close()


@pytest.fixture
def shots(tmp_path: Path):
    import os
    out = Path(os.environ.get("BEASTBT_SCREENSHOTS") or tmp_path)
    out.mkdir(parents=True, exist_ok=True)
    return lambda page, name: page.screenshot(path=str(out / f"station_{name}.png"))


def gps(i: int) -> dict:
    """A robot's state with a GPS fix a few metres apart per ``i``."""
    return {"pose": {"x": float(i), "y": 0.0, "yaw_deg": 90.0, "heading_deg": 0.0},
            "gps": {"lat": 40.4168 + i * 1e-5, "lon": -3.7038, "fix": 1}}


def open_page(browser, url: str, count: int):
    page = browser.new_page(viewport={"width": 1280, "height": 800})
    page.errors = []  # type: ignore[attr-defined]
    page.on("pageerror", lambda error: page.errors.append(str(error)))
    page.goto(url)
    until(lambda: page.locator("tr[data-robot]").count() == count, 10)
    return page


def row(page, name: str):
    return page.locator(f"tr[data-robot='{name}']")


def test_an_estopped_robot_is_red_on_one_line_and_the_controls_fit_at_1280_px(browser, fleet, shots):
    url, add = fleet
    stopped = add("beast-estopped-01", **gps(0))
    add("beast-running-02", **gps(1))
    stopped.estop_latched = True
    page = open_page(browser, url, 2)
    badge = row(page, "beast-estopped-01").locator("[data-testid=status]")
    until(lambda: "STOP" in (badge.text_content() or "").upper())
    shots(page, "estop_1280")
    text = badge.text_content() or ""
    assert "E-STOPPED" in text, text  # says what happened, not "idle · e-stop"
    lines = badge.evaluate("e => { const r = document.createRange(); r.selectNodeContents(e); "
                           "return new Set(Array.from(r.getClientRects()).map(q => Math.round(q.top))).size; }")
    assert lines == 1, lines
    red, green, blue = badge.evaluate("e => getComputedStyle(e).backgroundColor.match(/\\d+/g).slice(0, 3).map(Number)")
    assert red >= 180 and green <= 80 and blue <= 80, (red, green, blue)  # an alarm's red, not grey
    # every control of every row inside the robots' panel and the window: nothing overflows at 1280 px
    assert page.evaluate("document.documentElement.scrollWidth") <= 1280
    panel = page.locator("section.panel").first.bounding_box()
    buttons = page.locator("#robots button")
    assert buttons.count() >= 4
    for i in range(buttons.count()):
        b = buttons.nth(i).bounding_box()
        assert b["x"] >= panel["x"] and b["x"] + b["width"] <= panel["x"] + panel["width"] + 0.5, (i, b, panel)
    table = page.get_by_test_id("robots").bounding_box()
    assert table["x"] + table["width"] <= panel["x"] + panel["width"] + 0.5, (table, panel)
    assert page.errors == []


def test_a_mission_goes_by_the_file_picker_and_success_is_not_styled_as_an_error(browser, fleet, tmp_path, shots):
    url, add = fleet
    agent = add("picker-1", **gps(0))
    page = open_page(browser, url, 1)
    mission = tmp_path / "picked.yaml"
    mission.write_text("mission: picked\nsteps: [stop]\n", encoding="utf-8")
    with page.expect_file_chooser() as chooser:
        row(page, "picker-1").locator("[data-control=mission]").click()
    chooser.value.set_files(str(mission))
    request = agent.missions.get(timeout=5)
    assert request.payload == mission.read_bytes()
    request.answer(True, {"started": "picked", "warnings": []})
    notice = page.get_by_test_id("notice")
    until(lambda: "'picked' started" in (notice.text_content() or ""))
    ok_colour = notice.evaluate("e => getComputedStyle(e).backgroundColor")
    assert notice.get_attribute("data-kind") == "ok"
    shots(page, "picked_ok")
    # the same robot refuses the next one (it has a mission already): the error looks different from the success
    with page.expect_file_chooser() as chooser:
        row(page, "picker-1").locator("[data-control=mission]").click()
    chooser.value.set_files(str(mission))
    until(lambda: "busy" in (notice.text_content() or ""))
    assert notice.get_attribute("data-kind") == "error"
    assert notice.evaluate("e => getComputedStyle(e).backgroundColor") != ok_colour
    shots(page, "picked_error")
    assert page.errors == []


def test_a_lost_robots_controls_are_off(browser, fleet, shots):
    url, add = fleet
    add("here-1", **gps(0))
    lost = add("gone-2", **gps(1))
    page = open_page(browser, url, 2)
    lost.close()  # its liveliness token goes: the station marks it lost
    until(lambda: "lost" in (row(page, "gone-2").get_attribute("class") or ""), 15)
    time.sleep(0.6)  # one more redraw
    shots(page, "lost")
    buttons = row(page, "gone-2").locator("button")
    assert buttons.count() >= 1
    assert all(buttons.nth(i).is_disabled() for i in range(buttons.count()))
    alive = row(page, "here-1").locator("button")
    assert alive.count() >= 1 and not any(alive.nth(i).is_disabled() for i in range(alive.count()))
    assert page.errors == []


def test_the_map_has_a_scale_and_draws_gps_and_map_frame_robots_apart(browser, fleet, shots):
    url, add = fleet
    add("gps-1", **gps(0))
    add("gps-2", **gps(3))
    add("indoor-3", pose={"x": 250.0, "y": -40.0, "yaw_deg": 0.0, "heading_deg": 90.0}, gps=None)
    page = open_page(browser, url, 3)
    the_map = page.get_by_test_id("map")
    until(lambda: the_map.get_attribute("data-robots") == "gps-1,gps-2")
    assert the_map.get_attribute("data-frame") == "gps"
    views = page.locator("[data-testid=frame-view]")
    until(lambda: views.count() == 1)
    assert views.first.get_attribute("data-robot") == "indoor-3"
    assert "own map frame" in (views.first.text_content() or "")
    shots(page, "map_frames")
    # a scale bar on each: a round length, and its bar drawn where it says (light pixels on the dark map)
    for canvas in (the_map, views.first.locator("canvas")):
        metres, px = float(canvas.get_attribute("data-scale-m")), float(canvas.get_attribute("data-scale-px"))
        assert metres > 0 and px >= 10
        lit = canvas.evaluate("""(c) => { const k = devicePixelRatio, g = c.getContext('2d');
            const d = g.getImageData(Math.round(12 * k), c.height - Math.round(12 * k),
                                     Math.round((Number(c.dataset.scalePx) - 4) * k), 1).data;
            let n = 0; for (let i = 0; i < d.length; i += 4) if (d[i] > 150) n++; return n / k; }""")
        assert lit >= px - 6, (lit, px)
    # the GPS view's bar is the right length: the two robots are 3e-5 deg of latitude (3.34 m) apart, drawn with
    # 2 m round them, so the view's height (2/3 of its width, CSS px) holds 7.34 m
    width = the_map.bounding_box()["width"]
    per_m = float(the_map.get_attribute("data-scale-px")) / float(the_map.get_attribute("data-scale-m"))
    assert per_m == pytest.approx(round(width) * 2 / 3 / (3e-5 * 111320 + 4), rel=0.02)
    assert page.errors == []


@pytest.mark.parametrize("console_url,linked", [
    ("http://127.0.0.1:8123/", True),
    ("javascript:alert(document.cookie)", False),
    ("http://user:secret@127.0.0.1:8123/", False),
    ("file:///etc/passwd", False),
])
def test_a_robots_console_is_linked_only_when_it_is_an_http_address(browser, fleet, console_url, linked):
    url, add = fleet
    add("console-1", console_url, **gps(0))
    page = open_page(browser, url, 1)
    name = row(page, "console-1").locator("td").first
    until(lambda: "console-1" in (name.text_content() or ""))
    time.sleep(0.6)
    links = name.locator("a")
    if linked:
        until(lambda: links.count() == 1)
        assert links.first.get_attribute("href") == console_url
        assert "noopener" in links.first.get_attribute("rel")
    else:
        assert links.count() == 0
        until(lambda: name.locator("[data-testid=console-text]").count() == 1)  # shown as text, not a link
    assert page.errors == []


def test_a_robots_alerts_are_listed_in_its_row_the_newest_shown(browser, fleet, shots):
    url, add = fleet
    agent = add("watcher")
    page = open_page(browser, url, 1)
    agent.publish_event(12.0, "alert", "someone in the lab")
    for k in range(60):  # a busy run's other events do not push the alert out of the list
        agent.publish_event(13.0 + k, "step", f"step {k}")
    agent.publish_event(80.5, "alert", "door 3 open (photo alert-2.jpg)")
    alert = row(page, "watcher").get_by_test_id("alert")
    playwright_api.expect(alert).to_have_text("alert: door 3 open (photo alert-2.jpg) (t 80.5 s) · 1 earlier",
                                              timeout=5000)
    assert "t 12.0 s: someone in the lab" in alert.get_attribute("title")
    shots(page, "alerts")
    assert page.errors == []
