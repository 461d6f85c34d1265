"""Live tuning from the operator console's page, in a real browser (Debian's Chromium, driven by Playwright).

The line mission runs on the simulator at real time with a copy of the
simulator's profile; the operator moves the speed slider while the robot
follows the line, then saves. What the robot did is read from the console's
state and, afterwards, from the recording (its replay must be identical).
"""

from __future__ import annotations

import os
import time
from pathlib import Path

import pytest

from beastbt.recording.reader import read_recording
from beastbt.replay import replay
from console_support import CHROMIUM, CHROMIUM_ARGS, ConsoleRun, wait_for_page
from conftest import REPO

if os.environ.get("BEASTBT_REQUIRE_BROWSER"):
    import playwright.sync_api as playwright_api
    assert CHROMIUM is not None, "Chromium is not installed (.ci/run installs Debian's package)"
else:
    playwright_api = pytest.importorskip("playwright.sync_api")
pytestmark = pytest.mark.skipif(CHROMIUM is None, reason="Chromium is not installed (.ci/run installs Debian's)")

SLOW_MPS = 0.06
"""The speed limit the operator slides to, below the line follower's 0.12 m/s."""
MISSION = f"""mission: follow_the_tape
world: {REPO / 'worlds' / 'line_track.yaml'}
steps:
  - follow_line: {{until: {{time: 40 s}}}}
"""
"""Follows the tape of the line track at the follower's 0.12 m/s, on a straight stretch and round a bend."""
TOLERANCE_MPS = 0.003
"""The odometry's speed at the new limit, give or take this (m/s)."""


