"""The fleet on mutual TLS with the keys of ``beastbt station --init-keys``: robots with the fleet's certificate are
on it; a peer without the credentials is refused; Zenoh's access control lets only the station command robots.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import time

import pytest

from fleet_support import free_port, wait_for  # noqa: E402

zenoh = pytest.importorskip("zenoh")
pytestmark = pytest.mark.skipif(shutil.which("openssl") is None, reason="--init-keys needs the openssl command")

from beastbt.fleet.agent import FleetAgent  # noqa: E402
from beastbt.fleet.config import FleetOptions  # noqa: E402
from beastbt.fleet.station import Station  # noqa: E402


@pytest.fixture(scope="module")
def tls_fleet(tmp_path_factory):
    """Keys from ``beastbt station --init-keys``, a station and a robot's agent on mutual TLS."""
    keys = tmp_path_factory.mktemp("keys")
    shutil.rmtree(keys)
    proc = subprocess.run([sys.executable, "-m", "beastbt", "station", "--init-keys", str(keys)],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    endpoint = f"tls/127.0.0.1:{free_port()}"
    station = Station(endpoint, str(keys / "station.json5")).open()
    agent = FleetAgent("tls-1", FleetOptions(endpoint, str(keys / "robot.json5"))).start()
    wait_for(lambda: any(r["name"] == "tls-1" and r["alive"] for r in station.table.robots()), 5.0, "listed on TLS")
    yield {"keys": keys, "endpoint": endpoint, "station": station, "agent": agent}
    agent.close()
    station.close()


def test_init_keys_writes_a_ca_certificates_configs_and_a_howto(tls_fleet):
    keys = tls_fleet["keys"]
    for name in ("ca.crt", "ca.key", "station.crt", "station.key", "robot.crt", "robot.key", "station.json5",
                 "robot.json5", "README.txt"):
        assert (keys / name).is_file(), name
    assert (keys / "ca.key").stat().st_mode & 0o077 == 0
    station = json.loads((keys / "station.json5").read_text())
    assert station["transport"]["link"]["protocols"] == ["tls"]
    assert station["access_control"]["default_permission"] == "deny"
    again = subprocess.run([sys.executable, "-m", "beastbt", "station", "--init-keys", str(keys)],
                           capture_output=True, text=True, timeout=60)
    assert again.returncode == 2 and "already holds" in again.stderr


def test_the_station_commands_and_stops_a_robot_on_tls(tls_fleet):
    station, agent = tls_fleet["station"], tls_fleet["agent"]
    assert station.ask("beastbt/tls-1/cmd/estop", b"{}", 2.0) == (True, {"ok": True, "estop": True,
                                                                         "running": False})
    assert station.ask("beastbt/tls-1/cmd/estop_reset", b"{}", 2.0)[0] is True
    station.estop_all()
    wait_for(lambda: agent.estop_latched, 2.0, "the stop-all reaches the robot")
    agent.estop_latched = False


def _client(endpoint: str, tls: dict) -> dict:
    return {"mode": "client", "connect": {"endpoints": [endpoint]}, "scouting": {"multicast": {"enabled": False}},
            "transport": {"link": {"tls": tls}}}


def test_a_peer_without_the_credentials_is_refused(tls_fleet):
    endpoint, keys = tls_fleet["endpoint"], tls_fleet["keys"]
    plain = zenoh.Config()
    for key, value in {"mode": "client", "connect/endpoints": [endpoint.replace("tls/", "tcp/")],
                       "scouting/multicast/enabled": False}.items():
        plain.insert_json5(key, json.dumps(value))
    with pytest.raises(zenoh.ZError):
        zenoh.open(plain)  # TLS only: no plain TCP
    no_cert = zenoh.Config.from_json5(json.dumps(_client(endpoint, {"root_ca_certificate": str(keys / "ca.crt")})))
    with pytest.raises(zenoh.ZError):
        zenoh.open(no_cert)  # mutual TLS: a peer with no certificate of the fleet's CA cannot connect


def test_only_the_station_commands_robots(tls_fleet):
    endpoint, keys, agent = tls_fleet["endpoint"], tls_fleet["keys"], tls_fleet["agent"]
    robot = json.loads((keys / "robot.json5").read_text())
    robot["connect"]["endpoints"] = [endpoint]
    session = zenoh.open(zenoh.Config.from_json5(json.dumps(robot)))  # another robot, with the robots' certificate
    try:
        time.sleep(0.3)
        assert list(session.get("beastbt/tls-1/cmd/estop", payload=b"{}", timeout=1.0)) == []
        session.put("beastbt/fleet/estop", "stop")
        seen: list = []
        sub = session.declare_subscriber("beastbt/tls-1/state", lambda s: seen.append(s))
        time.sleep(0.6)
        sub.undeclare()
        assert not agent.estop_latched  # neither its command nor its stop-all reached the robot
        assert seen == []  # and it reads no other robot's state
    finally:
        session.close()


def test_a_robot_with_its_own_certificate_speaks_only_for_itself(tmp_path):
    keys = tmp_path / "keys"
    proc = subprocess.run([sys.executable, "-m", "beastbt", "station", "--init-keys", str(keys), "--robot-name", "ra",
                           "--robot-name", "rb"], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    assert not (keys / "robot.crt").exists() and (keys / "robot-ra.json5").exists()
    endpoint = f"tls/127.0.0.1:{free_port()}"
    station = Station(endpoint, str(keys / "station.json5")).open()
    honest = FleetAgent("ra", FleetOptions(endpoint, str(keys / "robot-ra.json5"))).start()
    impostor = FleetAgent("rb", FleetOptions(endpoint, str(keys / "robot-ra.json5"))).start()  # ra's certificate
    try:
        wait_for(lambda: any(r["name"] == "ra" and r["alive"] for r in station.table.robots()), 5.0, "ra listed")
        time.sleep(1.0)  # rb's token and states, sent with ra's certificate, never reach the station
        assert {r["name"] for r in station.table.robots()} == {"ra"}
        assert honest.published > 0 and impostor.published > 0
    finally:
        honest.close()
        impostor.close()
        station.close()
