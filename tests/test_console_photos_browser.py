"""The run's photos in the operator console, in a real browser (Debian's Chromium, driven by Playwright).

A short mission in the lab takes a ``photo:`` and an ``alert:`` with ``photo: true`` at ``--speed realtime`` with
``--console 127.0.0.1:0 --console-token always``: the page shows the newest photo and the alert's photo as pictures
whose bytes are the very JPEG files saved in the run folder, and opens one full size on a click. Screenshots go to
``$BEASTBT_SCREENSHOTS`` when it is set, else to the test's temporary folder.
"""

from __future__ import annotations

import os
import urllib.error
import urllib.request
from pathlib import Path

import pytest

from console_support import CHROMIUM, CHROMIUM_ARGS, ConsoleRun, wait_for_page
from conftest import REPO

if os.environ.get("BEASTBT_REQUIRE_BROWSER"):  # CI installs both: there a missing one is a failure, not a skip
    import playwright.sync_api as playwright_api
    assert CHROMIUM is not None, "Chromium is not installed (.ci/run installs Debian's package)"
else:
    playwright_api = pytest.importorskip("playwright.sync_api")
pytestmark = pytest.mark.skipif(CHROMIUM is None, reason="Chromium is not installed (.ci/run installs Debian's)")

MISSION = f"""mission: console_photos
world: {REPO / 'worlds' / 'lab.yaml'}
steps:
  - look: {{tilt: 40 deg}}
  - photo: {{name: gate}}
  - alert: {{text: "someone at the gate", photo: true}}
  - wait: 6 s
"""


def http_status(url: str) -> int:
    """The HTTP status of a GET (no token, no cookie)."""
    try:
        with urllib.request.urlopen(url, timeout=10) as r:
            return r.status
    except urllib.error.HTTPError as e:
        return e.code


def test_the_page_shows_the_runs_photos_and_the_alerts_photo_as_the_saved_jpegs(tmp_path: Path):
    mission = tmp_path / "mission.yaml"
    mission.write_text(MISSION, encoding="utf-8")
    runs = tmp_path / "runs"
    run = ConsoleRun(mission, "--runs-dir", str(runs), "--speed", "realtime", "--console-token", "always",
                     cwd=tmp_path)
    try:
        assert run.token  # the page and every photo need it, on loopback too
        run.wait_state(lambda s: s["photos"]["count"] == 2 and s["alert"] is not None, timeout_s=20)
        status, listing = run.api("/api/photos")
        assert status == 200 and [(p["name"], p["url"]) for p in listing["photos"]] == [
            ("gate", "/api/photos/gate.jpg"), ("alert-1", "/api/photos/alert-1.jpg")]
        assert http_status(f"{run.base}/api/photos/gate.jpg") == 401  # the token's rule, as every endpoint
        with playwright_api.sync_playwright() as pw:
            browser = pw.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS, headless=True)
            try:
                page = browser.new_page(viewport={"width": 1400, "height": 1000})
                got: dict[str, bytes] = {}
                page.on("response", lambda r: got.setdefault(r.url.split("?")[0].rsplit("/", 1)[-1], r.body())
                        if "/api/photos/" in r.url and r.status == 200 else None)
                page.goto(run.url)
                photo = page.get_by_test_id("photo-latest")
                playwright_api.expect(photo).to_be_visible(timeout=15000)
                wait_for_page(page, "(() => { const i = document.getElementById('photo-latest'), "
                                    "a = document.getElementById('alert-photo'); "
                                    "return i.complete && i.naturalWidth > 0 && a.complete && a.naturalWidth > 0; })()")
                playwright_api.expect(page.get_by_test_id("photo-caption")).to_have_text("alert-1 · 0.5 s")
                playwright_api.expect(page.get_by_test_id("alert")).to_contain_text("someone at the gate")
                # the newest photo, and the gate's in the strip under it, decoded at the camera's size
                sizes = page.evaluate("[...document.querySelectorAll('#photo-latest, #photo-strip img')]"
                                      ".map(i => [i.dataset.name, i.naturalWidth, i.naturalHeight])")
                assert sizes == [["alert-1", 320, 240], ["gate", 320, 240]]
                folder = next(runs.iterdir())
                assert got.get("alert-1.jpg") == (folder / "alert-1.jpg").read_bytes()  # the very bytes saved
                assert got.get("gate.jpg") == (folder / "gate.jpg").read_bytes()
                # the alert's banner shows the photo it took; a click opens it full size, another closes it
                src = page.get_by_test_id("alert-photo").get_attribute("src")
                assert src.split("?")[0] == "/api/photos/alert-1.jpg"
                page.get_by_test_id("alert-photo").click()
                view = page.get_by_test_id("photo-view")
                playwright_api.expect(view).to_be_visible()
                wait_for_page(page, "document.getElementById('photo-full').naturalWidth === 320")
                shots = Path(os.environ.get("BEASTBT_SCREENSHOTS") or tmp_path)
                shots.mkdir(parents=True, exist_ok=True)
                page.screenshot(path=str(shots / "console_photo_full.png"))
                view.click()
                playwright_api.expect(view).to_be_hidden()
                page.screenshot(path=str(shots / "console_photos.png"), full_page=True)
            finally:
                browser.close()
        code, _, _ = run.finish()
        assert code == 0
    finally:
        run.kill()
