"""The operator console on a robot (the real CLI, the Waveshare firmware emulated on a pty, in real time).

On the robot the loop sleeps between ticks on the wall clock and answers input
as it comes (a reactor woken by the console), the watchdog runs in its own
thread, and the base is driven over its serial JSON. The console must work as
on the simulator: the e-stop reaches the wheels at once, the page's stick
drives through the same deadman, and a stick that goes silent stops the wheels
within 0.5 s, as the base's wire shows.
"""

from __future__ import annotations

import time

from console_support import ConsoleRun
from fake_waveshare import FakeWaveshare
from test_hil_waveshare import beast_profile, wait_for

STAND = "mission: stand\nsteps:\n  - wait: 60 s\n"


def test_the_page_stick_drives_the_wheels_and_a_silent_stick_stops_them_within_half_a_second(tmp_path):
    with FakeWaveshare("ros") as fake:
        mission = tmp_path / "stand.yaml"
        mission.write_text(STAND, encoding="utf-8")
        run = ConsoleRun(mission, "--robot", str(beast_profile(tmp_path, fake.port, "ros")), "--no-record",
                         cwd=tmp_path)
        try:
            run.wait_state(lambda s: s["time_s"] > 0.3, 15)
            for _ in range(8):
                status, answer = run.api("/api/teleop", {"linear": 1.0, "angular": 0.0, "deadman": True})
                assert status == 200 and answer["driving"] is True
                time.sleep(0.1)
            last_message = time.monotonic()
            assert fake.moving_since() is not None  # T:1 with speed on the wire
            assert wait_for(lambda: fake.stopped_at(last_message) is not None, 2.0)
            assert fake.stopped_at(last_message) - last_message < 0.5
            run.wait_state(lambda s: s["status"] == "running" and not s["teleop"], 2)  # the mission goes on
        finally:
            run.kill()


def test_the_estop_reaches_the_wheels_at_once_without_waiting_for_a_tick(tmp_path):
    with FakeWaveshare("ros") as fake:
        mission = tmp_path / "stand.yaml"
        mission.write_text("mission: go\nsteps:\n  - drive: {distance: 5 m, speed: 0.3 m/s}\n", encoding="utf-8")
        run = ConsoleRun(mission, "--robot", str(beast_profile(tmp_path, fake.port, "ros")), "--no-record",
                         cwd=tmp_path)
        try:
            assert wait_for(lambda: fake.moving_since() is not None, 15)
            time.sleep(0.5)
            pressed = time.monotonic()
            status, answer = run.api("/api/estop", {})
            assert status == 200 and answer["estop"] is True
            assert wait_for(lambda: fake.stopped_at(pressed) is not None, 1.0)
            assert fake.stopped_at(pressed) - pressed < 0.2
            code, out, _ = run.finish(30)
            assert code == 1 and "emergency stop" in out
            sent = [c for _, c in fake.received]
            assert {"T": 0} not in sent  # never the torque release
        finally:
            run.kill()