def test_the_speed_slider_slows_the_robot_within_0_2_s_the_replay_is_identical_and_save_keeps_comments(tmp_path):
    robot = tmp_path / "robot.yaml"
    robot.write_text((REPO / "robots" / "sim.yaml").read_text(encoding="utf-8"), encoding="utf-8")
    mission = tmp_path / "mission.yaml"
    mission.write_text(MISSION, encoding="utf-8")
    run = ConsoleRun(mission, "--robot", str(robot), "--sim",
                     "--speed", "realtime", "--runs-dir", str(tmp_path / "runs"), cwd=tmp_path)
    try:
        with playwright_api.sync_playwright() as pw:
            browser = pw.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS, headless=True)
            page = browser.new_page(viewport={"width": 1400, "height": 1400})
            page.goto(run.url)
            slider = page.get_by_test_id("knob-limits.max_speed_mps")
            slider.wait_for(timeout=20000)
            # the line follower's gains and its error plot show while the line is followed
            page.get_by_test_id("knob-line_follower.curve_slowdown_m").wait_for(timeout=20000)
            playwright_api.expect(page.get_by_test_id("line-plot")).to_be_visible(timeout=10000)
            panel = page.get_by_test_id("tuning").inner_text()
            assert "above 0 and at most 0.35 m/s" in panel and "default 0.20 m" in panel, panel  # range and default
            run.wait_state(lambda s: s["speed_mps"] > 0.1, 20)
            wait_for_page(page, "document.querySelector('[data-testid=\"line-plot-info\"], #line-plot-info')"
                                ".textContent.includes(' cm')")
            moved_wall = time.monotonic()
            slider.fill(str(SLOW_MPS))  # as a drag ends: input, then change
            commanded = run.wait_state(lambda s: s["command"]["linear_mps"] <= SLOW_MPS, 5)
            commanded_wall_s = time.monotonic() - moved_wall
            slowed = run.wait_state(lambda s: s["speed_mps"] <= SLOW_MPS + TOLERANCE_MPS, 5)
            wall_s = time.monotonic() - moved_wall
            assert page.get_by_test_id("knob-limits.max_speed_mps").input_value() == str(SLOW_MPS)
            assert slowed["tuning"]["values"]["limits.max_speed_mps"] == SLOW_MPS
            playwright_api.expect(page.get_by_test_id("knob-value-limits.max_speed_mps")).to_have_class("val changed")
            # a real drag of a gain: sent as it moves (at most 10 a second), the slider never rebuilt under the finger
            curve = page.get_by_test_id("knob-line_follower.curve_slowdown_m")
            element = curve.element_handle()
            box = curve.bounding_box()
            y = box["y"] + box["height"] / 2
            page.mouse.move(box["x"] + box["width"] * 0.1, y)
            page.mouse.down()
            for i in range(1, 13):
                page.mouse.move(box["x"] + box["width"] * (0.1 + 0.03 * i), y)
                page.wait_for_timeout(60)
            page.mouse.up()
            assert element.evaluate("e => e.isConnected")
            dragged = float(curve.input_value())
            assert 0.5 < dragged < 1.0
            run.wait_state(lambda s: s["tuning"]["values"]["line_follower.curve_slowdown_m"] == dragged, 5)
            shots = Path(os.environ.get("BEASTBT_SCREENSHOTS") or tmp_path)
            shots.mkdir(parents=True, exist_ok=True)
            page.get_by_test_id("tuning").screenshot(path=str(shots / "console_tuning.png"))
            page.get_by_test_id("tuning-save").click()
            playwright_api.expect(page.get_by_test_id("tuning-save")).to_be_disabled(timeout=5000)  # nothing left
            assert run.api("/api/abort", {})[0] == 200  # enough: the run ends here, recorded
            print(f"slider to the command in the state: {commanded_wall_s * 1000:.0f} ms, to the odometry's speed: "
                  f"{wall_s * 1000:.0f} ms (wall; the state is pushed and polled every 100 ms)")
            assert commanded_wall_s < 3.0  # generous, for a loaded machine: the 0.2 s is checked on the run's clock
            browser.close()
        code, out, err = run.finish(60)
        assert "Traceback" not in err, err
    finally:
        run.kill()
    text = robot.read_text(encoding="utf-8")
    assert f"  max_speed_mps: {SLOW_MPS}        # the Beast's top speed is about 0.35 m/s" in text
    assert f"line_follower:\n  curve_slowdown_m: {dragged}\n" in text  # a section the profile did not have
    original = (REPO / "robots" / "sim.yaml").read_text(encoding="utf-8")
    assert [line for line in text.splitlines() if "#" in line] == [
        line.replace("max_speed_mps: 0.35", f"max_speed_mps: {SLOW_MPS}") for line in original.splitlines()
        if "#" in line]
    folder = next((tmp_path / "runs").iterdir())
    rec = read_recording(folder / "run.mcap")
    tunes = [m for m in rec.topic("/operator/input") if m["control"] == "tune"]
    assert [m["body"] for m in tunes if m["body"]["name"] == "limits.max_speed_mps"] == [
        {"name": "limits.max_speed_mps", "value": SLOW_MPS}]
    curves = [m["body"]["value"] for m in tunes if m["body"]["name"] == "line_follower.curve_slowdown_m"]
    assert len(curves) >= 2 and curves[-1] == dragged  # while it moved, and where it stopped
    tunes = [m for m in tunes if m["body"]["name"] == "limits.max_speed_mps"]
    changed_s = tunes[0]["now_s"]
    # On the run's clock, from the tick the change counted in: the wheels are commanded the new speed at once (the
    # gate's deceleration: 0.06 m/s in 0.06 s), and the robot's true speed has made 80 % of the change within 0.2 s
    # (the simulated base follows its command with a lag, as the real one does).
    gate = [(m["now_s"], m["linear_mps"]) for m in rec.topic("/cmd/gate")]
    before = next(v for t, v in reversed(gate) if t < changed_s)
    assert next(t for t, v in gate if t >= changed_s and v <= SLOW_MPS + 1e-9) - changed_s <= 0.1
    truth = [(m["t_s"], m["v_mps"]) for m in rec.topic("/truth")]
    assert before > 0.1
    # /truth is recorded at 10 Hz: the crossing of 80 % of the change lies between the two samples around it
    # (linear between them). The first sample past the line alone would count up to 0.1 s of sampling as lag,
    # by the phase of the change against the samples.
    line = SLOW_MPS + 0.2 * (before - SLOW_MPS)
    at = next(i for i, (t, v) in enumerate(truth) if t >= changed_s and v <= line)
    (t0, v0), (t1, v1) = truth[at - 1], truth[at]
    slowed_s = t1 if t0 < changed_s else t0 + (v0 - line) / (v0 - v1) * (t1 - t0)
    assert slowed_s - changed_s <= 0.2 + 1e-9, (changed_s, slowed_s, truth[at - 2:at + 1])
    assert any(m["kind"] == "tuning" and "limits.max_speed_mps: 0.35 -> 0.06 m/s" in m["text"]
               for m in rec.topic("/events"))
    result = replay(str(folder))
    assert result.identical, result.differences[:3]
