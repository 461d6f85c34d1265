"""The fleet is safe by default (issue 38): ``beastbt station`` makes its keys, robots join with their enrolment, and a
rogue Zenoh peer on this computer (a plain eclipse-zenoh session, no certificate) can neither command a robot nor
pose as one; plain TCP is an explicit, loud, loopback-only opt-out. Also what an idle robot reports (issue 37, 8).

Every process is on loopback, on free ports; the keys live in this test's folders (``XDG_STATE_HOME``).
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from fleet_support import free_port, http, wait_for  # noqa: E402

zenoh = pytest.importorskip("zenoh")
pytestmark = pytest.mark.skipif(shutil.which("openssl") is None, reason="the station's keys need openssl")

ROGUE_MISSION = b"mission: rogue\nsteps:\n  - drive: {distance: 5 m, speed: 0.3 m/s}\n"


def beastbt(*args: str, state: Path, cwd: Path) -> subprocess.Popen:
    """Start ``python -m beastbt ARGS`` with ``state`` as its per-user state folder (``XDG_STATE_HOME``)."""
    env = {**os.environ, "PYTHONUNBUFFERED": "1", "XDG_STATE_HOME": str(state)}
    return subprocess.Popen([sys.executable, "-m", "beastbt", *args], cwd=str(cwd), env=env,
                            stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def run(*args: str, state: Path, cwd: Path, timeout_s: float = 60.0) -> subprocess.CompletedProcess:
    """Run ``python -m beastbt ARGS`` to its end."""
    env = {**os.environ, "XDG_STATE_HOME": str(state)}
    return subprocess.run([sys.executable, "-m", "beastbt", *args], cwd=str(cwd), env=env, capture_output=True,
                          text=True, timeout=timeout_s, stdin=subprocess.DEVNULL)


def stop(procs) -> dict:
    """SIGTERM each process, then wait for it (kill one that does not end); their outputs."""
    for proc in procs:
        if proc.poll() is None:
            proc.send_signal(signal.SIGTERM)
    out = {}
    for proc in procs:
        try:
            out[proc.pid] = proc.communicate(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            out[proc.pid] = proc.communicate()
    return out


def robots(base: str) -> dict:
    """The station's robots by name."""
    return {r["name"]: r for r in http("GET", f"{base}/api/robots")[1]["robots"]}


@pytest.fixture(scope="module")
def default_fleet(tmp_path_factory):
    """``beastbt station`` as the quick path runs it (no --fleet-config, no keys yet: --listen gives only a port), and
    a simulated robot that joins with the enrolment the station printed, copied to its own state folder."""
    root = tmp_path_factory.mktemp("default-fleet")
    station_state, robot_state = root / "station-state", root / "robot-state"
    zport, hport = free_port(), free_port()
    base = f"http://127.0.0.1:{hport}"
    station = beastbt("station", "--listen", str(zport), "--console", f"127.0.0.1:{hport}", state=station_state,
                      cwd=root)
    procs = [station]
    try:
        keys = station_state / "beastbt" / "fleet"
        wait_for(lambda: station.poll() is not None or (keys / "robot" / "robot.json5").is_file(), 30.0,
                 "the station's keys")
        assert station.poll() is None, station.communicate()
        enrolled = robot_state / "beastbt" / "fleet"  # what the printed enrolment says: its robot/ folder, copied
        enrolled.mkdir(parents=True)
        for f in (keys / "robot").iterdir():
            shutil.copy(f, enrolled / f.name)
        robot = beastbt("serve", "--sim", "--name", "r1", "--fleet", f"tls/127.0.0.1:{zport}", "--runs-dir",
                        str(root / "runs"), state=robot_state, cwd=root)
        procs.append(robot)
        wait_for(lambda: any(p.poll() is not None for p in procs) or
                 (_listening(hport) and robots(base).get("r1", {}).get("alive")), 60.0,
                 "r1 listed, joined with its enrolment")
        assert all(p.poll() is None for p in procs), stop(procs)
        yield {"base": base, "zport": zport, "keys": keys, "station": station, "robot": robot, "root": root}
    finally:
        stop(procs)


