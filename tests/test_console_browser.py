"""The operator console in a real browser (Debian's Chromium, driven by Playwright) on simulator runs.

Each test starts ``beastbt run ... --console 127.0.0.1:0`` as a user would and
works the page through its ``data-testid``s; what the robot did is read back
from ``GET /api/state`` and the run's exit code. Screenshots go to
``$BEASTBT_SCREENSHOTS`` when it is set (to look at them), else to the test's
temporary folder.
"""

from __future__ import annotations

import os
import textwrap
import time
from pathlib import Path

import pytest

from console_support import (ASK, CHROMIUM, CHROMIUM_ARGS, SHORT, STILL_M, WAIT, ConsoleRun, moved_m,
                             wait_for_page)
from conftest import REPO

if os.environ.get("BEASTBT_REQUIRE_BROWSER"):  # CI installs both: there a missing one is a failure, not a skip
    import playwright.sync_api as playwright_api
    assert CHROMIUM is not None, "Chromium is not installed (.ci/run installs Debian's package)"
else:
    playwright_api = pytest.importorskip("playwright.sync_api")
pytestmark = pytest.mark.skipif(CHROMIUM is None, reason="Chromium is not installed (.ci/run installs Debian's)")
REBOUND = "MAP evil.test 127.0.0.1"
"""Chromium's resolver rule for the rebinding test: the name evil.test is 127.0.0.1."""



@pytest.fixture(scope="module")
def browser():
    with playwright_api.sync_playwright() as pw:
        # evil.test resolves to this computer: a DNS-rebinding page, without a DNS server (still loopback only)
        b = pw.chromium.launch(executable_path=CHROMIUM, args=[*CHROMIUM_ARGS, f"--host-resolver-rules={REBOUND}"],
                               headless=True)
        yield b
        b.close()


@pytest.fixture
def shots(tmp_path: Path):
    folder = Path(os.environ.get("BEASTBT_SCREENSHOTS") or tmp_path)
    folder.mkdir(parents=True, exist_ok=True)

    def shot(page, name: str, full_page: bool = True) -> Path:
        path = folder / f"console_{name}.png"
        page.screenshot(path=str(path), full_page=full_page)
        return path
    return shot


@pytest.fixture
def run_console(tmp_path: Path):
    runs: list[ConsoleRun] = []

    def start(mission, *extra: str, host: str = "127.0.0.1") -> ConsoleRun:
        path = mission if isinstance(mission, Path) else tmp_path / "mission.yaml"
        if not isinstance(mission, Path):
            path.write_text(mission, encoding="utf-8")
        run = ConsoleRun(path, "--runs-dir", str(tmp_path / "runs"), *extra, host=host, cwd=tmp_path)
        runs.append(run)
        return run
    yield start
    for run in runs:
        run.kill()


def open_page(browser, run: ConsoleRun):
    page = browser.new_page(viewport={"width": 1400, "height": 1000})
    page.goto(run.url)
    page.get_by_test_id("status").wait_for()
    return page


def test_the_page_follows_the_mission_step_and_tree(browser, run_console, shots):
    run = run_console(REPO / "missions" / "patrol.yaml", "--speed", "6", "--max-time", "40 s")
    page = open_page(browser, run)
    step = page.get_by_test_id("step")
    playwright_api.expect(step).not_to_have_text("-", timeout=10000)
    first = step.inner_text()
    tree = page.get_by_test_id("tree")
    rows = tree.locator("[data-node-id]")
    assert rows.count() == len(run.state()["tree"]) > 10  # every node of the compiled tree
    running_before = tree.locator(".node.running").evaluate_all("els => els.map(e => e.dataset.nodeId)")
    playwright_api.expect(step).not_to_have_text(first, timeout=20000)
    running_after = tree.locator(".node.running").evaluate_all("els => els.map(e => e.dataset.nodeId)")
    assert running_before and running_after and running_before != running_after
    assert tree.locator(".node.success").count() >= 1
    assert tree.locator(".node.on-path").count() >= 2  # the running branch, root to leaf
    playwright_api.expect(page.get_by_test_id("progress")).to_contain_text("/42 steps")
    assert page.get_by_test_id("battery").inner_text().startswith("battery ")
    wait_for_page(page, "window.beastbtVideoStats && window.beastbtVideoStats.frames > 2", timeout_s=20)
    shots(page, "patrol")


