"""The mission studio in a real browser (Debian's Chromium, driven by Playwright), as a teacher would use it.

Each test starts ``beastbt studio FOLDER --listen 127.0.0.1:0`` as a user would and works the page through its
``data-testid``s alone: clicks on the map, the template list, Try it and Save. What the page did is read back from
the file on disk, from ``beastbt validate`` and from the editor's own text. Screenshots go to
``$BEASTBT_SCREENSHOTS`` when it is set (to look at them), else to the test's temporary folder.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

import pytest

from console_support import CHROMIUM, CHROMIUM_ARGS, wait_for_page
from conftest import REPO

if os.environ.get("BEASTBT_REQUIRE_BROWSER"):  # CI installs both: there a missing one is a failure, not a skip
    import playwright.sync_api as playwright_api
    assert CHROMIUM is not None, "Chromium is not installed (.ci/run installs Debian's package)"
else:
    playwright_api = pytest.importorskip("playwright.sync_api")
pytestmark = pytest.mark.skipif(CHROMIUM is None, reason="Chromium is not installed (.ci/run installs Debian's)")
expect = playwright_api.expect

MISSION = """# yaml-language-server: $schema=../schemas/mission.schema.json
# A short patrol: the comments must survive every edit.
mission: short_patrol
steps:
  - drive: {distance: 1 m}
  - turn: {angle: 90 deg}
  - wait: 1 s
"""


class Studio:
    """``beastbt studio FOLDER --listen 127.0.0.1:0`` in a subprocess; ``url`` is the address it printed."""

    def __init__(self, folder: Path) -> None:
        cmd = [sys.executable, "-m", "beastbt", "studio", str(folder), "--listen", "127.0.0.1:0"]
        self.proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                     env={**os.environ, "PYTHONUNBUFFERED": "1"})
        self.url = ""
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline and not self.url:
            line = self.proc.stdout.readline()
            if not line:
                raise RuntimeError(f"beastbt studio ended before serving: {self.proc.stderr.read()}")
            m = re.search(r"(http://127\.0\.0\.1:\d+/\S*)", line)
            if m:
                self.url = m.group(1)
        assert self.url, "beastbt studio printed no address"

    def validate(self, text: str, path: str) -> list[dict]:
        """``POST /api/validate``'s problems for ``text`` saved at ``path``."""
        req = urllib.request.Request(self.url.split("?")[0] + "api/validate", method="POST",
                                     data=json.dumps({"text": text, "path": path}).encode(),
                                     headers={"Content-Type": "application/json"})
        with urllib.request.urlopen(req, timeout=20) as r:
            return json.loads(r.read())["problems"]

    def stop(self) -> None:
        """Ctrl-C (SIGINT: the studio stops the runs it started), then SIGTERM and SIGKILL if it lingers."""
        for end in (lambda: self.proc.send_signal(signal.SIGINT), self.proc.terminate, self.proc.kill):
            if self.proc.poll() is not None:
                return
            end()
            try:
                self.proc.communicate(timeout=10)
            except subprocess.TimeoutExpired:
                continue


@pytest.fixture(scope="module", autouse=True)
def patient_expect():
    """15 s for each expectation here (a loaded 2-core machine answers slower; a passing run does not wait), and
    Playwright's own 5 s again for the other test files."""
    expect.set_options(timeout=15_000)
    yield
    expect.set_options(timeout=5_000)


@pytest.fixture(scope="module")
def browser():
    with playwright_api.sync_playwright() as pw:
        b = pw.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS, headless=True)
        yield b
        b.close()


@pytest.fixture
def folder(tmp_path: Path) -> Path:
    """A teacher's folder: a worlds/ folder with the campus, a missions/ folder with one short mission."""
    root = tmp_path / "class"
    (root / "missions").mkdir(parents=True)
    (root / "worlds").mkdir()
    shutil.copyfile(REPO / "worlds" / "campus.yaml", root / "worlds" / "campus.yaml")
    (root / "missions" / "short.yaml").write_text(MISSION, encoding="utf-8")
    return root


@pytest.fixture
def studio(folder: Path):
    s = Studio(folder)
    yield s
    s.stop()


@pytest.fixture
def shots(tmp_path: Path):
    out = Path(os.environ.get("BEASTBT_SCREENSHOTS") or tmp_path)
    out.mkdir(parents=True, exist_ok=True)

    def shot(page, name: str) -> Path:
        path = out / f"studio_{name}.png"
        page.screenshot(path=str(path))
        return path
    return shot


def open_studio(browser, studio: Studio, query: str = ""):
    page = browser.new_page(viewport={"width": 1440, "height": 900})
    errors: list[str] = []
    asked: list[str] = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    page.on("request", lambda r: asked.append(r.url))  # the workers' requests (the schemas) come here too
    page.goto(studio.url + query)
    expect(page.get_by_test_id("file-list").get_by_test_id("file").first).to_be_visible()
    page.page_errors = errors  # type: ignore[attr-defined]
    page.asked = asked  # type: ignore[attr-defined]
    return page