def test_the_station_makes_its_keys_and_a_robot_joins_with_the_printed_enrolment(default_fleet):
    keys = default_fleet["keys"]
    config = json.loads((keys / "station.json5").read_text())
    assert config["transport"]["link"]["protocols"] == ["tls"]
    assert config["transport"]["link"]["tls"]["enable_mtls"] is True
    assert config["access_control"]["default_permission"] == "deny"
    assert (keys / "ca.key").stat().st_mode & 0o077 == 0 and keys.stat().st_mode & 0o077 == 0
    assert sorted(p.name for p in (keys / "robot").iterdir()) == ["ca.crt", "robot.crt", "robot.json5", "robot.key"]
    robot_config = json.loads((keys / "robot" / "robot.json5").read_text())
    assert robot_config["transport"]["link"]["tls"]["connect_certificate"] == "robot.crt"  # found beside the file
    assert robots(default_fleet["base"])["r1"]["alive"]


def _rogue_config(endpoint: str, tls: dict | None = None) -> "zenoh.Config":
    """A plain eclipse-zenoh peer that opens whether or not it gets through, as a rogue program would."""
    value = {"mode": "peer", "connect": {"endpoints": [endpoint], "exit_on_failure": False, "timeout_ms": 500},
             "listen": {"endpoints": []}, "scouting": {"multicast": {"enabled": False}}}
    if tls is not None:
        value["transport"] = {"link": {"tls": tls}}
    return zenoh.Config.from_json5(json.dumps(value))


def test_a_rogue_peer_can_neither_command_a_robot_nor_pose_as_one(default_fleet):
    zport, keys, base = default_fleet["zport"], default_fleet["keys"], default_fleet["base"]
    rogues = [_rogue_config(f"tcp/127.0.0.1:{zport}"),  # plain TCP to the station's port
              _rogue_config(f"tls/127.0.0.1:{zport}", {"root_ca_certificate": str(keys / "ca.crt")})]  # no client cert
    for config in rogues:
        session = zenoh.open(config)
        try:
            token = session.liveliness().declare_token("beastbt/spoof/alive")
            time.sleep(0.3)
            answers = {}
            for control in ("estop", "pause", "abort", "estop_reset"):
                answers[control] = list(session.get(f"beastbt/r1/cmd/{control}", payload=b"{}", timeout=0.5))
            answers["mission"] = list(session.get("beastbt/r1/mission", payload=ROGUE_MISSION, timeout=0.5))
            for _ in range(5):
                session.put("beastbt/fleet/estop", "stop")
                session.put("beastbt/spoof/state", json.dumps({"status": "idle", "mission": None}))
                session.put("beastbt/r1/state", json.dumps({"status": "failed", "estop": True}))
                time.sleep(0.1)
            time.sleep(0.6)
            assert all(replies == [] for replies in answers.values()), answers  # nothing reached the robot
            listed = robots(base)
            assert set(listed) == {"r1"}  # no spoofed robot on the station
            r1 = listed["r1"]
            assert r1["alive"] and r1["status"] == "idle" and r1["estop"] is False and r1["mission"] is None
            token.undeclare()
        finally:
            session.close()
    with pytest.raises(zenoh.ZError):  # a client must get through to open: it does not
        zenoh.open(zenoh.Config.from_json5(json.dumps(
            {"mode": "client", "connect": {"endpoints": [f"tcp/127.0.0.1:{zport}"]},
             "scouting": {"multicast": {"enabled": False}}})))


def test_the_station_still_commands_its_robot(default_fleet):
    base = default_fleet["base"]
    status, body = http("POST", f"{base}/api/robots/r1/estop", b"")
    assert status == 200 and body["estop"] is True
    wait_for(lambda: robots(base)["r1"]["estop"], 10.0, "r1 e-stopped by its station")
    status, body = http("POST", f"{base}/api/robots/r1/estop_reset", b"{}")
    assert status == 200, body
    wait_for(lambda: not robots(base)["r1"]["estop"], 10.0, "r1's e-stop reset by its station")


def test_an_idle_simulated_robot_reports_where_it_stands_and_its_battery(default_fleet):
    r1 = robots(default_fleet["base"])["r1"]
    assert r1["status"] == "idle" and r1["mission"] is None
    # no --world: it stands at the default world's start (the origin, facing east), battery full
    assert r1["pose"] == {"x": 0.0, "y": 0.0, "yaw_deg": 0.0, "heading_deg": 90.0}
    assert r1["battery"]["volts"] > 11.0 and 0 < r1["battery"]["percent"] <= 100