def test_pause_stops_the_robot_and_the_mission_clock_then_resume(browser, run_console, shots):
    run = run_console(REPO / "missions" / "patrol.yaml", "--speed", "realtime", "--max-time", "60 s")
    page = open_page(browser, run)
    run.wait_state(lambda s: s["speed_mps"] > 0.05, 20)
    page.get_by_test_id("pause").click()
    playwright_api.expect(page.get_by_test_id("status")).to_have_text("paused")
    paused = run.wait_state(lambda s: s["speed_mps"] == 0.0, 5)
    # both: that it is paused, and the step it is paused in
    assert paused["last_step"] not in (None, "-", "(paused)")
    playwright_api.expect(page.get_by_test_id("step")).to_have_text(f"{paused['last_step']} (paused)")
    time.sleep(1.0)
    later = run.state()
    assert later["status"] == "paused" and later["speed_mps"] == 0.0
    assert later["time_s"] == paused["time_s"]  # the mission's time stands still
    assert moved_m(later["pose"], paused["pose"]) < STILL_M  # held still, give or take the ramp-down's last mm
    shots(page, "paused")
    page.get_by_test_id("resume").click()
    playwright_api.expect(page.get_by_test_id("status")).to_have_text("running")
    moving = run.wait_state(lambda s: s["speed_mps"] > 0.05 and s["time_s"] > later["time_s"] + 0.5, 10)
    assert moving["status"] == "running"


def test_the_on_page_joystick_drives_while_pressed_and_stops_on_release(browser, run_console, shots):
    run = run_console(WAIT, "--speed", "realtime")
    page = open_page(browser, run)
    start = run.wait_state(lambda s: s["pose"] is not None, 10)["pose"]
    pad = page.get_by_test_id("joystick").bounding_box()
    cx, cy = pad["x"] + pad["width"] / 2, pad["y"] + pad["height"] / 2
    page.mouse.move(cx, cy)
    page.mouse.down()
    page.mouse.move(cx, cy - pad["height"] * 0.4, steps=5)  # stick forward
    driving = run.wait_state(lambda s: s["teleop"] and s["speed_mps"] > 0.05, 5)
    assert driving["step"] == "wait 60 s (teleop)"  # the operator took over: the mission waits at its step
    time.sleep(1.0)
    shots(page, "joystick")
    page.mouse.up()
    stopped = run.wait_state(lambda s: not s["teleop"] and s["speed_mps"] == 0.0, 3)
    moved = abs(stopped["pose"]["x"] - start["x"]) + abs(stopped["pose"]["y"] - start["y"])
    assert moved > 0.1
    time.sleep(0.5)
    assert moved_m(run.state()["pose"], stopped["pose"]) < STILL_M  # released: it stays stopped


def test_the_estop_button_stops_the_robot_and_ends_the_run(browser, run_console, shots):
    run = run_console(REPO / "missions" / "patrol.yaml", "--speed", "realtime")
    page = open_page(browser, run)
    run.wait_state(lambda s: s["speed_mps"] > 0.05, 20)
    assert page.get_by_test_id("estop").is_visible()
    page.get_by_test_id("estop").click()
    playwright_api.expect(page.get_by_test_id("status")).to_have_text("aborted", timeout=5000)
    assert page.get_by_test_id("estop").get_attribute("class").find("latched") >= 0
    shots(page, "estop")
    code, out, _ = run.finish()
    assert code == 1
    assert "emergency stop" in out


