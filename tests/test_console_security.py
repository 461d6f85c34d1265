"""The operator console against other web pages (CSRF, DNS rebinding) and malformed controls, over HTTP.

A real ``beastbt run --console 127.0.0.1:0`` of a robot that stands still
(the ``WAIT`` mission) is probed from outside with raw HTTP requests made to
look as a browser's would from another page: a foreign ``Origin``, a
``Host`` from a rebinding DNS name, a ``text/plain`` or form body, a
WebSocket from another page. Each rule is checked both ways: the refusal,
and the request the console's own page (or a script) makes, which must
still work. That nothing was done is read back from the run's state (not
paused, no e-stop, no teleop, not moved). What a real browser does with two
origins is in ``test_console_browser.py``.
"""

from __future__ import annotations

import asyncio
import http.client
import json
import subprocess
import sys
from pathlib import Path
from typing import Optional

import aiohttp
import pytest

from beastbt.live.console_control import Refused, check_teleop_body, parse_control_body
from beastbt.live.endpoint import host_allowed, host_on_network, same_origin
from console_support import WAIT, ConsoleRun

STICK = {"linear": 1.0, "angular": 0.0, "deadman": True}
"""Full stick forward with the deadman held: it would drive the robot at once."""


def request(run: ConsoleRun, method: str, path: str, body: Optional[bytes] = None,
            headers: Optional[dict] = None) -> tuple[int, dict, object]:
    """(status, headers, JSON or text) of one raw request; ``Host`` is 127.0.0.1:PORT unless given."""
    conn = http.client.HTTPConnection("127.0.0.1", run.port, timeout=10)
    sent = {"Host": f"127.0.0.1:{run.port}", **(headers or {})}
    conn.putrequest(method, path, skip_host=True, skip_accept_encoding=True)
    for name, value in sent.items():
        conn.putheader(name, value)
    if body is not None:
        conn.putheader("Content-Length", str(len(body)))
    conn.endheaders(body)
    r = conn.getresponse()
    raw = r.read()
    conn.close()
    try:
        payload: object = json.loads(raw)
    except ValueError:
        payload = raw.decode(errors="replace")
    return r.status, {k.lower(): v for k, v in r.getheaders()}, payload


def post(run: ConsoleRun, path: str, body: object, content_type: Optional[str] = "application/json",
         **headers: str) -> tuple[int, object]:
    """(status, answer) of a POST with the given content type and extra headers (``Origin=...``)."""
    data = body if isinstance(body, bytes) else json.dumps(body).encode()
    sent = {k.replace("_", "-"): v for k, v in headers.items()}
    if content_type is not None:
        sent["Content-Type"] = content_type
    status, _, answer = request(run, "POST", path, data, sent)
    return status, answer


def untouched(run: ConsoleRun) -> dict:
    """The state, asserted to be a robot nobody commanded: running, no e-stop, no teleop, standing still."""
    state = run.state()
    assert state["status"] == "running" and state["estop"] is False and not state["teleop"], state["status"]
    assert state["speed_mps"] == 0.0 and state["command"]["linear_mps"] == 0.0
    return state


@pytest.fixture(scope="module")
def standing(tmp_path_factory):
    """One console on a robot that waits a minute, shared by the tests that leave it as they found it."""
    folder = tmp_path_factory.mktemp("standing")
    path = folder / "mission.yaml"
    path.write_text(WAIT.replace("60 s", "300 s"), encoding="utf-8")
    run = ConsoleRun(path, "--speed", "realtime", "--no-record", cwd=folder)
    run.wait_state(lambda s: s["pose"] is not None, 15)
    yield run
    run.kill()


@pytest.fixture
def console(tmp_path: Path):
    runs: list[ConsoleRun] = []

    def start(*extra: str, host: str = "127.0.0.1") -> ConsoleRun:
        path = tmp_path / "mission.yaml"
        path.write_text(WAIT, encoding="utf-8")
        run = ConsoleRun(path, "--speed", "realtime", "--no-record", *extra, host=host, cwd=tmp_path)
        runs.append(run)
        return run
    yield start
    for run in runs:
        run.kill()


