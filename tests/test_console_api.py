"""The operator console's HTTP/WebSocket contract, on real ``beastbt run --console`` runs of the simulator."""

from __future__ import annotations

import asyncio
import json
import time
from pathlib import Path

import aiohttp
import pytest

from beastbt.live.console_state import video_caption
from console_support import ASK, SHORT, WAIT, ConsoleRun



@pytest.fixture
def console(tmp_path: Path):
    runs: list[ConsoleRun] = []

    def start(text: str, *extra: str, host: str = "127.0.0.1") -> ConsoleRun:
        path = tmp_path / "mission.yaml"
        path.write_text(text, encoding="utf-8")
        run = ConsoleRun(path, "--runs-dir", str(tmp_path / "runs"), "--summary", str(tmp_path / "summary.json"),
                         *extra, host=host, cwd=tmp_path)
        runs.append(run)
        return run
    yield start
    for run in runs:
        run.kill()


def test_the_state_has_every_field_and_every_node_with_ids_stable_for_the_run(console):
    steps = "".join(f"  - wait: {i % 3 + 1} s\n" for i in range(210))
    run = console(f"mission: long_one\nsteps:\n{steps}", "--speed", "realtime")
    first = run.wait_state(lambda s: s["battery"] is not None, 10)
    assert set(first) >= {"mission", "status", "time_s", "step", "progress", "pose", "gps", "speed_mps", "battery",
                          "estop", "teleop", "question", "tree"}
    assert first["mission"] == "long_one" and first["status"] == "running"
    assert set(first["progress"]) == {"done", "total", "eta_s"} and first["progress"]["total"] == 210
    assert set(first["pose"]) >= {"x", "y", "yaw_deg", "heading_deg"}
    assert first["battery"]["volts"] > 0 and 0 <= first["battery"]["percent"] <= 100
    tree = first["tree"]
    assert len(tree) == 211  # no limit on the number of nodes: root and 210 steps
    assert all(set(n) == {"id", "name", "kind", "status", "parent"} for n in tree)
    assert len({n["id"] for n in tree}) == 211
    ids = {n["id"] for n in tree}
    assert all(n["parent"] is None or n["parent"] in ids for n in tree)
    later = run.wait_state(lambda s: s["progress"]["done"] >= 1, 10)
    assert [(n["id"], n["name"]) for n in later["tree"]] == [(n["id"], n["name"]) for n in tree]
    assert later["progress"]["eta_s"] is not None and later["progress"]["eta_s"] > 0
    assert [n["status"] for n in later["tree"]] != [n["status"] for n in tree]


def test_the_websocket_pushes_5_times_a_second_and_the_final_state_before_closing(console):
    run = console(SHORT, "--speed", "realtime")

    async def watch() -> list[dict]:
        got = []
        async with aiohttp.ClientSession() as session:
            async with session.ws_connect(run.base + "/api/ws") as ws:
                async for msg in ws:
                    if msg.type == aiohttp.WSMsgType.TEXT:
                        got.append((time.monotonic(), json.loads(msg.data)))
        return got

    got = asyncio.run(asyncio.wait_for(watch(), 60))
    stamps = [t for t, _ in got]
    assert len(got) >= 10
    running = [t for t, s in got if s["status"] == "running"]
    span = running[-1] - running[0]
    assert len(running) - 1 >= 5 * span * 0.9  # at least 5 a second, every second of the run
    assert max(b - a for a, b in zip(stamps, stamps[1:])) < 0.5
    assert got[-1][1]["status"] == "succeeded"
    # The end says so, and names the step it ended in (the mission's last), not the step as if still running.
    final = got[-1][1]
    assert final["step"] == "ended: succeeded" and final["ended_at"] == final["last_step"] == "wait 1 s"
    assert video_caption(final) == [f"console_short  ended: succeeded  t {final['time_s']:.1f} s",
                                    "last step: wait 1 s"]
    assert {s["step"] for _, s in got if s["status"] == "running"} >= {"wait 1 s"}
    code, _, _ = run.finish()
    assert code == 0