def test_a_question_is_answered_on_the_page(browser, run_console, shots):
    run = run_console(ASK, "--speed", "realtime")
    page = open_page(browser, run)
    question = page.get_by_test_id("question")
    playwright_api.expect(question).to_be_visible(timeout=10000)
    playwright_api.expect(question).to_contain_text("Is the door open?")
    assert run.state()["question"] == {"id": "door", "text": "Is the door open?", "choices": ["yes", "no"]}
    shots(page, "question")
    page.get_by_test_id("answer-yes").click()
    playwright_api.expect(question).to_be_hidden(timeout=5000)
    playwright_api.expect(page.get_by_test_id("events")).to_contain_text("door: yes (by console)")
    playwright_api.expect(page.get_by_test_id("status")).to_have_text("succeeded", timeout=20000)
    code, out, _ = run.finish()
    assert code == 0
    assert "door: yes (by console)" in out


def test_the_page_shows_the_final_status_after_the_end(browser, run_console, shots):
    # In the lab, the camera levelled at the dock's tag 0 and the tag detector awake all along (for a tag 9 the lab
    # does not have): the page draws the tag found over the video.
    mission = f"""mission: console_short
world: {REPO / 'worlds' / 'lab.yaml'}
steps:
  - look: {{tilt: 40 deg}}
  - abort_if: {{sees: {{tag: 9}}}}
    steps:
      - drive: {{distance: 0.3 m}}
      - wait: 4 s
"""
    run = run_console(mission, "--speed", "realtime")
    page = open_page(browser, run)
    wait_for_page(page, "window.beastbtVideoStats.frames > 0", timeout_s=10)  # a frame, captioned "running"
    wait_for_page(page, "window.beastbtVideoStats.detections > 0", timeout_s=10)  # tag 0 outlined on it
    code, _, _ = run.finish()
    assert code == 0
    playwright_api.expect(page.get_by_test_id("status")).to_have_text("succeeded", timeout=5000)
    playwright_api.expect(page.get_by_test_id("pause")).to_be_disabled()
    # the outcome and the last step, not the last step as if it still ran; the video says it ended
    playwright_api.expect(page.locator("#bar .step")).to_have_text("ended: succeeded · last step: wait 4 s")
    ended = page.get_by_test_id("video").get_attribute("data-ended")
    assert ended is not None and ended.startswith("ended: succeeded at t ") and ended.endswith("last step: wait 4 s")
    dark, bright, below = page.get_by_test_id("video").evaluate("""c => {
        const g = c.getContext('2d'), band = Math.round(c.height / 16 * 3), px = (y, h, x = 0, w = c.width) => {
            const d = g.getImageData(x, y, w, h).data, out = [];
            for (let i = 0; i < d.length; i += 4) out.push((d[i] + d[i + 1] + d[i + 2]) / 3);
            return out; };
        // under the band, the middle half: the picture (a 4:3 camera has black bars either side in the 16:9 canvas)
        const top = px(0, band), under = px(band + 10, 10, c.width / 4, c.width / 2);
        return [top.filter(v => v < 40).length / top.length, top.filter(v => v > 150).length,
                under.reduce((a, v) => a + v, 0) / under.length]; }""")
    assert dark > 0.7 and bright > 100  # over the last frame: a dark band, with the words on it
    assert below > 60  # and under it the camera's last frame (grey floor), not an empty canvas
    shots(page, "final")


def test_off_loopback_the_page_and_the_api_need_the_token(browser, run_console):
    run = run_console(WAIT, "--speed", "realtime", host="0.0.0.0")
    assert run.token and len(run.token) >= 16
    for path in ("/", "/api/state", "/api/map"):
        status, body = run.api(path, token=False, host="127.0.0.1")
        assert status == 401 and "token" in body["error"]
    status, body = run.api("/api/estop", {}, token=False, host="127.0.0.1")
    assert status == 401 and run.state()["estop"] is False  # refused before it did anything
    assert run.api("/api/state")[0] == 200
    page = browser.new_page()
    page.goto(run.url.replace(run.url.split("/")[2].split(":")[0], "127.0.0.1", 1))
    playwright_api.expect(page.get_by_test_id("status")).to_have_text("running", timeout=10000)
    stranger = browser.new_context().new_page()  # no cookie from the visit with the token
    response = stranger.goto(f"http://127.0.0.1:{run.port}/")
    assert response.status == 401 and "token" in stranger.content()