# -- the checks themselves ----------------------------------------------------------------------

def test_the_host_and_origin_checks_accept_this_computer_and_nothing_else():
    for header in ("localhost", "localhost:8080", "LOCALHOST:1", "127.0.0.1:8080", "[::1]:8080", "[::1]", None):
        assert host_allowed(header, "127.0.0.1"), header
    assert host_allowed("127.0.0.2:80", "127.0.0.2") and host_allowed("127.0.0.2:80", "127.0.0.1")
    assert host_allowed("robot.lan:80", "robot.lan") and not host_allowed("robot.lan:80", "127.0.0.1")
    for header in ("evil.example", "evil.example:8080", "localhost.evil.example", "127.0.0.1.nip.io:80", "",
                   "127.0.0.1:99999", "user@127.0.0.1", "127.0.0.1/x", "[::1"):
        assert not host_allowed(header, "127.0.0.1"), header
    assert host_on_network("192.168.1.20:8080") and not host_on_network("evil.example:8080")
    assert same_origin("http://127.0.0.1:8080", "127.0.0.1:8080")
    assert same_origin("http://LOCALHOST:8080", "localhost:8080")
    for origin in ("http://localhost:8080", "http://127.0.0.1:8081", "http://127.0.0.1", "null", "",
                   "file://", "http://127.0.0.1:8080.evil.example", "http://127.0.0.1:8080/x"):
        assert not same_origin(origin, "127.0.0.1:8080"), origin


def test_control_bodies_are_strict_json_with_finite_small_numbers():
    assert parse_control_body(b"") == {} and parse_control_body(b' {"a": 1} ') == {"a": 1}
    for raw in (b'{"linear": ' + b"9" * 400 + b"}", b'{"linear": 1e400}', b'{"linear": -1e400}', b'{"linear": NaN}',
                b'{"linear": Infinity}', b'{"linear": -Infinity}', b"[" * 3000 + b"]" * 3000, b"\xff\xfe{}",
                b"{not json", b"[1, 2]", b'"text"', b"null", b"x" * 5000):
        with pytest.raises(Refused) as refused:
            parse_control_body(raw)
        assert refused.value.status in (400, 413) and len(str(refused.value)) < 200, raw[:40]
    for value in (10 ** 400, -(10 ** 5000), 1e308, float("nan"), float("inf"), "0.5", {"x": 1}, [0.5], True, None):
        with pytest.raises(Refused) as refused:
            check_teleop_body({"linear": value, "angular": 0, "deadman": True})
        assert refused.value.status == 400 and len(str(refused.value)) < 200
    assert check_teleop_body({"linear": 1, "angular": -0.5, "deadman": False}) == {"linear": 1.0, "angular": -0.5,
                                                                                   "deadman": False}


# -- Host: DNS rebinding ---------------------------------------------------------------------------

def test_a_host_that_is_not_this_computer_is_refused_on_every_route(standing):
    run = standing
    upgrade = {"Upgrade": "websocket", "Connection": "Upgrade", "Sec-WebSocket-Version": "13",
               "Sec-WebSocket-Key": "dGhlIHNhbXBsZSBub25jZQ=="}
    routes = [("GET", "/", None, {}), ("GET", "/api/state", None, {}), ("GET", "/api/map", None, {}),
              ("GET", "/static/console.js", None, {}), ("GET", "/api/ws", None, upgrade),
              ("GET", "/api/video", None, upgrade), ("GET", "/api/nothing", None, {}),
              ("POST", "/api/teleop", json.dumps(STICK).encode(), {"Content-Type": "application/json"}),
              ("POST", "/api/estop", b"{}", {"Content-Type": "application/json"})]
    for host in ("evil.example", f"evil.example:{run.port}", f"127.0.0.1.evil.example:{run.port}"):
        for method, path, body, headers in routes:
            status, _, answer = request(run, method, path, body, {"Host": host, **headers})
            assert status == 403, (host, path, status)
            assert "Host" in answer["error"] and "rebinding" in answer["error"], answer
    untouched(run)
    for host in (f"127.0.0.1:{run.port}", f"localhost:{run.port}", f"[::1]:{run.port}", "localhost"):
        status, _, answer = request(run, "GET", "/api/state", None, {"Host": host})
        assert status == 200 and answer["mission"] == "console_wait", host
        status, _, page = request(run, "GET", "/", None, {"Host": host})
        assert status == 200 and "E-STOP" in page