def editor_text(page) -> str:
    return page.evaluate("studio.editor.getValue()")


def open_file(page, path: str) -> None:
    page.get_by_test_id("file-list").locator(f'[data-path="{path}"]').click()
    expect(page.get_by_test_id("current-path")).to_have_text(path)
    wait_for_page(page, "studio.editor.getValue().length > 0")


def click_map(page, dx: float, dy: float) -> None:
    """Click the map at (dx, dy) pixels from its centre (x right, y down)."""
    box = page.get_by_test_id("map").bounding_box()
    page.mouse.click(box["x"] + box["width"] / 2 + dx, box["y"] + box["height"] / 2 + dy)


def test_a_gps_route_by_clicks_alone_tried_to_success_and_saved(browser, studio, folder, shots):
    """The non-programmer test: template, three places, a route, a keep-out fence, Try it, Save."""
    page = open_studio(browser, studio, "?speed=max&max_time=5%20min")
    page.get_by_test_id("template").select_option("gps_route")
    page.get_by_test_id("new-name").fill("missions/field_trip.yaml")
    page.get_by_test_id("create").click()
    expect(page.get_by_test_id("current-path")).to_have_text("missions/field_trip.yaml")
    template = editor_text(page)
    comments = [line for line in template.splitlines() if line.lstrip().startswith("#")]
    assert comments, "the template has comments to keep"
    expect(page.get_by_test_id("problems").get_by_test_id("problem")).to_have_count(0)
    expect(page.get_by_test_id("map")).to_have_attribute("data-ready", "true")  # the campus, round its datum

    # three places, one click each (north, north-east, east of the start: about 8 m apart at this zoom)
    for i, (dx, dy) in enumerate([(0, -35), (35, -35), (35, 0)], start=1):
        page.get_by_test_id("add-place").click()
        click_map(page, dx, dy)
        expect(page.get_by_test_id("place-marker")).to_have_count(i)
    names = page.get_by_test_id("place-marker").evaluate_all("els => els.map(e => e.dataset.place)")
    assert len(set(names)) == 3

    # one undo stack for map and text: Undo takes the last place away (text and map), Redo brings it back
    with_three = editor_text(page)
    page.get_by_test_id("undo").click()
    expect(page.get_by_test_id("place-marker")).to_have_count(2)
    assert f"{names[2]}: {{lat:" not in editor_text(page)
    page.get_by_test_id("redo").click()
    expect(page.get_by_test_id("place-marker")).to_have_count(3)
    assert editor_text(page) == with_three

    # dragging a place moves it in the text, and only that line changes
    marker = page.locator(f'[data-testid="place-marker"][data-place="{names[2]}"] .dot').bounding_box()
    x, y = marker["x"] + marker["width"] / 2, marker["y"] + marker["height"] / 2
    page.mouse.move(x, y)
    page.mouse.down()
    page.mouse.move(x + 5, y + 5, steps=5)
    page.mouse.move(x + 10, y + 10, steps=5)
    page.mouse.up()
    wait_for_page(page, f"studio.editor.getValue() !== {json.dumps(with_three)}")
    before, after = with_three.splitlines(), editor_text(page).splitlines()
    changed = [(a, b) for a, b in zip(before, after) if a != b]
    assert len(before) == len(after) and len(changed) == 1, changed
    assert changed[0][0].strip().startswith(f"{names[2]}:") and changed[0][1].strip().startswith(f"{names[2]}:")

    # the route: click the places in order, then Finish
    page.get_by_test_id("make-route").click()
    for name in names:
        page.locator(f'[data-testid="place-marker"][data-place="{name}"] .dot').click()
    page.get_by_test_id("finish").click()
    wait_for_page(page, "/route:/.test(studio.editor.getValue())")
    assert re.search(r"route: \{places: \[" + ", ".join(names) + r"\]\}", editor_text(page)), editor_text(page)

    # a keep-out fence south-west of the start, away from the route
    page.get_by_test_id("draw-fence").click()
    for dx, dy in [(-200, 60), (-120, 60), (-120, 140), (-200, 140)]:
        click_map(page, dx, dy)
    page.get_by_test_id("finish").click()
    wait_for_page(page, "/fences:/.test(studio.editor.getValue())")
    expect(page.get_by_test_id("map").get_by_test_id("fence")).to_have_count(1)
    text = editor_text(page)
    assert "keepout" in text  # the fence is watched by a failsafe
    for line in comments:
        assert line in text, f"the comment {line!r} was lost by a map edit"
    expect(page.get_by_test_id("problems").locator(".problem.error")).to_have_count(0)
    shots(page, "route_and_fence")

    # Try it on the simulator, to success
    page.get_by_test_id("try").click()
    expect(page.get_by_test_id("run-panel")).to_have_attribute("data-result", "success", timeout=60000)
    expect(page.get_by_test_id("try-outcome")).to_contain_text("succeeded")
    shots(page, "tried")

    # Save: the file on disk is the editor's text, it validates and keeps its comments
    page.get_by_test_id("save").click()
    expect(page.locator("#dirty")).to_be_hidden()
    saved = (folder / "missions" / "field_trip.yaml").read_text(encoding="utf-8")
    assert saved == editor_text(page)
    for line in comments:
        assert line in saved
    assert [p for p in studio.validate(saved, "missions/field_trip.yaml") if p["severity"] == "error"] == []
    done = subprocess.run([sys.executable, "-m", "beastbt", "validate", str(folder / "missions" / "field_trip.yaml")],
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stdout + done.stderr
    assert page.page_errors == []
    origin = studio.url.split("?")[0]
    assert page.asked and all(u.startswith(origin) or u.startswith(("data:", "blob:")) for u in page.asked), \
        [u for u in page.asked if not u.startswith(origin)]  # it works with no internet: nothing from elsewhere


def test_a_typo_shows_its_problem_at_its_line_and_column_within_a_second(browser, studio, shots):
    page = open_studio(browser, studio)
    open_file(page, "missions/short.yaml")
    expect(page.get_by_test_id("problems").locator(".problem.error")).to_have_count(0)
    # timed in the page: from the last change of the text to the problem in the list
    page.evaluate("""() => {
        window.typo = {};
        studio.editor.getModel().onDidChangeContent(() => { window.typo.last = performance.now(); });
        new MutationObserver(() => {
            const shown = [...document.querySelectorAll('[data-testid=problem]')]
                .some((e) => e.textContent.includes('drvie'));
            if (shown && !window.typo.seen) window.typo.seen = performance.now();
        }).observe(document.getElementById('problems'), {childList: true, subtree: true});
    }""")
    # "drive" on line 5, column 5 becomes "drvie", typed over the word as a user would
    page.evaluate("studio.editor.setSelection(new studio.monaco.Selection(5, 5, 5, 10)); studio.editor.focus()")
    page.keyboard.type("drvie")
    problem = page.get_by_test_id("problem").filter(has_text="drvie").first
    expect(problem).to_be_visible(timeout=5000)
    seen_s = page.evaluate("(window.typo.seen - window.typo.last) / 1000")
    assert (problem.get_attribute("data-line"), problem.get_attribute("data-column")) == ("5", "5")
    assert seen_s < 1.0, f"the problem showed {seen_s:.2f} s after the typing stopped"
    markers = page.evaluate("studio.monaco.editor.getModelMarkers({owner: 'beastbt'})"
                            ".map(m => [m.startLineNumber, m.startColumn, m.severity])")
    assert [5, 5, 8] in markers  # an error marker at the typo, in the text itself
    # a click on the problem selects the word it is about
    page.evaluate("studio.editor.setPosition({lineNumber: 1, column: 1})")
    problem.click()
    assert page.evaluate("(() => { const s = studio.editor.getSelection(); "
                         "return [s.startLineNumber, s.startColumn, studio.editor.getModel().getValueInRange(s)]; })()"
                         ) == [5, 5, "drvie"]
    shots(page, "typo")


def test_clicking_a_tree_node_selects_its_step(browser, studio, shots):
    page = open_studio(browser, studio)
    open_file(page, "missions/short.yaml")
    page.get_by_test_id("tab-tree").click()
    tree = page.get_by_test_id("tree-view")
    expect(tree.get_by_test_id("tree-node").first).to_be_visible(timeout=15000)
    turn = tree.locator('[data-testid="tree-node"][data-line="6"]').first
    turn.click()
    selection = page.evaluate("(() => { const s = studio.editor.getSelection(); "
                              "return [s.startLineNumber, s.endLineNumber, studio.editor.getModel()"
                              ".getValueInRange(s)]; })()")
    assert selection[0] == 6, selection
    assert "turn" in selection[2]
    shots(page, "tree")


def test_a_save_over_a_file_changed_on_disk_shows_both_and_overwrites_nothing(browser, studio, folder, shots):
    page = open_studio(browser, studio)
    open_file(page, "missions/short.yaml")
    page.evaluate("studio.editor.setPosition({lineNumber: 7, column: 14}); studio.editor.focus()")
    page.keyboard.type("  # mine")
    on_disk = folder / "missions" / "short.yaml"
    theirs = MISSION.replace("wait: 1 s", "wait: 2 s  # theirs")
    on_disk.write_text(theirs, encoding="utf-8")  # someone else saved meanwhile
    page.get_by_test_id("save").click()
    conflict = page.get_by_test_id("conflict")
    expect(conflict).to_be_visible()
    expect(conflict).to_contain_text("theirs")  # both texts are shown
    expect(conflict).to_contain_text("# mine")
    assert on_disk.read_text(encoding="utf-8") == theirs  # nothing was overwritten
    assert "# mine" in editor_text(page)  # and nothing of the user's was lost
    shots(page, "conflict")
    page.get_by_test_id("keep-mine").click()  # the user decides: their version replaces the disk's
    expect(conflict).to_be_hidden()
    expect(page.locator("#dirty")).to_be_hidden()
    assert on_disk.read_text(encoding="utf-8") == editor_text(page)
    assert (folder / "missions" / "short.yaml.bak").read_text(encoding="utf-8") == theirs