GAMEPAD = """
window.__pad = {id: "Test pad (STANDARD GAMEPAD)", index: 0, connected: true, mapping: "standard",
                axes: [0, 0, 0, 0], buttons: Array.from({length: 17}, () => ({pressed: false, value: 0}))};
navigator.getGamepads = () => [window.__pad];
"""


def test_a_gamepad_drives_through_the_browser_with_the_same_deadman(browser, run_console):
    run = run_console(WAIT, "--speed", "realtime")
    page = browser.new_page()
    page.add_init_script(GAMEPAD)  # a standard-mapping pad, as the Gamepad API reports one
    page.goto(run.url)
    start = run.wait_state(lambda s: s["pose"] is not None, 10)["pose"]
    page.evaluate("window.__pad.axes[1] = -0.9")  # stick forward, deadman not held
    time.sleep(1.0)
    assert run.state()["speed_mps"] == 0.0 and not run.state()["teleop"]  # no deadman, no motion
    page.evaluate("window.__pad.buttons[4] = {pressed: true, value: 1}")  # LB: the deadman
    run.wait_state(lambda s: s["teleop"] and s["speed_mps"] > 0.05, 5)
    playwright_api.expect(page.locator("#gamepad-info")).to_contain_text("driving")
    time.sleep(1.0)
    page.evaluate("window.__pad.buttons[4] = {pressed: false, value: 0}")
    stopped = run.wait_state(lambda s: not s["teleop"] and s["speed_mps"] == 0.0, 3)
    assert stopped["pose"]["x"] - start["x"] > 0.05


PHONE = {"viewport": {"width": 390, "height": 844}, "device_scale_factor": 2, "is_mobile": True, "has_touch": True}
DESKTOP = {"viewport": {"width": 1366, "height": 900}}
WATCH_SCROLL = "window.__maxScrollY = 0; addEventListener('scroll', () => { " \
               "window.__maxScrollY = Math.max(window.__maxScrollY, window.scrollY); });"
"""Records how far the page itself ever scrolled (the page is never scrolled by hand in these tests)."""


def box(page, selector: str) -> dict:
    """The element's bounding box in CSS px of the viewport (x, y, width, height, bottom)."""
    b = page.locator(selector).first.bounding_box()
    assert b is not None, f"{selector} is not rendered"
    return {**b, "bottom": b["y"] + b["height"]}


def text_lines(page, selector: str) -> int:
    """How many lines the element's text is laid out on (its line boxes)."""
    return page.locator(selector).evaluate(
        "e => { const r = document.createRange(); r.selectNodeContents(e); "
        "return new Set(Array.from(r.getClientRects()).map(q => Math.round(q.top))).size; }")


def open_watched(browser, run: ConsoleRun, device: dict):
    """A page of the console in a new context for ``device``, with every failed request and console error kept."""
    context = browser.new_context(**device)
    page = context.new_page()
    problems: list[str] = []
    page.on("console", lambda m: problems.append(f"console {m.type}: {m.text}") if m.type == "error" else None)
    page.on("response", lambda r: problems.append(f"{r.status} {r.url}") if r.status >= 400 else None)
    page.on("requestfailed", lambda r: problems.append(f"failed {r.url}"))
    page.add_init_script(WATCH_SCROLL)
    page.goto(run.url)
    page.get_by_test_id("status").wait_for()
    return context, page, problems