# -- Origin and content type: CSRF ------------------------------------------------------------------

def test_a_control_from_another_page_is_refused_and_nothing_moves(standing):
    run = standing
    start = untouched(run)["pose"]
    foreign = ["http://evil.example", f"http://localhost:{run.port}", f"http://127.0.0.1:{run.port + 1}", "null"]
    attempts = [("text/plain;charset=UTF-8", {}), ("application/x-www-form-urlencoded", {}),
                ("multipart/form-data; boundary=x", {}), (None, {})]
    attempts += [("text/plain", {"Origin": o}) for o in foreign]
    attempts += [("application/json", {"Origin": o}) for o in foreign]
    attempts += [("application/json", {"Sec-Fetch-Site": "cross-site"}),
                 ("application/json", {"Sec-Fetch-Site": "same-site", "Origin": f"http://127.0.0.1:{run.port}"})]
    for path, body in (("/api/teleop", STICK), ("/api/pause", {}), ("/api/abort", {}), ("/api/estop", {}),
                       ("/api/estop/reset", {}), ("/api/answer", {"id": "q", "choice": "yes"}), ("/api/resume", {})):
        for content_type, headers in attempts:
            status, answer = post(run, path, body, content_type, **headers)
            assert status == 403, (path, content_type, headers, status, answer)
            assert isinstance(answer["error"], str) and ("JSON" in answer["error"] or "page" in answer["error"])
    state = untouched(run)
    assert state["pose"] == start


def test_tuning_from_another_page_is_refused_and_no_knob_changes(standing):
    """Live tuning's endpoints sit behind the same guard as every control (a slower robot is harmless; a faster one,
    or a profile rewritten from another page, is not)."""
    run = standing
    before = run.wait_state(lambda s: s.get("tuning") is not None)["tuning"]["values"]  # once the run has ticked
    for path, body in (("/api/tuning", {"name": "limits.max_speed_mps", "value": 0.1}), ("/api/tuning/reset", {}),
                       ("/api/tuning/save", {})):
        for content_type, headers in (("text/plain", {}), ("application/x-www-form-urlencoded", {}),
                                      ("application/json", {"Origin": "http://evil.example"}),
                                      ("application/json", {"Sec-Fetch-Site": "cross-site"})):
            status, answer = post(run, path, body, content_type, **headers)
            assert status == 403, (path, content_type, headers, status, answer)
    status, _, answer = request(run, "GET", "/api/tuning", None, {"Origin": "http://evil.example"})
    assert status == 403
    status, _, answer = request(run, "GET", "/api/tuning", None, {"Host": "evil.example"})
    assert status == 403 and "rebinding" in answer["error"]
    status, _, answer = request(run, "GET", "/api/tuning")  # this computer's script may read them
    assert status == 200 and {k["name"]: k["value"] for k in answer["knobs"]} == before
    assert untouched(run)["tuning"]["values"] == before and before["limits.max_speed_mps"] == 0.35


