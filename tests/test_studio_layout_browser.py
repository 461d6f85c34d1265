"""The studio's layout in Chromium: the map stays put under the cursor, and the Tree tab fits a 1024 px screen.

A click on the map lands where the user aimed only if nothing moves the map between aiming and clicking: entering
a tool (Add place, Draw fence, Make route) or opening the Try panel must leave the map's box, and the lat/lon
under a fixed screen point, as they were.
"""

from __future__ import annotations

import pytest

from test_studio_browser import (Studio, expect, folder, open_file, open_studio, patient_expect,  # noqa: F401
                                 playwright_api, shots, studio)
from console_support import CHROMIUM, CHROMIUM_ARGS, wait_for_page

pytestmark = pytest.mark.skipif(CHROMIUM is None, reason="Chromium is not installed (.ci/run installs Debian's)")


@pytest.fixture(scope="module")
def browser():
    with playwright_api.sync_playwright() as pw:
        b = pw.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS, headless=True)
        yield b
        b.close()


def map_box(page) -> dict:
    """The map element's box on the page, px."""
    return page.get_by_test_id("map").bounding_box()


def dots(page) -> dict:
    """Where each place's dot is on the page, px: two places pin the map's lat/lon at every screen point."""
    return page.evaluate("""() => {
        const out = {};
        for (const m of document.querySelectorAll('[data-testid="place-marker"]')) {
          const r = m.querySelector('.dot').getBoundingClientRect();
          out[m.dataset.place] = [r.x + r.width / 2, r.y + r.height / 2];
        }
        return out;
    }""")


def still(page, what):
    """``what(page)`` once two reads 150 ms apart agree (a resize takes a frame or two to settle)."""
    last = None
    for _ in range(40):
        now = what(page)
        if now == last:
            return now
        last = now
        page.wait_for_timeout(150)
    raise AssertionError("it kept moving")


@pytest.mark.parametrize("width,height", [(1440, 900), (1024, 768)])
def test_no_tool_and_no_try_panel_moves_the_map_under_the_cursor(browser, studio, shots, width, height):
    page = open_studio(browser, studio, "?speed=realtime&max_time=20%20s")
    page.set_viewport_size({"width": width, "height": height})
    page.get_by_test_id("template").select_option("gps_route")
    page.get_by_test_id("new-name").fill("missions/aim.yaml")
    page.get_by_test_id("create").click()
    expect(page.get_by_test_id("map")).to_have_attribute("data-ready", "true")
    for i, dxdy in enumerate([(0, -40), (40, 0)], start=1):  # two places, for a route
        page.get_by_test_id("add-place").click()
        box = still(page, map_box)
        page.mouse.click(box["x"] + box["width"] / 2 + dxdy[0], box["y"] + box["height"] / 2 + dxdy[1])
        expect(page.get_by_test_id("place-marker")).to_have_count(i)
    page.get_by_test_id("map").hover()  # the mouse rests over the map, as a user's aiming hand does
    box0 = still(page, map_box)
    where0 = still(page, dots)
    assert len(where0) == 2
    shots(page, f"layout_{width}_before")

    def unmoved(why: str) -> None:
        box = still(page, map_box)
        assert box == pytest.approx(box0, abs=0.5), f"{why} moved the map: {box0} -> {box}"
        now = dots(page)
        for name, at in where0.items():  # the same place under the same pixel: a click lands where aimed
            assert now[name] == pytest.approx(at, abs=0.5), f"{why} moved what is under the cursor: {name}"

    for tool, name in (("add-place", "add_place"), ("draw-fence", "draw_fence"), ("make-route", "make_route")):
        page.get_by_test_id(tool).click()
        expect(page.get_by_test_id(tool)).to_have_class("active")
        shots(page, f"layout_{width}_{name}")
        unmoved(f"entering {tool}")
        page.get_by_test_id("cancel").click()
        unmoved(f"leaving {tool}")

    # a route's picks fill the Finish button's label: still no move
    page.get_by_test_id("make-route").click()
    for marker in page.get_by_test_id("place-marker").all():
        marker.locator(".dot").click()
    expect(page.get_by_test_id("finish")).to_be_enabled()
    unmoved("picking a route's places")
    page.get_by_test_id("cancel").click()

    page.get_by_test_id("try").click()
    expect(page.get_by_test_id("run-panel")).to_be_visible()
    expect(page.get_by_test_id("run-step")).not_to_have_text("-", timeout=60000)  # a try starts slowly on a busy machine
    shots(page, f"layout_{width}_try_open")
    unmoved("opening the Try panel")
    expect(page.get_by_test_id("run-panel")).to_have_attribute("data-result", "success", timeout=60000)
    page.get_by_test_id("run-output").evaluate("e => e.closest('details').open = true")  # the summary, unfolded
    shots(page, f"layout_{width}_try_done")
    unmoved("the Try panel's summary")
    page.get_by_test_id("run-close").click()
    unmoved("closing the Try panel")
    assert page.page_errors == []


DEEP = """mission: deep_patrol
description: Patrol and look both ways at each end.
tasks:
  look_around:
    - look: {pan: -45 deg}
    - wait: 2 s
    - look: {pan: 45 deg}
    - wait: 2 s
    - look: {pan: 0 deg}
steps:
  - repeat:
      times: 3
      steps:
        - drive: {distance: 3 m, speed: 0.15 m/s}
        - do: look_around
        - turn: {angle: 180 deg}
        - drive: {distance: 3 m, speed: 0.15 m/s}
        - do: look_around
        - turn: {angle: 180 deg}
"""
"""A tree five levels deep: laid out left to right it is wider than the Tree pane of a 1024 px screen."""


def test_the_tree_tab_shows_a_deep_tree_whole_on_a_1024_px_screen(browser, studio, folder, shots):
    (folder / "missions" / "deep.yaml").write_text(DEEP, encoding="utf-8")
    page = browser.new_page(viewport={"width": 1024, "height": 768})
    errors: list[str] = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    page.goto(studio.url)
    expect(page.get_by_test_id("file-list").get_by_test_id("file").first).to_be_visible()
    open_file(page, "missions/deep.yaml")
    page.get_by_test_id("tab-tree").click()
    view = page.get_by_test_id("tree-view")
    expect(view.locator(".node").first).to_be_visible()
    wait_for_page(page, "document.querySelectorAll('.tree-svg .node').length >= 10")
    page.wait_for_timeout(300)
    shots(page, "tree_1024")
    width = page.evaluate("document.documentElement.clientWidth")
    assert page.evaluate("document.documentElement.scrollWidth") <= width
    for sel in (".pane.right", ".tabs", '[data-testid="tree-view"]', ".bar .actions"):
        box = page.locator(sel).bounding_box()
        assert box and box["x"] >= 0 and box["x"] + box["width"] <= width + 0.5, (sel, box, width)
    # nothing of the tree is cut off at the pane's right edge, and no sideways scrolling is needed to see it
    assert view.evaluate("e => e.scrollWidth <= e.clientWidth"), "the tree is wider than its pane"
    right = view.evaluate("e => e.getBoundingClientRect().right")
    boxes = view.locator(".node rect").evaluate_all("els => els.map(e => e.getBoundingClientRect().right)")
    assert boxes and max(boxes) <= right, (max(boxes), right)
    # each step can still be picked: a click on the last turn selects its line in the text
    view.locator('.node[data-line="19"]').click()
    assert page.evaluate("studio.editor.getSelection().startLineNumber") == 19
    assert errors == []