def test_on_a_phone_and_a_desktop_the_question_header_and_pad_stay_in_sight_and_only_the_tree_scrolls(
        browser, run_console, shots):
    steps = "  - wait: 200 ms\n" * 220
    run = run_console(f"mission: many_steps\nsteps:\n  - ask: {{id: go, question: \"Start the long walk?\"}}\n"
                      f"    then:\n{textwrap.indent(steps, '    ')}", "--speed", "realtime")
    phone_context, phone, phone_problems = open_watched(browser, run, PHONE)
    desk_context, desk, desk_problems = open_watched(browser, run, DESKTOP)
    try:
        question = phone.get_by_test_id("question")
        playwright_api.expect(question).to_be_visible(timeout=10000)
        # the phone: a compact header, the question right under it, the buttons on one line, the pad on screen
        bar, asked = box(phone, "#bar"), box(phone, "#question")
        assert bar["y"] >= 0 and bar["height"] <= 0.16 * 844, bar  # not a fifth of the screen
        assert asked["y"] >= bar["bottom"] - 0.5 and asked["bottom"] <= 844, (bar, asked)  # in sight, not under
        for button in ("#estop", "#estop-reset", "#pause", "#resume", "#abort"):
            assert text_lines(phone, button) == 1, button
            assert box(phone, button)["height"] >= 44, button  # a finger's target (test_console_touch_browser.py)
            centre = box(phone, button)["y"] + box(phone, button)["height"] / 2
            assert abs(centre - (box(phone, "#estop")["y"] + box(phone, "#estop")["height"] / 2)) <= 1, button
            assert box(phone, button)["x"] + box(phone, button)["width"] <= 390, button
        pad = box(phone, "#joystick")
        assert pad["y"] >= asked["bottom"] and pad["bottom"] <= 844, pad  # on the first screen, no scrolling
        assert phone.evaluate("document.documentElement.scrollWidth") <= 390  # nothing wider than the phone
        shots(phone, "phone_question", full_page=False)
        phone.evaluate("window.scrollTo(0, 700)")  # the operator scrolls down to the map: the question stays
        scrolled = box(phone, "#question")
        assert phone.evaluate("window.scrollY") > 300 and 0 <= scrolled["y"] and scrolled["bottom"] <= 844, scrolled
        assert scrolled["y"] >= box(phone, "#bar")["bottom"] - 0.5
        phone.evaluate("window.scrollTo(0, 0); window.__maxScrollY = 0")
        phone.get_by_test_id("answer-yes").tap()
        playwright_api.expect(question).to_be_hidden(timeout=5000)
        # the tree advances (a new running row every 200 ms): it follows in its own panel, the pages never move
        for page in (phone, desk):
            wait_for_page(page, "document.querySelectorAll('#tree .node.success').length > 30", timeout_s=30)
        for page, bottom in ((phone, 1e9), (desk, 900)):
            tree = page.get_by_test_id("tree")
            assert tree.evaluate("t => t.scrollHeight > t.clientHeight && t.scrollTop > 0")  # it scrolled itself
            # the leaf (the deepest running row, the last in the document) is in the panel's sight, and on a desktop
            # (where the panel starts on the first screen) on the screen too
            in_view = tree.evaluate("""t => { const all = t.querySelectorAll('.node.running'), r = all[all.length - 1];
                if (!r || all.length < 3) return null;
                const a = r.getBoundingClientRect(), b = t.getBoundingClientRect();
                return a.top >= b.top - 1 && a.bottom <= b.bottom + 1 ? a.bottom : -1; }""")
            assert 0 < in_view <= bottom, in_view
            assert page.evaluate("[window.scrollY, window.__maxScrollY]") == [0, 0]
        # the desktop: the header covers neither the Camera's nor the Map's title
        header = box(desk, "#top")
        for title in (".video-panel h2", ".map-panel h2"):
            assert box(desk, title)["y"] >= header["bottom"], (title, header)
        pad = box(desk, "#joystick")
        assert pad["bottom"] <= 900, pad
        shots(phone, "phone_tree", full_page=False)
        shots(desk, "desktop_tree", full_page=False)
        # the favicon is served: no 404 and no error in either browser console
        assert phone_problems == [] and desk_problems == [], (phone_problems, desk_problems)
        desk.get_by_role("button", name="fold done").click()
    finally:
        phone_context.close()
        desk_context.close()