def test_bad_requests_get_a_json_4xx_and_the_run_goes_on(console):
    run = console(SHORT, "--speed", "realtime")
    for path, body in [("/api/teleop", {"linear": "fast", "angular": 0, "deadman": True}),
                       ("/api/teleop", {"linear": 0.5, "angular": 0, "deadman": "yes"}),
                       ("/api/teleop", {"linear": 5, "angular": 0, "deadman": True}),
                       ("/api/teleop", [1, 2]),
                       ("/api/answer", {"id": 3}),
                       ("/api/pause", b"{not json")]:
        status, answer = run.api(path, body)
        assert status == 400, (path, body, answer)
        assert isinstance(answer["error"], str) and "Traceback" not in answer["error"]
    assert run.api("/api/answer", {"id": "door", "choice": "yes"}) == (409, {"error": "no question is open"})
    assert run.api("/api/resume", {})[0] == 409  # not paused
    assert run.api("/api/estop/reset", {})[0] == 409  # not latched
    status, answer = run.api("/api/nothing")
    assert status == 404 and "error" in answer
    status, answer = run.api("/api/pause")  # a GET where a POST is needed
    assert status == 405 and "error" in answer
    status, answer = run.api("/api/teleop", b"x" * 200_000)
    assert 400 <= status < 500
    code, _, err = run.finish()
    assert code == 0 and "Traceback" not in err
    assert json.loads((Path(run.proc.args[run.proc.args.index("--summary") + 1])).read_text())["status"] == "success"


def test_teleop_stops_within_half_a_second_when_its_messages_stop(console):
    run = console(WAIT, "--speed", "realtime")
    run.wait_state(lambda s: s["pose"] is not None, 10)
    for _ in range(12):
        status, answer = run.api("/api/teleop", {"linear": 1.0, "angular": 0.0, "deadman": True})
        assert status == 200 and answer["driving"] is True
        time.sleep(0.1)
    assert run.state()["speed_mps"] > 0.1
    last = time.monotonic()
    released = run.wait_state(lambda s: s["command"]["linear_mps"] == 0.0 and not s["teleop"], 3)
    took = time.monotonic() - last
    assert took < 0.5 + 0.15  # 0.5 s, plus the state's own 0.1 s hand-over and the poll
    stopped = run.wait_state(lambda s: s["speed_mps"] == 0.0, 3)
    print(f"commanded zero {took:.2f} s, wheels still {time.monotonic() - last:.2f} s after the last message")
    assert released["status"] == "running" and stopped["status"] == "running"  # the mission carries on
    run.kill()


def test_abort_ends_the_run_as_aborted_with_a_summary_and_a_recording(console, tmp_path):
    run = console(WAIT, "--speed", "realtime")
    run.wait_state(lambda s: s["time_s"] > 0.5, 10)

    async def abort_and_watch() -> dict:
        async with aiohttp.ClientSession() as session:
            async with session.ws_connect(run.base + "/api/ws") as ws:
                async with session.post(run.base + "/api/abort", json={}) as r:
                    assert r.status == 200 and (await r.json())["status"] == "aborted"
                last = None
                async for msg in ws:
                    last = json.loads(msg.data)
                return last

    final = asyncio.run(asyncio.wait_for(abort_and_watch(), 30))
    assert final["status"] == "aborted"
    assert final["step"] == "ended: aborted" and final["ended_at"] == "wait 60 s"  # the tree was reset: as it was
    code, _, _ = run.finish()
    assert code == 1
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["status"] == "stopped"
    assert any(e["kind"] == "mission_end" and "aborted by the operator console" in e["text"] for e in summary["events"])
    recordings = list((tmp_path / "runs").glob("*/run.mcap"))
    assert len(recordings) == 1 and recordings[0].stat().st_size > 0


def test_answers_are_checked_against_the_open_question(console, tmp_path):
    run = console(ASK, "--speed", "realtime")
    q = run.wait_state(lambda s: s["question"] is not None, 10)["question"]
    assert q == {"id": "door", "text": "Is the door open?", "choices": ["yes", "no"]}
    assert run.api("/api/answer", {"id": "window", "choice": "yes"})[0] == 409
    status, answer = run.api("/api/answer", {"id": "door", "choice": "perhaps"})
    assert status == 400 and "yes" in answer["error"]
    assert run.api("/api/answer", {"id": "door", "choice": "yes"}) == (200, {"ok": True, "answered": "door",
                                                                            "choice": "yes"})
    code, _, _ = run.finish()
    assert code == 0
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["distance_m"] > 0.25


