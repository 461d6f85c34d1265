"""Issue 22's "Done when", on loopback: three ``beastbt serve --sim`` robots and a ``beastbt station``.

One station and three robots (separate processes, random free ports), then, in order:
listed within 5 s; a mission to one ends ``success`` while the others stay idle; a plain
Zenoh subscriber on ``beastbt/**`` sees each robot's state at 5 Hz or more; pause and
resume reach a running mission; ``POST /api/estop-all`` stops all three (the moving one's
run ends ``stopped``); ``kill -9`` of one shows it lost within 2 s.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
import urllib.error
from typing import Any

import pytest

from fleet_support import free_port, http, wait_for  # noqa: E402

zenoh = pytest.importorskip("zenoh")

SHORT = "mission: short_hop\nsteps:\n  - drive: {distance: 0.3 m, speed: 0.3 m/s}\n"
LONG = "mission: long_drive\nsteps:\n  - drive: {distance: 20 m, speed: 0.3 m/s}\n"


def robots(base: str) -> dict[str, dict]:
    """The station's robots by name."""
    return {r["name"]: r for r in http("GET", f"{base}/api/robots")[1]["robots"]}


def beastbt(*args: str, cwd: str) -> subprocess.Popen:
    """Start ``python -m beastbt ARGS`` in ``cwd``."""
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    return subprocess.Popen([sys.executable, "-m", "beastbt", *args], cwd=cwd, env=env, stdin=subprocess.DEVNULL,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)


@pytest.fixture
def fleet(tmp_path):
    """A station and three serve --sim robots (alpha, bravo, charlie); stopped afterwards."""
    zport, hport = free_port(), free_port()
    endpoint = f"tcp/127.0.0.1:{zport}"
    procs = {"station": beastbt("station", "--insecure-loopback", "--listen", endpoint, "--console", f"127.0.0.1:{hport}", cwd=str(tmp_path))}
    for name in ("alpha", "bravo", "charlie"):
        procs[name] = beastbt("serve", "--sim", "--insecure-loopback", "--name", name, "--fleet", endpoint, "--speed", "2",
                              "--runs-dir", str(tmp_path / "runs"), cwd=str(tmp_path))
    yield {"base": f"http://127.0.0.1:{hport}", "endpoint": endpoint, "procs": procs, "started": time.monotonic()}
    for proc in procs.values():
        if proc.poll() is None:
            proc.send_signal(signal.SIGTERM)
    for proc in procs.values():
        try:
            proc.wait(10)
        except subprocess.TimeoutExpired:
            proc.kill()


def state_rates(endpoint: str, seconds: float) -> tuple[dict[str, float], dict[str, float]]:
    """States per second of each robot, and the bytes per second of all its keys, as a plain Zenoh client
    subscribed to ``beastbt/**`` sees them."""
    config = zenoh.Config()
    for key, value in {"mode": "client", "connect/endpoints": [endpoint], "scouting/multicast/enabled": False}.items():
        config.insert_json5(key, json.dumps(value))
    seen: dict[str, list[float]] = {}
    volume: dict[str, int] = {}

    def take(sample: Any) -> None:
        key = str(sample.key_expr)
        seen.setdefault(key, []).append(time.monotonic())
        robot = key.split("/")[1]
        volume[robot] = volume.get(robot, 0) + len(sample.payload.to_bytes()) + len(key)
    session = zenoh.open(config)
    try:
        sub = session.declare_subscriber("beastbt/**", take)
        time.sleep(seconds)
        sub.undeclare()
    finally:
        session.close()
    rates = {key.split("/")[1]: (len(t) - 1) / (t[-1] - t[0]) for key, t in seen.items()
             if key.endswith("/state") and len(t) > 1}
    return rates, {robot: n / seconds for robot, n in volume.items()}


