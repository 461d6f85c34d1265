"""The operator console on a phone, in Chromium: every button is a touch target, and the robot's facing says which
convention it is in (a compass heading on Earth, a yaw from +x on a map).

A finger needs 44 × 44 CSS px (WCAG 2.5.5, Apple's and Android's guides); the E-STOP, the button that matters
most, gets more. On a run without a position on Earth there is no north: "90°" on a robot that faces the map's +x
would be read as "facing +y"; the page says "yaw 0° (+x)" there and "heading 80° E" on a GPS run.
"""

from __future__ import annotations

import pytest

from console_support import WAIT, wait_for_page
from conftest import REPO
from test_console_browser import PHONE, box, browser, playwright_api, run_console, shots  # noqa: F401

TOUCH_PX = 44
"""The least width and height of a touch target (CSS px)."""
ESTOP_PX = 52
"""The E-STOP's least height (CSS px): larger than every other target."""


def visible_buttons(page) -> list[dict]:
    """Every button the page shows: its id or text, and its box (CSS px)."""
    return page.evaluate("""() => [...document.querySelectorAll('button')]
        .filter((b) => b.offsetParent !== null)
        .map((b) => { const r = b.getBoundingClientRect();
                      return {name: b.id || b.textContent.trim(), width: r.width, height: r.height}; })""")


def test_on_a_phone_every_button_is_a_touch_target_and_the_estop_the_largest(browser, run_console, shots):
    run = run_console("mission: phone_ask\nsteps:\n  - ask: {id: go, question: \"Go?\"}\n    then:\n"
                      "      - wait: 60 s\n", "--speed", "realtime")
    context = browser.new_context(**PHONE)
    try:
        page = context.new_page()
        page.goto(run.url)
        playwright_api.expect(page.get_by_test_id("question")).to_be_visible(timeout=10000)
        shots(page, "phone_touch", full_page=False)
        buttons = visible_buttons(page)
        names = {b["name"] for b in buttons}
        assert {"pause", "resume", "abort", "estop-reset", "estop", "answer-yes", "answer-no"} <= names, names
        small = [b for b in buttons if b["width"] < TOUCH_PX or b["height"] < TOUCH_PX]
        assert small == [], small
        estop = next(b for b in buttons if b["name"] == "estop")
        assert estop["height"] >= ESTOP_PX, estop
        for b in buttons:
            if b["name"] != "estop":
                assert estop["width"] * estop["height"] > b["width"] * b["height"], (estop, b)
        # still one row of buttons, all inside the phone's width, and the header not a fifth of the screen
        assert page.evaluate("document.documentElement.scrollWidth") <= 390
        centres = {round(box(page, f"#{n}")["y"] + box(page, f"#{n}")["height"] / 2)
                   for n in ("pause", "resume", "abort", "estop-reset", "estop")}
        assert max(centres) - min(centres) <= 1, centres
        assert box(page, "#bar")["height"] <= 0.16 * 844
    finally:
        context.close()


FACING_MAP = f"""mission: facing_on_a_map
world: {REPO / "worlds" / "office.yaml"}
steps:
  - wait: 60 s
"""
"""Indoors: no GPS fix, the robot stands at the office's start facing +x (yaw 0°)."""
FACING_GPS = f"""mission: facing_on_gps
world: {REPO / "worlds" / "campus.yaml"}
steps:
  - wait: 60 s
failsafes:
  gps_lost: {{after: 3 s, then: hold}}
"""
"""Outdoors, with the GPS awake (a failsafe watches it): the campus start faces yaw 80° (nearly north), a compass
heading of 10° N."""


@pytest.mark.parametrize("mission,word,text,convention", [
    (FACING_MAP, "yaw", "yaw 0° (+x)", "counter-clockwise from the map's +x"),
    (FACING_GPS, "heading", "heading 10° N", "clockwise from north"),
])
def test_the_pose_says_whether_it_is_a_yaw_on_the_map_or_a_compass_heading(
        browser, run_console, shots, mission, word, text, convention):
    run = run_console(mission, "--speed", "realtime")
    page = browser.new_page(viewport={"width": 1400, "height": 1000})
    try:
        page.goto(run.url)
        facing = page.get_by_test_id("facing")
        playwright_api.expect(facing).to_have_text(word, timeout=15000)
        wait_for_page(page, f"document.getElementById('pose-text').textContent.includes({text!r})")
        assert convention in facing.get_attribute("title")
        shots(page, f"facing_{word}", full_page=False)
    finally:
        page.close()