def test_the_estop_latches_at_once_and_the_run_ends_stopped(console, tmp_path):
    run = console(WAIT, "--speed", "realtime")
    run.wait_state(lambda s: s["time_s"] > 0.3, 10)
    status, answer = run.api("/api/estop", {})
    assert status == 200 and answer["estop"] is True
    code, _, _ = run.finish()
    assert code == 1
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["status"] == "stopped"
    assert any(e["kind"] == "estop" and "operator console" in e["text"] for e in summary["events"])


def test_a_port_in_use_is_a_clear_error_before_anything_moves(console, tmp_path):
    run = console(WAIT, "--speed", "realtime")
    path = tmp_path / "second.yaml"
    path.write_text(WAIT, encoding="utf-8")
    import subprocess
    import sys
    second = subprocess.run([sys.executable, "-m", "beastbt", "run", str(path), "--console", f"127.0.0.1:{run.port}",
                             "--no-record"], capture_output=True, text=True, timeout=60, cwd=tmp_path)
    assert second.returncode == 2
    assert "--console" in second.stderr and "cannot listen" in second.stderr and "Traceback" not in second.stderr


def test_a_stalled_viewer_slows_neither_the_mission_nor_another_viewer(console):
    # Robust on a loaded machine: frames are waited for (a generous deadline), not counted in a short fixed window;
    # the camera and its encoder may take seconds to start when the cores are busy. A viewer held up by the stalled
    # one would get nothing at all once the stalled socket's buffers fill (a few frames), so 40 frames prove it.
    import socket
    run = console(WAIT, "--speed", "realtime")
    stalled = socket.create_connection(("127.0.0.1", run.port))
    stalled.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    stalled.sendall(b"GET /api/video HTTP/1.1\r\nHost: 127.0.0.1\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
                    b"Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\r\n")
    try:
        async def watch(want: int, timeout_s: float) -> tuple[int, int, float]:
            """Frames and bytes received until ``want`` frames (or ``timeout_s``), and the seconds from the first."""
            frames = size = 0
            first = None
            async with aiohttp.ClientSession() as session:
                async with session.ws_connect(run.base + "/api/video", max_msg_size=0) as ws:
                    end = time.monotonic() + timeout_s
                    while frames < want and time.monotonic() < end:
                        try:
                            msg = await asyncio.wait_for(ws.receive(), 1.0)
                        except asyncio.TimeoutError:
                            continue
                        if msg.type == aiohttp.WSMsgType.BINARY:
                            first = first if first is not None else time.monotonic()
                            frames += 1
                            size += len(msg.data)
            return frames, size, (time.monotonic() - first) if first is not None else 0.0

        run.wait_state(lambda s: s["time_s"] > 0.5, 60)  # the mission runs: the stalled viewer is connected by now
        t0, wall0 = run.state()["time_s"], time.monotonic()
        frames, size, span_s = asyncio.run(watch(40, 90.0))
        t1, wall = run.state()["time_s"], time.monotonic() - wall0
        assert frames >= 40  # the other viewer keeps getting frames while the stalled one takes none
        assert span_s > 0 and size * 8 / span_s <= 5_000_000  # within the bit budget
        assert t1 - t0 > 0.5 * wall  # the mission kept (about) real time meanwhile: not held up by the stalled viewer
    finally:
        stalled.close()


def test_a_pause_at_full_speed_holds_the_simulation_to_real_time(console):
    # Long enough to be paused well before its end at full speed, short enough to finish soon after the resume
    # on a loaded machine (a recorded simulated hour takes 40-50 s of wall time here).
    run = console("mission: long_wait\nsteps:\n  - wait: 1200 s\n", "--speed", "max", "--max-time", "2 h")
    status, _ = run.api("/api/pause", {})
    assert status == 200
    first = run.wait_state(lambda s: s["status"] == "paused", 5)
    time.sleep(1.5)
    later = run.state()
    assert later["time_s"] == first["time_s"]  # the mission's time stands still
    ran = later["sim_time_s"] - first["sim_time_s"]
    assert 0.5 < ran < 5.0  # the clock goes on about as fast as the wall's, not thousands of times faster
    assert run.api("/api/resume", {})[0] == 200
    code, _, _ = run.finish(120)
    assert code == 0