def test_the_consoles_own_page_and_a_script_on_this_computer_may_control(standing):
    run = standing
    own = {"Origin": f"http://127.0.0.1:{run.port}", "Sec-Fetch-Site": "same-origin"}
    assert post(run, "/api/pause", {}, **own)[0] == 200  # what the page sends from http://127.0.0.1:PORT
    run.wait_state(lambda s: s["status"] == "paused", 5)
    assert post(run, "/api/resume", {})[0] == 200  # a script with no Origin (not a browser), JSON
    run.wait_state(lambda s: s["status"] == "running", 5)
    status, _, answer = request(run, "POST", "/api/pause", b"{}",
                                {"Host": f"localhost:{run.port}", "Origin": f"http://localhost:{run.port}",
                                 "Content-Type": "application/json; charset=utf-8"})
    assert status == 200 and answer["ok"] is True  # the page opened as http://localhost:PORT
    run.wait_state(lambda s: s["status"] == "paused", 5)
    assert post(run, "/api/resume", {}, **own)[0] == 200
    run.wait_state(lambda s: s["status"] == "running", 5)


def test_websockets_from_another_page_are_refused(standing):
    run = standing

    async def connect(path: str, origin: Optional[str]) -> object:
        headers = {"Origin": origin} if origin else {}
        async with aiohttp.ClientSession() as session:
            try:
                async with session.ws_connect(f"{run.base}{path}", headers=headers, max_msg_size=0) as ws:
                    msg = await asyncio.wait_for(ws.receive(), 10)
                    return msg.type
            except aiohttp.WSServerHandshakeError as exc:
                return exc.status

    for path in ("/api/ws", "/api/video"):
        for origin in ("http://evil.example", f"http://localhost:{run.port}", f"http://127.0.0.1:{run.port + 1}"):
            assert asyncio.run(connect(path, origin)) == 403, (path, origin)
    assert asyncio.run(connect("/api/ws", f"http://127.0.0.1:{run.port}")) == aiohttp.WSMsgType.TEXT
    assert asyncio.run(connect("/api/ws", None)) == aiohttp.WSMsgType.TEXT  # a script, no Origin
    assert asyncio.run(connect("/api/video", f"http://127.0.0.1:{run.port}")) == aiohttp.WSMsgType.BINARY


def test_every_answer_carries_no_referrer_no_framing_and_the_api_is_not_cached(standing):
    run = standing
    for method, path, body, headers in [("GET", "/", None, {}), ("GET", "/static/console.js", None, {}),
                                        ("GET", "/favicon.ico", None, {}), ("GET", "/static/favicon.svg", None, {}),
                                        ("GET", "/api/state", None, {}), ("GET", "/api/nothing", None, {}),
                                        ("GET", "/api/state", None, {"Host": "evil.example"}),
                                        ("POST", "/api/pause", b"{}", {"Content-Type": "text/plain"}),
                                        ("POST", "/api/teleop", b"{", {"Content-Type": "application/json"})]:
        status, got, _ = request(run, method, path, body, headers)
        assert got.get("referrer-policy") == "no-referrer", (path, status)
        assert got.get("x-content-type-options") == "nosniff" and got.get("x-frame-options") == "DENY"
        csp = got.get("content-security-policy", "")
        assert "frame-ancestors 'none'" in csp and "script-src 'self';" in csp and "unsafe" not in csp
        if path.startswith("/api/"):
            assert got.get("cache-control") == "no-store", path
    assert "set-cookie" not in request(run, "GET", "/?token=x")[1]  # no token on loopback: no cookie to set
    for path in ("/favicon.ico", "/static/favicon.svg"):  # the icon: the package's own SVG, never a 404
        status, got, body = request(run, "GET", path)
        assert status == 200 and got["content-type"] == "image/svg+xml" and str(body).startswith("<svg "), path


# -- malformed numbers and bodies ---------------------------------------------------------------------