EVIL_PAGE = """<!doctype html><html><body><h1>cat pictures</h1>
<iframe name="sink" style="display:none"></iframe>
<form id="form" method="POST" target="sink" enctype="text/plain" action="__CONSOLE__/api/estop">
  <input name='{"x":"' value='"}'></form>
<script>
const CONSOLE = "__CONSOLE__";
const stick = JSON.stringify({linear: 1.0, angular: 0.0, deadman: true});
window.results = {read: [], answered: 0, ws: [], done: false};
async function attempt(what, promise) {
  try { const r = await promise; window.results.answered++;
        if (r.type !== "opaque") window.results.read.push(what + ": " + r.status + " " + (await r.text()).slice(0, 80));
  } catch (e) { /* refused by the browser or the console: nothing read */ }
}
async function attack() {
  for (let i = 0; i < 10; i++) {  // a stick held for 1 s, every way a page can send one
    await Promise.all([
      attempt("text/plain teleop", fetch(CONSOLE + "/api/teleop", {method: "POST", mode: "no-cors", body: stick,
                                                                 headers: {"Content-Type": "text/plain"}})),
      attempt("no-cors json teleop", fetch(CONSOLE + "/api/teleop", {method: "POST", mode: "no-cors", body: stick,
                                                                   headers: {"Content-Type": "application/json"}})),
      attempt("cors json teleop", fetch(CONSOLE + "/api/teleop", {method: "POST", mode: "cors", body: stick,
                                                                headers: {"Content-Type": "application/json"}})),
      attempt("credentials teleop", fetch(CONSOLE + "/api/teleop", {method: "POST", mode: "no-cors", body: stick,
                                                                  credentials: "include"})),
    ]);
    await new Promise((ok) => setTimeout(ok, 100));
  }
  for (const path of ["/api/pause", "/api/abort", "/api/estop"]) {
    await attempt("text/plain " + path, fetch(CONSOLE + path, {method: "POST", mode: "no-cors", body: "{}"}));
    await attempt("cors json " + path, fetch(CONSOLE + path, {method: "POST", body: "{}",
                                                             headers: {"Content-Type": "application/json"}}));
    navigator.sendBeacon(CONSOLE + path, new Blob(["{}"], {type: "text/plain"}));
  }
  await attempt("read state", fetch(CONSOLE + "/api/state"));
  await attempt("read map", fetch(CONSOLE + "/api/map", {credentials: "include"}));
  document.getElementById("form").submit();
  for (const path of ["/api/ws", "/api/video"]) {
    await new Promise((done) => {
      const ws = new WebSocket(CONSOLE.replace("http", "ws") + path);
      ws.onmessage = (ev) => window.results.ws.push(path + ": " + String(ev.data).slice(0, 80));
      ws.onerror = ws.onclose = () => done();
      setTimeout(done, 3000);
    });
  }
  window.results.done = true;
}
attack();
</script></body></html>"""
"""A page on another origin that tries every way a page can reach the console: simple and preflighted POSTs,
a beacon, a text/plain form, reads of the state and the map, both WebSockets."""


class EvilSite:
    """A second web server on loopback (another port: another origin) serving :data:`EVIL_PAGE` against a console."""

    def __init__(self, console_origin: str) -> None:
        import http.server
        import threading
        page = EVIL_PAGE.replace("__CONSOLE__", console_origin).encode()

        class Handler(http.server.BaseHTTPRequestHandler):
            def do_GET(self) -> None:  # noqa: N802 - the stdlib's name
                self.send_response(200)
                self.send_header("Content-Type", "text/html; charset=utf-8")
                self.send_header("Content-Length", str(len(page)))
                self.end_headers()
                self.wfile.write(page)

            def log_message(self, *args) -> None:
                pass

        self.httpd = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.port = self.httpd.server_address[1]
        threading.Thread(target=self.httpd.serve_forever, daemon=True).start()

    def close(self) -> None:
        """Stop serving."""
        self.httpd.shutdown()
        self.httpd.server_close()