def test_the_console_works_the_same_on_a_real_robots_profile(console, tmp_path):
    from conftest import REPO
    run = console(WAIT, "--robot", str(REPO / "robots" / "ugv_beast.yaml"), "--sim", "--speed", "realtime")
    state = run.wait_state(lambda s: s["battery"] is not None and s["time_s"] > 0.3, 15)
    assert state["status"] == "running" and state["tree"][0]["name"] == "mission console_wait"
    assert run.api("/api/pause", {})[0] == 200
    run.wait_state(lambda s: s["status"] == "paused", 5)
    assert run.api("/api/abort", {})[0] == 200
    code, out, _ = run.finish()
    assert code == 1 and "aborted by the operator console" in out


def test_the_map_has_the_worlds_track_and_the_missions_waypoints_in_plan_metres(tmp_path):
    from conftest import REPO
    route = ConsoleRun(REPO / "missions" / "gps_route.yaml", "--speed", "realtime", "--no-record", cwd=tmp_path)
    try:
        status, layers = route.api("/api/map")
        assert status == 200 and layers["datum"] is not None
        waypoints = {w["name"]: w for w in layers["waypoints"]}
        assert list(waypoints)[:3] == ["a", "b", "c"]
        assert waypoints["b"]["tolerance_m"] == 3.0 and waypoints["a"]["tolerance_m"] > 0  # b's own, a the default
        a, b = waypoints["a"]["xy"], waypoints["b"]["xy"]  # the campus notes: a ~11 m north, b 22 m N and 25 m E
        assert abs(a[0]) < 2 and 9 < a[1] < 13 and 20 < b[0] < 30 and 18 < b[1] < 26
    finally:
        route.kill()
    line = ConsoleRun(REPO / "missions" / "line_to_intersection.yaml", "--speed", "realtime", "--no-record",
                      cwd=tmp_path)
    try:
        status, layers = line.api("/api/map")
        assert status == 200 and layers["track"] and layers["start"] == {"x": 0.8, "y": 0.0, "yaw_deg": 0.0}
        xs = [p[0] for t in layers["track"] for p in t["points"]]
        assert min(xs) < 0 and max(xs) > 3.9  # the loop, from its round end to its right side
    finally:
        line.kill()


def test_a_paused_run_shows_the_step_it_is_paused_in_and_that_it_is_paused(console):
    run = console(WAIT, "--speed", "realtime")
    running = run.wait_state(lambda s: s["time_s"] > 0.3, 10)
    assert running["step"] == running["last_step"] == "wait 60 s" and running["ended_at"] is None
    assert run.api("/api/pause", {})[0] == 200
    paused = run.wait_state(lambda s: s["status"] == "paused", 5)
    assert paused["step"] == "wait 60 s (paused)" and paused["last_step"] == "wait 60 s"
    assert video_caption(paused)[1] == "step: wait 60 s (paused)"
    assert run.api("/api/resume", {})[0] == 200
    assert run.wait_state(lambda s: s["status"] == "running", 5)["step"] == "wait 60 s"


def test_the_video_declines_deflate_that_a_browser_offers_and_frames_keep_coming(console):
    # Every browser offers permessage-deflate. JPEG and H.264 do not shrink, and aiohttp deflates a large message
    # on an executor thread: the video socket must not take it. The state's small JSON keeps it.
    run = console(WAIT, "--speed", "realtime")

    async def watch() -> tuple[int, int, int]:
        async with aiohttp.ClientSession() as session:
            async with session.ws_connect(run.base + "/api/ws", compress=15) as state_ws:
                state_deflate = state_ws.compress
            async with session.ws_connect(run.base + "/api/video", max_msg_size=0, compress=15) as ws:
                frames = 0
                # Until 16 frames, with a generous deadline: on a loaded machine the camera may take seconds to start.
                end = time.monotonic() + 90.0
                while frames < 2 * 8 and time.monotonic() < end:
                    try:
                        msg = await asyncio.wait_for(ws.receive(), 1.0)
                    except asyncio.TimeoutError:
                        continue
                    frames += msg.type == aiohttp.WSMsgType.BINARY
                return state_deflate, ws.compress, frames

    state_deflate, video_deflate, frames = asyncio.run(watch())
    assert state_deflate == 15
    assert video_deflate == 0
    assert frames >= 2 * 8  # woken on the server's loop for each frame, no thread in between