def test_plain_tcp_is_an_explicit_loopback_only_opt_out(tmp_path):
    state = tmp_path / "state"
    port = free_port()
    wide = run("station", "--insecure-loopback", "--listen", f"tcp/0.0.0.0:{port}", state=state, cwd=tmp_path)
    assert wide.returncode == 2 and "this computer only" in wide.stderr
    plain = run("station", "--listen", f"tcp/127.0.0.1:{port}", state=state, cwd=tmp_path)
    assert plain.returncode == 2 and "--insecure-loopback" in plain.stderr and "mutual TLS" in plain.stderr
    for args in (["--fleet", f"tcp/127.0.0.1:{port}"],  # plain, not asked for
                 ["--fleet", f"tls/127.0.0.1:{port}"],  # no keys: no enrolment in its state folder
                 ["--insecure-loopback", "--fleet", f"tcp/10.0.0.1:{port}"]):  # plain beyond loopback
        robot = run("serve", "--sim", "--name", "r9", *args, state=state, cwd=tmp_path)
        assert robot.returncode == 2, (args, robot.stderr)
        assert "Traceback" not in robot.stderr
    assert not state.exists()  # a robot makes no keys; nothing was started
    hport = free_port()
    station = beastbt("station", "--insecure-loopback", "--listen", f"tcp/127.0.0.1:{port}", "--console",
                      f"127.0.0.1:{hport}", state=state, cwd=tmp_path)
    try:
        wait_for(lambda: station.poll() is not None or _listening(hport), 30.0, "the insecure station up")
        assert station.poll() is None
    finally:
        _, err = stop([station])[station.pid]
    assert "WARNING: --insecure-loopback" in err and "Any program of any user of this computer" in err


def _listening(port: int) -> bool:
    import socket
    with socket.socket() as s:
        s.settimeout(0.2)
        return s.connect_ex(("127.0.0.1", port)) == 0


def test_a_new_host_remakes_only_the_stations_certificate_and_a_robots_folder_is_never_taken(tmp_path):
    from beastbt.fleet.credentials import ensure_keys, station_names
    keys = tmp_path / "keys"
    assert ensure_keys(keys, ["vm"], "tls/127.0.0.1:7447") == (True, [], [])
    robot_cert = (keys / "robot" / "robot.crt").read_bytes()
    assert ensure_keys(keys, ["vm"], "tls/127.0.0.1:7447") == (False, [], [])  # kept as they are
    assert ensure_keys(keys, ["vm", "station.local", "192.168.1.10"], "tls/0.0.0.0:7447") == (
        False, ["station.local", "192.168.1.10"], [])
    assert {"localhost", "127.0.0.1", "vm", "station.local", "192.168.1.10"} <= set(station_names(keys))
    assert (keys / "robot" / "robot.crt").read_bytes() == robot_cert  # the robots keep their enrolment
    for cert in ("station.crt", "robot.crt"):  # both still of the one CA
        subprocess.run(["openssl", "verify", "-CAfile", str(keys / "ca.crt"), str(keys / cert)], check=True,
                       capture_output=True)
    enrolled = tmp_path / "robot-home"
    shutil.copytree(keys / "robot", enrolled)
    with pytest.raises(FileExistsError, match="no fleet CA"):
        ensure_keys(enrolled, [], "tls/127.0.0.1:7447")  # a station never writes over a robot's enrolment


def test_a_robot_enrolled_later_gets_a_certificate_of_its_own_and_joins_with_it(tmp_path):
    from beastbt.fleet.agent import FleetAgent
    from beastbt.fleet.config import FleetOptions
    from beastbt.fleet.credentials import ensure_keys
    from beastbt.fleet.station import Station
    keys = tmp_path / "keys"
    ensure_keys(keys, [], "tls/127.0.0.1:7447")
    assert ensure_keys(keys, [], "tls/127.0.0.1:7447", ["rc"]) == (False, [], ["rc"])
    assert ensure_keys(keys, [], "tls/127.0.0.1:7447", ["rc"]) == (False, [], [])  # once
    config = json.loads((keys / "station.json5").read_text())
    assert {s["id"]: s["cert_common_names"] for s in config["access_control"]["subjects"]} == {
        "robot-rc": ["rc"], "robots": ["robot"]}
    endpoint = f"tls/127.0.0.1:{free_port()}"
    station = Station(endpoint, str(keys / "station.json5")).open()
    rc = FleetAgent("rc", FleetOptions(endpoint, str(keys / "robot-rc" / "robot.json5"))).start()
    impostor = FleetAgent("rd", FleetOptions(endpoint, str(keys / "robot-rc" / "robot.json5"))).start()
    try:
        wait_for(lambda: any(r["name"] == "rc" and r["alive"] for r in station.table.robots()), 20.0, "rc listed")
        time.sleep(1.0)  # rd's token and states, sent with rc's certificate, never reach the station
        assert {r["name"] for r in station.table.robots()} == {"rc"} and impostor.published > 0
    finally:
        rc.close()
        impostor.close()
        station.close()