def test_a_page_on_another_origin_can_neither_command_nor_read_and_the_own_page_still_estops(browser, run_console):
    run = run_console(WAIT, "--speed", "realtime")
    start = run.wait_state(lambda s: s["pose"] is not None, 10)
    evil_sites = [EvilSite(f"http://127.0.0.1:{run.port}"), EvilSite(f"http://localhost:{run.port}")]
    try:
        # 127.0.0.1:P2 -> 127.0.0.1:P is same-site (the cookie would go), cross-origin; localhost:P2 -> localhost:P
        # too; localhost:P2 -> 127.0.0.1:P is cross-site
        pages = []
        for site, name in ((evil_sites[0], "127.0.0.1"), (evil_sites[0], "localhost"), (evil_sites[1], "localhost")):
            page = browser.new_page()
            page.goto(f"http://{name}:{site.port}/")
            pages.append(page)
        for page in pages:
            page.wait_for_function("window.results && window.results.done", timeout=30000)
            results = page.evaluate("window.results")
            assert results["read"] == [] and results["ws"] == [], results
        assert run.proc.poll() is None, "the run ended: a page on another origin aborted or e-stopped it"
        state = run.state()
        assert state["status"] == "running" and state["estop"] is False and not state["teleop"]
        assert state["speed_mps"] == 0.0 and state["pose"] == start["pose"]  # never moved, never paused
        # a rebinding page: its own origin, the console's address under its name
        rebound = browser.new_page()
        response = rebound.goto(f"http://evil.test:{run.port}/api/state")
        assert response.status == 403 and "console_wait" not in rebound.content()
        assert "rebinding" in rebound.content()
        # the console's own page, in the same browser: the space bar is the e-stop, and it takes effect at once
        own = browser.new_page()
        own.goto(run.url)
        playwright_api.expect(own.get_by_test_id("status")).to_have_text("running", timeout=10000)
        own.keyboard.press("Space")
        playwright_api.expect(own.get_by_test_id("status")).to_have_text("aborted", timeout=5000)
        code, out, _ = run.finish()
        assert code == 1 and "emergency stop" in out
    finally:
        for site in evil_sites:
            site.close()


def test_with_the_token_the_address_loses_it_and_the_page_keeps_control_after_a_reload(browser, run_console):
    run = run_console(WAIT, "--speed", "realtime", "--console-token", "always")
    assert "?token=" in run.url
    context = browser.new_context()
    page = context.new_page()
    page.goto(run.url)
    playwright_api.expect(page.get_by_test_id("status")).to_have_text("running", timeout=10000)
    assert "token" not in page.url and page.evaluate("location.href") == run.base + "/"
    assert page.evaluate("document.cookie") == ""  # HttpOnly: no script reads it
    cookie = next(c for c in context.cookies() if c["name"] == "beastbt_console_token")
    assert cookie["httpOnly"] and cookie["sameSite"] == "Strict" and cookie["path"] == "/"
    page.reload()
    playwright_api.expect(page.get_by_test_id("status")).to_have_text("running", timeout=10000)
    page.get_by_test_id("pause").click()
    playwright_api.expect(page.get_by_test_id("status")).to_have_text("paused", timeout=5000)
    fresh = context.new_page()  # a new tab: only the cookie, with the page's own Origin
    fresh.goto(run.base + "/")
    playwright_api.expect(fresh.get_by_test_id("status")).to_have_text("paused", timeout=10000)
    fresh.get_by_test_id("resume").click()
    playwright_api.expect(fresh.get_by_test_id("status")).to_have_text("running", timeout=5000)
    fresh.get_by_test_id("estop").click()
    playwright_api.expect(fresh.get_by_test_id("status")).to_have_text("aborted", timeout=5000)
    code, _, _ = run.finish()
    assert code == 1
    context.close()