def test_malformed_numbers_and_bodies_get_a_clear_4xx_never_a_500(standing):
    run = standing
    huge = "1" + "0" * 400
    bodies = [b'{"linear": ' + huge.encode() + b', "angular": 0, "deadman": true}',
              b'{"linear": 0, "angular": -' + huge.encode() + b', "deadman": true}',
              b'{"linear": ' + b"9" * 3000 + b', "angular": 0, "deadman": true}',
              b'{"linear": 1e400, "angular": 0, "deadman": true}', b'{"linear": NaN, "angular": 0, "deadman": true}',
              b'{"linear": Infinity, "angular": 0, "deadman": true}', b'{"linear": -Infinity, "deadman": true}',
              b'{"linear": 1e308, "angular": 0, "deadman": true}', b'{"linear": "0.5", "angular": 0, "deadman": true}',
              b'{"linear": {"x": 1}, "angular": 0, "deadman": true}', b'{"linear": [1], "deadman": true}',
              b'{"linear": 0.5, "angular": 0, "deadman": 1}', b"[" * 2000 + b"]" * 2000, b'{"a":' * 1500 + b"1" +
              b"}" * 1500, b"\xff\xfe\x00", b"", b"{", b"[0.5, 0, true]", b"x" * 20_000]
    for body in bodies:
        for path in ("/api/teleop", "/api/pause" if body.startswith(b"{\"linear\"") else "/api/answer"):
            status, answer = post(run, path, body)
            if path == "/api/pause" and status == 200:  # a pause takes any well-formed object
                assert post(run, "/api/resume", {})[0] == 200
                continue
            assert 400 <= status < 500, (path, body[:60], status, answer)
            assert isinstance(answer, dict) and "Traceback" not in answer["error"] and len(answer["error"]) < 300
    status, answer = post(run, "/api/teleop", b'{"linear": ' + huge.encode() + b', "angular": 0, "deadman": true}')
    assert status == 400 and "digits" in answer["error"]
    status, answer = post(run, "/api/teleop", b'{"linear": 1e400, "angular": 0, "deadman": true}')
    assert status == 400 and "finite" in answer["error"]
    status, answer = post(run, "/api/teleop", b'{"linear": NaN, "angular": 0, "deadman": true}')
    assert status == 400 and "NaN" in answer["error"]
    status, answer = post(run, "/api/teleop", b"x" * 20_000)
    assert status == 413 and "bytes" in answer["error"]
    run.wait_state(lambda s: s["status"] == "running", 5)
    untouched(run)
    status, answer = post(run, "/api/teleop", {"linear": 0.0, "angular": 0.0, "deadman": False})
    assert status == 200 and answer["driving"] is False  # the same control, well formed, is taken


# -- --console-token always, the cookie -------------------------------------------------------------------

def test_console_token_always_needs_the_token_on_loopback_and_keeps_it_out_of_the_address(console):
    run = console("--console-token", "always")
    assert run.token and len(run.token) >= 16 and run.url.startswith("http://127.0.0.1:")
    for path in ("/", "/api/state", "/api/map"):
        status, _, answer = request(run, "GET", path)
        assert status == 401 and "token" in answer["error"], path
    assert post(run, "/api/estop", {})[0] == 401 and run.state()["estop"] is False
    status, got, page = request(run, "GET", f"/?token={run.token}", None, {"Host": "robot.example:443"})
    assert status == 200 and "E-STOP" in page  # behind a proxy any name: a rebinding page has no token
    cookie = got["set-cookie"]
    assert cookie.startswith(f"beastbt_console_token={run.token};")
    attributes = {a.strip().split("=")[0].lower(): a.strip() for a in cookie.split(";")[1:]}
    assert "httponly" in attributes and attributes["samesite"].lower() == "samesite=strict"
    assert attributes["path"] == "Path=/"
    jar = {"Cookie": f"beastbt_console_token={run.token}"}
    assert request(run, "GET", "/api/state", None, jar)[0] == 200
    # the cookie goes with same-site requests from other ports too: it never stands for the page's Origin
    assert post(run, "/api/pause", {}, Origin=f"http://127.0.0.1:{run.port + 1}", **jar)[0] == 403
    assert post(run, "/api/pause", {}, "text/plain", **jar)[0] == 403
    assert run.state()["status"] == "running"
    assert post(run, "/api/pause", {}, Origin=f"http://127.0.0.1:{run.port}", **jar)[0] == 200
    run.wait_state(lambda s: s["status"] == "paused", 5)
    status, _ = post(run, "/api/resume", {}, "text/plain", Authorization=f"Bearer {run.token}")
    assert status == 200  # the token itself, whatever the body's type: no other page has it
    run.wait_state(lambda s: s["status"] == "running", 5)


