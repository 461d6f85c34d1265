"""A robot's newest photo on the station: sent by its agent on ``beastbt/<name>/photo``, kept and served by the station.

``beastbt station`` as the quick path runs it (its own keys, mutual TLS, Zenoh's access control that denies by
default: the robot's new key must be allowed) and ``beastbt serve --sim`` joined with the printed enrolment; a
mission with a ``photo:`` step is sent through the station's API. Every process is on loopback, on free ports.
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from beastbt.fleet.photos import PHOTO_MAX_BYTES, fleet_jpeg
from fleet_support import free_port, http, wait_for

pytest.importorskip("zenoh")
needs_openssl = pytest.mark.skipif(shutil.which("openssl") is None, reason="the station's keys need openssl")

MISSION = b"mission: door_photo\nsteps:\n  - look: {tilt: 30 deg}\n  - photo: {name: door}\n  - wait: 1 s\n"


def beastbt(*args: str, state: Path, cwd: Path) -> subprocess.Popen:
    """Start ``python -m beastbt ARGS`` with ``state`` as its per-user state folder (``XDG_STATE_HOME``)."""
    env = {**os.environ, "PYTHONUNBUFFERED": "1", "XDG_STATE_HOME": str(state)}
    return subprocess.Popen([sys.executable, "-m", "beastbt", *args], cwd=str(cwd), env=env,
                            stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def robots(base: str) -> dict:
    """The station's robots by name (none while its HTTP server is not up yet)."""
    try:
        return {r["name"]: r for r in http("GET", f"{base}/api/robots")[1]["robots"]}
    except OSError:
        return {}


def get_bytes(url: str) -> tuple[int, bytes]:
    """(status, body) of a GET."""
    import urllib.error
    import urllib.request
    try:
        with urllib.request.urlopen(url, timeout=10) as r:
            return r.status, r.read()
    except urllib.error.HTTPError as e:
        return e.code, e.read()


def shown_in_row(base: str, jpeg: bytes) -> None:
    """The station's page shows the photo in r1's row: an <img> that loaded these very bytes (when Chromium and
    Playwright are here: CI has both)."""
    from console_support import CHROMIUM, CHROMIUM_ARGS, wait_for_page
    try:
        import playwright.sync_api as playwright_api
    except ImportError:
        playwright_api = None
    if CHROMIUM is None or playwright_api is None:
        assert not os.environ.get("BEASTBT_REQUIRE_BROWSER"), "Chromium and Playwright are needed here"
        return
    with playwright_api.sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS, headless=True)
        try:
            page = browser.new_page(viewport={"width": 1400, "height": 900})
            got: list[bytes] = []
            page.on("response", lambda r: got.append(r.body()) if "/photo.jpg" in r.url and r.status == 200 else None)
            page.goto(base + "/")
            img = page.locator('tr[data-robot="r1"] img[data-testid="photo"]')
            playwright_api.expect(img).to_be_visible(timeout=10000)
            wait_for_page(page, "(() => { const i = document.querySelector('tr[data-robot=\"r1\"] "
                                "img[data-testid=\"photo\"]'); return i && i.complete && i.naturalWidth === 320; })()")
            assert got and got[-1] == jpeg
            shots = Path(os.environ.get("BEASTBT_SCREENSHOTS") or "")
            if os.environ.get("BEASTBT_SCREENSHOTS"):
                page.screenshot(path=str(shots / "station_photo.png"))
        finally:
            browser.close()


@needs_openssl
def test_the_station_shows_a_robots_newest_photo_sent_over_the_secured_fleet(tmp_path: Path):
    station_state, robot_state = tmp_path / "station-state", tmp_path / "robot-state"
    zport, hport = free_port(), free_port()
    base = f"http://127.0.0.1:{hport}"
    station = beastbt("station", "--listen", str(zport), "--console", f"127.0.0.1:{hport}", state=station_state,
                      cwd=tmp_path)
    procs = [station]
    try:
        keys = station_state / "beastbt" / "fleet"
        wait_for(lambda: station.poll() is not None or (keys / "robot" / "robot.json5").is_file(), 30.0,
                 "the station's keys")
        enrolled = robot_state / "beastbt" / "fleet"
        enrolled.mkdir(parents=True)
        for f in (keys / "robot").iterdir():
            shutil.copy(f, enrolled / f.name)
        runs = tmp_path / "runs"
        procs.append(beastbt("serve", "--sim", "--name", "r1", "--fleet", f"tls/127.0.0.1:{zport}", "--runs-dir",
                             str(runs), state=robot_state, cwd=tmp_path))
        wait_for(lambda: any(p.poll() is not None for p in procs) or robots(base).get("r1", {}).get("alive"), 60.0,
                 "r1 on the fleet")
        assert robots(base)["r1"]["photo"] is None
        assert get_bytes(f"{base}/api/robots/r1/photo.jpg")[0] == 404  # none yet
        status, body = http("POST", f"{base}/api/robots/r1/mission", MISSION, content_type="application/yaml")
        assert status == 200, body
        photo = wait_for(lambda: robots(base)["r1"]["photo"], 30.0, "r1's photo on the station")
        assert photo["name"] == "door" and photo["url"].startswith("/api/robots/r1/photo.jpg")
        status, jpeg = get_bytes(base + photo["url"])
        assert status == 200 and jpeg[:2] == b"\xff\xd8" and len(jpeg) == photo["bytes"] <= PHOTO_MAX_BYTES
        sent = cv2.imdecode(np.frombuffer(jpeg, np.uint8), cv2.IMREAD_COLOR)
        [saved] = list(runs.rglob("door.jpg"))  # the full-resolution photo in the run folder
        original = cv2.imread(str(saved), cv2.IMREAD_COLOR)
        assert sent.shape == original.shape  # 320x240: under the fleet's 640 px, not scaled
        assert float(np.mean(cv2.absdiff(sent, original))) < 4.0  # the same picture, re-encoded
        shown_in_row(base, jpeg)
    finally:
        for proc in procs:
            if proc.poll() is None:
                proc.send_signal(signal.SIGTERM)
        for proc in procs:
            try:
                proc.communicate(timeout=10)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.communicate()


def test_a_large_photo_is_scaled_and_reencoded_under_the_fleets_bound(tmp_path: Path):
    rng = np.random.default_rng(1)
    noisy = rng.integers(0, 256, (1080, 1920, 3), dtype=np.uint8)  # noise: the worst case for JPEG
    path = tmp_path / "big.jpg"
    cv2.imwrite(str(path), noisy, [cv2.IMWRITE_JPEG_QUALITY, 95])
    assert path.stat().st_size > 10 * PHOTO_MAX_BYTES
    jpeg = fleet_jpeg(str(path))
    assert jpeg is not None and len(jpeg) <= PHOTO_MAX_BYTES
    small = cv2.imdecode(np.frombuffer(jpeg, np.uint8), cv2.IMREAD_COLOR)
    assert max(small.shape[:2]) <= 640 and small.shape[1] / small.shape[0] == pytest.approx(1920 / 1080, rel=0.02)
    assert fleet_jpeg(str(tmp_path / "gone.jpg")) is None