def test_three_robots_and_a_station_on_loopback(fleet):
    base = fleet["base"]
    names = {"alpha", "bravo", "charlie"}

    def listed() -> bool:
        try:
            found = robots(base)
        except (urllib.error.URLError, ConnectionError):
            return False
        return names <= {n for n, r in found.items() if r["alive"] and r["status"] == "idle"}
    # the processes start (Python, zenoh, the simulator's imports) and then say they are alive: within 5 s
    wait_for(listed, 5.0 + 3.0, "the station lists all three robots, idle")
    assert time.monotonic() - fleet["started"] < 8.0

    # a mission to one runs and ends success; the others stay idle
    status, answer = http("POST", f"{base}/api/robots/alpha/mission", SHORT.encode(), "application/yaml")
    assert status == 200 and answer["started"] == "short_hop", answer
    done = wait_for(lambda: (robots(base)["alpha"]["last_run"] or {}).get("status"), 15.0, "alpha's mission ends")
    assert done == "success"
    now = robots(base)
    assert now["alpha"]["status"] == "idle"
    assert now["bravo"]["status"] == "idle" and now["bravo"]["last_run"] is None
    assert now["charlie"]["status"] == "idle" and now["charlie"]["last_run"] is None

    # an invalid mission: the positioned errors, as validate prints them, and nothing runs
    status, answer = http("POST", f"{base}/api/robots/charlie/mission",
                          b"mission: bad\nsteps:\n  - drivee: 1 m\n", "application/yaml")
    assert status == 422 and answer["errors"].startswith("mission.yaml:3:5: error: unknown step 'drivee'")

    # a plain Zenoh subscriber on beastbt/** sees each robot's state at 5 Hz or more, under 50 kB/s without video
    rates, volume = state_rates(fleet["endpoint"], 2.0)
    assert names <= set(rates), rates
    assert min(rates[n] for n in names) >= 5.0, rates
    assert max(volume[n] for n in names) < 50_000, volume

    # a long mission on bravo: pause and resume reach it, then the stop-all stops all three
    status, answer = http("POST", f"{base}/api/robots/bravo/mission", LONG.encode(), "application/yaml")
    assert status == 200, answer
    wait_for(lambda: robots(base)["bravo"]["status"] == "running" and robots(base)["bravo"]["pose"]["x"] > 0.05,
             10.0, "bravo drives")
    status, answer = http("POST", f"{base}/api/robots/bravo/pause", b"{}")
    assert status == 200 and answer["paused"] is True
    wait_for(lambda: robots(base)["bravo"]["status"] == "paused", 2.0, "bravo shows paused")
    status, answer = http("POST", f"{base}/api/robots/bravo/resume", b"{}")
    assert status == 200 and answer["paused"] is False
    status, answer = http("POST", f"{base}/api/robots/charlie/pause", b"{}")
    assert status == 409 and "no mission is running" in answer["error"]

    status, answer = http("POST", f"{base}/api/estop-all", b"")
    assert status == 200 and set(answer["robots"]) == names
    stopped = wait_for(lambda: (robots(base)["bravo"]["last_run"] or {}).get("status"), 3.0, "bravo's run ends")
    assert stopped == "stopped"
    wait_for(lambda: all(r["estop"] for r in robots(base).values()), 2.0, "all three show the e-stop latched")
    # an e-stopped robot takes no mission until its e-stop is reset
    status, answer = http("POST", f"{base}/api/robots/alpha/mission", SHORT.encode(), "application/yaml")
    assert status == 409 and "e-stop" in answer["error"]
    status, answer = http("POST", f"{base}/api/robots/alpha/estop_reset", b"{}")
    assert status == 200 and answer["estop"] is False
    wait_for(lambda: not robots(base)["alpha"]["estop"], 2.0, "alpha's state shows the e-stop reset")

    # kill -9 of one: lost within 2 s
    fleet["procs"]["charlie"].kill()
    killed = time.monotonic()
    wait_for(lambda: robots(base)["charlie"]["status"] == "lost", 2.0, "charlie shows lost")
    assert time.monotonic() - killed < 2.0
    lost = robots(base)["charlie"]
    assert lost["alive"] is False
    # those that need a person first: bravo's e-stop is still latched, charlie is lost, alpha is fine
    assert list(robots(base)) == ["bravo", "charlie", "alpha"]
