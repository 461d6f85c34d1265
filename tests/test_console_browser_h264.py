"""The console's H.264 in a real browser (Debian's Chromium, WebCodecs): the simulator's fake H.264 camera's access
units, passed through untouched, are decoded and drawn by the page with the overlay; a page without WebCodecs
says so and gets JPEG instead (issue 26, item 1)."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from console_support import CHROMIUM, CHROMIUM_ARGS, WAIT, ConsoleRun, wait_for_page
from conftest import REPO

if os.environ.get("BEASTBT_REQUIRE_BROWSER"):  # CI installs both: there a missing one is a failure, not a skip
    import playwright.sync_api as playwright_api
    assert CHROMIUM is not None, "Chromium is not installed (.ci/run installs Debian's package)"
else:
    playwright_api = pytest.importorskip("playwright.sync_api")
pytest.importorskip("av", reason="PyAV is not installed (pip install -e '.[video]')")
from beastbt.devices.h264 import encoder_available  # noqa: E402 - after the skip

pytestmark = [pytest.mark.skipif(CHROMIUM is None, reason="Chromium is not installed (.ci/run installs Debian's)"),
              pytest.mark.skipif(not encoder_available("libx264")[0],
                                 reason="this PyAV wheel has no libx264 for the simulator's fake H.264 camera")]


@pytest.fixture(scope="module")
def browser():
    with playwright_api.sync_playwright() as pw:
        # robot.test is this computer (still loopback): a page on a name that is not localhost, as an operator
        # on the robot's network opens it, is no secure context
        b = pw.chromium.launch(executable_path=CHROMIUM, args=[*CHROMIUM_ARGS, "--host-resolver-rules=MAP robot.test "
                                                               "127.0.0.1"], headless=True)
        yield b
        b.close()


@pytest.fixture
def start_h264_run(tmp_path: Path):
    """``beastbt run`` of a standing robot whose simulated camera gives its own H.264, with the console."""
    runs: list[ConsoleRun] = []

    def start(*extra: str) -> ConsoleRun:
        text = (REPO / "robots" / "sim.yaml").read_text(encoding="utf-8")
        profile = tmp_path / "robot.yaml"
        profile.write_text(text.replace("  device: sim\n", "  device: sim\n  format: h264\n"), encoding="utf-8")
        mission = tmp_path / "wait.yaml"
        mission.write_text(WAIT, encoding="utf-8")
        runs.append(ConsoleRun(mission, "--robot", str(profile), "--sim", "--speed", "realtime", "--max-time",
                               "30 s", "--runs-dir", str(tmp_path / "runs"), *extra, cwd=tmp_path))
        return runs[-1]
    yield start
    for run in runs:
        run.kill()


@pytest.fixture
def h264_run(start_h264_run):
    return start_h264_run()


def centre_of_picture(page) -> list[int]:
    return page.get_by_test_id("video").evaluate(
        "c => Array.from(c.getContext('2d').getImageData(c.width / 2, c.height * 0.6, 1, 1).data)")


def test_the_page_decodes_the_cameras_h264_with_webcodecs_and_draws_the_overlay(browser, h264_run):
    page = browser.new_page(viewport={"width": 1400, "height": 1000})
    page.goto(h264_run.url)
    supported = page.evaluate("""async () => typeof VideoDecoder !== 'undefined'
        && (await VideoDecoder.isConfigSupported({codec: 'avc1.42E01F'})).supported""")
    if not supported:
        pytest.skip("this Chromium has no WebCodecs H.264 decoder")
    stats = wait_for_page(page, "window.beastbtVideoStats.codec === 'h264' && window.beastbtVideoStats.drawn >= 10 "
                                "&& window.beastbtVideoStats", timeout_s=30)
    assert stats["quality"] == 0xFF01 and stats["h264"] == "" and stats["player"] == "webcodecs"
    assert stats["overlay"]["caption"]  # the overlay came with the units and was drawn
    r, g, b, a = centre_of_picture(page)
    assert a == 255 and r + g + b > 60  # the camera's floor, not the empty canvas
    assert "H.264" in page.locator("#video-info").inner_text()


def test_a_page_off_localhost_plays_the_h264_through_mse(browser, start_h264_run):
    """An http page on the robot's name is no secure context, so it has no WebCodecs: MSE plays the units."""
    run = start_h264_run("--console-token", "always")  # any name is served to the token
    page = browser.new_page(viewport={"width": 1400, "height": 1000})
    page.goto(run.url.replace("127.0.0.1", "robot.test"))
    assert page.evaluate("!window.isSecureContext && typeof VideoDecoder === 'undefined'")
    if not page.evaluate("""window.MediaSource && MediaSource.isTypeSupported('video/mp4; codecs="avc1.42E01F"')"""):
        pytest.skip("this Chromium's MSE does not play H.264")
    stats = wait_for_page(page, "window.beastbtVideoStats.codec === 'h264' && window.beastbtVideoStats.drawn >= 10 "
                                "&& window.beastbtVideoStats", timeout_s=30)
    assert stats["player"] == "mse" and stats["h264"] == "" and stats["size"] == [320, 240]
    assert stats["overlay"]["caption"]
    assert max(stats["ages"][-5:]) < 2000  # it keeps near the live edge, not a growing buffer behind it
    r, g, b, a = centre_of_picture(page)
    assert a == 255 and r + g + b > 60


def test_a_page_without_webcodecs_or_mse_says_why_and_gets_jpeg(browser, h264_run):
    page = browser.new_page(viewport={"width": 1400, "height": 1000})
    page.add_init_script("Object.defineProperty(window, 'VideoDecoder', {value: undefined});"
                         "Object.defineProperty(window, 'MediaSource', {value: undefined});")
    page.goto(h264_run.url)
    stats = wait_for_page(page, "window.beastbtVideoStats.drawn >= 3 && window.beastbtVideoStats", timeout_s=30)
    assert stats["codec"] == "jpeg" and stats["h264"] == "this browser has no WebCodecs; no MSE either"
    assert 20 <= stats["quality"] <= 90  # the console's JPEG of the decoded H.264 (only while such a page watches)
    r, g, b, a = centre_of_picture(page)
    assert a == 255 and r + g + b > 60