def test_console_token_is_checked_on_the_command_line(tmp_path):
    path = tmp_path / "m.yaml"
    path.write_text(WAIT, encoding="utf-8")
    for args, needle in ((["--console-token", "always"], "--console"), (["--console", "0", "--console-token", "x"],
                                                                       "invalid choice")):
        done = subprocess.run([sys.executable, "-m", "beastbt", "run", str(path), "--no-record", *args],
                              capture_output=True, text=True, timeout=60, cwd=tmp_path)
        assert done.returncode == 2 and needle in done.stderr and "Traceback" not in done.stderr


# -- the --stream server -------------------------------------------------------------------------------

def test_the_stream_server_refuses_other_hosts_and_pages_and_sends_no_referrer():
    import numpy as np
    from beastbt.live.video_stream import StreamConfig, VideoStreamServer
    server = VideoStreamServer(StreamConfig(port=0, width_px=160, height_px=120)).start()
    try:
        server.publish(np.full((120, 160, 3), 90, np.uint8))

        def get(path: str, **headers: str) -> tuple[int, dict, bytes]:
            conn = http.client.HTTPConnection("127.0.0.1", server.port, timeout=10)
            conn.putrequest("GET", path, skip_host=True)
            for name, value in {"Host": f"127.0.0.1:{server.port}", **headers}.items():
                conn.putheader(name, value)
            conn.endheaders()
            r = conn.getresponse()
            out = (r.status, {k.lower(): v for k, v in r.getheaders()}, r.read())
            conn.close()
            return out

        for path in ("/", "/status.json", "/snapshot.jpg", "/stream.mjpg"):
            status, headers, body = get(path, Host=f"evil.example:{server.port}")
            assert status == 403 and b"Host" in body and headers["referrer-policy"] == "no-referrer", path
            status, _, _ = get(path, Origin="http://evil.example")
            assert status == 403, path
        for host in (f"localhost:{server.port}", f"127.0.0.1:{server.port}", f"[::1]:{server.port}"):
            status, headers, body = get("/status.json", Host=host)
            assert status == 200 and "stream" in json.loads(body)
            assert headers["referrer-policy"] == "no-referrer" and headers["x-frame-options"] == "DENY"
        assert get("/snapshot.jpg", Origin=f"http://127.0.0.1:{server.port}")[0] == 200
    finally:
        server.close()


def test_a_link_from_another_page_may_open_the_console_but_not_act(standing):
    run = standing
    status, _, page = request(run, "GET", "/", None, {"Sec-Fetch-Site": "cross-site", "Sec-Fetch-Mode": "navigate"})
    assert status == 200 and "E-STOP" in page  # a navigation: the other page cannot read what it opened
    upgrade = {"Upgrade": "websocket", "Connection": "Upgrade", "Sec-WebSocket-Version": "13",
               "Sec-WebSocket-Key": "dGhlIHNhbXBsZSBub25jZQ==", "Sec-Fetch-Site": "cross-site"}
    assert request(run, "GET", "/api/ws", None, upgrade)[0] == 403
    assert request(run, "GET", "/api/ws", None, {**upgrade, "Sec-Fetch-Site": "same-origin"})[0] == 101
    assert post(run, "/api/pause", {}, Sec_Fetch_Site="same-site")[0] == 403
    untouched(run)
